"""The simulated UR controller's RTDE server, read by the REAL ur_rtde receive client and by a raw socket client."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
import rtde_receive

from drivers.arm import ArmState
from drivers.clock import VirtualClock
from drivers.errors import DeviceError
from protocols import rtde
from unitac_rig.sim.arm import SimArm
from unitac_rig.sim.rtde_server import SimURController, start_on_free_loopback
from unitac_rig.sim.world import FreeSpace

VARIABLES = [
    "timestamp",
    "actual_TCP_pose",
    "actual_TCP_force",
    "actual_TCP_speed",
    "robot_mode",
    "safety_mode",
    "safety_status_bits",
]


class SwitchableState:
    """A thread-safe state provider whose protective stop a test can flip."""

    def __init__(self) -> None:
        self.protective = threading.Event()

    def __call__(self) -> ArmState:
        stopped = self.protective.is_set()
        return ArmState(
            host_t_ns=0,
            controller_t_s=1234.5,
            tcp_pose=np.array([-0.15, 0.625, 0.21, 0.1, -2.2, 2.3]),
            tcp_force=np.array([1.5, -10.25, 0.125, 0.01, -0.02, 0.03]),
            robot_mode=7,
            safety_mode=3 if stopped else 1,
            protective_stop=stopped,
            tcp_speed=np.array([0.0, 0.005, 0.0, 0.0, 0.0, 0.0]),
        )


@pytest.fixture
def controller() -> Iterator[tuple[SimURController, SwitchableState]]:
    state = SwitchableState()
    with start_on_free_loopback(state, first=20) as server:
        yield server, state


def wait_until(condition: object, timeout_s: float = 2.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():  # type: ignore[operator]
            return True
        time.sleep(0.005)
    return False


def test_real_receive_client_reads_the_state_back_exactly(controller: tuple[SimURController, SwitchableState]) -> None:
    server, state = controller
    client = rtde_receive.RTDEReceiveInterface(server.host, 500.0, VARIABLES)
    try:
        assert client.isConnected()
        assert client.getTimestamp() == 1234.5
        assert client.getActualTCPPose() == [-0.15, 0.625, 0.21, 0.1, -2.2, 2.3]
        assert client.getActualTCPForce() == [1.5, -10.25, 0.125, 0.01, -0.02, 0.03]
        assert client.getActualTCPSpeed() == [0.0, 0.005, 0.0, 0.0, 0.0, 0.0]
        assert client.getRobotMode() == 7
        assert client.getSafetyMode() == 1
        assert not client.isProtectiveStopped()
        assert not client.isEmergencyStopped()

        state.protective.set()
        assert wait_until(client.isProtectiveStopped)
        assert client.getSafetyMode() == 3
        assert client.getSafetyStatusBits() & rtde.SAFETY_BIT_PROTECTIVE_STOP
        assert server.client_count == 1
    finally:
        client.disconnect()
    assert wait_until(lambda: server.client_count == 0)


class PackageReader:
    """Whole packages from a socket, in order, however the bytes were split across recv calls."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.parser = rtde.RtdePackageParser()
        self.queue: list[rtde.RtdePackage] = []

    def next(self) -> rtde.RtdePackage:
        while not self.queue:
            data = self.sock.recv(4096)
            assert data, "server closed the connection"
            self.queue += self.parser.feed(data)
        return self.queue.pop(0)


def handshake(server: SimURController, names: list[str], frequency_hz: float) -> tuple[PackageReader, rtde.RecipeReply]:
    sock = socket.create_connection(server.address, timeout=2.0)
    reader = PackageReader(sock)
    sock.sendall(rtde.encode_request_protocol_version())
    assert rtde.decode_protocol_version_reply(reader.next().payload)
    sock.sendall(rtde.encode_get_controller_version())
    assert rtde.decode_controller_version_reply(reader.next().payload).major == 5
    sock.sendall(rtde.encode_setup_outputs(frequency_hz, names, trailing_comma=True))
    return reader, rtde.decode_recipe_reply(reader.next().payload)


def test_unknown_output_names_are_not_found_and_inputs_in_use_are_flagged() -> None:
    with start_on_free_loopback(first=20) as plain:
        reader, reply = handshake(plain, ["timestamp", "warp_drive"], 500.0)
        with reader.sock:
            assert reply.types == ("DOUBLE", rtde.NOT_FOUND)
            assert reply.recipe_id == 0
    with SimURController(plain.host, registers_in_use=frozenset({"input_int_register_0"})) as server:
        reader, _ = handshake(server, ["timestamp"], 500.0)
        with reader.sock:
            reader.sock.sendall(rtde.encode_setup_inputs(["input_int_register_0", "input_double_register_1"]))
            assert rtde.decode_recipe_reply(reader.next().payload).types == (rtde.IN_USE, "DOUBLE")


def test_streams_after_start_and_stops_on_pause() -> None:
    with start_on_free_loopback(first=20) as server:
        reader, reply = handshake(server, ["timestamp", "robot_mode"], 125.0)
        with reader.sock:
            assert reply.ok and reply.types == ("DOUBLE", "INT32")
            reader.sock.sendall(rtde.encode_start())
            assert rtde.decode_accepted_reply(reader.next().payload)
            recipe_id, values = rtde.decode_data_package(reader.next().payload, reply.types)
            assert recipe_id == reply.recipe_id and values[1] == 7
            reader.sock.sendall(rtde.encode_pause())
            # data packages already in flight may precede the pause reply
            while (package := reader.next()).type == rtde.PackageType.DATA_PACKAGE:
                pass
            assert package.type == rtde.PackageType.CONTROL_PACKAGE_PAUSE
            sent = server.sent_packages
            time.sleep(0.05)
            assert server.sent_packages == sent


def test_address_in_use_is_a_device_error() -> None:
    with start_on_free_loopback(first=20) as server:
        with pytest.raises(DeviceError) as excinfo:
            SimURController(server.host)
        assert excinfo.value.hint


def test_a_simulated_arm_is_served_as_its_latest_state() -> None:
    arm = SimArm(FreeSpace(), clock=VirtualClock(), rng=np.random.default_rng(0))
    goal = arm.true_tcp_pose() + np.array([0.0, 0.02, 0.0, 0.0, 0.0, 0.0])
    arm.move_linear(goal, 0.1, 1.0)  # virtual time: done before the server starts
    with start_on_free_loopback(arm.latest_state, first=20) as server:
        client = rtde_receive.RTDEReceiveInterface(server.host, 500.0, VARIABLES)
        try:
            assert client.getActualTCPPose() == pytest.approx(list(goal), abs=1e-12)
            assert client.getTimestamp() == arm.clock.now_ns() / 1e9
            assert client.getActualTCPForce() == list(arm.read_state().tcp_force)
        finally:
            client.disconnect()
    arm.close()
