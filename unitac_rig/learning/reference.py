"""The same UniTac-NV model written the ordinary way (``nn.Module``, autograd).

It is the yardstick for the stacked engine: ``unitac_rig/bench/training.py`` trains it in the textbook loop
(``DataLoader``, standard Adam, one model at a time) against :class:`StackedAutoencoders` on the same data and batch
size, and tests check that both compute the same function and the same gradients, dropout included. It
shares no code with the engine's forward pass: one module per model and seed, ``nn.Linear`` layers, ``nn.Dropout``
(or explicit keep masks that it rescales itself) and one ``l1_loss`` per (source, target) pair. A per-sensor baseline
autoencoder is a ``UniTacModule`` of that one sensor.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch
from torch import nn

from unitac_rig.learning.engine import UNITAC_GROUP, ModelShape, StackedAutoencoders


def _mlp(widths: Sequence[int], dropout: float, dropout_after_last: bool) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(widths) - 1):
        layers.append(nn.Linear(widths[i], widths[i + 1]))
        last = i == len(widths) - 2
        if not last:
            layers.append(nn.ReLU())
        if not last or dropout_after_last:
            layers.append(nn.Dropout(dropout))
    return nn.Sequential(*layers)


def _run(mlp: nn.Module, h: torch.Tensor, keep: Mapping[str, torch.Tensor] | None, prefix: str) -> torch.Tensor:
    """``mlp(h)``, with each ``nn.Dropout`` replaced by ``keep[f"{prefix}/{i}"] / (1 - p)`` (i = index of the
    linear layer it follows) when ``keep`` is given."""
    linear = -1
    for module in mlp.children():
        if isinstance(module, nn.Linear):
            linear += 1
        if isinstance(module, nn.Dropout) and keep is not None:
            h = h * keep[f"{prefix}/{linear}"].to(h.dtype) / (1.0 - module.p)
        else:
            h = module(h)
    return h


class UniTacModule(nn.Module):
    """One encoder per sensor, one shared decoder that outputs every sensor's (flattened, normalised) frame."""

    def __init__(self, feature_dims: Mapping[str, int], shape: ModelShape = ModelShape()) -> None:
        super().__init__()
        self.sensors = tuple(feature_dims)
        self.feature_dims = dict(feature_dims)
        self.encoders = nn.ModuleDict(
            {
                s: _mlp([d, *shape.encoder_hidden, shape.latent_dim], shape.dropout, dropout_after_last=True)
                for s, d in feature_dims.items()
            }
        )
        self.decoder = _mlp([shape.latent_dim, *shape.decoder_hidden, sum(feature_dims.values())], shape.dropout, False)

    def forward(
        self, inputs: Sequence[torch.Tensor], keep: Mapping[str, torch.Tensor] | None = None
    ) -> list[torch.Tensor]:
        """Reconstructions of all sensors (B, sum F) from each sensor's latent, in sensor order.

        ``keep`` replaces the ``nn.Dropout`` draws with given masks (True = kept; kept units are scaled by 1/(1-p)
        here): ``enc_<sensor>/<i>`` (B, width) after encoder layer i, ``dec_<source>/<i>`` (B, width) after decoder
        layer i when decoding ``source``'s latent.
        """
        out = []
        for sensor, x in zip(self.sensors, inputs, strict=True):
            z = _run(self.encoders[sensor], x, keep, f"enc_{sensor}")
            out.append(_run(self.decoder, z, keep, f"dec_{sensor}"))
        return out

    def loss(self, inputs: Sequence[torch.Tensor], keep: Mapping[str, torch.Tensor] | None = None) -> torch.Tensor:
        """Sum over (source, target) of MAE(target frame, its reconstruction from the source's latent)."""
        target = torch.cat(list(inputs), dim=1)
        total = torch.zeros(())
        for recon in self.forward(inputs, keep):
            start = 0
            for sensor in self.sensors:
                stop = start + self.feature_dims[sensor]
                total = total + nn.functional.l1_loss(recon[:, start:stop], target[:, start:stop])
                start = stop
        return total

    def load_from_engine(self, engine: StackedAutoencoders, member: int = 0, group: str = UNITAC_GROUP) -> None:
        """Copy the weights of one engine member's model ``group`` (UniTac-NV or a baseline) into this module."""
        params = engine.layer_parameters(group, member)
        with torch.no_grad():
            for sensor in self.sensors:
                encoder = self.encoders[sensor]
                assert isinstance(encoder, nn.Sequential)
                linears = [m for m in encoder if isinstance(m, nn.Linear)]
                for i, linear in enumerate(linears):
                    weight, bias = params[f"enc_{sensor}/{i}"]
                    linear.weight.copy_(torch.from_numpy(weight.T))
                    linear.bias.copy_(torch.from_numpy(bias))
            for i, linear in enumerate(m for m in self.decoder if isinstance(m, nn.Linear)):
                weight, bias = params[f"dec/{i}"]
                linear.weight.copy_(torch.from_numpy(weight.T))
                linear.bias.copy_(torch.from_numpy(bias))
