"""A sensor that stalls or is unplugged mid-press: the press is aborted and kept, the sensor reconnected and the press
retried once; a second failure (or a sensor that never comes back) stops the session cleanly, with the arm backed off
to the stand-off, and the same call resumes. Faults are switched on from the live tick when the press force passes
5 N, and switched off by a listener on the rig's virtual clock, so they land mid-press whatever the timings."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from tests.robustness.robustness_helpers import few_angles
from unitac_rig.collection.press import TickInfo
from unitac_rig.collection.session import collect_session
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.sim.faults import FaultInjector
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path

MID_PRESS_N = 5.0


def fault_mid_press(
    rig: SimRig,
    switch: Callable[[FaultInjector, bool], None],
    *,
    press_suffix: str,
    times: int,
    lasts_s: float | None,
) -> tuple[Callable[[TickInfo], None], list[float]]:
    """An ``on_tick`` that turns a fault on at MID_PRESS_N (at most ``times`` times, only on presses whose id ends
    with ``press_suffix``) and off again ``lasts_s`` later (never if None). Returns it and the forces it fired at."""
    fired: list[float] = []

    def on_tick(tick: TickInfo) -> None:
        if not tick.press_id.endswith(press_suffix) or tick.press_force_n < MID_PRESS_N or len(fired) >= times:
            return
        if tick.phase != "press" or any(rig.clock.now_ns() < end for end in ends):
            return
        fired.append(tick.press_force_n)
        injectors = rig.sensor_fault_injectors()
        for injector in injectors:
            switch(injector, True)
        if lasts_s is not None:
            ends.append(rig.clock.now_ns() + round(lasts_s * 1e9))

            def release(now_ns: int, end: int = ends[-1]) -> None:
                if now_ns >= end:
                    for injector in injectors:
                        switch(injector, False)
                    rig.clock.remove_listener(release)

            rig.clock.on_advance(release)

    ends: list[int] = []
    return on_tick, fired


def stall(injector: FaultInjector, on: bool) -> None:
    injector.force_stall(on)


def unplug(injector: FaultInjector, on: bool) -> None:
    injector.force_disconnect(on)


def assert_backed_off_and_at_rest(rig: SimRig) -> None:
    state = rig.sim_arm.read_state()
    assert np.linalg.norm(state.tcp_speed[:3]) < 1e-6
    assert np.linalg.norm(state.tcp_force[:3]) < 3.0  # not left pressing on the object


def test_a_stall_mid_press_aborts_reconnects_and_the_retry_completes(tmp_path: Path) -> None:
    with SimRig(few_angles(3), seed=0) as rig:
        on_tick, fired = fault_mid_press(rig, stall, press_suffix="+00", times=1, lasts_s=0.7)
        outcome = collect_session(rig, get_object("hex_tpu"), "uskin", tmp_path, on_tick=on_tick)
    assert len(fired) == 1
    assert outcome.stopped is None
    assert (outcome.complete, outcome.aborted) == (3, 1)  # the aborted attempt was recorded, then redone
    assert any("rot000_ang+00" in n and "stalled" in n and "retried" in n for n in outcome.recovery_notes)
    presses = {p.press_id: p for p in read_presses(session_path(tmp_path, "hex_tpu", "uskin"))}
    assert {p.status for p in presses.values()} == {"complete"}
    assert presses["rot000_ang+00"].attrs["sensor_health"]["reconnects"] == 1


def test_a_second_stall_stops_the_session_cleanly_and_the_same_call_resumes(tmp_path: Path) -> None:
    obj = get_object("hex_tpu")
    with SimRig(few_angles(3), seed=0) as rig:
        on_tick, fired = fault_mid_press(rig, stall, press_suffix="+00", times=2, lasts_s=0.7)
        outcome = collect_session(rig, obj, "uskin", tmp_path, on_tick=on_tick)
        assert_backed_off_and_at_rest(rig)
    assert len(fired) == 2
    assert outcome.stopped is not None and "stalled twice at press rot000_ang+00" in outcome.stopped
    presses = {p.press_id: p for p in read_presses(session_path(tmp_path, "hex_tpu", "uskin"))}
    assert presses["rot000_ang-45"].status == "complete"
    stalled = presses["rot000_ang+00"]
    assert (stalled.status, stalled.reason) == ("aborted", "stall")
    assert stalled.press_force_n.max() >= MID_PRESS_N  # what was recorded before the stall is kept
    assert "rot000_ang+45" not in presses  # nothing after the stop
    with SimRig(few_angles(3), seed=0) as rig:
        resumed = collect_session(rig, obj, "uskin", tmp_path)
    assert (resumed.already_done, resumed.complete, resumed.stopped) == (1, 2, None)


def test_an_unplugged_papillarray_hub_is_reconnected_and_the_press_retried(tmp_path: Path) -> None:
    with SimRig(few_angles(3), seed=1) as rig:
        on_tick, fired = fault_mid_press(rig, unplug, press_suffix="+00", times=1, lasts_s=0.6)
        outcome = collect_session(rig, get_object("circle_tpu"), "papillarray", tmp_path, on_tick=on_tick)
    assert len(fired) == 1
    assert outcome.stopped is None and (outcome.complete, outcome.aborted) == (3, 1)
    assert any("failed" in n and "retried" in n for n in outcome.recovery_notes)
    presses = read_presses(session_path(tmp_path, "circle_tpu", "papillarray"))
    assert [p.status for p in presses] == ["complete"] * 3
    # the hub powered up again unbiased at 1000 Hz; the per-press tare keeps the matched frames near zero unloaded
    retried = next(p for p in presses if p.press_id == "rot000_ang+00")
    assert retried.extraction is not None and retried.extraction.n_matched >= 20


def test_a_sensor_that_does_not_come_back_stops_the_session_and_a_later_run_resumes(tmp_path: Path) -> None:
    obj = get_object("circle_tpu")
    with SimRig(few_angles(3), seed=1) as rig:
        on_tick, _ = fault_mid_press(rig, unplug, press_suffix="+00", times=1, lasts_s=None)
        outcome = collect_session(rig, obj, "papillarray", tmp_path, on_tick=on_tick)
        assert_backed_off_and_at_rest(rig)
    assert outcome.stopped is not None and "did not come back" in outcome.stopped
    presses = {p.press_id: p for p in read_presses(session_path(tmp_path, "circle_tpu", "papillarray"))}
    assert (presses["rot000_ang+00"].status, presses["rot000_ang+00"].reason) == ("aborted", "device_error")
    with SimRig(few_angles(3), seed=1) as rig:  # the hub is plugged back in
        resumed = collect_session(rig, obj, "papillarray", tmp_path)
    assert (resumed.already_done, resumed.complete) == (1, 2)
