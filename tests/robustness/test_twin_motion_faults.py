"""The four rows of the motion-safety review, against the real-time rig twin with the real ur_rtde clients.

``unitac-rig collect`` runs unchanged through the hardware path against :class:`RigTwin`; faults are injected on the
twin (the object placed away from where the rig file says) or on the process (SIGSTOP). Forces are the twin's ground
truth. The wider matrix (every motion x every fault) is ``benchmarks/fault_matrix.py``; its table is in
docs/reliability.md. Loopback addresses 127.0.0.200-209 belong to these tests.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers import console_script
from unitac_rig.sim.twin import ControllerParams, first_free_loopback
from unitac_rig.sim.twin.rig import RigTwin
from unitac_rig.storage.recorder import session_path

HARD_LIMIT_N = 25.0
OBJECT = "circle_pla"


@pytest.fixture
def twin(tmp_path: Path) -> Iterator[RigTwin]:
    with RigTwin(
        OBJECT,
        sensor="papillarray",
        host=first_free_loopback(200, 209),
        seed=3,
        params=ControllerParams(unlock_delay_s=0.3),
    ) as rig:
        yield rig


def rig_file(rig: RigTwin, tmp_path: Path, **tables: dict[str, object]) -> Path:
    path = tmp_path / "twin.toml"
    path.write_text(rig.rig_file(tables=tables or None))
    return path


def collect(rig_path: Path, data: Path, angles: int = 3) -> list[str]:
    return [
        console_script(),
        "collect",
        "--rig",
        str(rig_path),
        "--object",
        OBJECT,
        "--angles",
        str(angles),
        "--data",
        str(data),
        "--no-live",
    ]


def run_to_end(rig: RigTwin, cmd: list[str], *, freeze_at_contact_s: float = 0.0) -> tuple[int, str, bool]:
    """Run ``cmd``; with ``freeze_at_contact_s`` the process is stopped (SIGSTOP) that long the first time the pad
    touches anything, then continued. -> (exit code, stderr, whether it was frozen)."""
    rig.controller.reset_peak()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    frozen = False
    deadline = time.monotonic() + 240
    try:
        while proc.poll() is None and time.monotonic() < deadline:
            if freeze_at_contact_s and not frozen and rig.controller.truth().force_n > 0.5:
                os.kill(proc.pid, signal.SIGSTOP)
                frozen = True
                time.sleep(freeze_at_contact_s)
                os.kill(proc.pid, signal.SIGCONT)
            time.sleep(0.002)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return proc.returncode, err, frozen


def settle_and_check(rig: RigTwin, *, unloaded: bool = True) -> None:
    """The arm at rest, inside the rig file's workspace, the true peak below the limit; ``unloaded``: not pressing on
    anything (a program the watchdog stopped leaves the arm where it was: the host cannot move it then)."""
    time.sleep(0.3)
    truth = rig.controller.truth()
    assert truth.at_rest, truth
    assert truth.peak_force_n < HARD_LIMIT_N, truth.peak_force_n
    if unloaded:
        assert truth.force_n < 1.0, f"the pad was left loaded: {truth.force_n:.1f} N"
    x, y, z = truth.tcp_pose[:3]
    assert -0.6 <= x <= 0.4 and 0.2 <= y <= 1.0 and 0.0 <= z <= 0.6


def last_line(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line.strip()]
    return lines[-1] if lines else ""


@pytest.mark.slow
def test_an_object_50_mm_closer_than_the_rig_file_says_stays_under_the_hard_limit(
    twin: RigTwin, tmp_path: Path
) -> None:
    """Review row 1 (was 150.8 N: the back-off drove to the unreached stand-off into the object)."""
    twin.set_placement_error(0.0, -0.05)
    code, err, _ = run_to_end(twin, collect(rig_file(twin, tmp_path), tmp_path / "data"))
    assert code == 1, err
    assert last_line(err).startswith("error:") and "touch" in last_line(err)
    settle_and_check(twin)


@pytest.mark.slow
def test_the_double_fault_misplaced_object_and_a_host_frozen_at_first_contact_is_bounded(
    twin: RigTwin, tmp_path: Path
) -> None:
    """Review row 2 (was 84.3 N at 50 mm/s): the object 50 mm closer AND the host frozen 2 s at the first touch. Only
    the controller acts; the watchdog stops the move after 1/6 s, at the near speed (docs/real-rig.md's bound)."""
    twin.set_placement_error(0.0, -0.05)
    cmd = collect(rig_file(twin, tmp_path), tmp_path / "data")
    code, err, frozen = run_to_end(twin, cmd, freeze_at_contact_s=2.0)
    assert frozen and code == 1, err
    assert "run the same command again" in last_line(err), err  # the stopped program, not a sensor stall
    settle_and_check(twin, unloaded=False)  # the watchdog stopped the program: the pad rests where it stopped
    # the same command again, the object still misplaced: it pulls the pad off, touches it again, stops and retracts
    code, err, _ = run_to_end(twin, cmd)
    assert code == 1 and "touch" in last_line(err), err
    settle_and_check(twin)


@pytest.mark.slow
def test_a_workspace_that_excludes_the_second_press_is_refused_before_any_motion(twin: RigTwin, tmp_path: Path) -> None:
    """Review row 3 (was 37.9 N and the arm outside the box): the whole plan is checked first."""
    start = twin.controller.truth().tcp_pose.copy()
    path = rig_file(twin, tmp_path, limits={"workspace_max_m": [-0.13, 1.0, 0.6]})
    code, err, _ = run_to_end(twin, collect(path, tmp_path / "data", angles=2))
    assert code == 1, err
    line = last_line(err)
    assert "session plan (press 2 of 2)" in line and "ang+45" in line and "outside the workspace box" in line
    truth = twin.controller.truth()
    assert truth.peak_force_n == 0.0 and abs(truth.tcp_pose[:3] - start[:3]).max() < 1e-6  # nothing moved
    assert not session_path(tmp_path / "data", OBJECT, "papillarray").exists()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("table", "values", "field"),
    [
        ("limits", {"hard_force_n": float("inf")}, "limits.hard_force_n"),
        ("limits", {"hard_torque_nm": float("inf")}, "limits.hard_torque_nm"),
        ("limits", {"move_force_n": float("inf")}, "limits.move_force_n"),
        ("limits", {"workspace_max_m": [0.4, float("nan"), 0.6]}, "limits.workspace_max_m"),
    ],
)
def test_an_infinite_or_nan_limit_is_refused_before_connecting(
    twin: RigTwin, tmp_path: Path, table: str, values: dict[str, object], field: str
) -> None:
    """Review row 4 (was accepted: the check switched off silently)."""
    path = rig_file(twin, tmp_path, **{table: values})
    code, err, _ = run_to_end(twin, collect(path, tmp_path / "data"))
    assert code in (1, 2) and len(err.strip().splitlines()) == 1, err  # one line, no traceback
    assert field in last_line(err) and "finite" in last_line(err)
    assert twin.controller.truth().rtde_clients == 0  # refused before anything connected
