"""Damaged bytes and lost messages on the simulated rig's real transports, end to end through collect_session.

Serial routes (SLCAN ASCII lines, PapillArray binary packets) get split reads, flipped bits and line noise; the
virtual CAN bus loses whole messages (real CAN frames carry a CRC, so dropping is the fault that exists there).
Each session must finish, every press must be recorded, the damage must be counted in the press's
``sensor_health``, and the force-matched extraction must never pick a frame flagged invalid.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.robustness.robustness_helpers import few_angles
from unitac_rig.collection.session import collect_session
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.sim.faults import FaultPlan
from unitac_rig.storage.press_record import PressRecord
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path


def _collect(
    tmp_path: Path, sensor: str, faults: FaultPlan, angles: int, **options: dict[str, object]
) -> list[PressRecord]:
    with SimRig(few_angles(angles), seed=0, faults=faults, sensor_options=options) as rig:
        outcome = collect_session(rig, get_object("hex_tpu"), sensor, tmp_path)
    assert outcome.stopped is None
    assert outcome.complete == angles and outcome.failed == outcome.aborted == 0
    return read_presses(session_path(tmp_path, "hex_tpu", sensor))


def _matched_frames_are_valid(press: PressRecord) -> tuple[int, int]:
    """(targets matched, targets whose nearest frame was invalid); asserts no invalid frame was matched."""
    ex = press.extraction
    assert ex is not None
    picked = ex.frame_index >= 0
    invalid_nearest = picked & ~press.tactile_valid[np.maximum(ex.frame_index, 0)]
    assert not np.any(invalid_nearest & ~ex.miss), f"{press.press_id}: an invalid frame was matched"
    return ex.n_matched, int(invalid_nearest.sum())


def test_slcan_lines_split_corrupted_and_noisy_still_give_a_complete_session(tmp_path: Path) -> None:
    faults = FaultPlan(seed=3, split_max_bytes=5, corrupt_prob=0.01, garbage_prob=0.01)
    presses = _collect(tmp_path, "uskin", faults, angles=2, uskin={"transport": "slcan"})
    damaged_lines = sum(p.attrs["sensor_health"]["checksum_errors"] for p in presses)
    assert damaged_lines > 0  # the damage was seen and counted, not silently decoded
    for press in presses:
        matched, _ = _matched_frames_are_valid(press)
        assert matched >= 5
        assert press.attrs["peak_force_n"] >= 10.0


def test_papillarray_packets_split_corrupted_and_noisy_are_resynchronised(tmp_path: Path) -> None:
    faults = FaultPlan(seed=4, split_max_bytes=9, corrupt_prob=0.03, garbage_prob=0.03, drop_byte_prob=0.0005)
    presses = _collect(tmp_path, "papillarray", faults, angles=3)
    health = [p.attrs["sensor_health"] for p in presses]
    assert sum(h["checksum_errors"] for h in health) > 0
    assert sum(h["bytes_dropped"] for h in health) > 0
    assert sum(h["sequence_gaps"] for h in health) > 0  # damaged packets are dropped, and the counter shows where
    for press in presses:
        assert press.tactile_valid.all()  # a packet either passes its checksum or is not a frame at all
        matched, _ = _matched_frames_are_valid(press)
        assert matched >= 20


def test_dropped_can_messages_flag_frames_invalid_and_extraction_never_matches_them(tmp_path: Path) -> None:
    presses = _collect(tmp_path, "uskin", FaultPlan(seed=5, drop_message_prob=0.02), angles=3)
    skipped = 0
    for press in presses:
        invalid = ~press.tactile_valid
        assert 0.1 < invalid.mean() < 0.8  # 24 messages per frame: ~1 - 0.98^24 = 38 % of frames miss a taxel
        assert press.attrs["sensor_health"]["invalid_frames"] >= invalid.sum()
        matched, invalid_nearest = _matched_frames_are_valid(press)
        skipped += invalid_nearest
        assert matched > 0
    assert skipped > 0  # some targets fell on an invalid frame: they were counted as misses, not matched
