"""The UniTac-NV model: every model of a run, for every seed, as one ``nn.Module`` with one ``state_dict``.

:class:`StackedAutoencoders` holds all models of a run (UniTac-NV and the per-sensor baselines) for all seeds
("members"); :meth:`StackedAutoencoders.network` slices one member's model out of it as an ordinary PyTorch network
(:class:`Autoencoder`: ``nn.Linear``, ``nn.ReLU``, ``nn.Dropout``), the network the benchmark's plain loop trains;
``export-model`` writes the same member's layers (:func:`unitac_rig.learning.export.hub_model`). The trainer,
evaluation, translation, geometry and export all use this one model.

At the paper's batch size (64) the networks are so small that PyTorch's per-operation overhead, not arithmetic, sets
the speed of an ordinary loop (one ``nn.Module`` per model, a ``DataLoader``, an optimizer kernel per tensor, one
random number per dropout unit). What the stacked model keeps to stay fast, and why:

* every layer of a model is ONE :class:`StackedLinear`: a weight parameter ``(members, in, out)`` and a bias
  ``(members, 1, out)``, and one ``baddbmm`` runs that layer for every member, so the operation count does not grow
  with the number of seeds;
* the loss (:meth:`StackedAutoencoders.forward`) is the sum over models and members of each one's loss; members share
  no parameter, so autograd's gradient of the sum (``loss.backward()``) is each member's own gradient;
* the L1 losses of all (source, target) sensor pairs of a model are one weighted ``abs().sum()``;
* one fused Adam step updates every parameter tensor (Adam is element-wise, so this equals a separate Adam per model);
* dropout is not ``nn.Dropout``: that draws one number per unit from the global generator, so members would share a
  stream and a seed would train differently stacked than alone. A whole step's masks come from one buffer on the
  device, drawn per member from the member's own generator and sparsely: the dropped positions of a Bernoulli(p)
  sequence are the running sums of geometric gaps, so a fixed number of geometric draws per member (mean + 12 sd +
  50 of the binomial count, or every unit if that is fewer) gives an exact Bernoulli(p) mask unless the gaps run out
  before the buffer's end (probability below 1e-20) - at p = 0.007 about 1/100 of the random numbers of a dense
  mask, with no host round-trip. The streams' states are the module's extra state, so ``state_dict`` carries them.

Each member has its own random streams (initialisation, shuffling in :mod:`unitac_rig.learning.train`, dropout)
derived from its own seed, so a seed trains the same whether it runs alone or stacked with others (tested).

Layout of a frame in the model: the sensor's (n_taxels, 3) frame flattened taxel-major, normalised per channel
(:class:`unitac_rig.learning.data.Normaliser`); the decoder of a group outputs the concatenation of its sensors'
frames in the group's sensor order.

Why one module: the stacked layers, the dropout masks, the masked loss, frozen layers, the checkpoint
state and the plain per-member network all index one (member, layer) layout; apart, each piece would have to
re-explain that layout.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from unitac_rig.errors import ModelError
from unitac_rig.learning.network import (
    UNITAC_GROUP,
    Autoencoder,
    GroupSpec,
    ModelShape,
    StackedLinear,
    baseline_name,
    default_groups,
    head_part,
    stacked_mlp,
)

__all__ = [
    "UNITAC_GROUP",
    "Autoencoder",
    "GroupSpec",
    "ModelShape",
    "StackedAutoencoders",
    "StackedLinear",
    "baseline_name",
    "default_groups",
    "head_part",
]

log = logging.getLogger(__name__)

# Sparse dropout draws this many geometric gaps beyond the binomial mean (in standard deviations, plus a constant),
# which makes running out before the end of the mask buffer rarer than 1e-20 (Chernoff bound).
_GAP_MARGIN_SD = 12.0
_GAP_MARGIN_ABS = 50


def _stream_seed(seed: int, stream: int) -> int:
    """A 63-bit torch seed for one of a member's random streams (2 = dropout), independent across streams."""
    return int(np.random.SeedSequence([seed, stream]).generate_state(1, np.uint64)[0] >> np.uint64(1))


@dataclass(frozen=True)
class _Encoder:
    sensor: str
    layers: tuple[str, ...]  # layer keys, input to latent
    columns: tuple[int, int]  # the sensor's columns in a batch row


@dataclass(frozen=True)
class _Group:
    spec: GroupSpec
    encoders: tuple[_Encoder, ...]
    trunk: tuple[str, ...]  # the decoder's hidden layer keys, latent onwards (ReLU and dropout after each)
    heads: tuple[str, ...]  # its output layer keys, one per head; their outputs concatenated are the group's frames


def _alignment_term(latents: Sequence[torch.Tensor], present: torch.Tensor | None = None) -> torch.Tensor:
    """(members,) mean over sensor pairs of (mean matched latent L1) / (mean L1 to the partner of the next row in
    the batch): scale-free, so the encoders cannot lower it by shrinking their latents (beyond the paper).
    ``present`` (members, rows, sensors of ``latents``): means over the rows that have both sensors' frames."""

    def mean(values: torch.Tensor, weight: torch.Tensor | None) -> torch.Tensor:
        if weight is None:
            return values.mean(dim=-1)
        return (values * weight).sum(dim=-1) / weight.sum(dim=-1).clamp(min=1.0)

    terms = []
    for i in range(len(latents)):
        for j in range(i + 1, len(latents)):
            both = shifted = None
            if present is not None:
                both = present[..., i] * present[..., j]
                shifted = present[..., i] * present[..., j].roll(1, dims=1)
            matched = mean((latents[i] - latents[j]).abs().sum(dim=-1), both)
            unmatched = mean((latents[i] - latents[j].roll(1, dims=1)).abs().sum(dim=-1), shifted)
            terms.append(matched / (unmatched + 1e-6))
    return torch.stack(terms).mean(dim=0)


class StackedAutoencoders(nn.Module):
    """Every group x member of a run, trained in lock-step: one ``nn.Module`` whose ``layers`` (a ``ModuleDict`` of
    :class:`StackedLinear`, keyed ``<group>/<part>/<index>``) are all its parameters.

    ``feature_dims``: sensor -> flattened frame length (n_taxels * 3), in the run's sensor order.
    ``seeds``: one per member; member ``m`` is initialised and dropped out from ``seeds[m]`` alone.
    Build it on its device (``device``): ``.to()`` would leave its dropout streams and caches behind.
    """

    def __init__(
        self,
        feature_dims: Mapping[str, int],
        groups: Sequence[GroupSpec],
        seeds: Sequence[int],
        shape: ModelShape = ModelShape(),
        device: torch.device | str = "cpu",
        *,
        initialise: bool = True,
        frozen: Collection[str] = (),
    ) -> None:
        """``frozen``: layer keys that are never trained (their tensors do not require gradients and the optimizer
        does not hold them), as when a sensor is added to a trained model (:meth:`with_new_sensor`)."""
        super().__init__()
        if not seeds:
            raise ModelError("at least one seed is needed")
        if not 0.0 <= shape.dropout < 1.0:
            raise ModelError(f"dropout must be in [0, 1), got {shape.dropout}")
        self.feature_dims = dict(feature_dims)
        self.sensors = tuple(self.feature_dims)
        self.groups = list(groups)
        self.seeds = [int(s) for s in seeds]
        self.shape = shape
        self.device = torch.device(device)
        self.members = len(self.seeds)
        for group in self.groups:
            unknown = [s for s in group.sensors if s not in self.feature_dims]
            if unknown:
                raise ModelError(f"group {group.name} names unknown sensor(s) {unknown}")

        self._plan, self._layers = self._forward_plan()
        dotted = sorted({name for g in self.groups for name in (g.name, *g.sensors) if "." in name})
        if dotted:  # a state_dict key is "layers.<group>/<part>/<index>.weight": a dot would make it ambiguous
            raise ModelError(f"model and sensor names cannot contain a dot: {', '.join(dotted)}")
        self.layers = nn.ModuleDict(
            {
                k: StackedLinear(self.members, fan_in, fan_out, self.device)
                for k, (fan_in, fan_out) in self._layers.items()
            }
        )
        # plain dicts of the same layers and Parameters: the hot loop looks them up without nn.Module's __getattr__
        self._linear = {k: layer for k, layer in self.layers.items() if isinstance(layer, StackedLinear)}
        self.weights: dict[str, nn.Parameter] = {k: layer.weight for k, layer in self._linear.items()}
        self.biases: dict[str, nn.Parameter] = {k: layer.bias for k, layer in self._linear.items()}
        unknown_frozen = sorted(set(frozen) - set(self._layers))
        if unknown_frozen:
            raise ModelError(f"cannot freeze unknown layer(s) {unknown_frozen}")
        self.frozen = frozenset(frozen)
        for key in self.frozen:
            self.layers[key].requires_grad_(False)
        self._trained_plan = [g for g in self._plan if self._trains(g)]
        self._pair_masks = {g.spec.name: self._pair_mask(g) for g in self._plan}
        self._mask_plans: dict[int, tuple[int, int, dict[str, tuple[int, int, int]]]] = {}
        self._mask_buffers: dict[int, torch.Tensor] = {}
        self._loss_weight_cache: dict[tuple[str, int], torch.Tensor] = {}
        self._dropout_generators = [
            torch.Generator(device=self.device).manual_seed(_stream_seed(seed, 2)) for seed in self.seeds
        ]
        if initialise:
            self._initialise()

    # ---- structure -------------------------------------------------------------------------------------------
    def group(self, name: str) -> GroupSpec:
        for group in self.groups:
            if group.name == name:
                return group
        raise ModelError(f"no model {name!r} in this run", hint=f"models: {', '.join(g.name for g in self.groups)}")

    def _forward_plan(self) -> tuple[list[_Group], dict[str, tuple[int, int]]]:
        """Every group's layer keys (``<group>/<part>/<index>``, part ``enc_<sensor>``, ``dec`` or ``head_<sensors>``
        for an added output layer) and every layer's (fan_in, fan_out), in a fixed order (per group: each sensor's
        encoder, the decoder's hidden layers, its output layers), input to output."""
        columns, start = {}, 0
        for sensor in self.sensors:
            columns[sensor] = (start, start + self.feature_dims[sensor])
            start += self.feature_dims[sensor]
        shapes: dict[str, tuple[int, int]] = {}

        def chain(group: str, part: str, widths: Sequence[int], first: int = 0) -> tuple[str, ...]:
            keys = tuple(f"{group}/{part}/{first + i}" for i in range(len(widths) - 1))
            shapes.update({key: (widths[i], widths[i + 1]) for i, key in enumerate(keys)})
            return keys

        plan, trunk_widths = [], self.shape.trunk_widths
        for g in self.groups:
            encoders = tuple(
                _Encoder(
                    s,
                    chain(g.name, f"enc_{s}", self.shape.encoder_widths(self.feature_dims[s])),
                    columns[s],
                )
                for s in g.sensors
            )
            trunk = chain(g.name, "dec", trunk_widths)
            heads = tuple(
                chain(
                    g.name, head_part(head, h), [trunk_widths[-1], sum(self.feature_dims[s] for s in head)], len(trunk)
                )[0]
                for h, head in enumerate(g.output_heads)
            )
            plan.append(_Group(g, encoders, trunk, heads))
        return plan, shapes

    def _trains(self, group: _Group) -> bool:
        """Whether any layer of ``group`` is trained (a wholly frozen group is left out of the loss)."""
        keys = [k for e in group.encoders for k in e.layers] + [*group.trunk, *group.heads]
        return any(k not in self.frozen for k in keys)

    def _pair_mask(self, group: _Group) -> torch.Tensor | None:
        """(sources, targets) 1.0 where a (source, target) pair's loss reaches a trained layer (the source's
        encoder, the decoder's hidden layers or the target's head), else 0.0; None when every pair does. A pair of
        frozen layers only adds a constant to the loss, so it is left out (and the train loss reads as the loss of
        what is trained)."""
        trunk_trained = any(k not in self.frozen for k in group.trunk)
        head_of = {s: key for key, head in zip(group.heads, group.spec.output_heads, strict=True) for s in head}
        on = torch.tensor(
            [
                [
                    float(
                        trunk_trained
                        or any(k not in self.frozen for k in encoder.layers)
                        or head_of[target] not in self.frozen
                    )
                    for target in group.spec.sensors
                ]
                for encoder in group.encoders
            ]
        )
        return None if bool(on.all()) else on.to(self.device)

    def trainable_parameters(self) -> list[torch.Tensor]:
        """The parameters that are not frozen, in ``parameters()``' order (per layer: weight, bias): what the
        optimizer state refers to."""
        return [p for p in self.parameters() if p.requires_grad]

    @property
    def theta(self) -> torch.Tensor:
        """All parameters as one flat copy (per layer: weight then bias, each member-major), for comparisons."""
        return torch.cat([p.detach().reshape(-1) for p in self.parameters()])

    def _initialise(self, keys: Sequence[str] | None = None, stream: int | None = None) -> None:
        """PyTorch's ``nn.Linear`` default: weights and biases uniform in +-1/sqrt(fan_in), per member, drawn from
        the member's seed (or, for layers added later, its random stream ``stream``) in layer order."""
        with torch.no_grad():
            for member, seed in enumerate(self.seeds):
                generator = torch.Generator().manual_seed(seed if stream is None else _stream_seed(seed, stream))
                for key, (fan_in, fan_out) in self._layers.items():
                    if keys is not None and key not in keys:
                        continue
                    bound = 1.0 / math.sqrt(fan_in)
                    w = torch.empty(fan_in, fan_out).uniform_(-bound, bound, generator=generator)
                    b = torch.empty(1, fan_out).uniform_(-bound, bound, generator=generator)
                    self.weights[key][member].copy_(w)
                    self.biases[key][member].copy_(b)

    def parameter_count(self, group: str) -> int:
        """Parameters of one member of ``group``."""
        return sum(
            fan_in * fan_out + fan_out for k, (fan_in, fan_out) in self._layers.items() if k.startswith(group + "/")
        )

    # ---- dropout masks ---------------------------------------------------------------------------------------
    def _mask_plan(self, rows: int) -> tuple[int, int, dict[str, tuple[int, int, int]]]:
        """Per-member mask buffer for a batch of ``rows``: total units, geometric draws, key -> (offset, rows, width).

        A mask follows every layer except a decoder's output layer (so the latent is dropped out too); a wholly
        frozen group is not run in training and gets none.
        """
        if rows in self._mask_plans:
            return self._mask_plans[rows]
        plan: dict[str, tuple[int, int, int]] = {}
        offset = 0
        for group in self._trained_plan:
            for encoder in group.encoders:
                for key in encoder.layers:
                    width = self._layers[key][1]
                    plan[key] = (offset, rows, width)
                    offset += rows * width
            dec_rows = rows * len(group.encoders)
            for key in group.trunk:
                width = self._layers[key][1]
                plan[key] = (offset, dec_rows, width)
                offset += dec_rows * width
        mean = offset * self.shape.dropout
        draws = min(offset, math.ceil(mean + _GAP_MARGIN_SD * math.sqrt(mean) + _GAP_MARGIN_ABS))
        self._mask_plans[rows] = (offset, draws, plan)
        return self._mask_plans[rows]

    def draw_masks(self, rows: int) -> dict[str, torch.Tensor] | None:
        """Dropout masks for one step on a batch of ``rows``: layer key -> (members, rows, width) holding 0 (dropped)
        or 1 / (1 - p) (kept); None without dropout. Advances each member's dropout stream. The masks are views of
        one buffer that the next draw for the same batch size overwrites."""
        p = self.shape.dropout
        if p == 0.0:
            return None
        total, draws, plan = self._mask_plan(rows)
        gaps = torch.empty(self.members, draws, dtype=torch.float64, device=self.device)
        for member, generator in enumerate(self._dropout_generators):
            gaps[member].geometric_(p, generator=generator)  # trials up to and including the next drop, >= 1
        # dropped positions = running sums of the gaps, minus one; past the end lands in a spare last column
        positions = gaps.cumsum_(dim=1).sub_(1.0).clamp_(max=total).long()
        buffer = self._mask_buffers.get(rows)
        if buffer is None:  # reused: a fresh CPU allocation of this size costs more in page faults than the fill
            buffer = self._mask_buffers[rows] = torch.empty((self.members, total + 1), device=self.device)
        buffer.fill_(1.0 / (1.0 - p)).scatter_(1, positions, 0.0)
        return {
            key: buffer[:, off : off + n * width].view(self.members, n, width) for key, (off, n, width) in plan.items()
        }

    # ---- forward / loss --------------------------------------------------------------------------------------
    def _mlp(
        self, keys: Sequence[str], h: torch.Tensor, masks: Mapping[str, torch.Tensor] | None, *, hidden: bool = False
    ) -> torch.Tensor:
        """:func:`~unitac_rig.learning.network.stacked_mlp` over the layers ``keys``, each layer's output multiplied
        by its dropout mask when there is one."""

        def drop(i: int, x: torch.Tensor) -> torch.Tensor:
            mask = masks.get(keys[i]) if masks is not None else None
            return x if mask is None else x * mask

        return stacked_mlp([self._linear[k] for k in keys], h, hidden=hidden, dropout=drop if masks else None)

    def _decode(self, group: _Group, z: torch.Tensor, masks: Mapping[str, torch.Tensor] | None) -> torch.Tensor:
        """The group's decoder: hidden layers, then every output head (no ReLU, no dropout), concatenated."""
        h = self._mlp(group.trunk, z, masks, hidden=True)
        outs = [self._linear[key](h) for key in group.heads]
        return outs[0] if len(outs) == 1 else torch.cat(outs, dim=-1)

    def forward(
        self,
        batch: torch.Tensor,
        masks: Mapping[str, torch.Tensor] | None = None,
        present: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """The loss of every (group, member), a (groups, members) tensor (0 for a wholly frozen group), on ``batch``
        (members, B, sum of feature dims), normalised, sensor order.

        Loss per group: sum over (source, target) sensor pairs of the MAE of target's frame reconstructed from the
        source's latent. ``masks`` (from :meth:`draw_masks`) are the dropout masks; None runs without dropout.
        ``present`` (members, B, sensors) is 1.0 where a row has that sensor's frame and 0.0 where the contact was not
        recorded with it (the frame's columns must then hold finite filler, e.g. 0): each pair's MAE is then taken
        over the rows that have both sensors (the masked loss). Pairs and groups whose layers are all frozen are left
        out.
        """
        zero = torch.zeros(self.members, device=self.device)
        return torch.stack(
            [self._group_loss(g, batch, masks, present) if g in self._trained_plan else zero for g in self._plan]
        )

    def train_step(
        self,
        batch: torch.Tensor,
        optimizer: torch.optim.Optimizer,
        masks: Mapping[str, torch.Tensor] | None = None,
        present: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """One optimisation step of every member on ``batch`` (see :meth:`forward`); in training mode (the default,
        ``nn.Module.train()``) with this step's own dropout masks unless ``masks`` are given. Returns the detached
        (groups, members) losses; the gradients stay in the parameters' ``.grad``."""
        if masks is None and self.training:
            masks = self.draw_masks(batch.shape[1])
        optimizer.zero_grad(set_to_none=True)
        with torch.enable_grad():
            losses = self(batch, masks, present)
            losses.sum().backward()
        optimizer.step()
        return losses.detach()

    def _group_loss(
        self,
        group: _Group,
        batch: torch.Tensor,
        masks: Mapping[str, torch.Tensor] | None,
        present: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(members,) sum over the group's (source, target) pairs of the per-pair MAE."""
        members, rows, _ = batch.shape
        encoded = [self._mlp(e.layers, batch[..., e.columns[0] : e.columns[1]], masks) for e in group.encoders]
        latent = encoded[0] if len(encoded) == 1 else torch.cat(encoded, dim=1)
        recon = self._decode(group, latent, masks)
        if len(group.encoders) == len(self.sensors):
            target = batch
        else:
            target = torch.cat([batch[..., e.columns[0] : e.columns[1]] for e in group.encoders], dim=-1)
        diff = recon.view(members, len(group.encoders), rows, -1) - target.unsqueeze(1)
        pairs = self._pair_masks[group.spec.name]
        if present is None and pairs is None:
            loss = (diff.abs() * self._loss_weights(group.spec, rows)).sum(dim=(1, 2, 3))
        else:
            loss = (diff.abs() * self._masked_loss_weights(group, present, pairs, rows)).sum(dim=(1, 2, 3))
        if self.shape.align_weight > 0.0 and len(encoded) > 1:
            group_present = None
            if present is not None:
                group_present = present[..., [self.sensors.index(s) for s in group.spec.sensors]].to(torch.float32)
            loss = loss + self.shape.align_weight * _alignment_term(encoded, group_present)
        return loss

    def _masked_loss_weights(
        self, group: _Group, present: torch.Tensor | None, pairs: torch.Tensor | None, rows: int
    ) -> torch.Tensor:
        """(members, sources, rows, output columns): weight of each |error| so that the loss is the sum over the
        pairs ``pairs`` selects of each pair's MAE over the rows where ``present`` has both sensors."""
        sensors = [self.sensors.index(s) for s in group.spec.sensors]
        if present is None:
            p = torch.ones(self.members, rows, len(sensors), device=self.device)
        else:
            p = present[..., sensors].to(self.device, torch.float32)  # (members, rows, S)
        both = torch.einsum("mrs,mrt->mst", p, p)  # rows that have source s and target t
        per_pair = (pairs if pairs is not None else 1.0) / both.clamp(min=1.0)  # (members, S, S)
        column_sensor = torch.cat(
            [torch.full((self.feature_dims[s],), i, dtype=torch.long) for i, s in enumerate(group.spec.sensors)]
        ).to(self.device)
        inverse_features = torch.cat(
            [torch.full((self.feature_dims[s],), 1.0 / self.feature_dims[s]) for s in group.spec.sensors]
        ).to(self.device)
        column_weight = per_pair[:, :, column_sensor] * inverse_features  # (members, S, F)
        row_weight = p.transpose(1, 2).unsqueeze(-1) * p[:, :, column_sensor].unsqueeze(1)  # (members, S, rows, F)
        return row_weight * column_weight.unsqueeze(2)

    def _loss_weights(self, group: GroupSpec, rows: int) -> torch.Tensor:
        """Weight of |error| per output column in the sum of per-pair MAEs: 1 / (rows * that sensor's features)."""
        key = (group.name, rows)
        if key not in self._loss_weight_cache:
            self._loss_weight_cache[key] = torch.cat(
                [torch.full((self.feature_dims[s],), 1.0 / (rows * self.feature_dims[s])) for s in group.sensors]
            ).to(self.device)
        return self._loss_weight_cache[key]

    # ---- inference -------------------------------------------------------------------------------------------
    @torch.no_grad()
    def encode(self, group: str, sensor: str, x: torch.Tensor) -> torch.Tensor:
        """Latents (members, M, latent) of normalised frames ``x`` (M, F) or (members, M, F); no dropout."""
        spec = self._group_plan(group)
        for encoder in spec.encoders:
            if encoder.sensor == sensor:
                return self._mlp(encoder.layers, self._broadcast(x), None)
        raise ModelError(
            f"model {group} has no encoder for {sensor!r}", hint=f"it encodes {', '.join(spec.spec.sensors)}"
        )

    @torch.no_grad()
    def decode(self, group: str, z: torch.Tensor) -> dict[str, torch.Tensor]:
        """Every sensor's normalised frame (members, M, F_s) from latents (members, M, latent)."""
        spec = self._group_plan(group)
        out = self._decode(spec, self._broadcast(z), None)
        frames, start = {}, 0
        for sensor in spec.spec.sensors:
            stop = start + self.feature_dims[sensor]
            frames[sensor] = out[..., start:stop]
            start = stop
        return frames

    def _group_plan(self, name: str) -> _Group:
        spec = self.group(name)
        return next(g for g in self._plan if g.spec == spec)

    def _broadcast(self, x: torch.Tensor) -> torch.Tensor:
        x = x.to(self.device, torch.float32)
        if x.dim() == 2:
            return x.unsqueeze(0).expand(self.members, -1, -1)
        if x.shape[0] != self.members:
            raise ModelError(f"expected {self.members} member batches, got {x.shape[0]}")
        return x

    # ---- state -----------------------------------------------------------------------------------------------
    def make_optimizer(self, lr: float) -> torch.optim.Adam:
        """One fused Adam over every trainable parameter tensor (the ``foreach`` kernel where fused is not
        available); frozen layers are not in it, so no step can move them."""
        parameters = self.trainable_parameters()
        if not parameters:
            raise ModelError("every layer of this model is frozen: there is nothing to train")
        try:
            return torch.optim.Adam(parameters, lr=lr, fused=True)
        except (RuntimeError, ValueError):  # pragma: no cover - builds without fused Adam on this device
            return torch.optim.Adam(parameters, lr=lr, foreach=True)

    def state(self) -> dict[str, Any]:
        """Structure and ``state_dict`` (parameters and dropout streams) as tensors and plain Python values (no
        pickled objects): what a checkpoint stores as ``engine``."""
        return {
            "feature_dims": dict(self.feature_dims),
            "groups": [g.to_dict() for g in self.groups],
            "seeds": list(self.seeds),
            "shape": self.shape.to_dict(),
            "frozen": sorted(self.frozen),
            "state_dict": {
                k: v.detach().cpu().clone() if isinstance(v, torch.Tensor) else v for k, v in self.state_dict().items()
            },
        }

    def get_extra_state(self) -> dict[str, Any]:
        """Each member's dropout stream (so ``state_dict`` resumes the same masks), tagged with its device kind."""
        return {"device": self.device.type, "states": [g.get_state() for g in self._dropout_generators]}

    @classmethod
    def from_state(cls, state: Mapping[str, Any], device: torch.device | str = "cpu") -> StackedAutoencoders:
        """The model a :meth:`state` describes."""
        engine = cls(
            state["feature_dims"],
            [GroupSpec.from_dict(g) for g in state["groups"]],
            state["seeds"],
            ModelShape.from_dict(state["shape"]),
            device,
            initialise=False,
            frozen=[str(k) for k in state.get("frozen", ())],
        )
        tensors = dict(state["state_dict"])
        try:
            engine.load_state_dict({k: torch.as_tensor(v) if k != "_extra_state" else v for k, v in tensors.items()})
        except (RuntimeError, TypeError, ValueError) as exc:
            raise ModelError(
                "checkpoint parameters do not match the model they describe", hint="the file is damaged"
            ) from exc
        return engine

    def set_extra_state(self, saved: Any) -> None:
        """Continue each member's dropout stream where the checkpoint left it, when it was drawn on this kind of
        device (a CPU stream cannot continue on a GPU); otherwise the streams restart from the seeds."""
        if isinstance(saved, Mapping) and saved.get("device") == self.device.type:
            for generator, rng_state in zip(self._dropout_generators, saved["states"], strict=True):
                generator.set_state(torch.as_tensor(rng_state))
        else:
            log.warning("the dropout streams restart from the seeds: the checkpoint's were drawn elsewhere")

    def member(self, index: int, groups: Sequence[str] | None = None) -> StackedAutoencoders:
        """A one-member copy of member ``index`` (optionally only some groups), e.g. for inference."""
        keep = [g for g in self.groups if groups is None or g.name in groups]
        kept = {g.name for g in keep}
        single = StackedAutoencoders(
            self.feature_dims,
            keep,
            [self.seeds[index]],
            self.shape,
            self.device,
            initialise=False,
            frozen=[k for k in self.frozen if k.split("/", 1)[0] in kept],
        )
        with torch.no_grad():
            for key in single._layers:
                single.weights[key][0].copy_(self.weights[key][index])
                single.biases[key][0].copy_(self.biases[key][index])
        return single

    def network(self, group: str, member: int, dropout: float | None = None) -> Autoencoder:
        """Member ``member``'s model ``group`` as an ordinary PyTorch network (:class:`Autoencoder`), a copy of its
        weights: ``dropout`` None keeps the run's (``nn.Dropout`` where this model drops out), 0 leaves it out."""
        spec = self.group(group)
        net = Autoencoder(self.feature_dims, spec, self.shape, dropout).to(self.device)
        for key, linear in net.linears().items():
            self._linear[f"{group}/{key}"].copy_into(linear, member)
        return net

    def with_new_sensor(self, sensor: str, feature_dim: int, group: str = UNITAC_GROUP) -> StackedAutoencoders:
        """This engine with ``sensor`` added to ``group``: its own encoder and its own decoder output layer (head),
        freshly initialised per member (from the member's seed); every existing layer copied and frozen. Training
        the result moves only the new encoder and head against the frozen decoder trunk, so what the model already
        does for its sensors stays bit-for-bit the same."""
        if sensor in self.feature_dims:
            raise ModelError(f"the model already has sensor {sensor!r}", hint="name the sensor to add")
        spec = self.group(group)
        grown_groups = [
            GroupSpec(g.name, (*g.sensors, sensor), (*g.output_heads, (sensor,))) if g.name == spec.name else g
            for g in self.groups
        ]
        grown = StackedAutoencoders(
            {**self.feature_dims, sensor: int(feature_dim)},
            grown_groups,
            self.seeds,
            self.shape,
            self.device,
            initialise=False,
            frozen=set(self._layers) | self.frozen,
        )
        grown._initialise([k for k in grown._layers if k not in self._layers], stream=5)
        grown._dropout_generators = [  # its own dropout stream, not a replay of the trained run's first epochs
            torch.Generator(device=self.device).manual_seed(_stream_seed(seed, 6)) for seed in self.seeds
        ]
        with torch.no_grad():
            for key in self._layers:
                grown.weights[key].copy_(self.weights[key])
                grown.biases[key].copy_(self.biases[key])
        return grown

    def layer_parameters(self, group: str, member: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Weights (in, out) and biases (out,) of one member's layers, keyed ``enc_<sensor>/<i>`` / ``dec/<i>``."""
        return self._per_layer(group, member, lambda t: t.detach())

    def layer_gradients(self, group: str, member: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The last step's gradients, shaped and keyed like :meth:`layer_parameters`."""

        def grad(t: torch.Tensor) -> torch.Tensor:
            if t.grad is None:
                raise ModelError("no gradients yet", hint="run train_step first")
            return t.grad

        return self._per_layer(group, member, grad)

    def _per_layer(self, group: str, member: int, pick: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        out = {}
        for key in self._layers:
            g, part, index = key.split("/")
            if g == group:
                weight, bias = pick(self.weights[key]), pick(self.biases[key])
                out[f"{part}/{index}"] = (weight[member].cpu().numpy().copy(), bias[member, 0].cpu().numpy().copy())
        return out
