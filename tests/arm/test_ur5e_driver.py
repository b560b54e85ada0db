"""UR5eArm / UR5eReceiver: the real receive client against the simulated controller, a fake control object.

The control interface cannot be faked at the wire level (it uploads URScript), so a small recording class stands in
for it; these tests show every exit path stops the arm and a refused command becomes the right error.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from arm_fakes import FakeControl, FakeReceive

from drivers.arm import Arm, ArmState
from drivers.clock import VirtualClock
from drivers.errors import ArmError, DeviceNotFound, DeviceTimeout, ProtectiveStop
from drivers.ur5e import STALL_TIMEOUT_S, UR5eArm, UR5eReceiver
from unitac_rig.sim.rtde_server import SimURController, start_on_free_loopback

POSE = np.array([-0.15, 0.6, 0.21, 0.0, 2.2214, -2.2214])


class SwitchableState:
    def __init__(self) -> None:
        self.protective = threading.Event()

    def __call__(self) -> ArmState:
        stopped = self.protective.is_set()
        return ArmState(
            host_t_ns=0,
            controller_t_s=time.monotonic(),
            tcp_pose=POSE,
            tcp_force=np.array([0.0, 9.5, 0.0, 0.0, 0.0, 0.0]),
            robot_mode=7,
            safety_mode=3 if stopped else 1,
            protective_stop=stopped,
        )


@pytest.fixture
def controller() -> Iterator[tuple[SimURController, SwitchableState]]:
    state = SwitchableState()
    with start_on_free_loopback(state, first=40) as server:
        yield server, state


def test_real_receive_and_a_protective_stop_during_move_l(controller: tuple[SimURController, SwitchableState]) -> None:
    server, state = controller

    class StoppingControl(FakeControl):
        """moveL that ends in a protective stop, as a blocking ur_rtde moveL returns False then."""

        def moveL(self, pose: list[float], speed: float, acceleration: float, asynchronous: bool) -> object:
            self._record("moveL", pose, speed, acceleration, asynchronous)
            state.protective.set()
            deadline = time.monotonic() + 2.0  # until the real receive client has the new safety bits
            while not arm.read_state().protective_stop and time.monotonic() < deadline:
                time.sleep(0.002)
            return False

    control = StoppingControl()
    with UR5eArm(server.host, control=control) as arm:
        assert isinstance(arm, Arm)
        first = arm.read_state()
        assert np.array_equal(first.tcp_pose, POSE)
        assert first.tcp_force[1] == 9.5 and first.robot_mode == 7 and not first.protective_stop
        with pytest.raises(ProtectiveStop):
            arm.move_linear(POSE + np.array([0, 0.01, 0, 0, 0, 0]), 0.05, 0.5)
        assert arm.read_state().protective_stop
        assert control.calls[0] == ("moveL", (list(POSE + np.array([0, 0.01, 0, 0, 0, 0])), 0.05, 0.5, False))
        with pytest.raises(ProtectiveStop):  # refused up front while stopped: nothing reaches the controller
            arm.speed_linear(np.zeros(6), 0.5)
        assert "speedL" not in control.names()
    assert control.names()[-3:] == ["speedStop", "stopScript", "disconnect"]


def test_probe_receiver_reads_new_states_without_a_control_object(
    controller: tuple[SimURController, SwitchableState],
) -> None:
    server, _ = controller
    with UR5eReceiver(server.host) as receiver:
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


def test_close_stops_everything_even_when_a_step_fails() -> None:
    control = FakeControl()
    control.raise_on["speedStop"] = RuntimeError("script not running")
    arm = UR5eArm("ur", control=control, receive=FakeReceive())
    arm.force_mode(np.zeros(6), np.array([0, 0, 1, 0, 0, 0]), np.array([0, 0, 5.0, 0, 0, 0]), np.full(6, 0.01))
    arm.close()
    assert control.names() == ["forceMode", "forceModeStop", "speedStop", "stopScript", "disconnect"]
    arm.close()  # idempotent
    assert control.names().count("disconnect") == 1
    arm.stop()  # a no-op on a closed arm
    with pytest.raises(ArmError):
        arm.speed_linear(np.zeros(6), 0.5)


def test_leaving_a_with_block_on_an_exception_stops_the_arm() -> None:
    control = FakeControl()
    with pytest.raises(KeyboardInterrupt), UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        arm.speed_linear(np.array([0, 0.005, 0, 0, 0, 0]), 0.5)
        raise KeyboardInterrupt
    assert control.names() == ["speedL", "speedStop", "stopScript", "disconnect"]


def test_false_without_a_safety_stop_is_an_arm_error() -> None:
    control = FakeControl(moveL=False, zeroFtSensor=False)
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        with pytest.raises(ArmError) as excinfo:
            arm.move_linear(POSE, 0.1, 1.0)
        assert not isinstance(excinfo.value, ProtectiveStop)
        with pytest.raises(ArmError):
            arm.zero_ft()


def test_ur_rtde_runtime_errors_are_wrapped() -> None:
    control = FakeControl()
    control.raise_on["speedL"] = RuntimeError("RTDE control script is not running!")
    with UR5eArm("ur", control=control, receive=FakeReceive()) as arm:
        with pytest.raises(ArmError) as excinfo:
            arm.speed_linear(np.zeros(6), 0.5)
        assert isinstance(excinfo.value.__cause__, RuntimeError)


def test_stop_during_a_protective_stop_is_not_an_error() -> None:
    receive = FakeReceive()
    receive.protective = True
    control = FakeControl(speedStop=False)
    with UR5eArm("ur", control=control, receive=receive) as arm:
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
    assert control.calls[0] == ("speedL", ([0.0, 0.005, 0.0, 0.0, 0.0, 0.0], 0.5, 0.0))
    assert control.calls[1] == ("zeroFtSensor", ())
    assert control.calls[2] == ("forceMode", (list(frame), [0, 0, 1, 0, 0, 0], [0, 0, 5.0, 0, 0, 0], 2, [0.02] * 6))
    assert control.names()[3:5] == ["forceModeStop", "speedStop"]  # stop leaves force mode first
    assert [args for name, args in control.calls if name == "waitPeriod"] == [(1,), (2,)]


def test_a_stalled_stream_and_a_lost_connection_are_timeouts() -> None:
    receive = FakeReceive()
    clock = VirtualClock()
    receiver = UR5eReceiver("ur", receive=receive, clock=clock)
    receiver.read_state()
    receive.getTimestamp = lambda: 5.0  # type: ignore[method-assign]  # the controller clock stops
    receiver.read_state()
    clock.sleep(STALL_TIMEOUT_S + 0.01)
    with pytest.raises(DeviceTimeout):
        receiver.read_state()
    receive.connected = False
    with pytest.raises(DeviceTimeout):
        receiver.read_state()
    receiver.close()
    assert receive.disconnects == 1
