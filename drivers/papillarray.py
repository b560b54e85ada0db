"""Contactile PapillArray (3x3 pillars) driver over the Controller v2.0's USB serial stream.

The hub streams as soon as the port is open (no start command); the driver sets the rate (``f<rate>\\n``), decodes
packets with :class:`protocols.papillarray.PacketParser` and hands out frames of pillar forces (9, 3) in N with the
tip displacements (9, 3) in mm, ``seq`` = the hub's packet counter and ``device_t_us`` = its timestamp. A tare is
the device's own bias (``z\\n``, up to 2 s), refused when the frames show load or motion.

The contact check (any pillar's |Fz| above the SDK's 0.5 N contact threshold) reads forces relative to the hub's
last bias, so it is only made once the driver has biased the hub since opening the port: an unbiased hub (after
power-up or a replug, which powers it) reads its zero's offset and drift since the factory calibration, which no
threshold tells apart from a load. The first bias is therefore taken on the caller's word that the sensor is clear
(a session takes it in free air at the stand-off), and a bias taken under load shows at the next tare as a pillar
reading a negative Fz once unloaded, which is refused with that cause.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
import serial

from drivers.clock import Clock
from drivers.errors import DeviceError, DeviceNotFound
from drivers.frames import TactileFrame
from drivers.layouts import PAPILLARRAY
from drivers.sensor import TareRecord
from drivers.sensor_base import PumpedSensor
from protocols.papillarray import N_SENSOR_SLOTS, PacketParser
from protocols.papillarray_commands import VALID_RATES_HZ, Command, encode_command

logger = logging.getLogger(__name__)

CONTACT_THRESHOLD_N = 0.5  # the SDK's per-pillar contact threshold (CONTACT_THRESH)
MAX_TARE_STD_N = 0.1  # per-channel std over the tare window; resolution is <0.05 N (1 sigma)
BIAS_SETTLE_S = 2.0  # the hub takes up to 2 s to bias
MIN_TARE_FRAMES = 5
RATED_SHEAR_N = 4.0  # per-pillar Fx, Fy range
RATED_NORMAL_N = 15.0  # per-pillar Fz range
RATED_SHEAR_MM = 1.0  # per-pillar Dx, Dy range
RATED_NORMAL_MM = 2.5  # per-pillar Dz range
# Integrity (issue 28; why and how often, docs/reliability.md): the 16-bit byte-sum checksum misses two flips of one
# bit in opposite directions, so the driver also flags values no pillar produces: beyond IMPOSSIBLE_RANGE_FACTOR
# times the rated range (PTS 2.1 spec; a tip 4 mm sideways would have passed its neighbour on the 7 mm pitch) or not
# finite, or a move between packets dt apart faster than the hub's anti-alias filter (-3 dB at about 235 Hz) passes.
IMPOSSIBLE_RANGE_FACTOR = 4.0
PHYSICAL_LIMITS = IMPOSSIBLE_RANGE_FACTOR * np.array(
    [RATED_SHEAR_N, RATED_SHEAR_N, RATED_NORMAL_N, RATED_SHEAR_MM, RATED_SHEAR_MM, RATED_NORMAL_MM]
)  # |Fx| |Fy| |Fz| (N), |Dx| |Dy| |Dz| (mm)
ANTI_ALIAS_HZ = 235.0
LINK_CHECK = (
    "16-bit byte-sum checksum: two flips of the same bit in opposite directions cancel (about 6 % of double bit "
    "flips); values no pillar can report are counted in implausible_frames and flagged"
)
READ_CHUNK_BYTES = 65_536
MAX_READS_PER_PUMP = 64
IDLE_SLEEP_S = 0.002  # reader thread nap when the port had nothing (the port is read with timeout 0)

_URL_HINT = (
    "give a device path like /dev/ttyACM0 (simulated hubs register simpapill:// when unitac_rig.sim is imported)"
)
_PORT_HINT = (
    "check the hub is plugged in (ls /dev/ttyACM*) and that you may open it: sudo usermod -aG dialout $USER, "
    "then log in again"
)


def papillarray_saturated(values: np.ndarray) -> np.ndarray:
    """Per-pillar flag (9,): force outside the rated range (|Fx|, |Fy| >= 4 N or Fz >= 15 N)."""
    values = np.asarray(values)
    return (
        (np.abs(values[:, 0]) >= RATED_SHEAR_N)
        | (np.abs(values[:, 1]) >= RATED_SHEAR_N)
        | (values[:, 2] >= RATED_NORMAL_N)
    )


def implausible_pillars(readings: np.ndarray, previous: np.ndarray | None, dt_s: float | None) -> np.ndarray:
    """(n_pillars,) bool: pillars whose (n_pillars, 6) Fx Fy Fz (N) Dx Dy Dz (mm) reading no pillar can produce:
    outside :data:`PHYSICAL_LIMITS` or not finite, or moved from ``previous`` (the last plausible reading, ``dt_s``
    earlier) faster than the hub's anti-alias filter lets any signal move."""
    readings = np.asarray(readings, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~np.all(np.abs(readings) <= PHYSICAL_LIMITS, axis=1)  # NaN compares False: flagged
        if previous is not None and dt_s is not None and dt_s > 0:
            max_step = 2 * PHYSICAL_LIMITS * -np.expm1(-2 * np.pi * ANTI_ALIAS_HZ * dt_s)
            bad |= np.any(np.abs(readings - previous) > max_step, axis=1)
    return bad


class PapillArrayDriver(PumpedSensor):
    """One PapillArray on a Controller v2.0 hub; ``url`` is any pyserial URL (``/dev/ttyACM0``, ``simpapill://hub``).

    ``slot`` picks the sensor port on the hub (0 or 1); ``rate_hz`` one of 100, 250, 500, 1000.
    """

    def __init__(
        self,
        url: str,
        *,
        slot: int = 0,
        rate_hz: int = 100,
        clock: Clock | None = None,
        stall_timeout_s: float = 0.5,
        baudrate: int = 115_200,
        max_tare_std_n: float = MAX_TARE_STD_N,
    ) -> None:
        if not 0 <= slot < N_SENSOR_SLOTS:
            raise DeviceError(f"PapillArray slot {slot} does not exist", hint=f"use 0..{N_SENSOR_SLOTS - 1}")
        if rate_hz not in VALID_RATES_HZ:
            raise DeviceError(f"PapillArray rate {rate_hz} Hz is not supported", hint=f"use one of {VALID_RATES_HZ}")
        super().__init__(
            PAPILLARRAY,
            clock=clock,
            stall_timeout_s=stall_timeout_s,
            thread_name=f"papillarray-{slot}",
            is_saturated=papillarray_saturated,
        )
        self.url = url
        self.slot = slot
        self.rate_hz = rate_hz
        self.baudrate = baudrate
        self.max_tare_std_n = max_tare_std_n
        self._port: Any = None
        self._parser = PacketParser()
        self._parser_seen = self._parser.counters()
        self._last_counter: int | None = None
        self._last_plausible: np.ndarray | None = None  # (9, 6) last reading that passed the physics check
        self._last_plausible_counter: int | None = None
        self._zeroed_since_open = False  # biased by this driver since the port opened: Fz is relative to unloaded
        self._health.link_check = LINK_CHECK

    # ---- transport --------------------------------------------------------------------------------------------
    def _open(self) -> None:
        try:
            port = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0)
        except (ValueError, OSError) as exc:  # ValueError: unknown URL scheme or bad settings; SerialException: OSError
            hint = _URL_HINT if isinstance(exc, ValueError) else _PORT_HINT
            raise DeviceNotFound(f"cannot open PapillArray port {self.url!r}: {exc}", hint=hint) from exc
        self._port = port
        self._parser.reset()
        self._last_counter = None
        self._last_plausible = None
        self._last_plausible_counter = None
        self._zeroed_since_open = False  # a reopened port may be a replugged (so unbiased) hub
        self._write(encode_command(Command.SET_RATE, self.rate_hz))
        logger.info("papillarray: %s open, rate set to %d Hz", self.url, self.rate_hz)

    def _close(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError) as exc:
                logger.warning("papillarray: error closing %s: %s", self.url, exc)

    def _write(self, data: bytes) -> None:
        if self._port is None:
            raise DeviceError("PapillArray port is not open", hint="call connect() first")
        try:
            self._port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(
                f"cannot write to PapillArray port {self.url}: {exc}",
                hint="the hub went away; replug it, then reconnect()",
            ) from exc

    def _read_available(self) -> bytes:
        chunks = []
        for _ in range(MAX_READS_PER_PUMP):
            try:
                data = self._port.read(READ_CHUNK_BYTES)
            except (serial.SerialException, OSError) as exc:
                raise DeviceError(
                    f"PapillArray port {self.url} failed: {exc}",
                    hint="the hub went away (unplugged or powered off); replug it, then reconnect()",
                ) from exc
            if not data:
                break
            chunks.append(data)
        return b"".join(chunks)

    def _pump(self, wait_s: float) -> list[TactileFrame]:
        if self._port is None:
            raise DeviceError("PapillArray port is not open", hint="call connect() first")
        data = self._read_available()
        if not data and wait_s > 0:
            time.sleep(min(wait_s, IDLE_SLEEP_S))
            data = self._read_available()
        if not data:
            return []
        packets = self._parser.feed(data)
        self._account_parser()
        frames: list[TactileFrame] = []
        now_ns = self.clock.now_ns()
        for packet in packets:
            if self._last_counter is not None and packet.counter is not None:  # no hub block: no counter
                gap = (packet.counter - self._last_counter - 1) & 0xFFFF_FFFF
                if 0 < gap < 0x8000_0000:
                    self._count(sequence_gaps=gap)
            self._last_counter = packet.counter
            if self.slot >= len(packet.sensors):
                logger.warning("papillarray: packet %d has no slot %d", packet.counter, self.slot)
                continue
            sensor = packet.sensors[self.slot]
            if not self._right_shape(
                n := len(sensor.forces_n),
                f"PapillArray slot {self.slot} reports {n} pillars",
                hint="plug the 3x3 PapillArray into this slot, or choose its slot in the rig file",
            ):
                continue  # one damaged packet; the reader goes on
            forces = np.asarray(sensor.forces_n, dtype=np.float64)
            displacements = np.asarray(sensor.displacements_mm, dtype=np.float64)
            implausible = self._implausible(np.hstack((forces, displacements)), packet.counter)
            frames.append(
                TactileFrame(
                    sensor=PAPILLARRAY.name,
                    host_t_ns=now_ns,
                    values=forces,
                    seq=packet.counter,
                    device_t_us=packet.timestamp_us,
                    displacement_mm=displacements,
                    valid=not implausible.any(),
                    stale_mask=implausible if implausible.any() else None,
                )
            )
        return frames

    def _implausible(self, readings: np.ndarray, counter: int | None) -> np.ndarray:
        """Pillars of this packet no pillar could report (counted); else the reading becomes the last plausible one."""
        dt_s = None
        if counter is not None and self._last_plausible_counter is not None:
            samples = (counter - self._last_plausible_counter) & 0xFFFF_FFFF
            dt_s = samples / self.rate_hz if 0 < samples < 0x8000_0000 else None
        bad = implausible_pillars(readings, self._last_plausible, dt_s)
        if bad.any():
            self._count(implausible_frames=1)
            logger.debug("papillarray: packet %s holds impossible values on pillars %s", counter, np.flatnonzero(bad))
        else:
            self._last_plausible = readings
            self._last_plausible_counter = counter
        return bad

    def _account_parser(self) -> None:
        """Add what the parser counted since the last call (a framing error counts as a checksum error)."""
        now, seen = self._parser.counters(), self._parser_seen
        self._parser_seen = now
        errors = now["checksum_errors"] + now["framing_errors"] - seen["checksum_errors"] - seen["framing_errors"]
        self._count(checksum_errors=errors, bytes_dropped=now["bytes_dropped"] - seen["bytes_dropped"])

    # ---- the rest of TactileSensor ----------------------------------------------------------------------------
    def tare(self, frames: list[TactileFrame]) -> TareRecord:
        """Bias the hub (``z``) if ``frames`` show an unloaded, still sensor; blocks ~2 s while the hub biases.

        Refuses (DeviceError) when a channel's std exceeds ``max_tare_std_n`` and, once the hub has been biased
        since the port opened, when any pillar's |Fz| exceeds the SDK contact threshold (0.5 N): before that the
        readings carry the unbiased hub's offset (module docstring). Frames that arrive while the hub biases are
        discarded. The returned baseline is zero: the device removes the offset itself.
        """
        self._require_connected()
        if len(frames) < MIN_TARE_FRAMES:
            raise DeviceError(
                f"papillarray tare needs at least {MIN_TARE_FRAMES} frames, got {len(frames)}",
                hint="record about a second of unloaded frames before taring",
            )
        stack = np.stack([f.values for f in frames]).astype(np.float64)
        peak_fz = float(np.abs(stack[:, :, 2]).max())
        spread = float(stack.std(axis=0).max())
        if self._zeroed_since_open and peak_fz > CONTACT_THRESHOLD_N:
            raise _contact_refusal(stack[:, :, 2])
        if not self._zeroed_since_open:
            logger.info("papillarray: first bias since the port opened; unbiased |Fz| up to %.2f N", peak_fz)
        if spread > self.max_tare_std_n:
            raise DeviceError(
                f"papillarray tare refused: force std {spread:.3f} N exceeds {self.max_tare_std_n:.3f} N",
                hint="keep the sensor still and untouched for at least 1 s, then tare",
            )
        self._write(encode_command(Command.BIAS))
        self.clock.sleep(BIAS_SETTLE_S)
        self._zeroed_since_open = True
        discarded = self.poll()
        logger.info("papillarray: bias sent; %d frames during the bias discarded", len(discarded))
        return TareRecord(
            baseline=np.zeros(PAPILLARRAY.frame_shape),
            n_frames=len(frames),
            host_t_ns=self.clock.now_ns(),
            method="device-bias",
            spread=spread,
        )

    def link_counters(self) -> dict[str, int]:
        """The packet parser's counters (packets, bytes_dropped, checksum_errors, framing_errors)."""
        return self._parser.counters()

    def identity(self) -> dict[str, Any]:
        return {**super().identity(), "transport": f"serial:{self.url}", "slot": self.slot, "rate_hz": self.rate_hz}


def _contact_refusal(fz_n: np.ndarray) -> DeviceError:
    """The refusal for frames ``fz_n`` (frames, 9) N whose largest |Fz| passes the contact threshold: a load pushes
    a pillar's Fz up; a negative one means the last bias was taken while a pillar was loaded."""
    low, high = float(fz_n.min()), float(fz_n.max())
    if -low > high:
        return DeviceError(
            f"papillarray tare refused: a pillar reads Fz = {low:.2f} N unloaded (< -{CONTACT_THRESHOLD_N} N): "
            "the last bias was taken while it was loaded",
            hint="clear the sensor of everything, then run again: the first bias after the port opens is taken afresh",
        )
    return DeviceError(
        f"papillarray tare refused: a pillar reads |Fz| = {high:.2f} N (> {CONTACT_THRESHOLD_N} N contact)",
        hint="move the sensor clear of the object and keep it unloaded for at least 1 s, then tare",
    )
