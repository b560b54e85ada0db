"""The hardware rig: a real UR5e and real sensors, addressed only through the rig file."""

from __future__ import annotations

import logging
import os

from drivers.arm import Arm
from drivers.clock import MonotonicClock
from drivers.sensor import TactileSensor
from unitac_rig.errors import UsageError
from unitac_rig.rig.base import Rig
from unitac_rig.rig.config import RigConfig
from unitac_rig.rig.sensors import get_sensor

log = logging.getLogger(__name__)

# Real-time priority asked for the thread that drives the arm (and the threads it starts: ur_rtde's, the sensor
# readers): below the 10 a controller twin on the same box asks for, above every normal process.
REALTIME_PRIORITY = 5


def ask_realtime() -> tuple[int, int] | None:
    """Ask for SCHED_FIFO ``REALTIME_PRIORITY`` for the calling thread, as a controller host has it; -> the policy and
    priority to restore, or None when not granted (no CAP_SYS_NICE / rtprio limit; it runs on as it was).

    Why: the RTDE watchdog (6 Hz) stops the program when the loop deciding a motion writes nothing for 167 ms. On a
    2-core box at load ~20 a process of normal priority, even one that only sleeps, saw 160 ms wake-up gaps, and 10
    of 30 twin sessions were stopped mid-motion (docs/real-rig.md, "Safety"). New threads inherit the policy on
    Linux."""
    if not hasattr(os, "sched_setscheduler"):
        return None
    try:
        before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        if before[0] in (os.SCHED_FIFO, os.SCHED_RR):
            return None  # started real-time already (chrt): keep it
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    except OSError as exc:  # PermissionError included
        log.info("no real-time scheduling for the arm's control loop (%s); a loaded PC can trip the watchdog", exc)
        return None
    log.info("the arm's control loop runs under SCHED_FIFO %d", REALTIME_PRIORITY)
    return before


def restore_scheduling(before: tuple[int, int] | None) -> None:
    if before is None:
        return
    try:
        os.sched_setscheduler(0, before[0], os.sched_param(before[1]))
    except OSError as exc:
        log.warning("could not restore this thread's scheduling: %s", exc)


class HardwareRig(Rig):
    """A real UR5e and real sensors, addressed only through the rig file."""

    simulated = False

    def __init__(self, config: RigConfig) -> None:
        if config.arm is None:
            raise UsageError("this rig file has no [arm] section; without one the simulated rig is used")
        self.config = config
        self.clock = MonotonicClock()
        self._arm: Arm | None = None
        self._scheduling: tuple[int, int] | None = None  # what to restore at close
        self._asked_realtime = False

    @property
    def arm(self) -> Arm:
        if self._arm is None:
            from drivers.ur5e import UR5eArm

            arm = self.config.arm
            assert arm is not None
            if arm.unchecked_tool and (arm.tcp_offset is None or arm.payload_kg is None):
                log.warning(
                    "arm.unchecked_tool = true: the TCP and payload on the pendant are not checked; a wrong TCP moves "
                    "every pose and a wrong payload shifts the wrist force the press stops on"
                )
            if not self._asked_realtime:  # before connecting: ur_rtde's threads inherit it
                self._asked_realtime = True
                self._scheduling = ask_realtime()
            self._arm = UR5eArm(
                arm.host,
                frequency_hz=arm.frequency_hz,
                clock=self.clock,
                watchdog_hz=arm.watchdog_hz,
                expected_tcp_offset=arm.tcp_offset,
                expected_payload_kg=arm.payload_kg,
            )
        return self._arm

    def sensor_names(self) -> list[str]:
        return list(self.config.sensors)

    def open_sensor(self, name: str) -> TactileSensor:
        cfg = self.config.sensors.get(name)
        if cfg is None:
            raise UsageError(
                f"sensor {name!r} is not in the rig file",
                hint=f"configured: {', '.join(self.config.sensors) or 'none'}",
            )
        sensor = get_sensor(name).open_driver(cfg, self.clock)
        sensor.connect()
        sensor.start_reader()
        return sensor

    def close(self) -> None:
        try:
            if self._arm is not None:
                self._arm.close()
                self._arm = None
        finally:
            restore_scheduling(self._scheduling)
            self._scheduling, self._asked_realtime = None, False
