"""A tiny run end to end: train (several seeds with baselines), resume, metrics, report, translate, geometry,
through the Python API and the CLI, on synthetic contacts written as real session files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from drivers.layouts import PAPILLARRAY, USKIN
from tests.helpers import cli
from tests.learning.learning_helpers import small_sets, write_sessions
from unitac_rig.errors import DataError, ModelError, UsageError
from unitac_rig.learning import report as report_module
from unitac_rig.learning.contact_geometry import GeometryConfig, geometry_for_run
from unitac_rig.learning.data import build_paired_dataset, ray_deg
from unitac_rig.learning.paper import TABLE1_COLUMNS
from unitac_rig.learning.report import write_report
from unitac_rig.learning.train import TrainConfig, load_run, train
from unitac_rig.learning.translate import Translator

TINY = TrainConfig(epochs=3, seeds=(0, 1), tsne_contacts=60, checkpoint_every=1)


@pytest.fixture(scope="module")
def pairs():  # type: ignore[no-untyped-def]
    return build_paired_dataset(small_sets())


@pytest.fixture(scope="module")
def run_dir(pairs, tmp_path_factory) -> Path:  # type: ignore[no-untyped-def]
    out = tmp_path_factory.mktemp("run") / "nv"
    train(pairs, out, TINY, device="cpu")
    return out


def test_metrics_json_has_table1_rows_columns_and_alignment(run_dir: Path) -> None:
    write_report(run_dir, figures=False)
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert list(metrics["table1"]) == ["circle_pla", "hex_tpu", "all_seen", "irregular_pla"]
    for row in metrics["table1"].values():
        assert set(row) == set(TABLE1_COLUMNS)
        for cell in row.values():
            assert 0.0 <= cell["nmae"] < 1.0 and -1.0 <= cell["ssim"] <= 1.0
    assert metrics["test_rows"]["irregular_pla"] == 4 * 11 * 5
    assert metrics["test_rows"]["all_seen"] == 2 * 5  # one held-out angle (5 forces) per seen object
    latent_l1 = metrics["alignment"]["per_subset"]["all"]["latent_l1"]
    assert min(latent_l1["first_epoch"]) > 0 and min(latent_l1["final"]) > 0
    assert metrics["epochs"] == 3 and metrics["seed"] == 0 and metrics["seeds"] == [0, 1]
    assert set(metrics["table1_std"]) == set(metrics["table1"])  # several seeds -> spread reported


def test_resume_continues_exactly_where_an_uninterrupted_run_would_be(pairs, run_dir: Path, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    split_run = tmp_path / "split"
    train(pairs, split_run, TrainConfig(epochs=2, seeds=(0, 1), tsne_contacts=60, checkpoint_every=1), device="cpu")
    resumed = train(pairs, split_run, resume=True, epochs=3, device="cpu")
    assert [h["epoch"] for h in resumed.history] == [1, 2, 3]
    torch.testing.assert_close(load_run(split_run).engine.theta, load_run(run_dir).engine.theta)


def test_a_finished_run_is_not_overwritten_and_other_data_cannot_resume_it(pairs, run_dir: Path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(UsageError, match="already holds a run"):
        train(pairs, run_dir, TINY)
    with pytest.raises(DataError, match="differs"):
        train(pairs.subset(pairs.object_id != "hex_tpu"), run_dir, resume=True)


def test_report_writes_markdown_beside_the_paper_and_figures(run_dir: Path, tmp_path: Path) -> None:
    report = write_report(run_dir)
    text = report.read_text()
    assert "| *paper* |" in text and "0.318 / 0.581" in text  # the paper's irregular papillarray -> uskin
    simple = json.loads((run_dir / "metrics.json").read_text())["simple_baselines"]["table1"]
    cell = simple["all_seen"]["ridge_papillarray_to_uskin"]
    assert "## Simple baselines" in text and f"{cell['nmae']:.3f} / {cell['ssim']:.3f}" in text
    for name in ("curves.png", "tsne.png", "reconstructions_seen.png", "reconstructions_unseen.png"):
        assert (run_dir / "figures" / name).stat().st_size > 1000


def test_translator_maps_frames_between_sensors_in_their_units(run_dir: Path, pairs) -> None:  # type: ignore[no-untyped-def]
    translator = Translator.load(run_dir)
    uskin = pairs.values["uskin"][:4]
    out = translator.translate(uskin, "uskin", "papillarray")
    assert out.shape == (4, 9, 3) and out.dtype == np.float32
    single = translator.translate(uskin[0], "uskin", "papillarray")
    np.testing.assert_allclose(single, out[0], rtol=1e-5, atol=1e-6)
    assert translator.encode(uskin, "uskin").shape == (4, 16)
    with pytest.raises(ModelError, match="no sensor 'digit'"):
        translator.translate(uskin, "uskin", "digit")
    with pytest.raises(ModelError, match=r"\(\.\.\., 9, 3\)"):
        translator.translate(uskin, "papillarray", "uskin")
    latency = translator.single_frame_latency_ms("uskin", "papillarray", repeats=20)
    assert latency["median_ms"] > 0


def test_geometry_writes_n_by_n_scenarios_and_the_outline_figure(run_dir: Path) -> None:
    result, json_path, png_path = geometry_for_run(run_dir, config=GeometryConfig(epochs=2))
    data = json.loads(json_path.read_text())
    assert data["object"] == "irregular_pla"
    assert set(data["scenarios"]) == {
        "uskin_to_uskin",
        "uskin_to_papillarray",
        "papillarray_to_papillarray",
        "papillarray_to_uskin",
    }
    assert data["scenarios"]["uskin_to_papillarray"]["paper_mae_mm"] == 0.637
    assert all(np.isfinite(s["mae_mm"]) for s in data["scenarios"].values())
    # 10 % of the physical rays are held out, whole: 4 rays, one of them pressed under two (rotation, angle) keys on
    # the irregular prism (a split treats a ray as one unit), so 5 keys with their 5 forces each
    keys = set(zip(result.rotation_deg.tolist(), result.angle_deg.tolist(), strict=True))
    assert len({ray_deg(r, a) for r, a in keys}) == 4
    assert len(keys) == 5 and len(result.test_rows) == 5 * 5
    assert png_path.stat().st_size > 1000


def test_cli_trains_from_session_files_and_translates_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data"
    sets = small_sets(objects=("circle_pla", "irregular_pla"))
    write_sessions(data, sets)
    run = tmp_path / "run"
    assert cli(["train", "--data", str(data), "--out", str(run), "--epochs", "2", "--no-report"]) == 0
    assert (run / "checkpoint.pt").exists()

    session = data / "circle_pla__uskin.h5"
    assert cli(["translate", str(run), str(session), "--from", "uskin", "--to", "papillarray"]) == 0
    out = np.load(run / "translations" / "circle_pla__uskin_to_papillarray.npz")  # never into the dataset
    assert out["frames"].shape == (55, 9, 3)
    assert sorted(out["angle_deg"].tolist())[0] == -45.0
    assert "single-frame latency" in capsys.readouterr().out

    frames = tmp_path / "frames.npy"
    np.save(frames, sets[1].values[:3])  # papillarray frames
    args = [
        "translate",
        str(run),
        str(frames),
        "--from",
        "papillarray",
        "--to",
        "uskin",
        "--out",
        str(tmp_path / "t.npz"),
    ]
    assert cli(args) == 0
    assert np.load(tmp_path / "t.npz")["frames"].shape == (3, 24, 3)


def test_cli_errors_are_one_clear_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data"
    write_sessions(
        data,
        [
            s
            for s in small_sets(objects=("circle_pla", "hex_tpu"))
            if (s.object_id, s.sensor) in {("circle_pla", "uskin"), ("hex_tpu", "papillarray")}
        ],
    )
    assert cli(["train", "--data", str(data), "--out", str(tmp_path / "run")]) == 1
    assert "no joined pairs" in capsys.readouterr().err

    assert cli(["geometry", str(tmp_path)]) == 2
    assert "is not a training run" in capsys.readouterr().err


def test_three_sensors_train_and_translate(tmp_path: Path) -> None:
    from drivers.layouts import SensorLayout

    fake = SensorLayout("fakepad", "test-only pad", 2, 2, 6.0, "N", False, "a 2x2 pad that exists only in tests")
    pairs3 = build_paired_dataset(small_sets(layouts=(USKIN, PAPILLARRAY, fake), objects=("hex_tpu", "irregular_pla")))
    assert pairs3.sensors == ("uskin", "papillarray", "fakepad")
    outcome = train(pairs3, tmp_path / "run3", TrainConfig(epochs=2, tsne_contacts=30), device="cpu")
    test = outcome.history[-1]["test"]["all"]
    directions = {k for k in test if "_to_" in k}
    assert len(directions) == 9  # N x N
    assert {"ae_uskin", "ae_papillarray", "ae_fakepad"} <= set(test)
    out = Translator.load(tmp_path / "run3").translate(pairs3.values["fakepad"][:2], "fakepad", "uskin")
    assert out.shape == (2, 24, 3)
    write_report(tmp_path / "run3")  # no registered layout for fakepad: that figure is skipped, the rest drawn
    assert "fakepad → uskin" in (tmp_path / "run3" / "report.md").read_text()


def test_an_interrupted_report_leaves_metrics_and_report_as_they_were(
    run_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = tmp_path / "copy"
    shutil.copytree(run_dir, run)
    write_report(run, figures=False)
    before = {name: (run / name).read_bytes() for name in ("metrics.json", "report.md")}

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(report_module, "plot_curves", interrupted)  # Ctrl-C while the figures are drawn
    with pytest.raises(KeyboardInterrupt):
        write_report(run, nmae_normaliser="sensor_range")  # other numbers: metrics.json would change
    assert {name: (run / name).read_bytes() for name in before} == before
    assert not [p.name for p in run.iterdir() if p.name.endswith(".tmp")]
