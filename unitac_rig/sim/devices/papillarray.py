"""A simulated Contactile PapillArray Controller v2.0 (hub) behind the pyserial URL ``simpapill://NAME``.

Like the real hub it waits for the serial port to be opened, then streams binary packets (PTS v2.0 format, encoded
with :mod:`protocols.papillarray`) at 1000 Hz after power-up, with a u32 packet counter and a microsecond timestamp
from its own clock. It reports two sensor slots: ``slot`` carries the source's reading, the other an idle sensor.
It answers the ASCII commands: ``f100``..``f1000`` change the rate, ``z`` biases (the mean reading over the next
``bias_delay_s`` becomes the zero; the real hub takes up to 2 s), ``S``/``s`` start/stop slip detection.
A disconnect fault is an unplug: USB powers the hub, so afterwards it is back at 1000 Hz with no bias.
"""

from __future__ import annotations

import logging
import struct
from dataclasses import replace
from typing import Any

import numpy as np

from drivers.clock import Clock, MonotonicClock
from drivers.layouts import PAPILLARRAY
from protocols.papillarray import (
    N_SENSOR_SLOTS,
    PapillArrayPacket,
    PillarSensorData,
    encode_body,
    encode_packet,
    frame_body,
)
from protocols.papillarray_commands import Command as HubCommandKind
from protocols.papillarray_commands import CommandParser
from unitac_rig.sim.devices.base import SampleTimer
from unitac_rig.sim.devices.serial_port import SimSerialEndpoint, unique_name
from unitac_rig.sim.faults import FaultInjector, FaultPlan
from unitac_rig.sim.sensor_signals import SignalSource

logger = logging.getLogger(__name__)

POWER_UP_RATE_HZ = 1000
DEFAULT_BIAS_DELAY_S = 1.0


def _cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross(a, b)`` of (n, 3) rows, by the same products and differences numpy forms (so the same bits),
    without its axis handling: 14 us a sample against np.cross's 39 (measured issue 39; the hub samples 100-1000
    times a simulated second)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    out = np.empty((len(a), 3))  # what np.stack([...], axis=1) builds, without its wrapper
    out[:, 0] = a1 * b2 - a2 * b1
    out[:, 1] = a2 * b0 - a0 * b2
    out[:, 2] = a0 * b1 - a1 * b0
    return out


_F32_MAX = float(np.finfo(np.float32).max)
_PROBE_F32 = -1.5e-3  # a float32 with no zero byte: the bytes it changes are the field's four
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")


def _field(name: str, values: np.ndarray) -> dict[str, Any]:
    return {name: values}


class HubPacketWriter:
    """``encode_packet`` for the hub's stream, whose packets differ only in the counter, the timestamp and one slot's
    forces, displacements, global force and torque and slip flag: the bytes of everything else are encoded once and
    those fields written into a copy (the same bytes as ``encode_packet``; tests compare them).

    Where each field sits is found with the codec itself, by encoding the packet with that one field changed, so
    the layout stays the codec's. A packet the stream shape does not cover (another slot's data, a value float32
    cannot hold, NaN) goes through ``encode_packet`` as before, which also raises its errors.
    """

    def __init__(self, idle_slots: list[PillarSensorData], slot: int) -> None:
        self.slot = slot
        self._idle = idle_slots
        self._n = idle_slots[slot].n_pillars
        base = self._packet(0, 0, idle_slots[slot])
        self._body = bytearray(encode_body(base))
        template = bytes(self._body)

        def changed(packet: PapillArrayPacket) -> np.ndarray:
            probe = np.frombuffer(encode_body(packet), dtype=np.uint8)
            return np.flatnonzero(probe != np.frombuffer(template, dtype=np.uint8))

        zero = idle_slots[slot]
        positions = []
        for field in ("forces_n", "displacements_mm"):
            for i in range(self._n):
                for axis in range(3):
                    values = np.array(getattr(zero, field), dtype=np.float64)
                    values[i, axis] = _PROBE_F32
                    positions.append(changed(self._packet(0, 0, replace(zero, **_field(field, values)))))
        for field in ("global_force_n", "global_torque_nmm"):
            for axis in range(3):
                values = np.array(getattr(zero, field), dtype=np.float64)
                values[axis] = _PROBE_F32
                positions.append(changed(self._packet(0, 0, replace(zero, **_field(field, values)))))
        # each float field is four bytes of the body (a codec change that broke this must change this writer too)
        assert all(len(at) == 4 for at in positions), "the codec's float fields are not 4 bytes each"
        self._float_pos = np.concatenate(positions)
        self._counter_pos = int(changed(self._packet(0xFFFF_FFFF, 0, zero))[0])
        self._time_pos = int(changed(self._packet(0, 0xFFFF_FFFF_FFFF_FFFF, zero))[0])
        (self._active_pos,) = changed(self._packet(0, 0, replace(zero, slip_active=1)))

    def _packet(self, counter: int, timestamp_us: int, sensor: PillarSensorData) -> PapillArrayPacket:
        sensors = list(self._idle)
        sensors[self.slot] = sensor
        return PapillArrayPacket(counter=counter, timestamp_us=timestamp_us, sensors=sensors)

    def encode(
        self,
        counter: int,
        timestamp_us: int,
        forces_n: np.ndarray,
        displacements_mm: np.ndarray,
        torque_nmm: np.ndarray,
        slip_active: int,
    ) -> bytes:
        """The framed packet: this writer's slot reads ``forces_n`` and ``displacements_mm`` (n, 3), global force
        their sum and global torque ``torque_nmm`` (3,); the other slots idle."""
        force_n = np.add.reduce(forces_n, axis=0)  # forces_n.sum(axis=0), the ufunc without the method's wrapper
        values = np.concatenate([forces_n.ravel(), displacements_mm.ravel(), force_n, torque_nmm])
        if (
            values.size != 6 * self._n + 6
            or not np.maximum.reduce(np.abs(values)) <= _F32_MAX  # also for NaN
            or not (0 <= counter < 1 << 32 and 0 <= timestamp_us < 1 << 64)
        ):  # the codec writes it, or says why it cannot
            sensor = replace(
                self._idle[self.slot],
                forces_n=forces_n,
                displacements_mm=displacements_mm,
                global_force_n=force_n,
                global_torque_nmm=torque_nmm,
                slip_active=slip_active,
            )
            return encode_packet(self._packet(counter, timestamp_us, sensor))
        body = self._body
        u8 = np.frombuffer(body, dtype=np.uint8)
        u8[self._float_pos] = values.astype("<f4").view(np.uint8)  # the float32 fields' bytes, little-endian
        del u8  # the bytearray must not stay exported
        _U32.pack_into(body, self._counter_pos, counter)
        _U64.pack_into(body, self._time_pos, timestamp_us)
        body[self._active_pos] = slip_active
        return frame_body(bytes(body))


class SimPapillArrayHub(SimSerialEndpoint):
    """The hub; ``hub.url`` (``simpapill://NAME``) is the port :class:`drivers.papillarray.PapillArrayDriver` opens."""

    SCHEME = "simpapill"

    def __init__(
        self,
        name: str | None = None,
        *,
        source: SignalSource,
        slot: int = 0,
        clock: Clock | None = None,
        rate_hz: int = POWER_UP_RATE_HZ,
        faults: FaultPlan | None = None,
        bias_delay_s: float = DEFAULT_BIAS_DELAY_S,
    ) -> None:
        if not 0 <= slot < N_SENSOR_SLOTS:
            raise ValueError(f"slot must be 0..{N_SENSOR_SLOTS - 1}, got {slot}")
        self.source = source
        self.slot = slot
        self.bias_delay_s = bias_delay_s
        self.rate_hz = rate_hz
        self.counter = 0
        self.slip_active = False
        self.packets_sent = 0
        self._bias_due_ns: int | None = None
        self._bias_window: list[tuple[np.ndarray, np.ndarray]] = []  # raw readings averaged into the bias
        self._force_offset = np.zeros(PAPILLARRAY.frame_shape)
        self._displacement_offset = np.zeros(PAPILLARRAY.frame_shape)
        self._commands = CommandParser()
        self._powered = True
        the_clock = clock or MonotonicClock()
        self._power_on_ns = the_clock.now_ns()
        super().__init__(self.SCHEME, name or unique_name("hub"), clock=the_clock, faults=FaultInjector(faults))
        # built once, read every sample: the pillar positions and the idle slots' (encoding only reads them)
        xy = PAPILLARRAY.taxel_xy_mm()  # pillar tips relative to the centre pillar, mm (z out of the pad)
        self._positions_mm = np.concatenate([xy, np.zeros((PAPILLARRAY.n_taxels, 1))], axis=1)
        self._idle_slots = [PillarSensorData.unloaded() for _ in range(N_SENSOR_SLOTS)]
        self._writer = HubPacketWriter(self._idle_slots, slot)
        self._timer = SampleTimer(rate_hz, clock, self._tick, thread_name=f"sim-papillarray-{self.name}")

    @property
    def biased(self) -> bool:
        return bool(np.any(self._force_offset))

    # ---- commands ---------------------------------------------------------------------------------------------
    def on_host_bytes(self, data: bytes) -> None:
        for command in self._commands.feed(data):
            now_ns = self.clock.now_ns()
            if command.command is HubCommandKind.SET_RATE and command.rate_hz is not None:
                self.rate_hz = command.rate_hz
                self._timer.set_rate(command.rate_hz)
            elif command.command is HubCommandKind.BIAS:
                self._bias_due_ns = now_ns + round(self.bias_delay_s * 1e9)
                self._bias_window = []
            elif command.command is HubCommandKind.START_SLIP:
                self.slip_active = True
            elif command.command is HubCommandKind.STOP_SLIP:
                self.slip_active = False
            logger.debug("sim hub %s: %s", self.name, command)

    def _power_cycle(self, now_ns: int) -> None:
        self.rate_hz = POWER_UP_RATE_HZ
        self._timer.set_rate(POWER_UP_RATE_HZ)
        self._force_offset[:] = 0.0
        self._displacement_offset[:] = 0.0
        self._bias_due_ns = None
        self._bias_window = []
        self.slip_active = False
        self.counter = 0
        self._power_on_ns = now_ns
        self._commands = CommandParser()

    # ---- sampling ---------------------------------------------------------------------------------------------
    def _tick(self, t_ns: int) -> None:
        if self.check_disconnect():
            self.faults.note_disconnected()
            self._powered = False
            return
        if not self._powered:
            self._powered = True
            self._power_cycle(t_ns)
        sample = self.source.sample(t_ns)
        raw_forces = np.asarray(sample.values, dtype=np.float64)
        raw_displacement = (
            np.asarray(sample.displacement_mm, dtype=np.float64)
            if sample.displacement_mm is not None
            else np.zeros(PAPILLARRAY.frame_shape)
        )
        if self._bias_due_ns is not None:
            self._bias_window.append((raw_forces, raw_displacement))
            if t_ns >= self._bias_due_ns:
                self._force_offset = np.mean([f for f, _ in self._bias_window], axis=0)
                self._displacement_offset = np.mean([d for _, d in self._bias_window], axis=0)
                self._bias_due_ns = None
                self._bias_window = []
        if not self.attached:
            return  # "waiting for serial connection": the hub does not stream to a closed port
        counter = self.counter
        self.counter = (self.counter + 1) & 0xFFFF_FFFF
        if self.stalled(t_ns):
            return
        forces = raw_forces - self._force_offset
        packet = self._writer.encode(
            counter,
            (t_ns - self._power_on_ns) // 1000,
            forces,
            raw_displacement - self._displacement_offset,
            np.add.reduce(_cross_rows(self._positions_mm, forces), axis=0),
            1 if self.slip_active else 0,
        )
        self.send_to_host(packet, t_ns)
        self.packets_sent += 1

    def close(self) -> None:
        """Stop sampling and unplug the hub for good."""
        self._timer.close()
        self.close_endpoint()
