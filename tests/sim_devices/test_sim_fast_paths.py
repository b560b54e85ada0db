"""The fast twin's cheaper paths give the bytes and numbers of the plain ones (issue 27: the simulator 3x cheaper,
its sessions unchanged): the uSkin payloads and their bus delivery, the PapillArray hub's packets, the arm's F/T
noise drawn a block at a time, the scene's kept wrench."""

from __future__ import annotations

import itertools
import math

import can
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.clock import VirtualClock
from drivers.layouts import USKIN
from protocols.errors import ProtocolError
from protocols.papillarray import N_PILLARS, PillarSensorData, decode_packet, encode_packet
from protocols.xela_can import encode_taxel_message
from unitac_rig.rig.objects import get_object
from unitac_rig.sim.arm import SimArm, SimArmParams
from unitac_rig.sim.devices.lockstep_can import LockstepCanBus
from unitac_rig.sim.devices.papillarray import HubPacketWriter
from unitac_rig.sim.devices.xela_can import taxel_payloads
from unitac_rig.sim.scene import PressScene, SceneParams

_channels = itertools.count()
_counts = st.integers(min_value=0, max_value=0xFFFF)
_finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_subnormal=True, width=64)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(_counts, _counts, _counts), min_size=1, max_size=30))
def test_uskin_payloads_are_the_codecs_bytes(counts: list[tuple[int, int, int]]) -> None:
    payloads = taxel_payloads(np.array(counts, dtype=np.int64))
    assert payloads == [encode_taxel_message(0x100, x, y, z) for x, y, z in counts]


def test_frames_sent_in_a_batch_arrive_as_sending_each_message_would() -> None:
    channel = f"fast-paths-{next(_channels)}"
    with (
        LockstepCanBus(channel) as batch_sender,
        LockstepCanBus(channel, receive_own_messages=True) as plain_sender,
        LockstepCanBus(channel) as receiver,
    ):
        frames = [(0x100 + i, bytes([i, 0xFA, 0, 1, 2, 3, 4, 0])) for i in range(24)]
        batch_sender.send_standard_frames(frames)
        batched = [receiver.recv(timeout=0) for _ in frames]
        assert [bytes(m.data) for m in plain_sender_drain(plain_sender)] == [data for _, data in frames]
        for arbitration_id, data in frames:
            plain_sender.send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False))
        plain = [receiver.recv(timeout=0) for _ in frames]
        assert receiver.recv(timeout=0) is None
        own = plain_sender_drain(plain_sender)
    fields = ("arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame", "dlc", "data", "is_fd", "is_rx")
    for got, want in zip(batched, plain, strict=True):
        assert got is not None and want is not None
        assert [getattr(got, f) for f in fields] == [getattr(want, f) for f in fields]
        assert got.channel == channel
    assert all(m.is_rx is False for m in own) and len(own) == len(frames)  # its own copies, marked as sent
    batched[0].data[0] = 0x55  # a receiver's message is its own
    assert frames[0][1][0] == 0


def plain_sender_drain(bus: LockstepCanBus) -> list[can.Message]:
    out = []
    while (message := bus.recv(timeout=0)) is not None:
        out.append(message)
    return out


def _arrays(draw: st.DrawFn, shape: tuple[int, ...]) -> np.ndarray:
    return np.array(draw(st.lists(_finite, min_size=math.prod(shape), max_size=math.prod(shape)))).reshape(shape)


@st.composite
def _hub_samples(draw: st.DrawFn) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray, int]:
    return (
        draw(st.integers(0, 0xFFFF_FFFF)),
        draw(st.integers(0, 2**64 - 1)),
        _arrays(draw, (N_PILLARS, 3)),
        _arrays(draw, (N_PILLARS, 3)),
        _arrays(draw, (3,)),
        draw(st.integers(0, 1)),
    )


def _plain_packet(slot: int, sample: tuple[int, int, np.ndarray, np.ndarray, np.ndarray, int]) -> bytes:
    counter, timestamp_us, forces, displacements, torque, active = sample
    from protocols.papillarray import PapillArrayPacket

    sensors = [PillarSensorData.unloaded(), PillarSensorData.unloaded()]
    sensors[slot] = PillarSensorData(
        forces_n=forces,
        displacements_mm=displacements,
        global_force_n=forces.sum(axis=0),
        global_torque_nmm=torque,
        slip_active=active,
    )
    return encode_packet(PapillArrayPacket(counter=counter, timestamp_us=timestamp_us, sensors=sensors))


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 1), st.lists(_hub_samples(), min_size=1, max_size=4))
def test_hub_packets_are_the_codecs_bytes(slot: int, samples: list[tuple]) -> None:
    writer = HubPacketWriter([PillarSensorData.unloaded(), PillarSensorData.unloaded()], slot)
    for sample in samples:  # one writer, several packets: nothing of one packet stays in the next
        assert writer.encode(*sample) == _plain_packet(slot, sample)


def test_hub_values_the_template_cannot_hold_go_through_the_codec() -> None:
    writer = HubPacketWriter([PillarSensorData.unloaded(), PillarSensorData.unloaded()], 0)
    forces = np.zeros((N_PILLARS, 3))
    forces[4, 2] = np.nan  # NaN travels as the codec writes it
    sample = (7, 1000, forces, np.zeros((N_PILLARS, 3)), np.zeros(3), 0)
    packet = writer.encode(*sample)
    assert packet == _plain_packet(0, sample)
    assert np.isnan(decode_packet(packet).sensors[0].forces_n[4, 2])
    forces[4, 2] = 1e39  # beyond float32: refused by the codec, as before
    with pytest.raises(ProtocolError, match="float32"):
        writer.encode(7, 1000, forces, np.zeros((N_PILLARS, 3)), np.zeros(3), 0)
    with pytest.raises(ProtocolError, match="u32"):  # the codec's own checks of the hub block, as before
        writer.encode(2**32, 1000, np.zeros((N_PILLARS, 3)), np.zeros((N_PILLARS, 3)), np.zeros(3), 0)
    with pytest.raises(ProtocolError, match="u64"):
        writer.encode(7, -1, np.zeros((N_PILLARS, 3)), np.zeros((N_PILLARS, 3)), np.zeros(3), 0)


def _reference_ft(params: SimArmParams, seed: int, periods: int) -> np.ndarray:
    """The F/T readings with no contact as the arm formed them before the block drawing: every period six drift
    normals, then six noise normals, each scaled and added one period at a time, through the filter (alpha 1)."""
    rng = np.random.default_rng(seed)
    scale = np.array([1.0, 1.0, 1.0] + [params.ft_torque_scale_m] * 3)
    bias = rng.normal(0.0, params.ft_bias_sigma_n, 6) * scale
    filtered = np.zeros(6) + bias
    readings = []
    for _ in range(periods):
        drift = params.ft_bias_drift_n_per_sqrt_s * math.sqrt(0.002) * rng.standard_normal(6)
        bias = bias + drift * scale
        raw = np.zeros(6) + bias
        raw = raw + params.ft_noise_sigma_n * rng.standard_normal(6) * scale
        filtered = filtered + 1.0 * (raw - filtered)
        readings.append(1.0 * (filtered - np.zeros(6)))
    return np.array(readings)


def test_the_arms_ft_noise_is_the_per_period_draws_bit_for_bit() -> None:
    params = SimArmParams(ft_filter_cutoff_hz=None, ft_latency_s=0.0)  # the reading is bias + noise itself
    periods = 2500  # past two blocks of draws
    arm = SimArm(_NoContact(), clock=VirtualClock(), rng=np.random.default_rng(11), params=params)
    readings = []
    for _ in range(periods):
        arm.wait_period()
        readings.append(arm.read_state().tcp_force)
    assert np.array_equal(np.array(readings), _reference_ft(params, 11, periods))


class _NoContact:
    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        return np.zeros(6)


def test_the_scene_answers_a_repeated_pose_as_a_fresh_scene_does() -> None:
    def scene() -> PressScene:
        return PressScene(get_object("hex_tpu"), 0.0, USKIN, params=SceneParams().exact())

    kept, fresh, poser = scene(), scene(), scene()  # the same history for kept and fresh but the repeated asks
    pressing = poser.pose_at_travel(10.0, 1.5)
    first = kept.wrench_on_tool(pressing)
    assert np.linalg.norm(first[:3]) > 1.0
    with pytest.raises(ValueError):
        first[:] = 0.0  # the kept answer is read only: nobody can change what the next caller is told
    again = kept.wrench_on_tool(pressing)
    assert again is first  # the same answer, no copy (the arm then skips its own copy and force check)
    assert np.array_equal(again, fresh.wrench_on_tool(pressing))
    elsewhere = poser.pose_at_travel(10.0, 0.5)
    assert np.array_equal(kept.wrench_on_tool(elsewhere), fresh.wrench_on_tool(elsewhere))
    assert np.array_equal(kept.wrench_on_tool(pressing), again)


def test_moving_the_object_changes_what_a_kept_pose_feels() -> None:
    def scene() -> PressScene:
        return PressScene(get_object("hex_tpu"), 0.0, USKIN, params=SceneParams().exact())

    kept, moved_fresh, poser = scene(), scene(), scene()
    pressing = poser.pose_at_travel(0.0, 1.0)  # 1 mm into the hexagon, pressing along -y
    before = kept.wrench_on_tool(pressing)
    loads_before = kept.taxel_loads(pressing).forces_n
    shift = np.array([0.0, 0.5])  # the object 0.5 mm further from the pad
    kept.center_mm = kept.center_mm + shift
    moved_fresh.center_mm = moved_fresh.center_mm + shift
    after = kept.wrench_on_tool(pressing)
    assert np.array_equal(after, moved_fresh.wrench_on_tool(pressing))
    assert np.linalg.norm(after[:3]) < np.linalg.norm(before[:3])  # less travel into it, less force
    assert np.array_equal(kept.taxel_loads(pressing).forces_n, moved_fresh.taxel_loads(pressing).forces_n)
    assert not np.array_equal(kept.taxel_loads(pressing).forces_n, loads_before)
    with pytest.raises(ValueError):
        kept.center_mm[0] += 1.0  # only a whole new centre moves the object (and forgets what was kept)


class _ConstantWorld:
    """Answers the same array every time; ``read_only`` promises it never changes (a scene's kept answer)."""

    def __init__(self, wrench: np.ndarray, *, read_only: bool) -> None:
        self.wrench = np.array(wrench, dtype=np.float64)
        self.wrench.flags.writeable = not read_only

    def wrench_on_tool(self, tcp_pose: np.ndarray) -> np.ndarray:
        return self.wrench


def test_a_kept_read_only_wrench_above_the_limit_trips_the_protective_stop_every_period() -> None:
    params = SimArmParams()
    world = _ConstantWorld([0.0, -(params.protective_stop_n + 5.0), 0.0, 0.0, 0.0, 0.0], read_only=True)
    arm = SimArm(world, clock=VirtualClock(), rng=np.random.default_rng(0), params=params)
    arm.wait_period()
    assert arm.protective_stopped and arm.read_state().protective_stop
    arm.unlock_protective_stop()
    assert not arm.protective_stopped
    arm.wait_period()  # the same kept answer, still above the limit: it trips again
    assert arm.protective_stopped


def test_a_world_that_changes_its_writable_answer_in_place_is_felt_at_once() -> None:
    world = _ConstantWorld(np.zeros(6), read_only=False)
    arm = SimArm(world, clock=VirtualClock(), rng=np.random.default_rng(0), params=SimArmParams(ft_latency_s=0.0))
    arm.wait_period()
    assert not arm.true_wrench().any()
    world.wrench[1] = -500.0  # the same array object, changed: a writable answer is never trusted to be kept
    arm.wait_period()
    assert arm.true_wrench()[1] == -500.0
    assert arm.protective_stopped


def test_the_state_read_is_the_last_control_periods() -> None:
    """The snapshot is formed when first read, but shows the controller as it was after the last period: a program
    started again between two periods is reported running from the next period on, as before the change."""
    arm = SimArm(_NoContact(), clock=VirtualClock(), rng=np.random.default_rng(0))
    arm.wait_period()
    arm.stop_program("test")
    assert not arm.read_state().program_running
    arm.wait_period()
    arm.reupload_script()
    assert not arm.read_state().program_running  # still the last period's state
    arm.wait_period()
    state = arm.read_state()
    assert state.program_running and state.host_t_ns == arm.clock.now_ns()
    goal = arm.true_tcp_pose() + np.array([0.0, 0.01, 0.0, 0.0, 0.0, 0.0])
    arm.move_linear(goal, 0.05, 0.5)
    assert np.array_equal(arm.read_state().tcp_pose, arm.true_tcp_pose())
    assert arm.read_state().host_t_ns == arm.clock.now_ns()
