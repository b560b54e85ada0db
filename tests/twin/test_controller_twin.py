"""The REAL ur_rtde 1.6.5 control and receive clients against the controller twin.

What is asserted is what a robot would do (and what hardware-facts 3.8 and the script ur_rtde uploads say), with
margins for a loaded machine; never exact timing. Ground truth comes from the twin's shared memory.
"""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest
import rtde_control

from tests.twin.twin_helpers import TwinClients, open_twin, press_direction, wait_until
from unitac_rig.sim.twin import ControllerParams

UP = [0.0, 0.0, 0.01, 0.0, 0.0, 0.0]  # 10 mm/s straight up: away from the object, nothing to touch


def press_force_n(wrench: np.ndarray | list[float], direction: np.ndarray) -> float:
    """Force along the press (positive while pressing): minus the object's force on the tool along it."""
    return -float(np.dot(np.asarray(wrench)[:3], direction))


def test_the_real_control_client_connects_and_reads_the_controller(rig: TwinClients) -> None:
    control, receive, twin = rig.control, rig.receive, rig.twin
    assert control.isConnected() and control.isProgramRunning()
    truth = twin.truth()
    assert truth.program_running and truth.rtde_clients == 2
    assert receive.getRobotMode() == 7 and receive.getSafetyMode() == 1
    assert not receive.isProtectiveStopped() and not receive.isEmergencyStopped()
    assert receive.getActualTCPPose() == pytest.approx(list(rig.home), abs=1e-5)
    assert control.getTCPOffset() == pytest.approx(list(twin.params.tool_offset))
    assert receive.getPayload() == pytest.approx(twin.params.payload_kg)
    assert receive.getPayloadCog() == pytest.approx(list(twin.params.payload_cog_m))


def test_set_tcp_moves_the_reported_pose_with_the_tool_point(rig: TwinClients) -> None:
    control, receive, twin = rig.control, rig.receive, rig.twin
    longer = list(twin.params.tool_offset)
    longer[2] += 0.01  # a TCP 10 mm further out along the tool's z
    try:
        assert control.setTcp(longer)
        assert control.getTCPOffset() == pytest.approx(longer)
        expected = rig.home[:3] + 0.01 * press_direction(rig.home)
        assert wait_until(lambda: np.allclose(receive.getActualTCPPose()[:3], expected, atol=1e-6))
        assert np.allclose(twin.truth().pad_pose, rig.home, atol=1e-6)  # the pad itself did not move
    finally:
        assert control.setTcp(list(twin.params.tool_offset))


def test_a_controller_without_its_script_port_fails_the_constructor() -> None:
    twin = open_twin(ControllerParams(serve=("dashboard", "rtde")))
    try:
        with pytest.raises(RuntimeError, match="Connection refused"):
            rtde_control.RTDEControlInterface(twin.host, 500.0)
        assert twin.truth().script_uploads == 0
    finally:
        twin.close()


def test_a_controller_in_local_mode_refuses_a_control_client(rig: TwinClients) -> None:
    """ur_rtde asks the dashboard before it takes control (PolyScope 5.6+, host not 127.0.0.1)."""
    rig.twin.set_remote_control(False)
    try:
        with pytest.raises(RuntimeError, match="enable remote control"):
            rtde_control.RTDEControlInterface(rig.twin.host, 500.0)
    finally:
        rig.twin.set_remote_control(True)
    assert rig.twin.truth().program_running  # the refused client touched nothing


def test_blocking_move_arrives_and_an_asynchronous_move_stops_on_stopl(rig: TwinClients) -> None:
    control, twin = rig.control, rig.twin
    goal = rig.home + np.array([0.0, 0.0, 0.02, 0.0, 0.0, 0.0])
    assert control.moveL(list(goal), 0.1, 1.0)
    truth = twin.truth()
    assert truth.at_rest and np.allclose(truth.tcp_pose, goal, atol=1e-5)

    assert control.moveL(list(rig.home), 0.01, 0.5, True)  # 20 mm at 10 mm/s: returns at once, moves for 2 s
    assert wait_until(lambda: twin.truth().speed_m_s > 0.005)
    assert control.getAsyncOperationProgress() >= 0  # running
    time.sleep(0.3)
    control.stopL(1.0)
    assert wait_until(lambda: twin.truth().at_rest)
    stopped_z = twin.truth().tcp_pose[2]
    assert rig.home[2] + 0.002 < stopped_z < goal[2] - 0.001  # stopped part way
    assert wait_until(lambda: control.getAsyncOperationProgress() < 0)  # finished
    time.sleep(0.2)
    assert twin.truth().tcp_pose[2] == pytest.approx(stopped_z, abs=1e-7)


def test_speedl_without_a_time_limit_keeps_moving_after_its_client_is_gone(rig: TwinClients) -> None:
    twin = rig.twin
    assert rig.control.speedL(UP, 0.5, 0.0)
    assert wait_until(lambda: twin.truth().tcp_speed[2] == pytest.approx(0.01))
    rig.disconnect()  # the host is gone: nothing tells the controller to stop
    z = twin.truth().tcp_pose[2]
    time.sleep(0.3)
    truth = twin.truth()
    assert truth.program_running and truth.tcp_speed[2] == pytest.approx(0.01)
    assert truth.tcp_pose[2] - z > 0.002
    rig.connect()  # a new control client stops the running program before uploading its own: the arm stops
    assert wait_until(lambda: twin.truth().at_rest)


def test_speedl_with_a_time_limit_does_not_stop_by_itself(rig: TwinClients) -> None:
    """ur_rtde 1.6.5's speed thread loops ``speedl(xd, a, t=time)``: the limit only sets how often speedl returns."""
    twin = rig.twin
    assert rig.control.speedL(UP, 0.5, 0.05)
    time.sleep(0.5)  # ten times the limit
    assert twin.truth().tcp_speed[2] == pytest.approx(0.01)
    assert rig.control.speedStop(1.0)
    assert wait_until(lambda: twin.truth().at_rest)


def test_force_mode_presses_to_the_set_force_and_keeps_it_without_the_host(rig: TwinClients) -> None:
    control, twin = rig.control, rig.twin
    direction = press_direction(rig.home)
    frame = list(rig.home)  # task frame = the tool frame: its z is the press direction
    selection, target, limits = [0, 0, 1, 0, 0, 0], [0.0, 0.0, 8.0, 0.0, 0.0, 0.0], [0.1, 0.1, 0.02, 1.0, 1.0, 1.0]
    deadline = time.monotonic() + 2.5  # 15 mm to the object at <= 20 mm/s, then the force settles
    while time.monotonic() < deadline:
        period = control.initPeriod()
        assert control.forceMode(frame, selection, target, 2, limits)
        control.waitPeriod(period)
    truth = twin.truth()
    assert truth.force_n == pytest.approx(8.0, abs=2.5)  # regulated on a noisy, biased wrist sensor
    assert press_force_n(truth.reported_wrench, direction) == pytest.approx(8.0, abs=1.5)
    time.sleep(0.5)  # the host stops calling: the script's force thread keeps regulating
    truth = twin.truth()
    assert truth.program_running and truth.force_n == pytest.approx(8.0, abs=2.5)
    assert control.forceModeStop()
    assert wait_until(lambda: twin.truth().at_rest)


def test_watchdog_expiry_stops_the_arm_and_the_program(rig: TwinClients) -> None:
    control, twin = rig.control, rig.twin
    trips = twin.truth().watchdog_trips
    assert control.setWatchdog(5.0)  # 200 ms without a write stops the program
    assert control.speedL(UP, 0.5, 0.0)
    # speedL returns without waiting for the script; a kick (0 in the same register) sent within the same 2 ms
    # cycle would erase it, as on a real controller, so the host lets the script take it first (UR5eArm does not
    # kick in a period that sent a command)
    assert wait_until(lambda: twin.truth().speed_m_s > 0.0)
    deadline = time.monotonic() + 0.5
    while time.monotonic() < deadline:  # the host is alive: it keeps writing
        period = control.initPeriod()
        control.kickWatchdog()
        control.waitPeriod(period)
    truth = twin.truth()
    assert truth.program_running and truth.watchdog_armed and truth.speed_m_s > 0.009
    # the host stalls (or died): no more writes
    assert wait_until(lambda: not twin.truth().program_running, 3.0)
    assert wait_until(lambda: twin.truth().at_rest)
    truth = twin.truth()
    assert truth.watchdog_trips == trips + 1 and not truth.watchdog_armed
    assert wait_until(lambda: not control.isProgramRunning())
    assert control.zeroFtSensor() is False  # every command fails until the script is uploaded again
    assert control.reuploadScript() and wait_until(control.isProgramRunning)
    assert control.zeroFtSensor()


def _kick_for(control: rtde_control.RTDEControlInterface, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:  # a live host: one write per 2 ms period
        period = control.initPeriod()
        control.kickWatchdog()
        control.waitPeriod(period)


def test_a_twin_descheduled_for_longer_than_the_watchdog_window_keeps_a_live_hosts_program(rig: TwinClients) -> None:
    """The twin's process stops for 0.5 s (a loaded machine) while the host keeps writing: a real controller would
    have read those writes on time, so the program runs on; once the host stops writing, the watchdog trips."""
    control, twin = rig.control, rig.twin
    trips = twin.truth().watchdog_trips
    assert control.setWatchdog(5.0)  # 200 ms without a write stops the program
    assert control.speedL(UP, 0.5, 0.0)
    assert wait_until(lambda: twin.truth().speed_m_s > 0.0)
    _kick_for(control, 0.2)
    os.kill(twin.pid, signal.SIGSTOP)
    try:
        _kick_for(control, 0.5)  # the writes wait in the twin's socket
    finally:
        os.kill(twin.pid, signal.SIGCONT)
    _kick_for(control, 0.3)
    truth = twin.truth()
    assert truth.worst_lateness_s > 0.4  # the stall happened and was caught up
    assert truth.program_running and truth.watchdog_trips == trips
    assert wait_until(lambda: not twin.truth().program_running, 3.0)  # the host stops writing
    assert twin.truth().watchdog_trips == trips + 1
    assert wait_until(lambda: twin.truth().at_rest)
    assert control.reuploadScript() and wait_until(control.isProgramRunning)


def test_protective_stop_refuses_commands_until_unlocked_and_reuploaded(rig: TwinClients) -> None:
    control, receive, dashboard, twin = rig.control, rig.receive, rig.dashboard, rig.twin
    assert control.triggerProtectiveStop() is False  # the client sees the stop while waiting for "done"
    assert wait_until(receive.isProtectiveStopped)
    with pytest.raises(RuntimeError, match="Cannot unlock protective stop"):
        dashboard.unlockProtectiveStop()  # too soon after the stop
    assert receive.getSafetyMode() == 3 and wait_until(lambda: not control.isProgramRunning())
    assert control.moveL(list(rig.home), 0.05, 0.5) is False
    time.sleep(twin.params.unlock_delay_s)
    dashboard.unlockProtectiveStop()
    assert wait_until(lambda: not receive.isProtectiveStopped())
    assert control.moveL(list(rig.home), 0.05, 0.5) is False  # unlocked, but the program is still the stopped one
    assert control.reuploadScript() and wait_until(control.isProgramRunning)
    assert control.moveL(list(rig.home), 0.05, 0.5)


def test_pressing_past_the_force_limit_is_a_protective_stop(rig: TwinClients) -> None:
    control, receive, twin = rig.control, rig.receive, rig.twin
    stops = twin.truth().protective_stops
    direction = press_direction(rig.home)
    assert control.speedL([*(0.01 * direction), 0.0, 0.0, 0.0], 0.5, 0.0), twin.status()  # at 10 mm/s
    assert wait_until(receive.isProtectiveStopped, 6.0), (twin.truth(), twin.status())
    assert wait_until(lambda: twin.truth().at_rest)
    truth = twin.truth()
    assert truth.protective_stops == stops + 1 and not truth.program_running, (truth, twin.status())
    assert truth.peak_force_n > twin.params.protective_stop_n
    # the control client decides from its own RTDE stream, which may trail the receive client's by a few cycles
    assert wait_until(lambda: not control.isProgramRunning())
    assert control.speedL([0.0] * 6, 0.5, 0.0) is False
    twin.set_placement_error(0.0, 0.05)  # the operator frees the pad (here: pulls the object away)
    assert wait_until(lambda: twin.truth().force_n == 0.0)
    rig.recover()  # unlock, upload the program again, back home
    twin.set_placement_error(0.0, 0.0)  # and the object back in place


def test_emergency_stop_powers_the_arm_off_until_released_and_powered_on(rig: TwinClients) -> None:
    control, receive, dashboard, twin = rig.control, rig.receive, rig.dashboard, rig.twin
    assert control.speedL(UP, 0.5, 0.0)
    twin.emergency_stop()
    assert wait_until(receive.isEmergencyStopped)
    assert wait_until(lambda: twin.truth().at_rest and receive.getRobotMode() == 3)  # powered off at rest
    assert wait_until(lambda: not control.isProgramRunning())
    assert control.moveL(list(rig.home), 0.05, 0.5) is False
    control.reuploadScript()
    assert not wait_until(control.isProgramRunning, 0.3)  # no program starts on an emergency-stopped arm
    twin.release_emergency_stop()
    dashboard.powerOn()
    dashboard.brakeRelease()
    assert wait_until(lambda: receive.getRobotMode() == 7 and not receive.isEmergencyStopped())
    assert control.reuploadScript() and wait_until(control.isProgramRunning)
    assert control.moveL(list(rig.home), 0.05, 0.5)


def test_the_reported_tcp_force_is_the_contact_force_while_pressing(rig: TwinClients) -> None:
    control, receive, twin = rig.control, rig.receive, rig.twin
    direction = press_direction(rig.home)
    assert control.speedL([*(0.008 * direction), 0.0, 0.0, 0.0], 0.5, 0.0)
    pairs: list[tuple[float, float]] = []
    deadline = time.monotonic() + 6.0
    while time.monotonic() < deadline and twin.truth().force_n < 25.0:
        pairs.append(
            (press_force_n(twin.truth().true_wrench, direction), press_force_n(receive.getActualTCPForce(), direction))
        )
        time.sleep(0.005)
    assert control.speedStop(10.0)
    truth = twin.truth()
    assert truth.force_n > 20.0
    true_press, reported_press = (
        press_force_n(truth.true_wrench, direction),
        press_force_n(truth.reported_wrench, direction),
    )
    assert reported_press == pytest.approx(true_press, abs=3.0)  # at rest: noise and bias drift only
    loaded = [(t, r) for t, r in pairs if t > 8.0]
    assert loaded and all(r > 0 for _, r in loaded)  # pushing the tool into the object reads as a positive press
    assert all(abs(r - t) < 6.0 for t, r in loaded)  # latency and filter lag at ~160 N/s, plus noise
