"""``unitac-rig export-model``: a trained run as plain PyTorch/ONNX networks that need nothing of unitac-rig.

``safetensors`` (the default) is the Hugging Face Hub layout, ``model.safetensors`` + ``config.json`` + ``README.md``,
written by huggingface_hub's ``PyTorchModelHubMixin`` from :class:`unitac_rig.learning.network.UniTacNV`, so
``UniTacNV.from_pretrained(folder_or_repo)`` rebuilds the module from ``config.json`` and loads the weights
(safetensors files hold tensors only, never code). ``config.json`` holds the constructor's arguments and beside them
units, taxel layout, the folded normaliser, the training data's content hash, provenance and the SHA-256 of the
weights; :func:`push_to_hub` uploads such a folder. The other formats write one file per network.

For every sensor of the run's UniTac-NV model, one member (seed), from that member's layers of the one trained model
(:meth:`unitac_rig.learning.engine.StackedAutoencoders.layer_parameters`):

* ``encoder_<sensor>``: frames ``(B, n_taxels, 3)`` in the sensor's own units -> latent ``(B, latent_dim)``;
* ``decoder_<sensor>``: latent ``(B, latent_dim)`` -> frames ``(B, n_taxels, 3)`` in that sensor's units: the shared
  decoder's hidden layers followed by that sensor's slice of its output layer.

Translation is ``decoder_<target>(encoder_<source>(frames))``. The normaliser is folded into the weights (the
encoder's first layer absorbs ``(x - mean) / std``, the decoder's last layer ``y * std + mean``, computed in float64),
so each file is an ordinary ``Flatten -> Linear/ReLU... -> Linear`` (``-> Unflatten`` for a decoder): no
preprocessing outside it, no dropout (inference). Formats:

* ``torchscript``: ``<part>_<sensor>.torchscript.pt`` for ``torch.jit.load`` (deprecated by PyTorch: torch 2.13 warns
  on ``torch.jit.script`` in favour of ``torch.export``; the files still load with plain torch);
* ``onnx``: ``<part>_<sensor>.onnx`` (opset of torch's exporter, dynamic batch axis; needs the ``onnx`` extra:
  ``pip install "unitac-rig[onnx]"``);
* ``state-dict``: ``<part>_<sensor>.state_dict.pt``, the ``nn.Sequential``'s tensors only, for
  ``torch.load(..., weights_only=True)`` into the Sequential that ``model.json``'s layer widths describe.

Beside them: ``model.json`` (sensors, shapes, units, layer widths, files and their SHA-256, the folded normaliser,
training data hash, member and seed, provenance) and ``README.md``, the model card (data, metrics from the run's
``metrics.json``, intended use, limits, how to load).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import uuid
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import nn

from unitac_rig.errors import UsageError
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.network import head_part, linear_layers
from unitac_rig.learning.run import LoadedRun, load_run, provenance, read_metrics
from unitac_rig.storage.manifest import publish_when_done

if TYPE_CHECKING:
    from unitac_rig.learning.network import UniTacNV

log = logging.getLogger(__name__)

FORMATS = ("safetensors", "torchscript", "onnx", "state-dict")
SUFFIX = {"torchscript": ".torchscript.pt", "onnx": ".onnx", "state-dict": ".state_dict.pt"}
MODEL_JSON = "model.json"
CARD_NAME = "README.md"
EXPORT_FORMAT = "unitac-rig/unitac-nv-export"
EXPORT_VERSION = 1
WEIGHTS_NAME = "model.safetensors"
CONFIG_NAME = "config.json"
LICENSE = "mit"  # the package's licence (pyproject.toml), which the exported weights are shared under


@contextlib.contextmanager
def _quiet_exporters() -> Iterator[None]:
    """TorchScript's deprecation warning and torch.onnx's registry chatter (torchvision ops it skips) are not
    the user's business here; anything else still surfaces."""
    names = ("torch.onnx._internal.exporter._registration", "torch.onnx")
    loggers = [logging.getLogger(n) for n in names]
    levels = [lg.level for lg in loggers]
    try:
        import tqdm  # torch.onnx shows a tqdm bar when tqdm is installed (huggingface_hub brings it): its monitor

        tqdm.tqdm.monitor_interval = 0  # thread would outlive the export for the rest of the process
    except ImportError:
        pass
    try:
        for lg in loggers:
            lg.setLevel(logging.ERROR)
        with warnings.catch_warnings():
            warnings.filterwarnings(
                "ignore", message=r".*torch\.jit\.(script|trace).* deprecated", category=DeprecationWarning
            )
            warnings.filterwarnings("ignore", message=r".*training mode", category=UserWarning)
            warnings.filterwarnings("ignore", message=r".*treespec.*", category=Warning)
            yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def _write(module: nn.Module, example: torch.Tensor, path: Path, fmt: str, names: tuple[str, str]) -> None:
    if fmt == "torchscript":
        with _quiet_exporters():
            scripted = torch.jit.script(module)
        scripted.save(str(path))
    elif fmt == "state-dict":
        torch.save({k: v.detach().clone() for k, v in module.state_dict().items()}, path)
    else:
        try:
            import onnx  # noqa: F401  (torch.onnx needs it and onnxscript; fail with the fix, not deep inside)
            import onnxscript  # noqa: F401
        except ImportError as exc:
            raise UsageError(
                f"ONNX export needs the onnx and onnxscript packages ({exc.name} is missing)",
                hint='pip install "unitac-rig[onnx]"',
            ) from exc
        with _quiet_exporters():
            torch.onnx.export(
                module,
                (example,),
                str(path),
                dynamo=True,
                external_data=False,
                verbose=False,
                input_names=[names[0]],
                output_names=[names[1]],
                dynamic_shapes=({0: torch.export.Dim("batch", min=1)},),
            )


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _units_and_layout(sensor: str) -> tuple[str, dict[str, Any] | None]:
    from unitac_rig.rig.sensors import SENSORS

    spec = SENSORS.get(sensor)
    if spec is None:
        return "as recorded (not a registered sensor)", None
    layout = spec.layout
    return layout.units, {"rows": layout.rows, "cols": layout.cols, "pitch_mm": layout.pitch_mm, "units": layout.units}


def export_model(run_dir: Path, out: Path, fmt: str, member: int = 0) -> dict[str, Any]:
    """Write the run's encoders and decoders in ``fmt`` with ``model.json`` and the model card into ``out`` (built
    beside it and renamed into place, so ``out`` is complete or absent); returns the model.json content."""
    if fmt not in FORMATS:
        raise UsageError(f"unknown export format {fmt!r}", hint=f"use one of {', '.join(FORMATS)}")
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UsageError(f"{out} exists and is not empty", hint="export into a new directory")
    run = load_run(Path(run_dir))
    run.check_member(member)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.parent / f".{out.name}.export-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    staging.mkdir()  # not tempfile.mkdtemp: that is private (0700), and the export is meant to be shared
    with publish_when_done(staging, out):
        if fmt == "safetensors":
            document = _export_safetensors(run, staging, member)
        else:
            document = _export_into(run, staging, fmt, member)
    return document


def _sensor_entry(run: LoadedRun, sensor: str, files: dict[str, str]) -> dict[str, Any]:
    """What model.json / config.json say of one sensor: shape, units, layout, where its networks are (``files``),
    their layer widths and the normaliser folded into them."""
    engine = run.engine
    n_taxels = engine.feature_dims[sensor] // 3
    units, layout = _units_and_layout(sensor)
    return {
        "n_taxels": n_taxels,
        "frame_shape": [n_taxels, 3],
        "units": units,
        "layout": layout,
        **files,
        "encoder_widths": engine.shape.encoder_widths(n_taxels * 3),
        "decoder_widths": engine.shape.decoder_widths(n_taxels * 3),
        "normaliser_folded_in": {
            "mean": np.asarray(run.normaliser.mean[sensor], dtype=float).tolist(),
            "std": np.asarray(run.normaliser.std[sensor], dtype=float).tolist(),
            "mode": run.normaliser.mode,
        },
    }


def _export_into(run: LoadedRun, staging: Path, fmt: str, member: int) -> dict[str, Any]:
    """One file per network in ``fmt``: the exported module's (:func:`hub_model`) encoder behind ``Flatten`` and
    decoder before ``Unflatten``, so each takes and gives frames (B, n_taxels, 3)."""
    model = hub_model(run, member)
    files: dict[str, str] = {}
    entries: dict[str, Any] = {}
    for sensor in model.sensors:
        n_taxels = model.n_taxels[sensor]
        names = {"encoder": f"encoder_{sensor}{SUFFIX[fmt]}", "decoder": f"decoder_{sensor}{SUFFIX[fmt]}"}
        encoder = nn.Sequential(nn.Flatten(1), *model.encoders[sensor].children()).eval()
        decoder = nn.Sequential(*model.decoders[sensor].children(), nn.Unflatten(1, (n_taxels, 3))).eval()
        _write(encoder, torch.zeros(2, n_taxels, 3), staging / names["encoder"], fmt, ("frames", "latent"))
        _write(decoder, torch.zeros(2, model.latent_dim), staging / names["decoder"], fmt, ("latent", "frames"))
        for name in names.values():
            files[name] = _sha256(staging / name)
        entries[sensor] = _sensor_entry(run, sensor, names)
    document = _document(run, member, fmt, entries, model.latent_dim)
    document["frame"] = "(B, n_taxels, 3) float32; taxel i at (row, col) = divmod(i, cols); channels x, y, z"
    document["translate"] = "decoder_<target>(encoder_<source>(frames))"
    document["files"] = files
    (staging / MODEL_JSON).write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    (staging / CARD_NAME).write_text(render_card(document, read_metrics(run.run_dir)), encoding="utf-8")
    return document


def _document(run: LoadedRun, member: int, fmt: str, entries: dict[str, Any], latent_dim: int) -> dict[str, Any]:
    """What every export's model.json / config.json says: the format, the sensors' entries, and where the model
    came from (member, seed, epochs, the dataset's hash and summary, a new-sensor extension, provenance)."""
    payload = run.payload
    extension = payload.get("extension")
    return {
        "format": EXPORT_FORMAT,
        "version": EXPORT_VERSION,
        "export_format": fmt,
        "model": "UniTac-NV (Hou et al., IROS 2025): one encoder per sensor, one shared decoder",
        "latent_dim": latent_dim,
        "sensors": entries,
        "member": member,
        "seed": run.engine.seeds[member],
        "epochs": int(payload["epoch"]),
        "dataset_hash": payload["dataset_hash"],
        "dataset_summary": payload.get("dataset_summary", {}),
        "extension": (
            {k: extension[k] for k in ("new_sensor", "trained_sensors", "from_dataset_hash")} if extension else None
        ),
        "run_provenance": payload.get("provenance", {}),
        "exported_by": provenance(),
    }


def _metrics_lines(metrics: dict[str, Any] | None) -> list[str]:
    if metrics is None:
        return ["The run had no `metrics.json` when it was exported (run `unitac-rig report RUN` first to include it)."]
    table = metrics.get("table1", {})
    if not table:
        return ["`metrics.json` holds no test table."]
    columns = list(next(iter(table.values())).keys())
    lines = [
        "Test set of the run (held-out approach directions of the training objects, and objects kept out of training);"
        " each cell NMAE / SSIM, mean over the run's seeds:",
        "",
        "| row | " + " | ".join(c.replace("_to_", " → ") for c in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for row, cells in table.items():
        values = [cells.get(c) for c in columns]
        rendered = ["–" if v is None else f"{v['nmae']:.3f} / {v['ssim']:.3f}" for v in values]
        lines.append(f"| {row} | " + " | ".join(rendered) + " |")
    described = metrics.get("metrics") or {}
    settings = [f"{m.upper()}: {described[m]}" for m in ("nmae", "ssim") if m in described]
    if "preprocessing" in metrics:
        settings.append(f"preprocessing: {metrics['preprocessing']['text']}")
    lines += ["", "NMAE is the mean absolute error over a training range (docs/learning.md, Metrics)."]
    if settings:
        lines.append("Metric settings: " + "; ".join(settings) + ".")
    latent = metrics.get("alignment", {}).get("per_subset", {}).get("all", {}).get("latent_l1", {}).get("final")
    if latent:
        mean = sum(latent) / len(latent)
        lines.append(f"Mean L1 distance between two sensors' latents of the same contact: {mean:.3f}.")
    return lines


def render_card(document: dict[str, Any], metrics: dict[str, Any] | None) -> str:
    """The model card: what the files are, the data it learned from, its test metrics, intended use, limits, and
    how to load it with plain torch (or onnxruntime)."""
    sensors = document["sensors"]
    names = list(sensors)
    fmt = document["export_format"]
    summary = document.get("dataset_summary") or {}
    source, target = (names[0], names[1]) if len(names) > 1 else (names[0], names[0])
    rows = [
        f"| {s} | {e['n_taxels']} | ({e['n_taxels']}, 3) | {e['units']} | `{e['encoder']}` | `{e['decoder']}` |"
        for s, e in sensors.items()
    ]
    simulated = summary.get("simulated")
    data_kind = (
        "simulated (sessions marked simulated: the rig's twin or synthetic contacts)"
        if simulated
        else "recorded on a rig"
        if simulated is False
        else "not stated"
    )
    extension = document.get("extension")
    lines = [
        "# UniTac-NV tactile translation model",
        "",
        f"Exported by unitac-rig {document['exported_by'].get('package_version', '?')} as **{fmt}**. "
        "One encoder per sensor and the shared decoder's output for each sensor, as separate networks:",
        f"translate a frame with `{document['translate']}`. The normalisation the model was trained with is folded "
        "into the weights: inputs and outputs are tare-subtracted frames in each sensor's own units.",
        "",
        "| sensor | taxels | frame | units | encoder | decoder |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
        f"Latent: {document['latent_dim']} numbers. Frames: {document['frame']}. Batch axis first, any size.",
        "",
        "## Training data",
        "",
        f"- dataset content hash (SHA-256 of the paired frames and keys): `{document['dataset_hash']}`",
        f"- sensors {', '.join(summary.get('sensors', names))}; objects {', '.join(summary.get('objects', []))}; "
        f"{summary.get('rows', '?')} paired contacts; data: {data_kind}",
        f"- member {document['member']} (seed {document['seed']}) of the run, after {document['epochs']} epochs",
    ]
    if extension:
        lines.append(
            f"- `{extension['new_sensor']}` was added later to the model trained on "
            f"{', '.join(extension['trained_sensors'])}: only its encoder and output layer were trained, against the "
            f"frozen model (`unitac-rig train --from RUN --new-sensor`); the other sensors' networks are unchanged"
        )
    lines += ["", "## Metrics", "", *_metrics_lines(metrics), ""]
    lines += [
        "## Intended use",
        "",
        "- Translating tactile frames between the sensors above (and encoding them into a shared latent for "
        "downstream tasks, e.g. contact geometry), for sensors mounted as on the training rig and presses like the "
        "training ones: a flat pad pressed onto prism-shaped objects, normal forces in the trained range (the paper's "
        "protocol: 4 to 10 N), approach angles within ±45°.",
        "- Research and prototyping; comparing with the paper (Hou et al., UniTac-NV, IROS 2025).",
        "",
        "## Limits",
        "",
        "- Frames must be tare-subtracted, in the units above and in the taxel order above; a different firmware "
        "scaling, mounting orientation or taxel order gives wrong outputs without any error.",
        "- Contacts unlike the training ones (other shapes, materials, forces, sliding or dynamic contact) are "
        "outside what was tested; the table's unseen-object rows show how much error grows on a new shape.",
        "- No uncertainty estimate; deterministic (no dropout at inference).",
        "- Trained on simulated data: expect a gap on a real sensor until it is trained on recorded data."
        if simulated
        else "- Trained on one rig's recordings; other units of the same sensor model may differ.",
        "",
        "## How to load",
        "",
    ]
    lines += _loading_snippet(document, source, target)
    return "\n".join(lines)


def _loading_snippet(document: dict[str, Any], source: str, target: str) -> list[str]:
    """The card's "How to load" section: code that translates ``source`` frames into ``target`` frames."""
    fmt, src, dst = document["export_format"], document["sensors"][source], document["sensors"][target]
    n_src = src["n_taxels"]
    if fmt == "safetensors":
        return [
            "With unitac-rig installed (`pip install unitac-rig`; the class rebuilds itself from `config.json` "
            "through huggingface_hub's `PyTorchModelHubMixin`), from this folder or from its Hub repository:",
            "",
            "```python",
            "import torch",
            "from unitac_rig.learning.network import UniTacNV",
            "",
            'model = UniTacNV.from_pretrained(".")  # or the Hub repository id',
            f"frames = torch.zeros(1, {n_src}, 3)  # {source} frames, {src['units']}",
            "with torch.no_grad():",
            f'    latent = model.encode(frames, "{source}")  # (1, {document["latent_dim"]})',
            f'    translated = model.decode(latent, "{target}")  # (1, {dst["n_taxels"]}, 3) {target} frames, '
            f"{dst['units']}",
            "```",
            "",
            "Without unitac-rig, export the run with `--format torchscript` or `--format onnx` (plain torch or "
            f"onnxruntime load those). `{CONFIG_NAME}` lists every sensor's shape, units, layer widths and the "
            f"folded normaliser, every tensor's shape, and the SHA-256 of `{WEIGHTS_NAME}`.",
            "",
        ]
    if fmt == "torchscript":
        code = [
            "import torch",
            "",
            f'encoder = torch.jit.load("{src["encoder"]}")',
            f'decoder = torch.jit.load("{dst["decoder"]}")',
            f"frames = torch.zeros(1, {n_src}, 3)  # {source} frames, {src['units']}",
            "with torch.no_grad():",
            f"    translated = decoder(encoder(frames))  # (1, {dst['n_taxels']}, 3) {target} frames, {dst['units']}",
        ]
    elif fmt == "onnx":
        code = [
            "import numpy as np",
            "import onnxruntime as ort",
            "",
            f'encoder = ort.InferenceSession("{src["encoder"]}")',
            f'decoder = ort.InferenceSession("{dst["decoder"]}")',
            f"frames = np.zeros((1, {n_src}, 3), dtype=np.float32)  # {source} frames, {src['units']}",
            '(latent,) = encoder.run(None, {"frames": frames})',
            f'(translated,) = decoder.run(None, {{"latent": latent}})  # {target} frames, {dst["units"]}',
        ]
    else:
        code = [
            "import json",
            "import torch",
            "from torch import nn",
            "",
            "",
            "def mlp(widths, flatten=False, taxels=None):",
            "    layers = [nn.Flatten(1)] if flatten else []",
            "    for i in range(len(widths) - 1):",
            "        layers.append(nn.Linear(widths[i], widths[i + 1]))",
            "        if i < len(widths) - 2:",
            "            layers.append(nn.ReLU())",
            "    if taxels is not None:",
            "        layers.append(nn.Unflatten(1, (taxels, 3)))",
            "    return nn.Sequential(*layers).eval()",
            "",
            "",
            'card = json.load(open("model.json"))',
            f'src, dst = card["sensors"]["{source}"], card["sensors"]["{target}"]',
            'encoder = mlp(src["encoder_widths"], flatten=True)',
            'encoder.load_state_dict(torch.load(src["encoder"], weights_only=True))',
            'decoder = mlp(dst["decoder_widths"], taxels=dst["n_taxels"])',
            'decoder.load_state_dict(torch.load(dst["decoder"], weights_only=True))',
            "with torch.no_grad():",
            f"    translated = decoder(encoder(torch.zeros(1, {n_src}, 3)))  # {target} frames, {dst['units']}",
        ]
    return [
        "```python",
        *code,
        "```",
        "",
        f"`{MODEL_JSON}` lists every sensor's shape, units, layer widths, file names and their SHA-256 "
        "(check a copy with `sha256sum`).",
        "",
    ]


def hub_model(run: LoadedRun, member: int = 0) -> UniTacNV:
    """Member ``member`` of ``run`` as the exported module (normaliser folded in, no dropout, eval mode, CPU): per
    sensor, the member's encoder with ``(x - mean) / std`` folded into its first layer, and the shared hidden layers
    plus that sensor's columns of its output layer with ``y * std + mean`` folded into the last (in float64)."""
    from unitac_rig.learning.network import UniTacNV  # imports huggingface_hub: only when asked

    engine = run.engine
    group = engine.group(UNITAC_GROUP)
    model = UniTacNV({s: _sensor_entry(run, s, {}) for s in group.sensors}, engine.shape.latent_dim)
    params = engine.layer_parameters(UNITAC_GROUP, member)  # key -> (weight (in, out), bias (out,))
    n_hidden = len(engine.shape.decoder_hidden)
    for sensor in group.sensors:
        dims = engine.feature_dims
        mean = np.tile(np.asarray(run.normaliser.mean[sensor], dtype=np.float64), dims[sensor] // 3)  # per column
        scale = np.tile(np.asarray(run.normaliser.std[sensor], dtype=np.float64), dims[sensor] // 3)
        h, head = next((h, head) for h, head in enumerate(group.output_heads) if sensor in head)
        start = sum(dims[s] for s in head[: head.index(sensor)])
        out_weight, out_bias = params[f"{head_part(head, h)}/{n_hidden}"]
        layers = [params[f"enc_{sensor}/{i}"] for i in range(len(engine.shape.encoder_hidden) + 1)]
        layers += [params[f"dec/{i}"] for i in range(n_hidden)]
        layers.append((out_weight[:, start : start + dims[sensor]], out_bias[start : start + dims[sensor]]))
        layers = [(w.astype(np.float64), b.astype(np.float64)) for w, b in layers]
        (w, b), inverse = layers[0], 1.0 / scale
        layers[0] = (w * inverse[:, None], b - (mean * inverse) @ w)
        w, b = layers[-1]
        layers[-1] = (w * scale[None, :], b * scale + mean)
        linears = linear_layers(model.encoders[sensor]) + linear_layers(model.decoders[sensor])
        with torch.no_grad():
            for linear, (w, b) in zip(linears, layers, strict=True):
                linear.weight.copy_(torch.from_numpy(w.T.copy()))
                linear.bias.copy_(torch.from_numpy(b.copy()))
    return model.eval()


def _export_safetensors(run: LoadedRun, staging: Path, member: int) -> dict[str, Any]:
    """Write model.safetensors, config.json and README.md into ``staging``; returns the config document."""
    model = hub_model(run, member)
    entries = {  # the tensors of model.encoders[sensor] and model.decoders[sensor], each an nn.Sequential
        s: _sensor_entry(run, s, {"encoder": f"encoders.{s}.*", "decoder": f"decoders.{s}.*"}) for s in model.sensors
    }
    metrics = read_metrics(run.run_dir)
    document = _document(run, member, "safetensors", entries, model.latent_dim)
    document |= {
        "class": "unitac_rig.learning.network.UniTacNV",
        "weights": WEIGHTS_NAME,
        "tensors": {name: list(t.shape) for name, t in model.state_dict().items()},
        "frame": "(B, n_taxels, 3) float32, tare-subtracted, sensor units; taxel i at (row, col) = divmod(i, cols); "
        "channels x, y, z",
        "translate": "model(frames, source, target) = model.decode(model.encode(frames, source), target)",
    }
    (staging / CARD_NAME).write_text(_hub_card(document, metrics), encoding="utf-8")  # before: the mixin keeps it
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
        commit = api.upload_folder(
            repo_id=repo_id, repo_type="model", folder_path=str(folder), commit_message="unitac-rig export-model"
        )
    except (HfHubHTTPError, OSError) as exc:
        from unitac_rig.errors import ModelError

        raise ModelError(
            f"upload to {repo_id} failed: {exc}",
            hint="check the token (hf auth login) and the network; the export itself is complete in " + str(folder),
        ) from exc
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
                *(
                    f"    - {{type: {k}, name: {k.upper()}, value: {float(value[k]):.6g}}}"
                    for k in ("nmae", "ssim")
                    if isinstance(value.get(k), int | float)
                ),
            ]
    return lines


def _hub_card(document: dict[str, Any], metrics: dict[str, Any] | None) -> str:
    """The Hub model card: YAML front matter (license, library, pipeline tag, tags, datasets, model-index), then the
    shared card (:func:`render_card`) with the ``from_pretrained`` loading code."""
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
    return "\n".join(front) + "\n" + render_card(document, metrics)
