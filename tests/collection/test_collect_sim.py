"""Collection end to end on the simulated rig: sessions, swap, resume after a kill, failures and safety stops."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from drivers.errors import ProtectiveStop
from tests.helpers import cli, console_script
from unitac_rig.collection.safety_check import TickInfo
from unitac_rig.collection.session import collect_session
from unitac_rig.rig.config import RigConfig, parse_rig_config
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.storage.reader import load_matched_set, read_presses
from unitac_rig.storage.recorder import session_path
from unitac_rig.storage.summary import inspect_dataset

FEW_ANGLES = {"press": {"angle_count": 3}}


def run_cli(*args: str) -> int:
    """:func:`tests.helpers.cli` without the live view (its output is what the tests read)."""
    return cli([*args, "--no-live"] if args[0] in ("collect", "campaign") else list(args))


def test_collect_twice_swaps_sensor_and_pairs_join(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert not run_cli("collect", "--object", "hex_tpu", "--data", str(tmp_path), "--angles", "3")
    assert "mounting uskin" in capsys.readouterr().out
    assert not run_cli("collect", "--object", "hex_tpu", "--data", str(tmp_path), "--angles", "3")
    assert "mounting papillarray" in capsys.readouterr().out
    report = inspect_dataset(tmp_path)
    by_sensor = {s["sensor"]: s for s in report["sessions"]}
    assert set(by_sensor) == {"uskin", "papillarray"}
    for s in by_sensor.values():
        assert s["presses_planned"] == s["presses_complete"] == 3
        assert s["simulated"] is True
        assert 10.0 <= s["peak_force_n"]["median"] <= 13.0
        assert s["targets_matched"] > 0.8 * 75
    matched = {s.sensor: s for s in (load_matched_set(session_path(tmp_path, "hex_tpu", n)) for n in by_sensor)}
    keys = [set(zip(m.rotation_deg, m.angle_deg, m.target_n, strict=True)) for m in matched.values()]
    assert report["pairs"]["hex_tpu"] == len(keys[0] & keys[1]) > 0
    # matched frames are tared: the uSkin z excursion at 10 N is in the thousands of counts, PapillArray a few N
    assert 500 < np.abs(matched["uskin"].values[..., 2]).max() < 8000
    assert 1.0 < matched["papillarray"].values[..., 2].max() < 8.0
    # a third run has nothing left to do on the simulated rig
    assert run_cli("collect", "--object", "hex_tpu", "--data", str(tmp_path), "--angles", "3") == 2
    assert "already has a complete session" in capsys.readouterr().err


def test_inspect_json_has_the_documented_keys(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert not run_cli(
        "collect", "--object", "circle_pla", "--sensor", "papillarray", "--data", str(tmp_path), "--angles", "2"
    )
    capsys.readouterr()
    assert not run_cli("inspect", str(tmp_path), "--json")
    doc = json.loads(capsys.readouterr().out)
    (session,) = doc["sessions"]
    for key in (
        "object",
        "sensor",
        "simulated",
        "presses_planned",
        "presses_complete",
        "presses_failed",
        "targets_matched",
        "targets_missed",
        "match_error_n",
        "peak_force_n",
        "duration_s",
    ):
        assert key in session
    assert set(session["match_error_n"]) == {"median", "p95", "max"}
    assert set(session["peak_force_n"]) == {"median", "max"}
    assert doc["pairs"] == {"circle_pla": 0}
    assert session["targets_matched"] + session["targets_missed"] == 2 * 25


def test_soft_object_that_cannot_reach_the_threshold_fails_the_press(tmp_path: Path) -> None:
    config = parse_rig_config({**FEW_ANGLES, "limits": {"max_travel_after_contact_mm": 0.3}})
    with SimRig(config, seed=1) as rig:
        outcome = collect_session(rig, get_object("hex_tpu"), "uskin", tmp_path)
    assert (outcome.complete, outcome.failed) == (0, 3)
    presses = read_presses(session_path(tmp_path, "hex_tpu", "uskin"))
    assert {p.reason for p in presses} == {"travel"}
    assert all(p.attrs["peak_force_n"] < 10.0 for p in presses)
    assert all(p.robot_t_s.size > 0 for p in presses)  # the streams were kept


def test_protective_stop_mid_press_stops_keeps_data_and_resumes(tmp_path: Path) -> None:
    config = parse_rig_config(FEW_ANGLES)
    obj = get_object("square_pla")
    with SimRig(config, seed=2) as rig:
        fired = []

        def trip(tick: TickInfo) -> None:
            if tick.press_id.endswith("+00") and tick.press_force_n > 5.0 and not fired:
                fired.append(tick.press_force_n)
                rig.sim_arm.trigger_protective_stop()

        with pytest.raises(ProtectiveStop):
            collect_session(rig, obj, "uskin", tmp_path, on_tick=trip)
        assert np.linalg.norm(rig.sim_arm.read_state().tcp_speed[:3]) < 1e-6  # the arm is at rest
    presses = {p.press_id: p for p in read_presses(session_path(tmp_path, "square_pla", "uskin"))}
    assert presses["rot000_ang-45"].status == "complete"
    assert presses["rot000_ang+00"].status == "aborted"
    assert presses["rot000_ang+00"].reason == "protective_stop"
    assert presses["rot000_ang+00"].press_force_n.max() > 5.0
    # after the stop is cleared (a fresh rig here), the same call finishes the session without redoing press 1
    with SimRig(config, seed=2) as rig:
        outcome = collect_session(rig, obj, "uskin", tmp_path)
    assert (outcome.already_done, outcome.complete) == (1, 2)


def test_kill_at_a_random_moment_then_resume_loses_nothing(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    cmd = [
        console_script(),
        "collect",
        "--object",
        "hex_pla",
        "--sensor",
        "uskin",
        "--data",
        str(tmp_path),
        "--angles",
        "6",
        "--no-live",
    ]
    journal = tmp_path / ".journal" / "hex_pla__uskin"
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and len(list(journal.glob("*.h5"))) < 2 and proc.poll() is None:
            time.sleep(0.02)
        time.sleep(float(rng.uniform(0.0, 0.3)))
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, timeout=300)
    with h5py.File(session_path(tmp_path, "hex_pla", "uskin"), "r") as f:
        ids = sorted(f["presses"])
        statuses = [f["presses"][i].attrs["status"] for i in ids]
    assert len(ids) == len(set(ids)) == 6
    assert all(s == "complete" for s in statuses)


def test_rig_config_reaches_the_press(tmp_path: Path) -> None:
    config: RigConfig = parse_rig_config({**FEW_ANGLES, "press": {"angle_count": 2, "strategy": "two-phase"}})
    with SimRig(config, seed=3) as rig:
        collect_session(rig, get_object("circle_tpu"), "papillarray", tmp_path)
    presses = read_presses(session_path(tmp_path, "circle_tpu", "papillarray"))
    assert {p.attrs["strategy"] for p in presses} == {"two-phase"}
    assert all(p.tactile_displacement_mm is not None for p in presses)


def test_a_slow_sensor_open_after_the_arm_is_connected_does_not_trip_the_watchdog(tmp_path: Path) -> None:
    """In a campaign the arm is connected (watchdog armed) before each session opens its sensor; python-can's slcan
    alone waits 2 s after opening the port. The session keeps the watchdog fed through it."""
    config = parse_rig_config(FEW_ANGLES)
    with SimRig(config, seed=3) as rig:
        rig.arm.zero_ft()  # the arm is in use: from here on, 1 / watchdog_hz without a write stops the program
        open_sensor = rig.open_sensor

        def slow_open(name: str):  # type: ignore[no-untyped-def]
            rig.clock.sleep(2.0)
            return open_sensor(name)

        rig.open_sensor = slow_open  # type: ignore[method-assign]
        outcome = collect_session(rig, get_object("hex_pla"), "uskin", tmp_path)
        assert rig.sim_arm.program_stop_reason is None
    assert outcome.complete == 3
