"""UR5eArm / UR5eReceiver with a recording fake in place of the control client (the real receive client reads the
controller twin where a test needs a controller).

The fake shows the exact ur_rtde calls and argument order, and lets a test make the client refuse, raise or be
interrupted on cue: every exit path stops the arm, a refused command becomes the right error, nothing escapes
unwrapped. (tests/arm/test_ur5e_twin.py drives the real control client against the controller twin.)
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from drivers.arm import Arm
from drivers.clock import VirtualClock
from drivers.errors import (
    ArmError,
    ControlScriptStopped,
    DeviceNotFound,
    DeviceTimeout,
    ProtectiveStop,
    RobotStateLost,
)
from drivers.ur5e import KEEP_ALIVE_KICK_S, REST_WATCHDOG_HZ, UR5eArm
from drivers.ur5e_receive import STALL_TIMEOUT_S, UR5eReceiver
from tests.arm.arm_fakes import FakeControl, FakeReceive
from unitac_rig.collection.guarded_motion import move_to
from unitac_rig.sim.twin import ControllerParams, ControllerTwin, start_twin_on_free_loopback

POSE = np.array([-0.15, 0.6, 0.21, 0.0, 2.2214, -2.2214])


@pytest.fixture(scope="module")
def twin() -> Iterator[ControllerTwin]:
    """A controller twin, still arm at ``POSE`` and no object: the real receive client reads it."""
    with start_twin_on_free_loopback(40, 59, start_pose=POSE, params=ControllerParams(unlock_delay_s=0.0)) as server:
        yield server


def test_real_receive_and_a_protective_stop_during_move_l(twin: ControllerTwin) -> None:
    class StoppingControl(FakeControl):
        """moveL refused because a protective stop came in (ur_rtde returns False when it sees the safety bit)."""

        def moveL(self, pose: list[float], speed: float, acceleration: float, asynchronous: bool) -> object:
            self._record("moveL", pose, speed, acceleration, asynchronous)
            twin.trigger_protective_stop()
            deadline = time.monotonic() + 2.0  # until the real receive client has the new safety bits
            while not arm.read_state().protective_stop and time.monotonic() < deadline:
                time.sleep(0.002)
            return False

    control = StoppingControl()
    try:
        with UR5eArm(twin.host, control=control) as arm:
            assert isinstance(arm, Arm)
            first = arm.read_state()
            assert np.array_equal(first.tcp_pose, POSE)
            assert first.robot_mode == 7 and not first.protective_stop
            target = POSE + np.array([0, 0.01, 0, 0, 0, 0])
            with pytest.raises(ProtectiveStop) as excinfo:
                arm.start_move_linear(target, 0.05, 0.5)
            assert "teach pendant" in (excinfo.value.hint or "") and "same command" in (excinfo.value.hint or "")
            assert arm.read_state().protective_stop
            assert ("moveL", (list(target), 0.05, 0.5, True)) in control.calls  # asynchronous: stoppable
            with pytest.raises(ProtectiveStop):  # refused up front while stopped: nothing reaches the controller
                arm.speed_linear(np.zeros(6), 0.5)
            assert "speedL" not in control.names()
        assert control.names()[-3:] == ["speedStop", "stopScript", "disconnect"]
    finally:
        twin.unlock_protective_stop()


def test_a_controller_without_the_tcp_speed_output_is_read_without_it() -> None:
    """A controller (or a fake written from the RTDE facts) that answers NOT_FOUND for actual_TCP_speed makes ur_rtde
    refuse the whole output recipe; the receiver must connect without it rather than report no controller."""
    params = ControllerParams(rtde_outputs_not_found=("actual_TCP_speed",))
    with (
        start_twin_on_free_loopback(40, 59, start_pose=POSE, params=params) as server,
        UR5eReceiver(server.host) as receiver,
    ):
        read = receiver.wait_for_new_state()
        assert np.array_equal(read.tcp_pose, POSE) and read.robot_mode == 7
        assert read.tcp_speed is None
        assert receiver.payload_kg() is None


def test_probe_receiver_reads_new_states_without_a_control_object(twin: ControllerTwin) -> None:
    with UR5eReceiver(twin.host) as receiver:
        first = receiver.wait_for_new_state()
        second = receiver.wait_for_new_state()
        assert second.controller_t_s > first.controller_t_s
        assert np.array_equal(second.tcp_pose, POSE)


def test_unreachable_host_is_device_not_found_with_a_hint() -> None:
    with pytest.raises(DeviceNotFound) as excinfo:
        UR5eArm("127.0.0.254", control=FakeControl())
    assert excinfo.value.hint and "30004" in excinfo.value.hint
    assert isinstance(excinfo.value.__cause__, RuntimeError)


def test_control_connection_failure_closes_the_receive_side() -> None:
    receive = FakeReceive()
    with pytest.raises(DeviceNotFound) as excinfo:
        UR5eArm("127.0.0.254", receive=receive)  # the real control interface finds nothing there
    assert "Remote Control" in (excinfo.value.hint or "")
    assert receive.disconnects == 1


def test_connect_arms_the_watchdog_at_its_rest_window_and_every_period_kicks_it() -> None:
    control = FakeControl()
    with UR5eArm("ur", control=control, receive=FakeReceive(), watchdog_hz=8.0) as arm:
        assert control.calls[0] == ("setWatchdog", (REST_WATCHDOG_HZ,))  # nothing is commanded yet
        arm.wait_period()
        arm.wait_period()
    kicks_and_waits = [n for n in control.names() if n in ("kickWatchdog", "waitPeriod")]
    assert kicks_and_waits == ["kickWatchdog", "waitPeriod", "kickWatchdog", "waitPeriod"]


def test_a_period_that_sent_a_realtime_command_is_not_kicked_so_the_kick_cannot_overwrite_it() -> None:
    """speedL/forceMode go out without waiting; a kick right after writes 0 to the same command register and, landing
    in the same controller cycle, would erase the command before ur_rtde's script read it."""
    control = FakeControl()
    with UR5eArm("ur", control=control, receive=FakeReceive(), watchdog_hz=8.0) as arm:
        arm.speed_linear(np.array([0, 0, 0.005, 0, 0, 0]), 0.5)
        arm.wait_period()
        arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.02))
        arm.wait_period()
        arm.wait_period()  # nothing sent this period: the kick keeps the watchdog fed
    names = [n for n in control.names() if n in ("speedL", "forceMode", "kickWatchdog", "waitPeriod")]
    assert names == ["speedL", "waitPeriod", "forceMode", "waitPeriod", "kickWatchdog", "waitPeriod"]


def test_a_protective_stop_at_connect_is_refused_before_taking_control() -> None:
    receive = FakeReceive()
    receive.protective = True
    control = FakeControl()
    with pytest.raises(ProtectiveStop) as excinfo:
        UR5eArm("ur", control=control, receive=receive)
    assert "unlock the protective stop" in (excinfo.value.hint or "")
    assert control.calls == [] and receive.disconnects == 1


def test_a_different_tcp_offset_on_the_pendant_is_refused_with_one_line() -> None:
    control = FakeControl()
    control.tcp_offset = [0.0, 0.0, 0.12, 0.0, 0.0, 0.0]
    receive = FakeReceive()
    with pytest.raises(ArmError) as excinfo:
        UR5eArm("ur", control=control, receive=receive, expected_tcp_offset=[0.0, 0.0, 0.1, 0.0, 0.0, 0.0])
    line = excinfo.value.one_line()
    assert "\n" not in line and "arm.tcp_offset" in line and "0.1200" in line and "teach pendant" in line
    assert control.names()[-2:] == ["stopScript", "disconnect"] and receive.disconnects == 1
    # within 1 mm and 0.01 rad it connects
    control = FakeControl()
    control.tcp_offset = [0.0, 0.0, 0.1005, 0.0, 0.0, 0.005]
    UR5eArm("ur", control=control, receive=FakeReceive(), expected_tcp_offset=[0, 0, 0.1, 0, 0, 0]).close()


def test_a_different_payload_is_refused() -> None:
    receive = FakeReceive()
    receive.payload = 0.9
    with pytest.raises(ArmError, match=r"payload of 0\.900 kg .* arm\.payload_kg is 0\.350 kg"):
        UR5eArm("ur", control=FakeControl(), receive=receive, expected_payload_kg=0.35)
    receive = FakeReceive()
    receive.payload = 0.37
    UR5eArm("ur", control=FakeControl(), receive=receive, expected_payload_kg=0.35).close()


def test_close_stops_everything_even_when_a_step_fails() -> None:
    control = FakeControl()
    control.raise_on["speedStop"] = RuntimeError("script not running")
    arm = UR5eArm("ur", control=control, receive=FakeReceive())
    arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.01))
    arm.close()
    assert control.commands() == [
        "setWatchdog",  # at connect
        "setWatchdog",  # again as the motion starts (a fresh script after a silent reconnect has none)
        "forceMode",
        "forceModeStop",
        "speedStop",
        "stopScript",
        "disconnect",
    ]
    arm.close()  # idempotent
    assert control.names().count("disconnect") == 1
    arm.stop()  # a no-op on a closed arm
    with pytest.raises(ArmError):
        arm.speed_linear(np.zeros(6), 0.5)


def test_a_second_ctrl_c_during_close_cannot_skip_the_stop() -> None:
    control = FakeControl()
    control.raise_on["forceModeStop"] = KeyboardInterrupt()
    receive = FakeReceive()
    arm = UR5eArm("ur", control=control, receive=receive)
    arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.01))
    with pytest.raises(KeyboardInterrupt):
        arm.close()
    assert control.commands()[-4:] == ["forceModeStop", "speedStop", "stopScript", "disconnect"]
    assert receive.disconnects == 1


def test_a_second_ctrl_c_during_stop_still_sends_every_stop() -> None:
    control = FakeControl()
    control.raise_on["forceModeStop"] = KeyboardInterrupt()
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.01))
        with pytest.raises(KeyboardInterrupt):
            arm.stop()
        assert control.commands()[-2:] == ["forceModeStop", "speedStop"]


def test_leaving_a_with_block_on_an_exception_stops_the_arm() -> None:
    control = FakeControl()
    with pytest.raises(KeyboardInterrupt), UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        arm.speed_linear(np.array([0, 0.005, 0, 0, 0, 0]), 0.5)
        raise KeyboardInterrupt
    assert control.commands() == ["setWatchdog", "setWatchdog", "speedL", "speedStop", "stopScript", "disconnect"]


def test_false_without_a_safety_stop_is_an_arm_error() -> None:
    control = FakeControl(moveL=False, zeroFtSensor=False)
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        with pytest.raises(ArmError) as excinfo:
            arm.start_move_linear(POSE, 0.1, 1.0)
        assert not isinstance(excinfo.value, ProtectiveStop | ControlScriptStopped)
        with pytest.raises(ArmError):
            arm.zero_ft()


def test_a_stopped_program_refuses_commands_and_says_why() -> None:
    control = FakeControl()
    with UR5eArm("ur", control=control, receive=FakeReceive(), watchdog_hz=8.0) as arm:
        control.program_running = False  # the watchdog tripped: the host sent nothing for 125 ms (at 8 Hz)
        assert not arm.read_state().program_running
        with pytest.raises(ControlScriptStopped) as excinfo:
            arm.speed_linear(np.zeros(6), 0.5)
        assert "125 ms" in (excinfo.value.hint or "")
        assert "speedL" not in control.names()
        arm.stop()  # stopping a stopped controller is not an error


def test_ur_rtde_runtime_and_value_errors_are_wrapped() -> None:
    control = FakeControl()
    control.raise_on["speedL"] = RuntimeError("RTDE control script is not running!")
    control.raise_on["forceMode"] = ValueError("speed limit out of range")
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        with pytest.raises(ArmError) as excinfo:
            arm.speed_linear(np.zeros(6), 0.5)
        assert isinstance(excinfo.value.__cause__, RuntimeError)
        with pytest.raises(ArmError) as excinfo:
            arm.force_mode(np.zeros(6), np.ones(6), np.zeros(6), np.full(6, 0.01))
        assert isinstance(excinfo.value.__cause__, ValueError)


def test_out_of_range_speeds_are_refused_before_reaching_ur_rtde() -> None:
    control = FakeControl()
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        with pytest.raises(ArmError, match=r"tool speed 5\.0 m/s"):
            arm.start_move_linear(POSE, 5.0, 1.0)
        with pytest.raises(ArmError, match="acceleration"):
            arm.speed_linear(np.array([0, 0.01, 0, 0, 0, 0]), 0.0)
    assert "moveL" not in control.names() and "speedL" not in control.names()


def test_stop_during_a_protective_stop_is_not_an_error() -> None:
    receive = FakeReceive()
    control = FakeControl(speedStop=False)
    with UR5eArm("ur", control=control, receive=receive) as arm:
        receive.protective = True
        arm.stop(5.0)
        assert control.calls[-1] == ("speedStop", (5.0,))


def test_commands_pass_through_with_ur_rtde_argument_order() -> None:
    control = FakeControl()
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        arm.speed_linear(np.array([0, 0.005, 0, 0, 0, 0]), 0.5)
        arm.zero_ft()
        frame, selection = np.arange(6.0), np.array([0, 0, 1, 0, 0, 0])
        arm.force_mode(frame, selection, np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.02))
        arm.stop(10.0)
        arm.wait_period()
        arm.wait_period()
    calls = [c for c in control.calls if c[0] not in ("kickWatchdog", "setWatchdog")]
    # speedL always carries a time limit of a few control periods (4 x 2 ms)
    assert calls[0] == ("speedL", ([0.0, 0.005, 0.0, 0.0, 0.0, 0.0], 0.5, pytest.approx(0.008)))
    assert calls[1] == ("zeroFtSensor", ())
    assert calls[2] == ("forceMode", (list(frame), [0, 0, 1, 0, 0, 0], [0, 0, 5.0, 0, 0, 0], 2, [0.02] * 6))
    assert [name for name, _ in calls[3:5]] == ["forceModeStop", "speedStop"]  # stop leaves force mode first
    assert [args for name, args in calls if name == "waitPeriod"] == [(1,), (2,)]


def test_an_asynchronous_move_is_polled_and_stop_ends_it_with_stop_l() -> None:
    control = FakeControl()
    receive = FakeReceive()
    with UR5eArm("ur", control=control, receive=receive) as arm:
        receive.pose = list(POSE)
        state = move_to(arm, POSE, 0.05, 0.5)  # the fake reports the arm on the target; progress 0, 0, 0 then -2
        assert np.allclose(state.tcp_pose, POSE)
        assert control.commands()[-2:] == ["moveL", "setWatchdog"]  # the move is over: the rest window
        control.move_periods = 1000
        arm.start_move_linear(POSE + np.array([0, 0, 0.05, 0, 0, 0]), 0.05, 0.5)
        assert arm.move_running()
        arm.stop()
        assert control.commands()[-3:] == ["stopL", "speedStop", "setWatchdog"]
        assert not arm.move_running()


def test_a_move_that_arrives_before_its_progress_word_ends_is_ended_so_nothing_stays_commanded() -> None:
    """The pose can show the move over while the control client's progress word still shows it running; a move
    left "running" kept the watchdog tight through the host's work at rest, which tripped it ~0.17 s after every
    session's last retract (issue 37). move_to ends it (stopL), and the watchdog is back at its rest window."""
    control = FakeControl()
    receive = FakeReceive()
    with UR5eArm("ur", control=control, receive=receive, watchdog_hz=8.0) as arm:
        receive.pose = list(POSE)
        control.move_periods = 1000  # the word shows the move long after the arm is on its target
        move_to(arm, POSE, 0.05, 0.5)
        assert "stopL" in control.commands()
        assert [args for name, args in control.calls if name == "setWatchdog"][-1] == (REST_WATCHDOG_HZ,)


class DocumentedStatus:
    """A progress status with only the methods hardware-facts documents (isAsyncOperationRunning, progress)."""

    def __init__(self, running: bool) -> None:
        self.running = running

    def isAsyncOperationRunning(self) -> bool:
        return self.running

    def progress(self) -> int:
        return 0 if self.running else -2


def test_a_move_is_followed_by_the_running_flag_alone_when_the_status_has_no_operation_id() -> None:
    """A control client written from the documented API gives no operation id: the move must still be polled to
    its end, and a 'not running' read before the controller shows the move started must not end it."""

    class DocumentedControl(FakeControl):
        def __init__(self) -> None:
            super().__init__()
            self.words: list[bool] = []

        def getAsyncOperationProgressEx(self) -> DocumentedStatus:  # type: ignore[override]
            return DocumentedStatus(self.words.pop(0) if self.words else False)

    control = DocumentedControl()
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        control.words = [False]  # read as the move starts: nothing running
        arm.start_move_linear(POSE, 0.05, 0.5)
        control.words = [False, False, True, True, False]  # not yet started, started, running, done
        assert [arm.move_running() for _ in range(5)] == [True, True, True, True, False]
        assert not arm.move_running()


def test_keep_alive_kicks_from_a_thread_and_refuses_commands_inside() -> None:
    control = FakeControl()
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        before = control.names().count("kickWatchdog")
        with arm.keep_alive():
            time.sleep(6 * KEEP_ALIVE_KICK_S)
            with pytest.raises(ArmError, match="keep_alive"):
                arm.speed_linear(np.zeros(6), 0.5)
            assert arm.read_state().tcp_pose is not None  # reading is fine
        assert control.names().count("kickWatchdog") - before >= 3
        assert not any(t.name == "ur5e-watchdog-kick" for t in threading.enumerate())


def test_a_stalled_stream_and_a_lost_connection_are_robot_state_lost() -> None:
    receive = FakeReceive()
    clock = VirtualClock()
    receiver = UR5eReceiver("ur", receive=receive, clock=clock)
    receiver.read_state()
    receive.getTimestamp = lambda: 5.0  # type: ignore[method-assign]  # the controller clock stops
    receiver.read_state()
    with pytest.raises(RobotStateLost) as excinfo:
        for _ in range(round(STALL_TIMEOUT_S / 0.002) + 2):  # the control loop reads every 2 ms
            clock.sleep(0.002)
            receiver.read_state()
    assert isinstance(excinfo.value, DeviceTimeout) and isinstance(excinfo.value, ArmError)
    receive.connected = False
    with pytest.raises(RobotStateLost):
        receiver.read_state()
    receiver.close()
    assert receive.disconnects == 1


def test_a_host_that_was_frozen_does_not_call_a_live_controller_lost() -> None:
    """SIGSTOP for 2 s: the first read after waking sees the timestamp of before the freeze (ur_rtde's own receive
    thread was frozen too). That is no evidence against the controller; the next state it sends settles it. (Calling
    it lost made stop() send nothing after a host freeze.)"""
    receive = FakeReceive()
    clock = VirtualClock()
    receiver = UR5eReceiver("ur", receive=receive, clock=clock)
    receive.getTimestamp = lambda: 5.0  # type: ignore[method-assign]
    receiver.read_state()
    clock.sleep(2.0)  # the host is frozen
    receiver.read_state()  # awake: still the old timestamp
    receive.getTimestamp = lambda: 7.0  # type: ignore[method-assign]  # the controller's state of now arrives
    assert receiver.read_state().controller_t_s == 7.0
    receiver.close()


def test_a_freeze_right_after_a_read_that_saw_no_new_state_does_not_call_the_controller_lost() -> None:
    """The fault matrix's stall-0.5s-approach: the loop reads twice within one RTDE period (the second read sees the
    same timestamp and starts the stall count), then the host is frozen 0.5 s with ur_rtde's receive thread. The
    first reads after waking must not count the freeze as the controller's silence (that line blamed the cable for
    what the watchdog did); reads without a gap for STALL_TIMEOUT_S still do."""
    receive = FakeReceive()
    clock = VirtualClock()
    receiver = UR5eReceiver("ur", receive=receive, clock=clock)
    receive.getTimestamp = lambda: 5.0  # type: ignore[method-assign]
    receiver.read_state()
    clock.sleep(0.001)
    receiver.read_state()  # the same timestamp: the stall count starts here
    clock.sleep(STALL_TIMEOUT_S + 0.01)  # the host is frozen
    for _ in range(10):  # awake: 20 ms of reads while the receive thread catches up
        clock.sleep(0.002)
        receiver.read_state()
    receive.getTimestamp = lambda: 7.0  # type: ignore[method-assign]
    assert receiver.read_state().controller_t_s == 7.0
    receiver.close()


def test_a_stale_stream_with_the_program_stopped_is_a_stopped_program_not_a_lost_controller() -> None:
    """After a host freeze past the watchdog the receive stream may lag; the control side already says the program
    stopped. That is ControlScriptStopped (its hint: the same command resumes), and stop() has nothing to send."""
    control, receive, clock = FakeControl(), FakeReceive(), VirtualClock()
    arm = UR5eArm("ur", control=control, receive=receive, clock=clock)
    receive.getTimestamp = lambda: 5.0  # type: ignore[method-assign]
    arm.read_state()
    for _ in range(round(STALL_TIMEOUT_S / 0.002) - 5):  # the loop reads every 2 ms: not yet stale
        clock.sleep(0.002)
        arm.read_state()
    control.program_running = False  # the watchdog stopped the program
    with pytest.raises(ControlScriptStopped) as excinfo:
        for _ in range(20):
            clock.sleep(0.002)
            arm.read_state()
    assert not isinstance(excinfo.value, RobotStateLost)
    assert "run the same command again" in excinfo.value.one_line()
    arm.stop()  # no RobotStateLost: the controller already stopped the arm
    control.program_running = True  # running, yet no new state: the controller is lost
    with pytest.raises(RobotStateLost):
        clock.sleep(0.002)
        arm.read_state()
    arm.close()


def test_a_move_reported_finished_before_the_pose_stream_shows_it_is_not_an_error() -> None:
    """The progress word comes with the control client's RTDE stream, the pose with the receive client's; the first
    can be a few periods ahead (seen on the real-time twin at 50 mm/s: 'a move ended 0.6 mm from its target')."""

    class LaggingReceive(FakeReceive):
        def __init__(self) -> None:
            super().__init__()
            self.reads = 0

        def getActualTCPPose(self) -> list[float]:
            self.reads += 1
            lag = 0.0006 if self.reads < 12 else 0.0  # still 0.6 mm short for the first reads
            return list(POSE + np.array([0.0, -lag, 0, 0, 0, 0]))

    control = FakeControl()
    control.move_periods = 2  # the controller says "done" after two polls
    with UR5eArm("ur", control=control, receive=LaggingReceive()) as arm:
        state = move_to(arm, POSE, 0.05, 0.5)
    assert np.allclose(state.tcp_pose, POSE)


def test_a_vanished_controller_gets_no_blocking_stop_commands_and_the_watchdog_is_named() -> None:
    """ur_rtde's blocking commands to a controller that vanished return False only after ~301 s each: stop and close
    must not send them when the receive side has lost the stream (the controller's watchdog stops the program)."""
    control, receive = FakeControl(), FakeReceive()
    arm = UR5eArm("ur", control=control, receive=receive, watchdog_hz=8.0)
    arm.speed_linear(np.array([0, 0, 0.005, 0, 0, 0]), 0.5)
    receive.connected = False  # the cable is pulled
    sent_before = len(control.calls)
    with pytest.raises(RobotStateLost) as excinfo:
        arm.stop(5.0)
    assert "watchdog (8 Hz)" in (excinfo.value.hint or "")
    arm.close()
    assert [name for name, _ in control.calls[sent_before:]] == ["disconnect"]
    assert receive.disconnects == 1


def test_the_watchdog_is_armed_again_as_each_motion_starts_but_not_every_period() -> None:
    """ur_rtde reconnects on its own after a network error and uploads a fresh script, which has no watchdog."""
    control = FakeControl()
    with UR5eArm("ur", control=control, receive=FakeReceive(), watchdog_hz=8.0) as arm:
        for _ in range(3):
            arm.speed_linear(np.array([0, 0, 0.005, 0, 0, 0]), 0.5)
            arm.wait_period()
        arm.stop()
        arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.02))
        arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.02))
        arm.stop()
        arm.start_move_linear(np.array([0.1, 0.2, 0.3, 0, 0, 0]), 0.05, 0.5)
    names = [n for n in control.commands() if n in ("setWatchdog", "speedL", "forceMode", "moveL")]
    assert names == [
        "setWatchdog",
        "setWatchdog",
        "speedL",
        "speedL",
        "speedL",
        "setWatchdog",  # stop: the rest window
        "setWatchdog",
        "forceMode",
        "forceMode",
        "setWatchdog",
        "setWatchdog",
        "moveL",
    ]


def test_the_watchdog_is_tight_exactly_while_a_motion_is_commanded() -> None:
    """Issue 37: a watchdog held tight at rest tripped under set-up work and ~0.17 s after every session's last
    retract. It is at ``watchdog_hz`` from each motion's start to its end (stop, the move seen over,
    forceModeStop), at the rest window otherwise; a move's end does not relax it while a speed command still runs."""
    control = FakeControl()

    def watchdog() -> float:
        return [args[0] for name, args in control.calls if name == "setWatchdog"][-1]  # type: ignore[return-value]

    with UR5eArm("ur", control=control, receive=FakeReceive(), watchdog_hz=8.0) as arm:
        assert watchdog() == REST_WATCHDOG_HZ
        arm.start_move_linear(np.array([0.1, 0.2, 0.3, 0, 0, 0]), 0.05, 0.5)
        assert watchdog() == 8.0
        assert arm.move_running() and watchdog() == 8.0
        control.stop_moves()
        assert not arm.move_running() and watchdog() == REST_WATCHDOG_HZ  # the move is over
        arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.02))
        assert watchdog() == 8.0
        arm.force_mode_stop()
        assert watchdog() == REST_WATCHDOG_HZ
        arm.speed_linear(np.array([0, 0, 0.005, 0, 0, 0]), 0.5)
        arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.02))
        arm.force_mode_stop()
        assert watchdog() == 8.0  # the speed command still runs
        arm.stop()
        assert watchdog() == REST_WATCHDOG_HZ
        sets = len([n for n in control.names() if n == "setWatchdog"])
        arm.stop()
        with arm.keep_alive():
            pass
        assert len([n for n in control.names() if n == "setWatchdog"]) == sets  # at rest already: no round trip


def test_an_earlier_moves_finish_signal_cannot_end_the_next_move() -> None:
    """move_to may end a move on arrival while its thread still runs; if the next move starts and the stream then
    shows the earlier operation finishing, only the operation id tells the two apart."""
    control = FakeControl()
    control.move_periods = 1000
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        arm.start_move_linear(np.array([0.1, 0.2, 0.3, 0, 0, 0]), 0.05, 0.5)
        assert arm.move_running()
        arm.start_move_linear(np.array([0.1, 0.25, 0.3, 0, 0, 0]), 0.05, 0.5)  # the first one's thread still ran
        control.stale_words = [1 << 24]  # operation 1 (the first move) finished: seen after the second started
        assert arm.move_running()
        control.move_periods = 0
        control.stop_moves()
        assert not arm.move_running()  # operation 2 finished


def test_relaxing_the_watchdog_of_a_program_that_already_stopped_is_no_error_of_its_own() -> None:
    """A host frozen 0.5 s mid-press: the controller's watchdog stopped the program; the press's force_mode_stop
    then relaxes the watchdog. That setWatchdog is refused (no program runs), and the stop must surface as the
    stopped program (which the press reports with what happened and how to resume), not as 'setWatchdog: ...'."""
    control = FakeControl()
    with UR5eArm("ur", control=control, receive=FakeReceive(), watchdog_hz=8.0) as arm:
        arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.02))
        control.program_running = False
        control.results["setWatchdog"] = False
        arm.force_mode_stop()  # nothing left to relax: no error of its own
        with pytest.raises(ControlScriptStopped):
            arm.speed_linear(np.array([0, 0, 0.005, 0, 0, 0]), 0.5)
