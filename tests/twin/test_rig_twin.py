"""The real-time twin of the whole rig: its rig file, its sensors on loopback transports, and collect through it.

The sensors are opened the way the hardware rig opens them (HardwareRig.open_sensor with the printed rig file); the
arm is moved by the real ur_rtde control client. Loopback addresses 127.0.0.130-139 belong to these tests.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
import tomllib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import rtde_control

from drivers.frames import TactileFrame
from drivers.sensor import TactileSensor
from tests.helpers import console_script
from tests.twin.twin_helpers import wait_until
from unitac_rig.errors import UsageError
from unitac_rig.rig.config import ObjectPlacement, load_rig_config, parse_rig_config
from unitac_rig.rig.hardware import HardwareRig, ask_realtime, restore_scheduling
from unitac_rig.sim.twin import first_free_loopback
from unitac_rig.sim.twin.rig import DEFAULT_HOST, RigTwin, rig_file_text
from unitac_rig.sim.twin.world import build_scene
from unitac_rig.storage.reader import press_summaries

REPO = Path(__file__).resolve().parents[2]


def free_host() -> str:
    return first_free_loopback(130, 139)


@pytest.fixture
def papillarray_twin() -> Iterator[RigTwin]:
    with RigTwin("circle_pla", sensor="papillarray", host=free_host(), seed=3) as rig:
        yield rig


def frames_for(sensor: TactileSensor, seconds: float) -> list[TactileFrame]:
    frames: list[TactileFrame] = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        frames += sensor.poll()
        time.sleep(0.02)
    return frames


def test_the_example_rig_file_is_the_one_the_twin_prints_and_points_at_it() -> None:
    text = rig_file_text(DEFAULT_HOST, ObjectPlacement())
    assert (REPO / "examples" / "twin.toml").read_text() == text
    config = load_rig_config(REPO / "examples" / "twin.toml")
    assert config.arm is not None and config.arm.host == DEFAULT_HOST
    assert config.sensors["papillarray"].port == f"socket://{DEFAULT_HOST}:30100"  # type: ignore[attr-defined]
    assert config.sensors["uskin"].url == f"ws://{DEFAULT_HOST}:5000"  # type: ignore[attr-defined]
    assert config.object == ObjectPlacement()  # the twin's scene stands where the file says


def test_each_sensor_writes_its_own_table_with_its_options() -> None:
    """The rig file's sensor tables come from the sensors' simulated sides: the uSkin's route and the PapillArray's
    rate are their options, and an option the twin cannot serve is refused before anything starts."""
    options = {"uskin": {"transport": "slcan"}, "papillarray": {"rate_hz": 500, "twin_port": 30111}}
    config = parse_rig_config(tomllib.loads(rig_file_text("127.0.0.9", ObjectPlacement(), sensor_options=options)))
    uskin, papillarray = config.sensors["uskin"], config.sensors["papillarray"]
    assert (uskin.type, uskin.can_interface, uskin.can_channel) == ("uskin-can", "slcan", "socket://127.0.0.9:30101")  # type: ignore[attr-defined]
    assert (papillarray.port, papillarray.rate_hz) == ("socket://127.0.0.9:30111", 500)  # type: ignore[attr-defined]
    with pytest.raises(UsageError, match="serves the uSkin through slcan or xela-server, not 'can'"):
        RigTwin("circle_pla", host="127.0.0.9", sensor_options={"uskin": {"transport": "can"}})
    with pytest.raises(UsageError, match="PapillArray samples at 100, 250, 500, 1000 Hz, not 300"):
        RigTwin("circle_pla", host="127.0.0.9", sensor_options={"papillarray": {"rate_hz": 300}})


def test_a_rehearsed_rig_file_keeps_its_object_press_and_limits() -> None:
    """``unitac-rig twin --like FILE`` prints a twin rig file with that file's object placement, press and limits."""
    mine = load_rig_config(REPO / "examples" / "rig.toml")
    tables = {"press": mine.press.model_dump(mode="json"), "limits": mine.limits.model_dump(mode="json")}
    twin_file = parse_rig_config(tomllib.loads(rig_file_text("127.0.0.9", mine.object, tables=tables)))
    assert (twin_file.object, twin_file.press, twin_file.limits) == (mine.object, mine.press, mine.limits)
    assert twin_file.arm is not None and twin_file.arm.host == "127.0.0.9"


def test_the_mounted_sensor_feels_the_arm_the_controller_moves(papillarray_twin: RigTwin) -> None:
    rig = papillarray_twin
    config = parse_rig_config(tomllib.loads(rig.rig_file()))
    hardware = HardwareRig(config)
    sensor = hardware.open_sensor("papillarray")
    control = rtde_control.RTDEControlInterface(rig.host, 500.0)
    try:
        rest = frames_for(sensor, 0.5)
        assert len(rest) > 10
        baseline = np.mean([f.values for f in rest], axis=0)
        pressed = build_scene(rig.spec).pose_at_travel(0.0, 1.0)  # 1 mm past first touch, at approach angle 0
        assert control.moveL(list(pressed), 0.05, 0.5)
        sensor.poll()  # drop frames from the way there
        truth = rig.controller.truth()
        assert truth.force_n > 1.0
        loaded = np.mean([f.values for f in frames_for(sensor, 0.3)], axis=0) - baseline
        assert float(loaded[:, 2].sum()) == pytest.approx(truth.force_n, rel=0.35)  # pillars carry the contact
        assert control.moveL(list(rig.controller.settings.start_pose), 0.05, 0.5)
        sensor.poll()
        unloaded = np.mean([f.values for f in frames_for(sensor, 0.3)], axis=0) - baseline
        assert abs(float(unloaded[:, 2].sum())) < 0.3
    finally:
        control.disconnect()
        sensor.disconnect()
        hardware.close()


def test_both_uskin_transports_stream_from_the_twin() -> None:
    with RigTwin("circle_pla", sensor="uskin", host=free_host(), seed=4) as rig:
        for via in ("xela-server", "slcan"):
            config = parse_rig_config(tomllib.loads(rig.rig_file(sensor_options={"uskin": {"transport": via}})))
            hardware = HardwareRig(config)
            sensor = hardware.open_sensor("uskin")
            try:
                assert wait_until(lambda s=sensor: s.poll(), 4.0), via  # type: ignore[misc]
            finally:
                sensor.disconnect()
                hardware.close()


@pytest.mark.slow
def test_collect_runs_through_the_hardware_path_against_the_twin(tmp_path: Path) -> None:
    host = free_host()
    rig_file = tmp_path / "twin.toml"
    environment = {**os.environ, "PYTHONUNBUFFERED": "1"}
    twin = subprocess.Popen(
        [
            console_script(),
            "twin",
            "--object",
            "circle_pla",
            "--host",
            host,
            "--write-rig",
            str(rig_file),
            "--unlock-delay",
            "0.5",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=environment,
    )
    try:
        assert wait_until(rig_file.exists, 30.0), "the twin did not start"
        collect = subprocess.run(
            [
                console_script(),
                "collect",
                "--rig",
                str(rig_file),
                "--object",
                "circle_pla",
                "--angles",
                "2",
                "--data",
                str(tmp_path / "data"),
                "--no-live",
            ],
            capture_output=True,
            text=True,
            timeout=300,
            env=environment,
        )
        assert collect.returncode == 0, collect.stdout + collect.stderr
        assert "detected mounted sensor: uskin" in collect.stdout
        presses = press_summaries(tmp_path / "data" / "circle_pla__uskin.h5")
        assert [p["status"] for p in presses] == ["complete", "complete"]
        assert all(p["tactile_frames"] > 10 and p["robot_samples"] > 100 for p in presses)
        time.sleep(0.5)  # issue 37: the controller stopped the program ~0.17 s after every session's last retract
    finally:
        twin.send_signal(signal.SIGTERM)
        out, err = twin.communicate(timeout=30)
    assert twin.returncode == 0, err.decode()
    assert "watchdog" not in err.decode(), err.decode()  # no fault was injected: nothing may trip it
    assert err.decode().rstrip().endswith("twin: stopped")
    assert out.decode().startswith("# Rig file of the real-time twin")


def test_the_arms_control_loop_asks_for_real_time_scheduling_and_gives_it_back() -> None:
    """Issue 37: at load ~20 on 2 cores a normal-priority host stalled 168 ms mid-motion in 10 of 30 twin sessions
    (the watchdog stopped the program). The hardware rig asks for SCHED_FIFO where it may, for the thread that drives
    the arm, and gives the thread back as it was at close."""
    seen: dict[str, object] = {}

    def probe() -> None:  # may this machine's threads be real-time at all?
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            seen["permitted"] = True
        except OSError:
            seen["permitted"] = False

    def drive() -> None:  # a thread of its own: the test process keeps its scheduling whatever happens
        before = ask_realtime()
        seen["granted"], seen["during"] = before is not None, os.sched_getscheduler(0)
        restore_scheduling(before)
        seen["after"] = os.sched_getscheduler(0)

    for target in (probe, drive):
        thread = threading.Thread(target=target)
        thread.start()
        thread.join()
    if not seen["permitted"]:
        pytest.skip("this machine does not grant SCHED_FIFO (no CAP_SYS_NICE or rtprio limit)")
    assert seen["granted"] and seen["during"] == os.SCHED_FIFO and seen["after"] == os.SCHED_OTHER
