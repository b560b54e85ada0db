"""The controller twin's RTDE port, read by the REAL ur_rtde receive client and by a raw socket client.

Loopback addresses 127.0.0.20-39 belong to these tests.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest
import rtde_receive

from drivers.errors import DeviceError
from protocols import rtde
from tests.twin.twin_helpers import RECEIVE_VARIABLES, wait_until
from unitac_rig.sim.twin import ControllerParams, ControllerTwin, start_twin_on_free_loopback

VARIABLES = RECEIVE_VARIABLES[:7]  # the state a receive client reads: time, pose, force, speed, modes, safety bits
POSE = (-0.15, 0.625, 0.21, 0.1, -2.2, 2.3)  # m, rad: a still pad, no object in front of it


@pytest.fixture(scope="module")
def twin() -> Iterator[ControllerTwin]:
    params = ControllerParams(unlock_delay_s=0.0, rtde_registers_in_use=("input_int_register_0",))
    with start_twin_on_free_loopback(20, 39, start_pose=POSE, params=params) as controller:
        yield controller


def test_real_receive_client_reads_the_state_back_exactly(twin: ControllerTwin) -> None:
    client = rtde_receive.RTDEReceiveInterface(twin.host, 500.0, VARIABLES)
    try:
        assert client.isConnected()
        assert client.getActualTCPPose() == list(POSE)  # bit for bit through the wire
        assert client.getActualTCPSpeed() == [0.0] * 6
        assert 0.0 < client.getTimestamp() <= twin.truth().controller_t_s
        assert len(client.getActualTCPForce()) == 6
        assert client.getRobotMode() == 7
        assert client.getSafetyMode() == 1
        assert not client.isProtectiveStopped()
        assert not client.isEmergencyStopped()

        twin.trigger_protective_stop()
        assert wait_until(client.isProtectiveStopped)
        assert client.getSafetyMode() == 3
        assert client.getSafetyStatusBits() & rtde.SAFETY_BIT_PROTECTIVE_STOP
        assert twin.truth().rtde_clients == 1
        twin.unlock_protective_stop()
        assert wait_until(lambda: not client.isProtectiveStopped())
    finally:
        client.disconnect()
    assert wait_until(lambda: twin.truth().rtde_clients == 0)


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


def handshake(twin: ControllerTwin, names: list[str], frequency_hz: float) -> tuple[PackageReader, rtde.RecipeReply]:
    sock = socket.create_connection((twin.host, rtde.RTDE_PORT), timeout=2.0)
    reader = PackageReader(sock)
    sock.sendall(rtde.encode_request_protocol_version())
    assert rtde.decode_protocol_version_reply(reader.next().payload)
    sock.sendall(rtde.encode_get_controller_version())
    assert rtde.decode_controller_version_reply(reader.next().payload).major == 5
    sock.sendall(rtde.encode_setup_outputs(frequency_hz, names, trailing_comma=True))
    return reader, rtde.decode_recipe_reply(reader.next().payload)


def test_unknown_output_names_are_not_found_and_inputs_in_use_are_flagged(twin: ControllerTwin) -> None:
    reader, reply = handshake(twin, ["timestamp", "warp_drive"], 500.0)
    with reader.sock:
        assert reply.types == ("DOUBLE", rtde.NOT_FOUND)
        assert reply.recipe_id == 0
        reader.sock.sendall(rtde.encode_setup_inputs(["input_int_register_0", "input_double_register_1"]))
        reply = rtde.decode_recipe_reply(reader.next().payload)
        assert reply.types == (rtde.IN_USE, "DOUBLE") and reply.recipe_id == 0


def test_streams_after_start_and_stops_on_pause(twin: ControllerTwin) -> None:
    reader, reply = handshake(twin, ["timestamp", "robot_mode"], 125.0)
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
        reader.sock.settimeout(0.05)  # more than six 125 Hz periods: nothing more comes
        with pytest.raises(TimeoutError):
            reader.next()


def test_address_in_use_is_a_device_error(twin: ControllerTwin) -> None:
    with pytest.raises(DeviceError) as excinfo:
        ControllerTwin(twin.host)
    assert excinfo.value.hint
