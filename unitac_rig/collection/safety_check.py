"""The safety check every control period of every press goes through, whatever its strategy, and the press's
record it keeps while checking: the robot and tactile streams, one control period at a time.

:meth:`PressStreams.tick` is handed to every motion of a press as its ``on_period``. It raises on a stopped controller
(protective stop, the RTDE watchdog), a tactile stream that stalls, a wrist force that points the wrong way, travel
beyond first contact (:class:`TravelLimit`), a contact whose force leaves the friction cone around the press axis
(:class:`OffAxisLimit`), and |F| or |T| past the hard limits; it records host stalls.

The off-axis bound (docs/real-rig.md, "Safety" item 9, has its derivation): force mode regulates the press axis
only, so a lateral force beyond Coulomb friction on the pad's face (``OFF_AXIS_FRICTION`` x the filtered press force
+ ``OFF_AXIS_FLOOR_N`` for the wrist's noise across the axis) means the object touches the pad's rim. At the 10 N
threshold it lets |F| reach 14.4 N at most.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from drivers.arm import Arm, ArmState
from drivers.errors import DeviceTimeout
from drivers.frames import TactileFrame
from drivers.sensor import TactileSensor
from unitac_rig.collection.guarded_motion import check_controller, force_magnitude, settle
from unitac_rig.collection.transit import PressPlan
from unitac_rig.errors import SafetyLimit
from unitac_rig.interrupts import raise_if_interrupted
from unitac_rig.rig.config import LimitsConfig, PressConfig
from unitac_rig.rig.poses import press_force_n

HOST_GAP_EVENT_S = 0.02  # controller-clock gaps between two reads longer than this are recorded (host stall)
# A reversed wrist sign is caught in the first millimetre of contact: the mean of the last SIGN_SAMPLES readings (20 ms)
# below -SIGN_FACTOR x the contact threshold. The threshold is >= 4.5 sigma of one filtered reading; the 20 ms mean's
# noise is ~0.6 sigma (readings correlated over ~8 ms), so noise alone never reaches it, while 1 mm into a 10 N/mm
# object reads -10 N. The stop rule's 100 ms window alone let a stiff object reach the hard limit first.
SIGN_SAMPLES = 10
SIGN_FACTOR = 1.5
# Lateral force allowed per newton of press force (a friction cone of 35 deg): 1.55x the largest friction coefficient
# the project knows (the PapillArray's pillars on printed plastic, 0.45 in sim/scene.py).
OFF_AXIS_FRICTION = 0.7
# Lateral force allowed at no press force, N: the 20 ms mean of the wrist's noise across the axis still swings 1-2 N (a
# 1.5 N floor stopped 1 of 91 well-placed hex_tpu presses on the twin); a UR5e's F/T precision is +-3.5 N.
OFF_AXIS_FLOOR_N = 3.0
OFF_AXIS_PHASES = ("approach", "press", "dwell")  # while the pad is driven into the object or held there


@dataclass
class TickInfo:
    """What the live panel shows, handed to ``on_tick`` once per control period."""

    press_id: str
    phase: str
    press_force_n: float
    latest_frame: TactileFrame | None


class TravelLimit(Exception):
    """Raised inside the control loop when the pad went too far past first contact."""


class OffAxisLimit(TravelLimit):
    """Raised inside the control loop when the lateral force leaves the friction cone (see the module docstring): the
    press stops, fails as ``off_axis`` and feeds no extraction."""


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
    lateral: list[np.ndarray] = field(default_factory=list)  # force across the press axis (3,) per period, N
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
        force = self._record(state)
        wrench = np.asarray(state.tcp_force, dtype=np.float64)[:3]
        self.lateral.append(wrench + force * np.asarray(self.plan.direction))  # F minus its press-axis part
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
        quick = float(np.mean(self.press_force[-SIGN_SAMPLES:]))
        if self.phase in ("approach", "press") and (
            filtered <= -self.contact_threshold_n or quick <= -SIGN_FACTOR * self.contact_threshold_n
        ):
            # Pressing into something must read as a positive press force. A negative one of contact size means the
            # wrist force's sign or frame is wrong: force mode would then push on, so stop at once.
            read_n = min(filtered, quick)
            raise SafetyLimit(
                f"the wrist force points the wrong way: moving into the object reads a press force of {read_n:.1f} N "
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
        if self.phase in OFF_AXIS_PHASES:
            self._check_off_axis(quick)
        magnitude, torque = force_magnitude(state)
        if magnitude >= self.limits.hard_force_n or torque >= self.limits.hard_torque_nm:
            raise SafetyLimit(
                f"wrist force |F| {magnitude:.1f} N (press {force:.1f} N), |T| {torque:.2f} N*m passed the hard limit "
                f"{self.limits.hard_force_n} N / {self.limits.hard_torque_nm} N*m during press {self.plan.press_id}"
            )
        if self.on_tick is not None:
            self.on_tick(TickInfo(self.plan.press_id, self.phase, force, self.frames[-1] if self.frames else None))

    def _check_off_axis(self, filtered_press_n: float) -> None:
        """Raise OffAxisLimit when the mean lateral force of the last ``SIGN_SAMPLES`` periods (20 ms: its noise,
        ~0.25 N per axis, is 6 sigma under the floor) passes ``OFF_AXIS_FRICTION`` x the press force over the same
        window + ``OFF_AXIS_FLOOR_N``."""
        lateral_n = float(np.linalg.norm(np.mean(self.lateral[-SIGN_SAMPLES:], axis=0)))
        bound_n = OFF_AXIS_FRICTION * max(filtered_press_n, 0.0) + OFF_AXIS_FLOOR_N
        if lateral_n > bound_n:
            self.event("off_axis", f"lateral {lateral_n:.1f} N at press force {filtered_press_n:.1f} N")
            raise OffAxisLimit(
                f"lateral force {lateral_n:.1f} N at a press force of {filtered_press_n:.1f} N passed the friction "
                f"bound {bound_n:.1f} N: the object touches the pad's rim, not its face (it stands to the side?)"
            )

    def recording(self, guard: Callable[[ArmState], None]) -> Callable[[ArmState], None]:
        """An ``on_period`` for the move back to the stand-off: ``guard`` checks, and the streams go on recording
        (the pad is off the object: free-air readings that let the extraction measure what the F/T zero left over)
        without the press's contact, travel and tactile-stall rules."""

        def on_period(state: ArmState) -> None:
            guard(state)
            self._record(state)
            self.frames.extend(self.sensor.poll())

        return on_period

    def _record(self, state: ArmState) -> float:
        """Append one period's robot streams; -> its press force, N."""
        force = press_force_n(state.tcp_force, self.plan.direction)
        self.robot_t.append(state.host_t_ns / 1e9)
        self.robot_force.append(np.asarray(state.tcp_force, dtype=np.float64))
        self.robot_pose.append(np.asarray(state.tcp_pose, dtype=np.float64))
        self.press_force.append(force)
        return force

    def hold(self, seconds: float) -> None:
        settle(self.arm, seconds, self.tick)
