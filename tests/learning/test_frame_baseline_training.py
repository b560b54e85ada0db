"""``train --frame-baseline recording`` trains on frames referenced to the start of each recording (the paper's
preprocessing), records it, resumes on it, and feeds `translate` the frames it trained on; a run from before the
option existed reads as "press"."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import cli
from unitac_rig.errors import UsageError
from unitac_rig.learning.config import TrainConfig
from unitac_rig.learning.data import build_paired_dataset, load_sets
from unitac_rig.learning.run import load_checkpoint, load_test_set, stored_frame_baseline
from unitac_rig.learning.train import train
from unitac_rig.learning.translate import Translator
from unitac_rig.storage.reader import load_matched_set


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("baseline_train") / "data"
    for _ in range(2):  # each sensor in turn on the simulated rig
        assert cli(["collect", "--object", "hex_pla", "--data", str(root), "--angles", "4", "--no-live"]) == 0
    return root


def test_a_recording_baseline_run_trains_records_and_resumes_on_those_frames(data: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    args = ["train", "--data", str(data), "--out", str(run), "--epochs", "2", "--no-report"]
    assert cli([*args, "--frame-baseline", "recording"]) == 0
    assert tomllib.loads((run / "config.toml").read_text())["preprocessing"]["frame_baseline"] == "recording"
    assert stored_frame_baseline(run) == "recording"

    recording = build_paired_dataset(load_sets(data, "recording"))
    pressed = build_paired_dataset(load_sets(data))
    test = load_test_set(run)
    assert test.frame_baseline == "recording"
    rows = [
        int(np.flatnonzero((recording.angle_deg == a) & (recording.target_n == t))[0])
        for a, t in zip(test.angle_deg, test.target_n, strict=True)
    ]
    assert np.array_equal(test.values["uskin"], recording.values["uskin"][rows])
    assert not np.array_equal(test.values["uskin"], pressed.values["uskin"][rows])  # drift: the baselines differ

    # translate feeds the run a session's frames as it trained on them
    session = data / "hex_pla__uskin.h5"
    assert cli(["translate", str(run), str(session), "--from", "uskin", "--to", "papillarray"]) == 0
    written = np.load(run / "translations" / "hex_pla__uskin_to_papillarray.npz")["frames"]
    frames = load_matched_set(session, "recording").values
    assert np.allclose(written, Translator.load(run).translate(frames, "uskin", "papillarray"))

    # the resume reads the data as the run did (reading it per press would change its content hash and be refused)
    assert cli(["train", "--data", str(data), "--out", str(run), "--resume", "--epochs", "3", "--no-report"]) == 0
    assert load_checkpoint(run)["epoch"] == 3


def test_options_and_data_on_different_baselines_are_refused_before_anything_is_written(
    data: Path, tmp_path: Path
) -> None:
    pressed = build_paired_dataset(load_sets(data))
    with pytest.raises(UsageError, match="recording baseline, the data was read with the press one"):
        train(pressed, tmp_path / "run", TrainConfig(epochs=1, frame_baseline="recording"), device="cpu")
    assert not (tmp_path / "run").exists()


def test_a_run_stored_before_the_option_existed_trained_per_press() -> None:
    stored = TrainConfig().to_dict()
    del stored["frame_baseline"]
    assert TrainConfig.from_dict(stored).frame_baseline == "press"
    with pytest.raises(UsageError):
        TrainConfig(frame_baseline="session")
