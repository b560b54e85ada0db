"""`unitac-rig export-model`: the networks leave the tool. A TorchScript export loads in a Python process that imports
only torch and translates a frame exactly as the translator does (sensor units in and out: the normaliser is folded
in); the state-dict and ONNX exports do the same; the model card and model.json say what the files are."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from tests.helpers import cli
from tests.learning.learning_helpers import REFUSE_PROJECT_IMPORTS, small_sets
from unitac_rig.learning.data import PairedDataset, build_paired_dataset
from unitac_rig.learning.extend import ExtendConfig, add_sensor
from unitac_rig.learning.report import write_report
from unitac_rig.learning.train import TrainConfig, train
from unitac_rig.learning.translate import Translator

DIRECTIONS = [("uskin", "papillarray"), ("papillarray", "uskin"), ("uskin", "uskin"), ("papillarray", "papillarray")]

# Runs in a fresh interpreter that can import torch and nothing of this project: a meta-path hook refuses them.
PLAIN_TORCH = (
    REFUSE_PROJECT_IMPORTS
    + """
import torch

export, frames_path, out_path = sys.argv[1:4]
frames = torch.load(frames_path, weights_only=True)
results = {}
for source, target in [("uskin", "papillarray"), ("papillarray", "uskin"), ("uskin", "uskin"),
                       ("papillarray", "papillarray")]:
    encoder = torch.jit.load(f"{export}/encoder_{source}.torchscript.pt")
    decoder = torch.jit.load(f"{export}/decoder_{target}.torchscript.pt")
    with torch.no_grad():
        results[f"{source}_to_{target}"] = decoder(encoder(frames[source]))
torch.save(results, out_path)
print(sorted(m for m in sys.modules if m.split(".")[0] in ("unitac_rig", "drivers", "protocols")))
"""
)


@pytest.fixture(scope="module")
def pairs() -> PairedDataset:
    return build_paired_dataset(small_sets())


@pytest.fixture(scope="module")
def run_dir(pairs: PairedDataset, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("export") / "run"
    train(pairs, out, TrainConfig(epochs=30, seeds=(0, 1), tsne_contacts=30, eval_every=30), device="cpu")
    write_report(out, figures=False)  # metrics.json, which the model card quotes
    return out


def _assert_matches(got: np.ndarray, expected: np.ndarray) -> None:
    scale = float(np.abs(expected).max())
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-5 * scale)


def test_torchscript_translates_in_a_plain_torch_process_like_the_translator(
    run_dir: Path, pairs: PairedDataset, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    export = tmp_path / "ts"
    assert cli(["export-model", str(run_dir), "--format", "torchscript", "--out", str(export)]) == 0
    assert "encoder_uskin.torchscript.pt" in capsys.readouterr().out
    frames = {s: torch.from_numpy(pairs.values[s][:7].copy()) for s in pairs.sensors}
    torch.save(frames, tmp_path / "frames.pt")

    done = subprocess.run(
        [sys.executable, "-I", "-c", PLAIN_TORCH, str(export), str(tmp_path / "frames.pt"), str(tmp_path / "o.pt")],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"  # nothing of unitac-rig was imported
    results = torch.load(tmp_path / "o.pt", weights_only=True)
    translator = Translator.load(run_dir)
    for source, target in DIRECTIONS:
        expected = translator.translate(pairs.values[source][:7], source, target)
        _assert_matches(results[f"{source}_to_{target}"].numpy(), expected)


def test_model_card_and_json_say_what_the_files_are(run_dir: Path, tmp_path: Path) -> None:
    export = tmp_path / "card"
    assert cli(["export-model", str(run_dir), "--format", "torchscript", "--out", str(export)]) == 0
    document = json.loads((export / "model.json").read_text())
    assert document["sensors"]["uskin"]["frame_shape"] == [24, 3] and document["sensors"]["uskin"]["units"] == "counts"
    assert document["sensors"]["papillarray"]["units"] == "N" and document["latent_dim"] == 16
    assert document["sensors"]["papillarray"]["encoder_widths"] == [27, 64, 48, 16]
    for name, digest in document["files"].items():
        assert hashlib.sha256((export / name).read_bytes()).hexdigest() == digest
    card = (export / "README.md").read_text()
    checkpoint = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    assert checkpoint["dataset_hash"] in card
    metrics = json.loads((run_dir / "metrics.json").read_text())
    cell = metrics["table1"]["irregular_pla"]["uskin_to_papillarray"]
    assert f"{cell['nmae']:.3f} / {cell['ssim']:.3f}" in card
    for heading in ("## Training data", "## Metrics", "## Intended use", "## Limits", "## How to load"):
        assert heading in card
    assert 'torch.jit.load("encoder_uskin.torchscript.pt")' in card


def test_state_dict_loads_into_plain_sequentials_for_any_member(
    run_dir: Path, pairs: PairedDataset, tmp_path: Path
) -> None:
    export = tmp_path / "sd"
    assert cli(["export-model", str(run_dir), "--format", "state-dict", "--out", str(export), "--member", "1"]) == 0
    document = json.loads((export / "model.json").read_text())
    assert document["member"] == 1 and document["seed"] == 1

    def mlp(widths: list[int], flatten: bool = False, taxels: int | None = None) -> nn.Sequential:
        layers: list[nn.Module] = [nn.Flatten(1)] if flatten else []
        for i in range(len(widths) - 1):
            layers.append(nn.Linear(widths[i], widths[i + 1]))
            if i < len(widths) - 2:
                layers.append(nn.ReLU())
        if taxels is not None:
            layers.append(nn.Unflatten(1, (taxels, 3)))
        return nn.Sequential(*layers).eval()

    translator = Translator.load(run_dir, member=1)
    for source, target in DIRECTIONS:
        src, dst = document["sensors"][source], document["sensors"][target]
        encoder = mlp(src["encoder_widths"], flatten=True)
        encoder.load_state_dict(torch.load(export / src["encoder"], weights_only=True))
        decoder = mlp(dst["decoder_widths"], taxels=dst["n_taxels"])
        decoder.load_state_dict(torch.load(export / dst["decoder"], weights_only=True))
        with torch.no_grad():
            got = decoder(encoder(torch.from_numpy(pairs.values[source][:5].copy()))).numpy()
        _assert_matches(got, translator.translate(pairs.values[source][:5], source, target))


def test_onnx_runs_in_onnxruntime_like_the_translator(run_dir: Path, pairs: PairedDataset, tmp_path: Path) -> None:
    pytest.importorskip("onnxscript", reason="the onnx extra is not installed: pip install 'unitac-rig[onnx]'")
    ort = pytest.importorskip("onnxruntime", reason="the onnx extra is not installed: pip install 'unitac-rig[onnx]'")
    export = tmp_path / "onnx"
    assert cli(["export-model", str(run_dir), "--format", "onnx", "--out", str(export)]) == 0
    assert not list(export.glob("*.data"))  # weights inside each .onnx file, nothing to lose on the way
    translator = Translator.load(run_dir)
    for source, target in DIRECTIONS:
        encoder = ort.InferenceSession(str(export / f"encoder_{source}.onnx"), providers=["CPUExecutionProvider"])
        decoder = ort.InferenceSession(str(export / f"decoder_{target}.onnx"), providers=["CPUExecutionProvider"])
        frames = pairs.values[source][:3].astype(np.float32)
        (latent,) = encoder.run(None, {"frames": frames})
        (got,) = decoder.run(None, {"latent": latent})
        _assert_matches(got, translator.translate(frames, source, target))


@pytest.mark.filterwarnings("ignore:`torch.jit.load` is deprecated:DeprecationWarning")
def test_an_added_sensor_exports_with_its_own_output_layer(run_dir: Path, tmp_path: Path) -> None:
    fake = SensorLayout("fakepad", "test-only pad", 2, 2, 6.0, "N", False, "a 2x2 pad that exists only in tests")
    sets = small_sets(layouts=(USKIN, PAPILLARRAY, fake))
    extended = tmp_path / "ext"
    add_sensor(run_dir, sets, "fakepad", extended, ExtendConfig(epochs=3), device="cpu")
    export = tmp_path / "ext_ts"
    assert cli(["export-model", str(extended), "--format", "torchscript", "--out", str(export)]) == 0
    document = json.loads((export / "model.json").read_text())
    assert document["extension"]["new_sensor"] == "fakepad"
    assert "as recorded" in document["sensors"]["fakepad"]["units"]  # not a registered sensor: no unit to claim
    translator = Translator.load(extended)
    uskin = next(s for s in sets if s.sensor == "uskin").values[:4]
    for source, target, frames in [("uskin", "fakepad", uskin), ("fakepad", "papillarray", None)]:
        if frames is None:
            frames = next(s for s in sets if s.sensor == "fakepad").values[:4]
        encoder = torch.jit.load(str(export / f"encoder_{source}.torchscript.pt"))
        decoder = torch.jit.load(str(export / f"decoder_{target}.torchscript.pt"))
        with torch.no_grad():
            got = decoder(encoder(torch.from_numpy(frames.copy()))).numpy()
        _assert_matches(got, translator.translate(frames, source, target))


def test_bad_requests_are_one_line_usage_errors(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli(["export-model", str(run_dir), "--format", "pickle", "--out", str(tmp_path / "a")]) == 2
    assert "unknown export format 'pickle'" in capsys.readouterr().err
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep.txt").write_text("mine")
    assert cli(["export-model", str(run_dir), "--format", "state-dict", "--out", str(tmp_path / "full")]) == 2
    assert "not empty" in capsys.readouterr().err
    assert (tmp_path / "full" / "keep.txt").read_text() == "mine"
    args = ["export-model", str(run_dir), "--format", "state-dict", "--out", str(tmp_path / "b"), "--member", "5"]
    assert cli(args) == 2
    assert "member 5 does not exist" in capsys.readouterr().err
