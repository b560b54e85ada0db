"""What a matched frame is referenced to: each press's own tare (the default), or the tare at the start of its
recording (``baseline="recording"``, the paper's one baseline per recorded file, one file per object rotation), so
the sensor's drift since then stays in the frame. Checked against the raw stream the recorder kept."""

from __future__ import annotations

from pathlib import Path
from typing import get_args

import numpy as np
import pytest

from tests.helpers import cli
from unitac_rig.errors import DataError
from unitac_rig.learning.config import FrameBaseline
from unitac_rig.storage.paired import build_paired_dataset, load_sets
from unitac_rig.storage.reader import FRAME_BASELINES, PressTare, load_matched_set, read_presses, recording_shifts


def test_each_press_shifts_to_the_first_tare_of_its_own_rotation_by_time_not_by_file_order() -> None:
    a, b, c, d = (np.full((1, 3), v) for v in (5.0, 2.0, 40.0, 47.0))
    tares = [
        PressTare(start_s=9.0, rotation_deg=0.0, tare=a),
        PressTare(start_s=1.0, rotation_deg=0.0, tare=b),  # the rotation's recording began here
        PressTare(start_s=20.0, rotation_deg=90.0, tare=c),
        PressTare(start_s=25.0, rotation_deg=90.0, tare=d),
    ]
    shifts = recording_shifts(tares)
    assert [float(s[0, 0]) for s in shifts] == [3.0, 0.0, 0.0, 7.0]


@pytest.fixture(scope="module")
def irregular(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The irregular prism at its four rotations, 2 angles each, by each sensor on the simulated rig (which drifts)."""
    root = tmp_path_factory.mktemp("baseline") / "data"
    for _ in range(2):  # the simulated rig mounts the next sensor without a complete session
        assert cli(["collect", "--object", "irregular_pla", "--data", str(root), "--angles", "2", "--no-live"]) == 0
    return root


def test_recording_frames_are_the_raw_frames_minus_the_tare_at_the_start_of_their_rotation(irregular: Path) -> None:
    path = irregular / "irregular_pla__uskin.h5"
    presses = sorted(read_presses(path), key=lambda p: float(p.tactile_t_s[0]))
    first_tare = {}
    expected = {}
    for press in presses:
        first_tare.setdefault(press.rotation_deg, np.asarray(press.tare_baseline, np.float64))
        picked = press.extraction.frame_index[~press.extraction.miss]
        raw = np.asarray(press.tactile_values, np.float64)[picked]
        expected[press.press_id] = raw - first_tare[press.rotation_deg]
    assert len(first_tare) == 4

    by_press = load_matched_set(path, "press")
    by_recording = load_matched_set(path, "recording")
    assert by_recording.baseline == "recording" and by_press.baseline == "press"
    start = 0
    moved = 0.0
    for press in read_presses(path):  # file order, as the reader walks it
        n = int((~press.extraction.miss).sum())
        got = by_recording.values[start : start + n].astype(np.float64)
        assert np.allclose(got, expected[press.press_id], atol=0.05)  # float32 counts of ~1e3
        moved = max(moved, float(np.abs(got - by_press.values[start : start + n]).max()))
        start += n
    assert start == len(by_recording)
    assert moved > 1.0  # the twin's uSkin drifts: the two baselines differ after the first press of a rotation


def test_the_first_press_of_each_rotation_reads_the_same_under_both_baselines(irregular: Path) -> None:
    path = irregular / "irregular_pla__papillarray.h5"
    firsts = {}
    for press in sorted(read_presses(path), key=lambda p: float(p.tactile_t_s[0])):
        firsts.setdefault(press.rotation_deg, press.angle_deg)
    by_press, by_recording = load_matched_set(path), load_matched_set(path, "recording")
    for rotation, angle in firsts.items():
        rows = (by_press.rotation_deg == rotation) & (by_press.angle_deg == angle)
        assert rows.any()
        assert np.array_equal(by_press.values[rows], by_recording.values[rows])


def test_a_paired_dataset_says_which_baseline_and_refuses_a_mix(irregular: Path) -> None:
    dataset = build_paired_dataset(load_sets(irregular, "recording"))
    assert dataset.frame_baseline == "recording"
    assert dataset.subset(np.arange(3)).frame_baseline == "recording"
    assert build_paired_dataset(load_sets(irregular)).frame_baseline == "press"
    mixed = [load_matched_set(irregular / "irregular_pla__uskin.h5", "recording")]
    mixed.append(load_matched_set(irregular / "irregular_pla__papillarray.h5", "press"))
    with pytest.raises(DataError, match="different frame baselines"):
        build_paired_dataset(mixed)
    with pytest.raises(DataError, match="unknown frame baseline"):
        load_matched_set(irregular / "irregular_pla__uskin.h5", "session")


def test_the_training_options_and_the_reader_know_the_same_frame_baselines() -> None:
    """The config's Literal (what a TOML or --frame-baseline accepts) and the reader's names are one list twice."""
    assert get_args(FrameBaseline) == FRAME_BASELINES
