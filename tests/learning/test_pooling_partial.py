"""Training data from several dataset directories (pooled with the export's rule: one session per (object, sensor),
identical copies once, different ones refused) and the partial join (contacts some sensors did not record)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from tests.helpers import cli
from tests.learning.learning_helpers import small_sets, write_sessions
from unitac_rig.errors import DataError
from unitac_rig.learning.data import build_paired_dataset, load_sets
from unitac_rig.learning.run import load_test_set
from unitac_rig.learning.train import TrainConfig, load_run, train
from unitac_rig.learning.translate import Translator


@pytest.fixture(scope="module")
def two_dirs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """The same sessions once in one directory, and split over two (a rig's and another day's)."""
    root = tmp_path_factory.mktemp("pool")
    sets = small_sets(objects=("circle_pla", "hex_tpu", "irregular_pla"))
    write_sessions(root / "all", sets)
    for name in ("a", "b"):
        (root / name).mkdir()
    for path in sorted((root / "all").glob("*.h5")):
        shutil.copy2(path, root / ("a" if path.name.startswith(("circle", "irregular")) else "b") / path.name)
    return root / "all", root / "a", root / "b"


def test_two_directories_pool_to_the_dataset_of_one(two_dirs: tuple[Path, Path, Path]) -> None:
    everything, a, b = two_dirs
    pooled = build_paired_dataset(load_sets([a, b]))
    single = build_paired_dataset(load_sets(everything))
    assert pooled.objects == ("circle_pla", "hex_tpu", "irregular_pla")
    assert pooled.content_hash() == single.content_hash()


def test_an_identical_copy_pools_once_and_a_different_session_is_refused(
    two_dirs: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    everything, a, b = two_dirs
    copy = tmp_path / "copy"
    copy.mkdir()
    shutil.copy2(a / "circle_pla__uskin.h5", copy / "circle_pla__uskin.h5")
    assert (
        build_paired_dataset(load_sets([a, b, copy])).content_hash()
        == build_paired_dataset(load_sets(everything)).content_hash()
    )

    other = tmp_path / "other"
    write_sessions(other, [s for s in small_sets(objects=("circle_pla",), seed=7) if s.sensor == "uskin"])
    with pytest.raises(DataError, match=r"two sources disagree on session circle_pla/uskin"):
        load_sets([a, b, other])


def test_train_takes_repeated_data_options_and_names_a_conflict_in_one_line(
    two_dirs: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, a, b = two_dirs
    run = tmp_path / "run"
    assert cli(["train", "--data", str(a), "--data", str(b), "--out", str(run), "--epochs", "1", "--no-report"]) == 0
    out = " ".join(capsys.readouterr().out.split())  # the console wraps at the terminal's width
    assert "objects circle_pla, hex_tpu, irregular_pla" in out

    other = tmp_path / "other"
    write_sessions(other, [s for s in small_sets(objects=("hex_tpu",), seed=7) if s.sensor == "papillarray"])
    code = cli(["train", "--data", str(a), "--data", str(b), "--data", str(other), "--out", str(tmp_path / "r2")])
    err = capsys.readouterr().err
    assert code == 1 and "two sources disagree on session hex_tpu/papillarray" in err
    assert len(err.strip().splitlines()) == 1


def test_partial_join_keeps_contacts_two_sensors_share_and_marks_the_missing() -> None:
    fake = SensorLayout("fakepad", "test-only pad", 2, 2, 6.0, "N", False, "a 2x2 pad that exists only in tests")
    sets = small_sets(layouts=(USKIN, PAPILLARRAY, fake), objects=("circle_pla", "hex_tpu"))
    # hex_tpu was never pressed on the PapillArray: its contacts have the uSkin and the fake pad only
    sets = [s for s in sets if (s.object_id, s.sensor) != ("hex_tpu", "papillarray")]

    full = build_paired_dataset(sets)
    assert full.objects == ("circle_pla",) and full.present is None and full.complete_rows().all()

    partial = build_paired_dataset(sets, partial=True)
    assert partial.objects == ("circle_pla", "hex_tpu") and partial.present is not None
    hex_rows = partial.object_id == "hex_tpu"
    assert hex_rows.sum() == len(full)  # the same 11 angles x 5 targets
    assert not partial.has("papillarray")[hex_rows].any() and partial.has("uskin")[hex_rows].all()
    assert np.isnan(partial.values["papillarray"][hex_rows]).all()
    assert np.isfinite(partial.values["fakepad"]).all()
    assert (partial.complete_rows() == ~hex_rows).all()
    # the complete rows are the full join's, frame for frame
    complete = partial.subset(partial.complete_rows())
    for sensor in full.sensors:
        np.testing.assert_array_equal(complete.values[sensor], full.values[sensor])
    # a sensor's frames that no other sensor shares are left out, and counted
    only_uskin = [s for s in sets if s.sensor == "uskin" or s.object_id == "circle_pla"]
    assert build_paired_dataset(only_uskin, partial=True).dropped_per_sensor["uskin"] == len(full)


def test_training_uses_contacts_some_sensors_missed_and_scores_only_complete_ones(tmp_path: Path) -> None:
    fake = SensorLayout("fakepad", "test-only pad", 2, 2, 6.0, "N", False, "a 2x2 pad that exists only in tests")
    sets = small_sets(layouts=(USKIN, PAPILLARRAY, fake), objects=("circle_pla", "hex_tpu", "irregular_pla"))
    sets = [s for s in sets if (s.object_id, s.sensor) != ("hex_tpu", "papillarray")]  # hex_tpu: no PapillArray
    config = TrainConfig(epochs=150, learning_rate=2e-3, tsne_contacts=30, eval_every=150, baselines=False)
    train(build_paired_dataset(sets), tmp_path / "complete", config, device="cpu")
    partial_pairs = build_paired_dataset(sets, partial=True)
    partial = train(partial_pairs, tmp_path / "partial", config, device="cpu")

    assert all(np.isfinite(h["train_loss"]["unitac"]).all() for h in partial.history)
    test = load_test_set(tmp_path / "partial")
    assert "hex_tpu" not in test.objects and len(test) > 0  # scored on contacts every sensor recorded
    summary = torch.load(tmp_path / "partial" / "checkpoint.pt", weights_only=True)["dataset_summary"]
    assert summary["partial_train_rows"] > 0

    # hex_tpu's contacts (uSkin and fake pad only) are learned, not dropped: the partial run translates them between
    # its two sensors far better than the complete-only run, which never saw the object (measured 0.04 vs 0.37 of a
    # mean-frame error of 0.38; on the one held-out direction of this small grid both runs extrapolate badly)
    hex_rows = partial_pairs.subset((partial_pairs.object_id == "hex_tpu") & partial.split.train_mask)
    assert len(hex_rows) > 0

    def error(run: Path) -> float:
        translated = Translator.load(run).translate(hex_rows.values["uskin"], "uskin", "fakepad")
        return float(np.abs(translated - hex_rows.values["fakepad"]).mean())

    assert error(tmp_path / "partial") < 0.5 * error(tmp_path / "complete")


def test_a_partial_run_resumes_without_repeating_the_option(tmp_path: Path) -> None:
    fake = SensorLayout("fakepad", "test-only pad", 2, 2, 6.0, "N", False, "a 2x2 pad that exists only in tests")
    sets = small_sets(layouts=(USKIN, PAPILLARRAY, fake), objects=("circle_pla", "hex_tpu", "irregular_pla"))
    data = tmp_path / "data"
    write_sessions(data, [s for s in sets if (s.object_id, s.sensor) != ("hex_tpu", "papillarray")])
    run = tmp_path / "run"
    base = ["train", "--data", str(data), "--out", str(run), "--no-report"]
    assert cli([*base, "--partial", "--epochs", "1"]) == 0
    assert cli([*base, "--resume", "--epochs", "2"]) == 0
    assert load_run(run).payload["epoch"] == 2
