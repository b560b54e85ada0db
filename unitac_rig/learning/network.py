"""The model's shape and its one multilayer perceptron, as ordinary PyTorch.

:class:`ModelShape` (layer widths, dropout) and :class:`GroupSpec` (which sensors one autoencoder encodes) describe
every model of a run. :func:`mlp` is the MLP of this package for one member (``nn.Linear``, ``nn.ReLU``,
``nn.Dropout``); :class:`StackedLinear` and :func:`stacked_mlp` are the same layers and forward with a members
dimension, so the trainer (:class:`unitac_rig.learning.engine.StackedAutoencoders`) and the geometry head
(:mod:`unitac_rig.learning.contact_geometry`) train every seed or sensor at once; ``StackedAutoencoders.network`` and
the saved geometry head hand one member back as the plain :func:`mlp`. :class:`Autoencoder` is one member of one
group; :class:`UniTacNV` is what ``export-model`` writes and ``stream`` runs."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import torch
from huggingface_hub import PyTorchModelHubMixin
from torch import nn

from unitac_rig.errors import ModelError

UNITAC_GROUP = "unitac"


@dataclass(frozen=True)
class ModelShape:
    """Layer widths and dropout of every autoencoder (the paper's values by default)."""

    encoder_hidden: tuple[int, ...] = (64, 48)
    latent_dim: int = 16
    decoder_hidden: tuple[int, ...] = (64, 96)
    dropout: float = 0.007
    # beyond the paper: weight of a scale-free alignment term (matched / shifted-partner latent L1) in the loss
    align_weight: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def encoder_widths(self, features: int) -> list[int]:
        """A sensor's encoder, frame (``features`` = n_taxels * 3) to latent."""
        return [features, *self.encoder_hidden, self.latent_dim]

    @property
    def trunk_widths(self) -> list[int]:
        """The decoder's hidden layers (shared by every sensor), latent onwards."""
        return [self.latent_dim, *self.decoder_hidden]

    def decoder_widths(self, features: int) -> list[int]:
        """The decoder for one sensor's frame, latent to ``features``."""
        return [*self.trunk_widths, features]

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ModelShape:
        return cls(**{**d, "encoder_hidden": tuple(d["encoder_hidden"]), "decoder_hidden": tuple(d["decoder_hidden"])})


@dataclass(frozen=True)
class GroupSpec:
    """One autoencoder: an encoder per sensor in ``sensors`` and one decoder that outputs all of them.

    UniTac-NV is the group of every sensor; a per-sensor baseline is a group of one.
    """

    name: str
    sensors: tuple[str, ...]
    # The decoder's output layers, each for some of ``sensors`` (in order); () means one layer for all of them. A
    # sensor added to a trained model gets its own output layer (its "head") beside the frozen original one.
    heads: tuple[tuple[str, ...], ...] = ()

    def __post_init__(self) -> None:
        if self.heads and tuple(s for head in self.heads for s in head) != tuple(self.sensors):
            raise ModelError(f"group {self.name}: heads {self.heads} do not list its sensors {self.sensors} in order")

    @property
    def output_heads(self) -> tuple[tuple[str, ...], ...]:
        return self.heads or (tuple(self.sensors),)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "sensors": list(self.sensors)}
        if len(self.output_heads) > 1:
            out["heads"] = [list(head) for head in self.heads]
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GroupSpec:
        heads = tuple(tuple(str(s) for s in head) for head in d.get("heads") or ())
        return cls(str(d["name"]), tuple(str(s) for s in d["sensors"]), heads if len(heads) > 1 else ())


def head_part(head: Sequence[str], index: int) -> str:
    """Layer-key part of a decoder output layer: ``dec`` for the first (the original model's), ``head_<sensors>``
    for a head added later, so a trained model's keys never change when a sensor is added."""
    return "dec" if index == 0 else "head_" + "+".join(head)


def baseline_name(sensor: str) -> str:
    return f"ae_{sensor}"


def default_groups(sensors: Sequence[str], baselines: bool) -> list[GroupSpec]:
    groups = [GroupSpec(UNITAC_GROUP, tuple(sensors))]
    if baselines:
        groups += [GroupSpec(baseline_name(s), (s,)) for s in sensors]
    return groups


def mlp(widths: Sequence[int], dropout: float = 0.0, *, hidden: bool = False) -> nn.Sequential:
    """THE multilayer perceptron of this package, one member: ``nn.Linear`` layers of ``widths``, ReLU between them
    (after the last too when ``hidden``) and ``nn.Dropout`` after every layer (when ``dropout`` > 0). The exported
    model, ``stream``, the per-seed network and the saved geometry head are built by it; :func:`stacked_mlp` runs
    the same layers for many members at once."""
    modules: list[nn.Module] = []
    for i in range(len(widths) - 1):
        modules.append(nn.Linear(widths[i], widths[i + 1]))
        if hidden or i < len(widths) - 2:
            modules.append(nn.ReLU())
        if dropout > 0.0:
            modules.append(nn.Dropout(dropout))
    return nn.Sequential(*modules)


class StackedLinear(nn.Module):
    """``members`` independent ``nn.Linear`` layers of one shape, run by one ``baddbmm``: ``weight`` (members, in,
    out) and ``bias`` (members, 1, out). Member ``m`` computes ``x @ weight[m] + bias[m]``, i.e. ``nn.Linear`` with
    ``weight[m].T``."""

    def __init__(self, members: int, fan_in: int, fan_out: int, device: torch.device | str = "cpu") -> None:
        super().__init__()
        self.weight = nn.Parameter(torch.zeros(members, fan_in, fan_out, device=device))
        self.bias = nn.Parameter(torch.zeros(members, 1, fan_out, device=device))

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        """(members, rows, in) -> (members, rows, out)."""
        return torch.baddbmm(self.bias, h, self.weight)

    def copy_into(self, linear: nn.Linear, member: int) -> nn.Linear:
        """Member ``member``'s layer written into ``linear``."""
        with torch.no_grad():
            linear.weight.copy_(self.weight[member].T)
            linear.bias.copy_(self.bias[member, 0])
        return linear


def stacked_mlp(
    layers: Sequence[StackedLinear],
    h: torch.Tensor,
    *,
    hidden: bool = False,
    dropout: Callable[[int, torch.Tensor], torch.Tensor] | None = None,
) -> torch.Tensor:
    """:func:`mlp`'s forward for every member at once: (members, rows, in) -> (members, rows, out), ReLU between the
    layers (after the last too when ``hidden``); ``dropout(i, h)`` (when given) drops out layer ``i``'s output, from
    each member's own random stream (the trainer's sparse masks, the geometry head's per-sensor rate)."""
    last = len(layers) if hidden else len(layers) - 1
    for i, layer in enumerate(layers):
        h = layer(h)
        if i < last:
            h = torch.relu_(h)  # in place on baddbmm's output, which its backward does not need
        if dropout is not None:
            h = dropout(i, h)
    return h


class Autoencoder(nn.Module):
    """One member of one group (UniTac-NV, or a per-sensor baseline) as ordinary PyTorch: what
    :meth:`StackedAutoencoders.network` slices out and what the training benchmark's plain loop trains.

    ``encoders[sensor]``: frames (B, F) -> latent, ``nn.Linear`` with ReLU between and ``nn.Dropout`` after every
    layer (the latent's too); ``decoder``: the hidden layers, each followed by ReLU and dropout; ``heads``: the output
    layers (no ReLU, no dropout), whose outputs side by side are the group's sensors' frames in order.
    """

    def __init__(
        self, feature_dims: Mapping[str, int], spec: GroupSpec, shape: ModelShape, dropout: float | None = None
    ) -> None:
        super().__init__()
        p = shape.dropout if dropout is None else dropout
        self.sensors = tuple(spec.sensors)
        self.output_heads = spec.output_heads
        self.feature_dims = {s: int(feature_dims[s]) for s in spec.sensors}
        trunk = shape.trunk_widths
        self.encoders = nn.ModuleDict({s: mlp(shape.encoder_widths(d), p) for s, d in self.feature_dims.items()})
        self.decoder = mlp(trunk, p, hidden=True)
        self.heads = nn.ModuleList(
            nn.Linear(trunk[-1], sum(self.feature_dims[s] for s in head)) for head in self.output_heads
        )

    def linears(self) -> dict[str, nn.Linear]:
        """Every layer keyed as in :meth:`StackedAutoencoders.layer_parameters` (``enc_<sensor>/<i>``, ``dec/<i>``,
        ``head_<sensors>/<i>``)."""
        out: dict[str, nn.Linear] = {}
        for sensor, mlp in self.encoders.items():
            out |= {f"enc_{sensor}/{i}": m for i, m in enumerate(linear_layers(mlp))}
        hidden = linear_layers(self.decoder)
        out |= {f"dec/{i}": m for i, m in enumerate(hidden)}
        for h, (head, linear) in enumerate(zip(self.output_heads, linear_layers(self.heads), strict=True)):
            out[f"{head_part(head, h)}/{len(hidden)}"] = linear
        return out

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Latents (B, latent) -> every sensor's frame side by side (B, sum of feature dims)."""
        h = self.decoder(z)
        return torch.cat([head(h) for head in self.heads], dim=-1)

    def forward(self, inputs: Sequence[torch.Tensor]) -> list[torch.Tensor]:
        """Per source sensor (in order), the reconstruction of every sensor's frame from its latent."""
        return [self.decode(self.encoders[s](x)) for s, x in zip(self.sensors, inputs, strict=True)]

    def loss(self, inputs: Sequence[torch.Tensor]) -> torch.Tensor:
        """The training loss: the sum over (source, target) of MAE(target frame, its reconstruction from the
        source's latent)."""
        total = torch.zeros((), device=inputs[0].device)
        for recon in self(inputs):
            for target, estimate in zip(inputs, recon.split(list(self.feature_dims.values()), dim=-1), strict=True):
                total = total + nn.functional.l1_loss(estimate, target)
        return total


def linear_layers(module: nn.Module) -> list[nn.Linear]:
    """The ``nn.Linear`` layers of ``module``, in order."""
    return [m for m in module.modules() if isinstance(m, nn.Linear)]


class UniTacNV(
    nn.Module,
    PyTorchModelHubMixin,
    library_name="unitac-rig",
    pipeline_tag="feature-extraction",
    tags=["tactile", "robotics", "cross-sensor", "unitac-nv"],
):
    """One member of a trained UniTac-NV model as ``export-model`` writes it: per sensor an encoder (frames (B,
    n_taxels, 3) in the sensor's units -> latent) and a decoder (latent -> that sensor's frames), each a plain
    :func:`mlp` with the normaliser folded into its first/last layer, so nothing happens outside the networks.

    ``UniTacNV.from_pretrained(folder_or_repo)`` (huggingface_hub's mixin) rebuilds it from ``config.json``'s
    ``sensors`` (each sensor's ``n_taxels``, ``encoder_widths``, ``decoder_widths``) and loads ``model.safetensors``;
    ``stream`` runs the same module on live frames.
    """

    def __init__(self, sensors: dict[str, dict[str, Any]], latent_dim: int) -> None:
        super().__init__()
        self.latent_dim = int(latent_dim)
        self.n_taxels = {s: int(spec["n_taxels"]) for s, spec in sensors.items()}
        self.encoders = nn.ModuleDict({s: mlp(spec["encoder_widths"]) for s, spec in sensors.items()})
        self.decoders = nn.ModuleDict({s: mlp(spec["decoder_widths"]) for s, spec in sensors.items()})
        self.eval()

    @property
    def sensors(self) -> tuple[str, ...]:
        return tuple(self.encoders)

    def _known(self, sensor: str) -> None:
        if sensor not in self.encoders:
            raise ModelError(f"this model knows no sensor {sensor!r}", hint=f"it has {', '.join(self.sensors)}")

    def encode(self, frames: torch.Tensor, sensor: str) -> torch.Tensor:
        """Frames (B, n_taxels, 3) of ``sensor``, tare-subtracted, its units -> latents (B, latent_dim)."""
        self._known(sensor)
        return self.encoders[sensor](frames.reshape(frames.shape[0], -1))

    def decode(self, latent: torch.Tensor, sensor: str) -> torch.Tensor:
        """Latents (B, latent_dim) -> frames (B, n_taxels, 3) of ``sensor`` in its units."""
        self._known(sensor)
        return self.decoders[sensor](latent).reshape(latent.shape[0], self.n_taxels[sensor], 3)

    def forward(self, frames: torch.Tensor, source: str, target: str) -> torch.Tensor:
        """``source`` frames (B, n_taxels, 3) -> the same contacts as ``target`` frames."""
        return self.decode(self.encode(frames, source), target)
