"""YARDSTICK BEING RETIRED: the hand-written training engine that :mod:`unitac_rig.learning.engine` replaced.

Kept only so ``benchmarks/bench_training.py`` can measure, in the same run, what computing the gradients by autograd
costs against writing the backward out by hand. Nothing in the package trains with it; delete this module together
with the benchmark's "legacy" column once that comparison is no longer wanted.

It is the engine as it stood before the change (git history: ``unitac_rig/learning/engine.py`` before the autograd
trainer), trimmed to what training needs: every model of a run in ONE flat parameter tensor viewed per layer as
(members, in, out), forward and backward written by hand (``baddbmm`` / ``bmm`` / ``threshold_backward``, no autograd
graph), gradients written straight into one flat buffer, one fused Adam step, and dropout masks drawn on the host
with numpy (a binomial count, then that many distinct positions) and copied to the device. It starts from the same
initial parameters as the autograd engine for the same seeds (same per-seed generator, same layer order).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from unitac_rig.errors import ModelError
from unitac_rig.learning.engine import GroupSpec, ModelShape


@dataclass(frozen=True)
class _Layer:
    key: str
    fan_in: int
    fan_out: int
    w_offset: int
    b_offset: int


class LegacyStackedAutoencoders:
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

    # ---- optimizer -------------------------------------------------------------------------------------------
    def make_optimizer(self, lr: float) -> torch.optim.Adam:
        """One fused Adam over the flat parameters (the ``foreach`` kernel where fused is not available)."""
        try:
            return torch.optim.Adam([self.theta], lr=lr, fused=True)
        except (RuntimeError, ValueError):  # pragma: no cover - builds without fused Adam on this device
            return torch.optim.Adam([self.theta], lr=lr, foreach=True)
