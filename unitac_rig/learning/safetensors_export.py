"""``export-model --format safetensors`` (the default): the Hub layout, ``model.safetensors`` + ``config.json`` +
``README.md``, loadable with torch and safetensors alone.

``model.safetensors`` holds, per sensor of the run, the encoder's and the decoder's linear layers in order:
``encoder.<sensor>.<i>.weight`` (out, in) and ``.bias``, likewise ``decoder.<sensor>.<i>.*``, float32, with ReLU
between layers and none after the last. The normaliser is folded in exactly as for the other formats
(:func:`unitac_rig.learning.export.encoder_module`): frames in, frames out, each in the sensor's own units.
``config.json`` says the shapes (layer widths, frame shape), the folded normaliser, units, taxel layout and the training
data's content hash; the card's loading code builds the networks from it (safetensors files hold tensors only, never
code, which is why the Hub prefers them to pickles and TorchScript).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from unitac_rig.learning.engine import UNITAC_GROUP, StackedAutoencoders
from unitac_rig.learning.train import LoadedRun

WEIGHTS_NAME = "model.safetensors"
CONFIG_NAME = "config.json"
PARTS = ("encoder", "decoder")


def _linears(module: nn.Sequential) -> list[nn.Linear]:
    return [m for m in module if isinstance(m, nn.Linear)]


def export_into(run: LoadedRun, engine: StackedAutoencoders, staging: Path, member: int) -> dict[str, Any]:
    """Write model.safetensors, config.json and README.md into ``staging``; returns the config document."""
    from safetensors.torch import save_file

    from unitac_rig.learning.export import (
        CARD_NAME,
        EXPORT_FORMAT,
        EXPORT_VERSION,
        _layout,
        _sha256,
        _units,
        decoder_module,
        encoder_module,
        run_fields,  # export.py dispatches here: imported when used
    )

    sensors = engine.group(UNITAC_GROUP).sensors
    latent = engine.shape.latent_dim
    tensors: dict[str, torch.Tensor] = {}
    entries: dict[str, Any] = {}
    for sensor in sensors:
        n_taxels = engine.feature_dims[sensor] // 3
        mean, std = run.normaliser.mean[sensor], run.normaliser.std[sensor]
        modules = {"encoder": encoder_module(engine, mean, std, sensor, member),
                   "decoder": decoder_module(engine, mean, std, sensor, member)}  # fmt: skip
        for part, module in modules.items():
            for i, linear in enumerate(_linears(module)):
                tensors[f"{part}.{sensor}.{i}.weight"] = linear.weight.detach().to(torch.float32).contiguous()
                tensors[f"{part}.{sensor}.{i}.bias"] = linear.bias.detach().to(torch.float32).contiguous()
        entries[sensor] = {
            "n_taxels": n_taxels,
            "frame_shape": [n_taxels, 3],
            "units": _units(sensor),
            "layout": _layout(sensor),
            "encoder_widths": [n_taxels * 3, *engine.shape.encoder_hidden, latent],
            "decoder_widths": [latent, *engine.shape.decoder_hidden, n_taxels * 3],
            "encoder": f"encoder.{sensor}.*",  # tensors encoder.<sensor>.<i>.weight and .bias, layer i in order
            "decoder": f"decoder.{sensor}.*",
            "normaliser_folded_in": {
                "mean": np.asarray(mean, dtype=float).tolist(),
                "std": np.asarray(std, dtype=float).tolist(),
                "mode": getattr(run.normaliser, "mode", "channel_z"),
            },
        }
    payload = run.payload
    metadata = {"format": "pt", "producer": "unitac-rig", "dataset_hash": str(payload["dataset_hash"])}
    save_file(tensors, str(staging / WEIGHTS_NAME), metadata=metadata)
    metrics_path = run.run_dir / "metrics.json"
    metrics = json.loads(metrics_path.read_text(encoding="utf-8")) if metrics_path.is_file() else None
    document: dict[str, Any] = {
        "format": EXPORT_FORMAT,
        "version": EXPORT_VERSION,
        "export_format": "safetensors",
        "model": "UniTac-NV (Hou et al., IROS 2025): one encoder per sensor, one shared decoder",
        "weights": WEIGHTS_NAME,
        "architecture": "per sensor and part: Linear(widths[i], widths[i+1]) for each i, ReLU between them; the "
        "encoder flattens (B, n_taxels, 3) first, the decoder's output is reshaped to (B, n_taxels, 3)",
        "latent_dim": latent,
        "sensors": entries,
        "tensors": {name: list(t.shape) for name, t in tensors.items()},
        "frame": "(B, n_taxels, 3) float32, tare-subtracted, sensor units; taxel i at (row, col) = divmod(i, cols); "
        "channels x, y, z",
        "translate": "decoder_<target>(encoder_<source>(frames))",
        **run_fields(payload, engine, member),
        "files": {WEIGHTS_NAME: _sha256(staging / WEIGHTS_NAME)},
    }
    (staging / CONFIG_NAME).write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    (staging / CARD_NAME).write_text(render_card(document, metrics), encoding="utf-8")
    return document


LOADER = '''import json

import torch
from safetensors.torch import load_file

config = json.load(open("config.json"))
weights = load_file("model.safetensors")


def network(part, sensor):
    """part "encoder": frames (B, n_taxels, 3) -> latent (B, 16); "decoder": latent -> frames (B, n_taxels, 3)."""
    spec = config["sensors"][sensor]
    widths = spec[part + "_widths"]
    layers = [torch.nn.Flatten(1)] if part == "encoder" else []
    for i in range(len(widths) - 1):
        linear = torch.nn.Linear(widths[i], widths[i + 1])
        linear.load_state_dict({"weight": weights[f"{part}.{sensor}.{i}.weight"],
                                "bias": weights[f"{part}.{sensor}.{i}.bias"]})
        layers += [linear, torch.nn.ReLU()]
    layers.pop()  # no ReLU after the last layer
    if part == "decoder":
        layers.append(torch.nn.Unflatten(1, (spec["n_taxels"], 3)))
    return torch.nn.Sequential(*layers).eval()
'''


def render_card(document: dict[str, Any], metrics: dict[str, Any] | None) -> str:
    """The Hub model card: YAML front matter, then the shared card of export.py with safetensors loading code."""
    from unitac_rig.learning.export import render_card as shared_card

    names = list(document["sensors"])
    source, target = (names[0], names[1]) if len(names) > 1 else (names[0], names[0])
    src = document["sensors"][source]
    front = [
        "---",
        "library_name: pytorch",
        "tags: [tactile, robotics, cross-sensor, unitac-nv, safetensors]",
        "---",
        "",
    ]
    body = shared_card(document, metrics)
    head, _, _ = body.partition("## How to load")
    loading = [
        "## How to load",
        "",
        "Needs only `torch` and `safetensors` (`pip install torch safetensors`); run in this directory:",
        "",
        "```python",
        LOADER.rstrip(),
        "",
        "",
        f'encoder, decoder = network("encoder", "{source}"), network("decoder", "{target}")',
        f"frames = torch.zeros(1, {src['n_taxels']}, 3)  # {source} frames, {src['units']}",
        "with torch.no_grad():",
        f"    latent = encoder(frames)  # (1, {document['latent_dim']})",
        f"    translated = decoder(latent)  # {target} frames, {document['sensors'][target]['units']}",
        "```",
        "",
        f"`{CONFIG_NAME}` lists every sensor's shape, units, layer widths and the folded normaliser, every tensor's "
        f"shape, and the SHA-256 of `{WEIGHTS_NAME}`.",
        "",
    ]
    return "\n".join(front) + "\n" + head + "\n".join(loading)
