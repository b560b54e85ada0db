"""A fast CPU/GPU engine for the UniTac-NV autoencoders: every model of a run in one flat parameter tensor.

Why not ``nn.Module`` + autograd: at the paper's batch size (64) the networks are so small that PyTorch's per-op
overhead (autograd bookkeeping, DataLoader collation, one optimizer kernel per tensor, one RNG call per dropout
layer) costs more than the arithmetic. Here

* all models (UniTac-NV and the per-sensor baselines) and all seeds ("members") live in one contiguous tensor; each
  layer is a view of shape (members, in, out), so one ``baddbmm`` runs a layer of every member at once;
* forward and backward are written out by hand (ReLU MLPs with dropout and an MAE loss have short, exact
  gradients), so there is no autograd graph; gradients land directly in one flat buffer;
* one fused Adam step updates everything (Adam is element-wise, so this equals a separate Adam per model);
* dropout masks for a whole step come from one buffer: with p = 0.007 the dropped positions are drawn directly
  (a binomial count, then that many distinct positions), which is an exact Bernoulli(p) mask at a fraction of
  the cost of one uniform number per unit.

Each member has its own random streams (initialisation, shuffling, dropout) seeded from its own seed.

Layout of a frame in the model: the sensor's (n_taxels, 3) frame flattened taxel-major, normalised per channel
(:class:`unitac_rig.learning.data.Normaliser`); the decoder of a group outputs the concatenation of its sensors'
frames in the group's sensor order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import ModelError

UNITAC_GROUP = "unitac"


@dataclass(frozen=True)
class ModelShape:
    """Layer widths and dropout of every autoencoder (the paper's values by default)."""

    encoder_hidden: tuple[int, ...] = (64, 48)
    latent_dim: int = 16
    decoder_hidden: tuple[int, ...] = (64, 96)
    dropout: float = 0.007

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ModelShape:
        return cls(
            encoder_hidden=tuple(int(x) for x in d["encoder_hidden"]),
            latent_dim=int(d["latent_dim"]),
            decoder_hidden=tuple(int(x) for x in d["decoder_hidden"]),
            dropout=float(d["dropout"]),
        )


@dataclass(frozen=True)
class GroupSpec:
    """One autoencoder: an encoder per sensor in ``sensors`` and one decoder that outputs all of them.

    UniTac-NV is the group of every sensor; a per-sensor baseline is a group of one.
    """

    name: str
    sensors: tuple[str, ...]


def baseline_name(sensor: str) -> str:
    return f"ae_{sensor}"


def default_groups(sensors: Sequence[str], baselines: bool) -> list[GroupSpec]:
    groups = [GroupSpec(UNITAC_GROUP, tuple(sensors))]
    if baselines:
        groups += [GroupSpec(baseline_name(s), (s,)) for s in sensors]
    return groups


@dataclass(frozen=True)
class _Layer:
    key: str
    fan_in: int
    fan_out: int
    w_offset: int
    b_offset: int


class StackedAutoencoders:
    """Every group x member of a run, trained in lock-step.

    ``feature_dims``: sensor -> flattened frame length (n_taxels * 3), in the run's sensor order.
    ``seeds``: one per member; member ``m`` is initialised, shuffled and dropped out from ``seeds[m]`` alone.
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
    ) -> None:
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

        self._layers: dict[str, _Layer] = {}
        offset = 0
        for key, fan_in, fan_out in self._layer_plan():
            w_offset = offset
            offset += self.members * fan_in * fan_out
            b_offset = offset
            offset += self.members * fan_out
            self._layers[key] = _Layer(key, fan_in, fan_out, w_offset, b_offset)
        self.theta = torch.zeros(offset, dtype=torch.float32, device=self.device)
        self.grad = torch.zeros_like(self.theta)
        self.theta.grad = self.grad
        self._param_views = {k: self._views(self.theta, layer) for k, layer in self._layers.items()}
        self._grad_views = {k: self._views(self.grad, layer) for k, layer in self._layers.items()}
        self._mask_plans: dict[int, tuple[int, dict[str, tuple[int, int, int]]]] = {}
        self._dropout_rngs = [np.random.default_rng([seed, 2]) for seed in self.seeds]
        self._weight_cache: dict[tuple[str, int], torch.Tensor] = {}
        if initialise:
            self._initialise()

    # ---- structure -------------------------------------------------------------------------------------------
    def group(self, name: str) -> GroupSpec:
        for group in self.groups:
            if group.name == name:
                return group
        raise ModelError(f"no model {name!r} in this run", hint=f"models: {', '.join(g.name for g in self.groups)}")

    def _encoder_widths(self, sensor: str) -> list[int]:
        return [self.feature_dims[sensor], *self.shape.encoder_hidden, self.shape.latent_dim]

    def _decoder_widths(self, group: GroupSpec) -> list[int]:
        out = sum(self.feature_dims[s] for s in group.sensors)
        return [self.shape.latent_dim, *self.shape.decoder_hidden, out]

    @staticmethod
    def _key(group: str, part: str, index: int) -> str:
        return f"{group}/{part}/{index}"

    def _layer_plan(self) -> list[tuple[str, int, int]]:
        plan = []
        for group in self.groups:
            for sensor in group.sensors:
                widths = self._encoder_widths(sensor)
                plan += [
                    (self._key(group.name, f"enc_{sensor}", i), widths[i], widths[i + 1])
                    for i in range(len(widths) - 1)
                ]
            widths = self._decoder_widths(group)
            plan += [(self._key(group.name, "dec", i), widths[i], widths[i + 1]) for i in range(len(widths) - 1)]
        return plan

    def _views(self, flat: torch.Tensor, layer: _Layer) -> tuple[torch.Tensor, torch.Tensor]:
        m, i, o = self.members, layer.fan_in, layer.fan_out
        weight = flat[layer.w_offset : layer.w_offset + m * i * o].view(m, i, o)
        bias = flat[layer.b_offset : layer.b_offset + m * o].view(m, 1, o)
        return weight, bias

    def _stack(self, group: str, part: str, n_layers: int) -> list[tuple[torch.Tensor, torch.Tensor]]:
        return [self._param_views[self._key(group, part, i)] for i in range(n_layers)]

    def _grad_stack(self, group: str, part: str, n_layers: int) -> list[tuple[torch.Tensor, torch.Tensor]]:
        return [self._grad_views[self._key(group, part, i)] for i in range(n_layers)]

    @property
    def _n_enc(self) -> int:
        return len(self.shape.encoder_hidden) + 1

    @property
    def _n_dec(self) -> int:
        return len(self.shape.decoder_hidden) + 1

    def _initialise(self) -> None:
        """PyTorch's ``nn.Linear`` default: weights and biases uniform in +-1/sqrt(fan_in), per member."""
        for member, seed in enumerate(self.seeds):
            generator = torch.Generator().manual_seed(seed)
            for key, layer in self._layers.items():
                bound = 1.0 / math.sqrt(layer.fan_in)
                weight, bias = self._param_views[key]
                w = torch.empty(layer.fan_in, layer.fan_out).uniform_(-bound, bound, generator=generator)
                b = torch.empty(1, layer.fan_out).uniform_(-bound, bound, generator=generator)
                weight[member].copy_(w)
                bias[member].copy_(b)

    def parameter_count(self, group: str) -> int:
        """Parameters of one member of ``group``."""
        return sum(
            lay.fan_in * lay.fan_out + lay.fan_out for k, lay in self._layers.items() if k.startswith(group + "/")
        )

    # ---- dropout masks ---------------------------------------------------------------------------------------
    def _mask_plan(self, batch: int) -> tuple[int, dict[str, tuple[int, int, int]]]:
        """Per-member mask buffer layout for a batch size: key -> (offset, rows, width)."""
        if batch in self._mask_plans:
            return self._mask_plans[batch]
        plan: dict[str, tuple[int, int, int]] = {}
        offset = 0
        for group in self.groups:
            for sensor in group.sensors:
                for i, width in enumerate([*self.shape.encoder_hidden, self.shape.latent_dim]):
                    plan[self._key(group.name, f"enc_{sensor}", i)] = (offset, batch, width)
                    offset += batch * width
            rows = batch * len(group.sensors)
            for i, width in enumerate(self.shape.decoder_hidden):
                plan[self._key(group.name, "dec", i)] = (offset, rows, width)
                offset += rows * width
        self._mask_plans[batch] = (offset, plan)
        return offset, plan

    def _draw_masks(self, batch: int) -> dict[str, torch.Tensor] | None:
        p = self.shape.dropout
        if p == 0.0:
            return None
        total, plan = self._mask_plan(batch)
        buffer = torch.full((self.members, total), 1.0 / (1.0 - p), device=self.device)
        dropped = []
        for member, rng in enumerate(self._dropout_rngs):
            count = int(rng.binomial(total, p))
            if count:
                dropped.append(rng.choice(total, size=count, replace=False) + member * total)
        if dropped:
            index = torch.from_numpy(np.concatenate(dropped)).to(self.device)
            buffer.view(-1).index_fill_(0, index, 0.0)
        return {
            key: buffer[:, off : off + rows * width].view(self.members, rows, width)
            for key, (off, rows, width) in plan.items()
        }

    # ---- forward / backward ----------------------------------------------------------------------------------
    @staticmethod
    def _mlp_forward(
        layers: list[tuple[torch.Tensor, torch.Tensor]],
        h: torch.Tensor,
        masks: list[torch.Tensor | None],
        keep_inputs: bool,
    ) -> tuple[torch.Tensor, list[torch.Tensor]]:
        """ReLU between layers, dropout after every layer whose mask is given; returns output and layer inputs."""
        inputs: list[torch.Tensor] = []
        last = len(layers) - 1
        for k, (weight, bias) in enumerate(layers):
            if keep_inputs:
                inputs.append(h)
            h = torch.baddbmm(bias, h, weight)
            if k < last:
                h = torch.relu_(h)
            mask = masks[k]
            if mask is not None:
                h = h.mul_(mask)
        return h, inputs

    def _mlp_backward(
        self,
        layers: list[tuple[torch.Tensor, torch.Tensor]],
        grads: list[tuple[torch.Tensor, torch.Tensor]],
        inputs: list[torch.Tensor],
        masks: list[torch.Tensor | None],
        grad_out: torch.Tensor,
        need_input_grad: bool,
    ) -> torch.Tensor | None:
        """Writes every layer's weight/bias gradient; returns d(loss)/d(input) when asked."""
        scale = 1.0 / (1.0 - self.shape.dropout)
        last = len(layers) - 1
        dy = grad_out
        last_mask = masks[last]
        if last_mask is not None:
            dy = dy * last_mask
        for k in range(last, -1, -1):
            weight, _ = layers[k]
            grad_w, grad_b = grads[k]
            torch.bmm(inputs[k].transpose(1, 2), dy, out=grad_w)
            torch.sum(dy, dim=1, keepdim=True, out=grad_b)
            if k == 0:
                return torch.bmm(dy, weight.transpose(1, 2)) if need_input_grad else None
            dy = torch.bmm(dy, weight.transpose(1, 2))
            # inputs[k] = relu(pre) * mask: zero where it is zero (ReLU off or dropped), else times the mask scale.
            dy = torch.ops.aten.threshold_backward(dy, inputs[k], 0.0)
            if masks[k - 1] is not None:
                dy = dy.mul_(scale)
        return None

    def train_step(self, batch: torch.Tensor, optimizer: torch.optim.Optimizer) -> torch.Tensor:
        """One optimisation step on ``batch`` (members, B, sum of feature dims), normalised, sensor order.

        Loss per group: sum over (source, target) sensor pairs of the MAE of target's frame reconstructed from the
        source's latent. Returns the loss of every (group, member) as a (groups, members) tensor.
        """
        members, rows, _ = batch.shape
        masks = self._draw_masks(rows)
        losses = []
        columns = self._columns()
        for group in self.groups:
            name = group.name
            encoded, caches = [], []
            for sensor in group.sensors:
                part = f"enc_{sensor}"
                start, stop = columns[sensor]
                layer_masks = [masks[self._key(name, part, i)] if masks else None for i in range(self._n_enc)]
                z, inputs = self._mlp_forward(
                    self._stack(name, part, self._n_enc), batch[..., start:stop], layer_masks, True
                )
                encoded.append(z)
                caches.append((part, inputs, layer_masks))
            latent = encoded[0] if len(encoded) == 1 else torch.cat(encoded, dim=1)
            dec_masks: list[torch.Tensor | None] = [
                masks[self._key(name, "dec", i)] if masks else None for i in range(self._n_dec - 1)
            ]
            dec_masks.append(None)
            recon, dec_inputs = self._mlp_forward(self._stack(name, "dec", self._n_dec), latent, dec_masks, True)
            target = self._group_target(batch, group, columns)
            n_src = len(group.sensors)
            diff = recon.view(members, n_src, rows, -1) - target.unsqueeze(1)
            weights = self._loss_weights(group, rows)
            grad_recon = torch.sign(diff).mul_(weights)
            losses.append((grad_recon * diff).sum(dim=(1, 2, 3)))  # = sum of |diff| * weight
            grad_recon = grad_recon.view(members, n_src * rows, -1)
            grad_latent = self._mlp_backward(
                self._stack(name, "dec", self._n_dec),
                self._grad_stack(name, "dec", self._n_dec),
                dec_inputs,
                dec_masks,
                grad_recon,
                need_input_grad=True,
            )
            assert grad_latent is not None
            for i, (part, inputs, layer_masks) in enumerate(caches):
                self._mlp_backward(
                    self._stack(name, part, self._n_enc),
                    self._grad_stack(name, part, self._n_enc),
                    inputs,
                    layer_masks,
                    grad_latent[:, i * rows : (i + 1) * rows],
                    need_input_grad=False,
                )
        optimizer.step()
        return torch.stack(losses)

    def _columns(self) -> dict[str, tuple[int, int]]:
        columns, start = {}, 0
        for sensor in self.sensors:
            columns[sensor] = (start, start + self.feature_dims[sensor])
            start += self.feature_dims[sensor]
        return columns

    def _group_target(self, batch: torch.Tensor, group: GroupSpec, columns: dict[str, tuple[int, int]]) -> torch.Tensor:
        if group.sensors == self.sensors:
            return batch
        return torch.cat([batch[..., columns[s][0] : columns[s][1]] for s in group.sensors], dim=-1)

    def _loss_weights(self, group: GroupSpec, rows: int) -> torch.Tensor:
        """d(sum of per-pair MAEs)/d|error| per output column: 1 / (rows * features of that column's sensor)."""
        cache = self._weight_cache
        key = (group.name, rows)
        if key not in cache:
            cache[key] = torch.cat(
                [torch.full((self.feature_dims[s],), 1.0 / (rows * self.feature_dims[s])) for s in group.sensors]
            ).to(self.device)
        return cache[key]

    # ---- inference -------------------------------------------------------------------------------------------
    @torch.no_grad()
    def encode(self, group: str, sensor: str, x: torch.Tensor) -> torch.Tensor:
        """Latents (members, M, latent) of normalised frames ``x`` (M, F) or (members, M, F); no dropout."""
        spec = self.group(group)
        if sensor not in spec.sensors:
            raise ModelError(
                f"model {group} has no encoder for {sensor!r}", hint=f"it encodes {', '.join(spec.sensors)}"
            )
        h = self._broadcast(x)
        out, _ = self._mlp_forward(self._stack(group, f"enc_{sensor}", self._n_enc), h, [None] * self._n_enc, False)
        return out

    @torch.no_grad()
    def decode(self, group: str, z: torch.Tensor) -> dict[str, torch.Tensor]:
        """Every sensor's normalised frame (members, M, F_s) from latents (members, M, latent)."""
        spec = self.group(group)
        out, _ = self._mlp_forward(
            self._stack(group, "dec", self._n_dec), self._broadcast(z), [None] * self._n_dec, False
        )
        frames, start = {}, 0
        for sensor in spec.sensors:
            stop = start + self.feature_dims[sensor]
            frames[sensor] = out[..., start:stop]
            start = stop
        return frames

    def _broadcast(self, x: torch.Tensor) -> torch.Tensor:
        x = x.to(self.device, torch.float32)
        if x.dim() == 2:
            return x.unsqueeze(0).expand(self.members, -1, -1)
        if x.shape[0] != self.members:
            raise ModelError(f"expected {self.members} member batches, got {x.shape[0]}")
        return x

    # ---- state -----------------------------------------------------------------------------------------------
    def make_optimizer(self, lr: float) -> torch.optim.Adam:
        """One fused Adam over the flat parameters (the ``foreach`` kernel where fused is not available)."""
        try:
            return torch.optim.Adam([self.theta], lr=lr, fused=True)
        except (RuntimeError, ValueError):  # pragma: no cover - builds without fused Adam on this device
            return torch.optim.Adam([self.theta], lr=lr, foreach=True)

    def state(self) -> dict[str, Any]:
        return {
            "feature_dims": dict(self.feature_dims),
            "groups": [{"name": g.name, "sensors": list(g.sensors)} for g in self.groups],
            "seeds": list(self.seeds),
            "shape": self.shape.to_dict(),
            "theta": self.theta.detach().cpu().clone(),
            "dropout_rng": [rng.bit_generator.state for rng in self._dropout_rngs],
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any], device: torch.device | str = "cpu") -> StackedAutoencoders:
        engine = cls(
            state["feature_dims"],
            [GroupSpec(g["name"], tuple(g["sensors"])) for g in state["groups"]],
            state["seeds"],
            ModelShape.from_dict(state["shape"]),
            device,
            initialise=False,
        )
        theta = torch.as_tensor(state["theta"])
        if theta.shape != engine.theta.shape:
            raise ModelError("checkpoint parameters do not match the model they describe", hint="the file is damaged")
        engine.theta.copy_(theta)
        for rng, rng_state in zip(engine._dropout_rngs, state.get("dropout_rng", []), strict=False):
            rng.bit_generator.state = rng_state
        return engine

    def member(self, index: int, groups: Sequence[str] | None = None) -> StackedAutoencoders:
        """A one-member copy of member ``index`` (optionally only some groups), e.g. for inference."""
        keep = [g for g in self.groups if groups is None or g.name in groups]
        single = StackedAutoencoders(
            self.feature_dims, keep, [self.seeds[index]], self.shape, self.device, initialise=False
        )
        for key in single._layers:
            weight, bias = single._param_views[key]
            src_w, src_b = self._param_views[key]
            weight[0].copy_(src_w[index])
            bias[0].copy_(src_b[index])
        return single

    def layer_parameters(self, group: str, member: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Weights (in, out) and biases (out,) of one member's layers, keyed ``enc_<sensor>/<i>`` / ``dec/<i>``."""
        out = {}
        for key in self._layers:
            g, part, index = key.split("/")
            if g == group:
                weight, bias = self._param_views[key]
                out[f"{part}/{index}"] = (weight[member].cpu().numpy().copy(), bias[member, 0].cpu().numpy().copy())
        return out
