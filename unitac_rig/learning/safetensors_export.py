"""``export-model --format safetensors`` (the default): the Hugging Face Hub layout, ``model.safetensors`` +
``config.json`` + ``README.md``, written by huggingface_hub's ``PyTorchModelHubMixin`` from
:class:`unitac_rig.learning.network.UniTacNV`, so ``UniTacNV.from_pretrained(folder_or_repo)`` rebuilds the module from
``config.json`` and loads the weights (safetensors files hold tensors only, never code: the Hub prefers them to
pickles and TorchScript). The normaliser is folded in exactly as for the other formats
(:func:`unitac_rig.learning.export.encoder_module`): frames in, frames out, each in the sensor's own units.

``config.json`` holds the constructor's arguments (``sensors``: per sensor ``n_taxels`` and layer widths;
``latent_dim``) and beside them what a user needs to trust the file: units, taxel layout, the folded normaliser, the
training data's content hash, provenance and the SHA-256 of the weights. :func:`push_to_hub` uploads such a folder.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.errors import UsageError
from unitac_rig.learning.engine import UNITAC_GROUP, StackedAutoencoders
from unitac_rig.learning.network import UniTacNV
from unitac_rig.learning.train import LoadedRun

WEIGHTS_NAME = "model.safetensors"
CONFIG_NAME = "config.json"
LICENSE = "mit"  # the package's licence (pyproject.toml), which the exported weights are shared under


def hub_model(run: LoadedRun, member: int = 0) -> UniTacNV:
    """Member ``member`` of ``run`` as the exported module (normaliser folded in, no dropout, eval mode, CPU)."""
    from unitac_rig.learning.export import decoder_module, encoder_module

    engine = run.engine
    sensors = engine.group(UNITAC_GROUP).sensors
    latent = engine.shape.latent_dim
    specs = {
        s: {
            "n_taxels": engine.feature_dims[s] // 3,
            "encoder_widths": [engine.feature_dims[s], *engine.shape.encoder_hidden, latent],
            "decoder_widths": [latent, *engine.shape.decoder_hidden, engine.feature_dims[s]],
        }
        for s in sensors
    }
    model = UniTacNV(specs, latent)
    for sensor in sensors:
        mean, std = run.normaliser.mean[sensor], run.normaliser.std[sensor]
        parts = {"encoders": encoder_module(engine, mean, std, sensor, member),
                 "decoders": decoder_module(engine, mean, std, sensor, member)}  # fmt: skip
        for part, folded in parts.items():
            target = getattr(model, part)[sensor]
            source = [m for m in folded if isinstance(m, torch.nn.Linear)]
            mine = [m for m in target if isinstance(m, torch.nn.Linear)]
            with torch.no_grad():
                for a, b in zip(mine, source, strict=True):
                    a.weight.copy_(b.weight.to(torch.float32))
                    a.bias.copy_(b.bias.to(torch.float32))
    return model.eval()


def export_into(run: LoadedRun, engine: StackedAutoencoders, staging: Path, member: int) -> dict[str, Any]:
    """Write model.safetensors, config.json and README.md into ``staging``; returns the config document."""
    from unitac_rig.learning.export import (
        CARD_NAME,
        EXPORT_FORMAT,
        EXPORT_VERSION,
        _layout,
        _sha256,
        _units,
        run_fields,
    )

    model = hub_model(run, member)
    entries: dict[str, Any] = {}
    for sensor in model.sensors:
        n_taxels = model.n_taxels[sensor]
        mean, std = run.normaliser.mean[sensor], run.normaliser.std[sensor]
        widths = {
            part: [layers[0].in_features, *(m.out_features for m in layers)]
            for part, net in (("encoder", model.encoders[sensor]), ("decoder", model.decoders[sensor]))
            if (layers := [m for m in net.modules() if isinstance(m, torch.nn.Linear)])
        }
        entries[sensor] = {
            "n_taxels": n_taxels,
            "frame_shape": [n_taxels, 3],
            "units": _units(sensor),
            "layout": _layout(sensor),
            "encoder_widths": widths["encoder"],
            "decoder_widths": widths["decoder"],
            "encoder": f"encoders.{sensor}.*",  # tensors of model.encoders[sensor], an nn.Sequential
            "decoder": f"decoders.{sensor}.*",
            "normaliser_folded_in": {
                "mean": np.asarray(mean, dtype=float).tolist(),
                "std": np.asarray(std, dtype=float).tolist(),
                "mode": getattr(run.normaliser, "mode", "channel_z"),
            },
        }
    metrics_path = run.run_dir / "metrics.json"
    metrics = json.loads(metrics_path.read_text(encoding="utf-8")) if metrics_path.is_file() else None
    document: dict[str, Any] = {
        "format": EXPORT_FORMAT,
        "version": EXPORT_VERSION,
        "export_format": "safetensors",
        "model": "UniTac-NV (Hou et al., IROS 2025): one encoder per sensor, one shared decoder",
        "class": "unitac_rig.learning.network.UniTacNV",
        "weights": WEIGHTS_NAME,
        "latent_dim": model.latent_dim,
        "sensors": entries,
        "tensors": {name: list(t.shape) for name, t in model.state_dict().items()},
        "frame": "(B, n_taxels, 3) float32, tare-subtracted, sensor units; taxel i at (row, col) = divmod(i, cols); "
        "channels x, y, z",
        "translate": "model(frames, source, target) = model.decode(model.encode(frames, source), target)",
        **run_fields(run.payload, engine, member),
    }
    (staging / CARD_NAME).write_text(render_card(document, metrics), encoding="utf-8")  # before: the mixin keeps it
    model.save_pretrained(staging, config=document)  # its config.json sorts keys: rewritten below in sensor order
    document["files"] = {WEIGHTS_NAME: _sha256(staging / WEIGHTS_NAME)}
    (staging / CONFIG_NAME).write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    return document


def push_to_hub(folder: Path, repo_id: str, *, private: bool = False) -> str:
    """Upload an exported folder to the Hugging Face Hub model repository ``repo_id`` (created when missing; the
    token is huggingface_hub's: ``hf auth login`` or ``HF_TOKEN``). Returns the commit's URL."""
    from huggingface_hub import HfApi
    from huggingface_hub.errors import HfHubHTTPError

    folder = Path(folder)
    if not (folder / CONFIG_NAME).is_file() or not (folder / WEIGHTS_NAME).is_file():
        raise UsageError(f"{folder} is not a safetensors export", hint="--push-to-hub needs --format safetensors")
    api = HfApi()
    try:
        api.create_repo(repo_id, repo_type="model", private=private, exist_ok=True)
        commit = api.upload_folder(repo_id=repo_id, repo_type="model", folder_path=str(folder),
                                   commit_message="unitac-rig export-model")  # fmt: skip
    except (HfHubHTTPError, OSError) as exc:
        from unitac_rig.errors import ModelError

        raise ModelError(f"upload to {repo_id} failed: {exc}", hint="check the token (hf auth login) and the "
                         "network; the export itself is complete in " + str(folder)) from exc  # fmt: skip
    return str(getattr(commit, "commit_url", commit))


def _model_index(document: dict[str, Any], metrics: dict[str, Any] | None) -> list[str]:
    """The card's ``model-index`` (YAML): the run's test table as Hub metrics, one result per table row and
    direction (NMAE and SSIM)."""
    table = (metrics or {}).get("table1") or {}
    if not table:
        return []
    name = f"unitac-nv-{'-'.join(document['sensors'])}"
    lines = ["model-index:", f"- name: {name}", "  results:"]
    for row, cells in table.items():
        for direction, value in cells.items():
            if not isinstance(value, dict):
                continue
            label = f"{row}: {direction.replace('_to_', ' to ')}"
            lines += [
                "  - task:",
                "      type: feature-extraction",
                "      name: Cross-sensor tactile translation",
                "    dataset:",
                "      type: unitac-rig-press-dataset",
                f"      name: {json.dumps(label)}",
                f"      revision: {document['dataset_hash']}",
                "    metrics:",
                *(f"    - {{type: {k}, name: {k.upper()}, value: {float(value[k]):.6g}}}" for k in ("nmae", "ssim")
                  if isinstance(value.get(k), int | float)),
            ]  # fmt: skip
    return lines


def render_card(document: dict[str, Any], metrics: dict[str, Any] | None) -> str:
    """The Hub model card: YAML front matter (license, library, pipeline tag, tags, datasets, model-index), then the
    shared card of export.py with the ``from_pretrained`` loading code."""
    from unitac_rig.learning.export import render_card as shared_card

    names = list(document["sensors"])
    source, target = (names[0], names[1]) if len(names) > 1 else (names[0], names[0])
    src, dst = document["sensors"][source], document["sensors"][target]
    front = [
        "---",
        f"license: {LICENSE}",
        "library_name: unitac-rig",
        "pipeline_tag: feature-extraction",
        "tags: [tactile, robotics, cross-sensor, unitac-nv, safetensors, pytorch_model_hub_mixin]",
        "datasets:",
        f"- unitac-rig/{document['dataset_hash'][:16]}  # content hash of the paired training frames (prefix)",
        *_model_index(document, metrics),
        "---",
        "",
    ]
    body = shared_card(document, metrics)
    head, _, _ = body.partition("## How to load")
    loading = [
        "## How to load",
        "",
        "With unitac-rig installed (`pip install unitac-rig`; the class rebuilds itself from `config.json` through "
        "huggingface_hub's `PyTorchModelHubMixin`), from this folder or from its Hub repository:",
        "",
        "```python",
        "import torch",
        "from unitac_rig.learning.network import UniTacNV",
        "",
        'model = UniTacNV.from_pretrained(".")  # or the Hub repository id',
        f"frames = torch.zeros(1, {src['n_taxels']}, 3)  # {source} frames, {src['units']}",
        "with torch.no_grad():",
        f'    latent = model.encode(frames, "{source}")  # (1, {document["latent_dim"]})',
        f'    translated = model.decode(latent, "{target}")  # (1, {dst["n_taxels"]}, 3) {target} frames, '
        f"{dst['units']}",
        "```",
        "",
        "Without unitac-rig, export the run with `--format torchscript` or `--format onnx` (plain torch or "
        f"onnxruntime load those). `{CONFIG_NAME}` lists every sensor's shape, units, layer widths and the folded "
        f"normaliser, every tensor's shape, and the SHA-256 of `{WEIGHTS_NAME}`.",
        "",
    ]
    return "\n".join(front) + "\n" + head + "\n".join(loading)
