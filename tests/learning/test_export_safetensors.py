"""`export-model --format safetensors` (the default): model.safetensors + config.json + the model card, the Hugging
Face Hub layout written by huggingface_hub's PyTorchModelHubMixin. The card's own loading code
(`UniTacNV.from_pretrained(".")`), run as written in a fresh process with the Hub offline, translates in all four
directions and encodes exactly as `translate` does (1e-5 of the output's range); the card's YAML is what the Hub
reads (license, pipeline tag, datasets, metrics as a model-index); `--push-to-hub` sends that folder."""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
import yaml
from safetensors import safe_open

from tests.helpers import cli
from tests.learning.learning_helpers import small_sets
from unitac_rig.learning.data import PairedDataset, build_paired_dataset
from unitac_rig.learning.network import UniTacNV
from unitac_rig.learning.report import write_report
from unitac_rig.learning.train import TrainConfig, train
from unitac_rig.learning.translate import Translator

DIRECTIONS = [("uskin", "papillarray"), ("papillarray", "uskin"), ("uskin", "uskin"), ("papillarray", "papillarray")]

# Appended to the card's code: translate the frames saved by the test with the model it loaded.
COMPARE = """
import sys
frames = torch.load(sys.argv[1], weights_only=True)
results = {}
with torch.no_grad():
    for source in ("uskin", "papillarray"):
        results[f"latent_{source}"] = model.encode(frames[source], source)
        for target in ("uskin", "papillarray"):
            results[f"{source}_to_{target}"] = model(frames[source], source, target)
torch.save(results, sys.argv[2])
"""


@pytest.fixture(scope="module")
def pairs() -> PairedDataset:
    return build_paired_dataset(small_sets())


@pytest.fixture(scope="module")
def run_dir(pairs: PairedDataset, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("safetensors") / "run"
    train(pairs, out, TrainConfig(epochs=30, seeds=(0,), tsne_contacts=30, eval_every=30), device="cpu")
    write_report(out, figures=False)  # metrics.json, which the model card quotes
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


def test_the_cards_from_pretrained_code_translates_like_translate_offline(
    exported: Path, run_dir: Path, pairs: PairedDataset, tmp_path: Path
) -> None:
    frames = {s: torch.from_numpy(pairs.values[s][:9].copy()) for s in pairs.sensors}
    torch.save(frames, tmp_path / "frames.pt")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "PYTHONPATH": str(Path(__file__).parents[2])}
    done = subprocess.run(
        [sys.executable, "-c", _card_code(exported) + COMPARE, str(tmp_path / "frames.pt"), str(tmp_path / "out.pt")],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=exported,
        env=env,
    )
    assert done.returncode == 0, done.stderr
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


def test_from_pretrained_rebuilds_the_module_from_config_json_alone(exported: Path) -> None:
    model = UniTacNV.from_pretrained(exported)
    config = json.loads((exported / "config.json").read_text())
    assert model.sensors == ("uskin", "papillarray") and model.latent_dim == config["latent_dim"] == 16
    widths = [m.out_features for m in model.encoders["papillarray"] if isinstance(m, torch.nn.Linear)]
    assert widths == config["sensors"]["papillarray"]["encoder_widths"][1:]
    assert not model.training  # inference: no dropout
    assert tuple(model.decode(torch.zeros(2, 16), "uskin").shape) == (2, 24, 3)


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
        assert list(handle.get_tensor("encoders.papillarray.0.weight").shape) == [64, 27]  # (out, in), nn.Linear's
    assert names == set(config["tensors"])
    assert {"encoders.uskin.4.bias", "decoders.papillarray.0.weight"} <= names
    card = (exported / "README.md").read_text()
    for heading in ("## Training data", "## Metrics", "## Intended use", "## Limits", "## How to load"):
        assert heading in card
    assert checkpoint["dataset_hash"] in card


def _front_matter(card: str) -> dict[str, Any]:
    assert card.startswith("---\n")
    front, _, _ = card[4:].partition("\n---\n")
    loaded = yaml.safe_load(front)
    assert isinstance(loaded, dict)
    return loaded


def test_the_card_is_hub_metadata_with_the_run_metrics_as_a_model_index(exported: Path, run_dir: Path) -> None:
    card = (exported / "README.md").read_text()
    meta = _front_matter(card)
    assert meta["license"] == "mit" and meta["pipeline_tag"] == "feature-extraction"
    assert meta["library_name"] == "unitac-rig" and "tactile" in meta["tags"]
    config = json.loads((exported / "config.json").read_text())
    assert meta["datasets"] and config["dataset_hash"][:16] in meta["datasets"][0]
    table = json.loads((run_dir / "metrics.json").read_text())["table1"]
    results = meta["model-index"][0]["results"]
    expected = {(row, direction): cell for row, cells in table.items() for direction, cell in cells.items() if cell}
    assert len(results) == len(expected)
    for result in results:
        row, direction = result["dataset"]["name"].split(": ")
        cell = expected[(row, direction.replace(" to ", "_to_"))]
        values = {m["type"]: m["value"] for m in result["metrics"]}
        assert values == pytest.approx({"nmae": cell["nmae"], "ssim": cell["ssim"]}, rel=1e-5)
    assert "{'" not in card and "': " not in card  # no Python dict printed into the card


def test_push_to_hub_sends_the_export_folder_to_the_model_repo(
    exported: Path, run_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import huggingface_hub

    sent: list[tuple[str, dict[str, Any]]] = []

    def create_repo(self: Any, repo_id: str, **kwargs: Any) -> None:
        sent.append(("create_repo", {"repo_id": repo_id, **kwargs}))

    def upload_folder(self: Any, **kwargs: Any) -> str:
        sent.append(
            ("upload_folder", {**kwargs, "files": sorted(p.name for p in Path(kwargs["folder_path"]).iterdir())})
        )
        return "https://huggingface.co/lab/unitac-nv/commit/0"

    monkeypatch.setattr(huggingface_hub.HfApi, "create_repo", create_repo)
    monkeypatch.setattr(huggingface_hub.HfApi, "upload_folder", upload_folder)
    out = tmp_path / "pushed"
    assert cli(["export-model", str(run_dir), "--out", str(out), "--push-to-hub", "lab/unitac-nv"]) == 0
    assert [name for name, _ in sent] == ["create_repo", "upload_folder"]
    assert sent[0][1]["repo_id"] == "lab/unitac-nv" and sent[0][1]["repo_type"] == "model"
    upload = sent[1][1]
    assert upload["repo_id"] == "lab/unitac-nv" and Path(upload["folder_path"]) == out
    assert upload["files"] == ["README.md", "config.json", "model.safetensors"]
    sent.clear()
    other = tmp_path / "ts"
    assert (
        cli(["export-model", str(run_dir), "--format", "torchscript", "--out", str(other), "--push-to-hub", "lab/x"])
        == 2
    )
    assert sent == [] and not other.exists()  # refused before anything was written or sent
