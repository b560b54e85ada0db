"""`export-model --format safetensors` (the default): model.safetensors + config.json + the model card. The card's own
loading code, run as written in a `python -I` process that refuses every import of this project, translates in all
four directions and encodes exactly as `translate` does (1e-5 of the output's range)."""

from __future__ import annotations

import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors import safe_open

from tests.helpers import cli
from tests.learning.learning_helpers import REFUSE_PROJECT_IMPORTS, small_sets
from unitac_rig.learning.data import PairedDataset, build_paired_dataset
from unitac_rig.learning.evaluate import write_metrics
from unitac_rig.learning.train import TrainConfig, train
from unitac_rig.learning.translate import Translator

DIRECTIONS = [("uskin", "papillarray"), ("papillarray", "uskin"), ("uskin", "uskin"), ("papillarray", "papillarray")]

# Appended: translate the frames saved by the test with the card's networks.
COMPARE = """
frames = torch.load(sys.argv[1], weights_only=True)
results = {}
with torch.no_grad():
    for source in ("uskin", "papillarray"):
        results[f"latent_{source}"] = network("encoder", source)(frames[source])
        for target in ("uskin", "papillarray"):
            results[f"{source}_to_{target}"] = network("decoder", target)(network("encoder", source)(frames[source]))
torch.save(results, sys.argv[2])
print(sorted(m for m in sys.modules if m.split(".")[0] in ("unitac_rig", "drivers", "protocols")))
"""


@pytest.fixture(scope="module")
def pairs() -> PairedDataset:
    return build_paired_dataset(small_sets())


@pytest.fixture(scope="module")
def run_dir(pairs: PairedDataset, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("safetensors") / "run"
    train(pairs, out, TrainConfig(epochs=30, seeds=(0,), tsne_contacts=30, eval_every=30), device="cpu")
    write_metrics(out)
    return out


@pytest.fixture(scope="module")
def exported(run_dir: Path) -> Path:
    out = run_dir.parent / "hub"
    assert cli(["export-model", str(run_dir), "--out", str(out)]) == 0  # no --format: safetensors is the default
    return out


def _card_code(export: Path) -> str:
    card = (export / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", card, flags=re.S)
    assert len(blocks) == 1
    return blocks[0]


def test_the_cards_code_translates_like_translate_in_a_process_without_the_project(
    exported: Path, run_dir: Path, pairs: PairedDataset, tmp_path: Path
) -> None:
    frames = {s: torch.from_numpy(pairs.values[s][:9].copy()) for s in pairs.sensors}
    torch.save(frames, tmp_path / "frames.pt")
    script = REFUSE_PROJECT_IMPORTS + _card_code(exported) + "\nimport sys\n" + COMPARE
    done = subprocess.run(
        [sys.executable, "-I", "-c", script, str(tmp_path / "frames.pt"), str(tmp_path / "out.pt")],
        capture_output=True, text=True, timeout=300, cwd=exported,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"  # nothing of unitac-rig was imported
    results = torch.load(tmp_path / "out.pt", weights_only=True)
    translator = Translator.load(run_dir)
    for source, target in DIRECTIONS:
        expected = translator.translate(pairs.values[source][:9], source, target)
        scale = float(np.abs(expected).max())
        np.testing.assert_allclose(results[f"{source}_to_{target}"].numpy(), expected, rtol=0, atol=1e-5 * scale)
    for sensor in pairs.sensors:
        expected = translator.encode(pairs.values[sensor][:9], sensor)
        scale = float(np.abs(expected).max())
        np.testing.assert_allclose(results[f"latent_{sensor}"].numpy(), expected, rtol=0, atol=1e-5 * scale)


def test_config_json_says_shapes_normaliser_units_and_data_hash(exported: Path, run_dir: Path) -> None:
    assert sorted(p.name for p in exported.iterdir()) == ["README.md", "config.json", "model.safetensors"]
    config = json.loads((exported / "config.json").read_text())
    assert config["export_format"] == "safetensors" and config["latent_dim"] == 16
    uskin, papill = config["sensors"]["uskin"], config["sensors"]["papillarray"]
    assert uskin["frame_shape"] == [24, 3] and uskin["units"] == "counts" and papill["units"] == "N"
    assert papill["encoder_widths"] == [27, 64, 48, 16] and papill["decoder_widths"][-1] == 27
    assert len(uskin["normaliser_folded_in"]["mean"]) == 3 and len(uskin["normaliser_folded_in"]["std"]) == 3
    checkpoint = torch.load(run_dir / "checkpoint.pt", weights_only=True)
    assert config["dataset_hash"] == checkpoint["dataset_hash"]
    digest = hashlib.sha256((exported / "model.safetensors").read_bytes()).hexdigest()
    assert config["files"] == {"model.safetensors": digest}
    with safe_open(str(exported / "model.safetensors"), framework="pt") as handle:
        names = set(handle.keys())
        assert handle.metadata()["dataset_hash"] == checkpoint["dataset_hash"]
        assert list(handle.get_tensor("encoder.papillarray.0.weight").shape) == [64, 27]  # (out, in), nn.Linear's
    assert names == set(config["tensors"])
    assert {"encoder.uskin.2.bias", "decoder.papillarray.0.weight"} <= names
    card = (exported / "README.md").read_text()
    assert card.startswith("---\nlibrary_name: pytorch")
    for heading in ("## Training data", "## Metrics", "## Intended use", "## Limits", "## How to load"):
        assert heading in card
    assert checkpoint["dataset_hash"] in card
