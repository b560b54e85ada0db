"""One press's record in the making: the robot and tactile streams, one control period at a time, and the checks
every control period of every press goes through, whatever its strategy.

:meth:`PressStreams.tick` is handed to every motion of a press as its ``on_period``. It raises on a stopped controller
(protective stop, the RTDE watchdog), a tactile stream that stalls, a wrist force that points the wrong way, travel
beyond first contact (:class:`TravelLimit`) and |F| or |T| past the hard limits; it records host stalls.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from drivers.arm import Arm, ArmState
from drivers.errors import DeviceTimeout
from drivers.frames import TactileFrame
from drivers.motion import check_controller, force_magnitude
from drivers.sensor import TactileSensor
from unitac_rig.collection.transit import PressPlan
from unitac_rig.errors import SafetyLimit
from unitac_rig.interrupts import raise_if_interrupted
from unitac_rig.rig.config import LimitsConfig, PressConfig
from unitac_rig.rig.poses import press_force_n

HOST_GAP_EVENT_S = 0.02  # controller-clock gaps between two reads longer than this are recorded (host stall)


@dataclass
class TickInfo:
    """What the live panel shows, handed to ``on_tick`` once per control period."""

    press_id: str
    phase: str
    press_force_n: float
    latest_frame: TactileFrame | None


class TravelLimit(Exception):
    """Raised inside the control loop when the pad went too far past first contact."""


@dataclass
class PressStreams:
    """Accumulates the robot and tactile streams of one press, one control period at a time."""

    arm: Arm
    sensor: TactileSensor
    plan: PressPlan
    press: PressConfig
    limits: LimitsConfig
    stall_timeout_s: float
    on_tick: Callable[[TickInfo], None] | None
    contact_threshold_n: float  # press force that counts as first contact, N (above the F/T noise)
    # The controller regulates force mode on its own zeroed F/T; the host reads that minus a host-side offset, so a
    # press force P seen here is P - offset_along_press_n on the controller (set-points are sent corrected).
    offset_along_press_n: float = 0.0
    robot_t: list[float] = field(default_factory=list)
    robot_force: list[np.ndarray] = field(default_factory=list)
    robot_pose: list[np.ndarray] = field(default_factory=list)
    press_force: list[float] = field(default_factory=list)
    frames: list[TactileFrame] = field(default_factory=list)
    events: list[tuple[float, str, str]] = field(default_factory=list)
    phase: str = "approach"
    contact_pose: np.ndarray | None = None
    last_frame_ns: int | None = None
    last_controller_t_s: float | None = None
    max_gap_s: float = 0.0

    def event(self, kind: str, detail: str = "") -> None:
        self.events.append((self.arm.clock.now_ns() / 1e9, kind, detail))

    def tick(self, state: ArmState) -> None:
        raise_if_interrupted()  # a Ctrl-C that compiled code swallowed is raised here, within one control period
        # A stopped controller first: after a host freeze the tactile stream looks stalled too, but what happened is
        # that the watchdog stopped the program (no sensor reconnect and retry for that).
        check_controller(state, f"press {self.plan.press_id}")
        force = press_force_n(state.tcp_force, self.plan.direction)
        self.robot_t.append(state.host_t_ns / 1e9)
        self.robot_force.append(np.asarray(state.tcp_force, dtype=np.float64))
        self.robot_pose.append(np.asarray(state.tcp_pose, dtype=np.float64))
        self.press_force.append(force)
        if self.last_controller_t_s is not None:
            gap = state.controller_t_s - self.last_controller_t_s
            if gap > HOST_GAP_EVENT_S:
                self.event("host_stall", f"{1000 * gap:.0f} ms between two reads of the controller state")
            self.max_gap_s = max(self.max_gap_s, gap)
        self.last_controller_t_s = state.controller_t_s
        new = self.sensor.poll()
        if new:
            self.frames.extend(new)
            self.last_frame_ns = new[-1].host_t_ns
        now = state.host_t_ns
        if self.last_frame_ns is None:
            self.last_frame_ns = now
        elif now - self.last_frame_ns > self.stall_timeout_s * 1e9:
            self.event("stall", f"no tactile frame for {(now - self.last_frame_ns) / 1e9:.3f} s")
            raise DeviceTimeout(f"{self.sensor.layout.name} stopped sending frames during press {self.plan.press_id}")
        filtered = float(np.mean(self.press_force[-self.press.stop_samples :]))
        if self.phase in ("approach", "press") and filtered <= -self.contact_threshold_n:
            # Pressing into something must read as a positive press force. A negative one of contact size means the
            # wrist force's sign or frame is wrong: force mode would then push on, so stop at once.
            raise SafetyLimit(
                f"the wrist force points the wrong way: moving into the object reads a press force of {filtered:.1f} N "
                f"during press {self.plan.press_id} (it must rise against the motion)",
                hint="check the F/T sign convention and the TCP on the teach pendant (unitac-rig probe ur5e "
                "--sign-check) before pressing again",
            )
        if self.contact_pose is None and filtered >= self.contact_threshold_n:
            # filtered like the stop rule: one noise spike in the approach must not start the travel-after-contact
            # budget millimetres before the pad touches
            self.contact_pose = np.asarray(state.tcp_pose, dtype=np.float64)
            self.event("contact", f"{force:.2f} N")
        elif (
            self.contact_pose is not None
            and self.phase in ("approach", "press")
            and filtered < 0.5 * self.contact_threshold_n
        ):
            self.contact_pose = None  # it was noise after all: nothing pushes back
            self.event("contact_lost", f"{filtered:.2f} N")
        if self.contact_pose is not None and self.phase in ("approach", "press"):
            travel_mm = 1000.0 * float(np.dot(state.tcp_pose[:3] - self.contact_pose[:3], self.plan.direction))
            if travel_mm > self.limits.max_travel_after_contact_mm:
                raise TravelLimit(f"{travel_mm:.1f} mm past first contact below {self.press.threshold_n} N")
        magnitude, torque = force_magnitude(state)
        if magnitude >= self.limits.hard_force_n or torque >= self.limits.hard_torque_nm:
            raise SafetyLimit(
                f"wrist force |F| {magnitude:.1f} N (press {force:.1f} N), |T| {torque:.2f} N*m passed the hard limit "
                f"{self.limits.hard_force_n} N / {self.limits.hard_torque_nm} N*m during press {self.plan.press_id}"
            )
        if self.on_tick is not None:
            self.on_tick(TickInfo(self.plan.press_id, self.phase, force, self.frames[-1] if self.frames else None))

    def recording(self, guard: Callable[[ArmState], None]) -> Callable[[ArmState], None]:
        """An ``on_period`` for the move back to the stand-off: ``guard`` checks, and the streams go on recording
        (the pad is off the object: free-air readings that let the extraction measure what the F/T zero left over)
        without the press's contact, travel and tactile-stall rules."""

        def on_period(state: ArmState) -> None:
            guard(state)
            self.robot_t.append(state.host_t_ns / 1e9)
            self.robot_force.append(np.asarray(state.tcp_force, dtype=np.float64))
            self.robot_pose.append(np.asarray(state.tcp_pose, dtype=np.float64))
            self.press_force.append(press_force_n(state.tcp_force, self.plan.direction))
            self.frames.extend(self.sensor.poll())

        return on_period

    def hold(self, seconds: float) -> None:
        for _ in range(max(0, round(seconds / self.arm.control_period_s))):
            self.arm.wait_period()
            self.tick(self.arm.read_state())
