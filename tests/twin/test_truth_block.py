"""The controller twin's shared truth block: never a torn snapshot, and a writer stalled mid-write (descheduled on a
loaded box) leaves the previous snapshot readable instead of making every reader wait and fail."""

from __future__ import annotations

import tempfile
import time
from collections.abc import Iterator

import numpy as np
import pytest

from unitac_rig.sim.twin.truth import _SEQ, _SLOT, TruthBlock, TwinTruth


def snapshot(cycles: int) -> TwinTruth:
    pose = np.array([0.1 * cycles, 0.2, 0.3, 0.0, 3.14, 0.0])
    zeros = np.zeros(6)
    return TwinTruth(
        controller_t_s=0.002 * cycles,
        cycles=cycles,
        pad_pose=pose,
        tcp_pose=pose,
        true_wrench=zeros,
        reported_wrench=zeros,
        tcp_speed=zeros,
        force_n=float(cycles),
        peak_force_n=float(cycles),
        robot_mode=7,
        safety_mode=1,
        safety_status_bits=1,
        robot_status_bits=3,
        runtime_state=2,
        program_running=True,
        watchdog_armed=True,
        watchdog_trips=0,
        protective_stops=0,
        emergency_stops=0,
        program_starts=1,
        script_uploads=1,
        rtde_clients=2,
        last_input_t_s=0.0,
        worst_lateness_s=0.0,
        late_cycles=0,
        skipped_cycles=0,
        achieved_rate_hz=500.0,
        commands_done=cycles,
    )


@pytest.fixture
def block_pair() -> Iterator[tuple[TruthBlock, TruthBlock]]:
    """A writer's and a reader's view of one freshly created block, as the controller and the handle map it."""
    with tempfile.TemporaryFile() as f:
        f.truncate(TruthBlock.size)
        writer, reader = TruthBlock(f.fileno()), TruthBlock(f.fileno())
        yield writer, reader
        writer.close()
        reader.close()


def test_nothing_is_read_before_the_first_write_and_the_newest_after(
    block_pair: tuple[TruthBlock, TruthBlock],
) -> None:
    writer, reader = block_pair
    start = time.monotonic()
    assert reader.read() is None and reader.read_pad_pose() is None
    assert time.monotonic() - start < 0.1  # an empty block is not waited on
    for cycles in (1, 2, 3):
        writer.write(snapshot(cycles))
        truth = reader.read()
        assert truth is not None and truth.cycles == cycles and truth.commands_done == cycles
        pose = reader.read_pad_pose()
        assert pose is not None and np.allclose(pose, snapshot(cycles).pad_pose)


def test_a_writer_stalled_mid_write_leaves_the_previous_snapshot_readable(
    block_pair: tuple[TruthBlock, TruthBlock],
) -> None:
    writer, reader = block_pair
    writer.write(snapshot(1))
    writer.write(snapshot(2))
    # snapshot 3 started (slot 1, odd sequence) and half written when the writer lost the CPU
    _SEQ.pack_into(reader._map, _SLOT, 5)
    reader._map[_SLOT + _SEQ.size : _SLOT + _SEQ.size + 64] = b"\xff" * 64
    start = time.monotonic()
    truth = reader.read(timeout_s=0.5)
    assert truth is not None and truth.cycles == 2  # the last complete one, at once
    pose = reader.read_pad_pose(timeout_s=0.5)
    assert pose is not None and np.allclose(pose, snapshot(2).pad_pose)
    assert time.monotonic() - start < 0.1


def test_a_writer_that_died_in_its_first_write_gives_nothing_after_the_timeout(
    block_pair: tuple[TruthBlock, TruthBlock],
) -> None:
    _, reader = block_pair
    _SEQ.pack_into(reader._map, _SLOT, 1)  # generation 1 goes to slot 1: started, never finished
    start = time.monotonic()
    assert reader.read(timeout_s=0.05) is None
    assert time.monotonic() - start >= 0.05


def test_a_writer_reopened_on_a_used_block_goes_on_counting() -> None:
    # a new writer on a block that already holds snapshots must not restart at 1: its first snapshot would lose to
    # the older ones' higher sequence numbers and readers would see the old state for ever
    with tempfile.TemporaryFile() as f:
        f.truncate(TruthBlock.size)
        first, reader = TruthBlock(f.fileno()), TruthBlock(f.fileno())
        for cycles in range(1, 6):
            first.write(snapshot(cycles))
        second = TruthBlock(f.fileno())
        second.write(snapshot(100))
        truth = reader.read()
        assert truth is not None and truth.cycles == 100
        for block in (first, second, reader):
            block.close()
