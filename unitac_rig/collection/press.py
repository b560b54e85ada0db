"""One force-terminated press: approach along the ray toward the object's centre, stop at the threshold, dwell, retract.

Strategies (each press records which it used):

* ``guarded``: constant speed from the stand-off until the press force reaches the threshold (the paper's procedure);
* ``two-phase``: fast until first contact, then slow to the threshold (shorter presses, the same final approach);
* ``force-ramp``: fast until first contact, then force control whose set-point rises at a fixed rate (N/s), stopping
  when the measured force reaches the threshold (slow force rise = small force-matching error).

What bounds the force is on the controller, not in this loop (docs/real-rig.md, "Safety"): every approach from the
stand-off runs in the controller's force mode, compliant along the press direction with the press speed as its speed
limit and a force set-point just above the threshold (``press.setpoint_margin_n``). In free air that is a constant-
speed approach; in contact the controller itself regulates the force toward the set-point, so a host that freezes
mid-press (GC, a slow disk) cannot push past it, and a host that dies stops the program through the RTDE watchdog.
The host ends the press when the mean of the last ``press.stop_samples`` wrist readings reaches the threshold.

On top of that, this loop checks every period: |F| on all axes and |T| against the hard limits, travel beyond first
contact (a soft object fails the press instead of being crushed), the travel budget (no contact at all: the object is
missing or misplaced), protective stops, the tactile stream, and gaps in the controller clock (recorded as
``host_stall`` events). Position moves never end closer to the object than the stand-off (``object.standoff_mm``,
at least ``limits.min_standoff_mm``); every waypoint is checked against the workspace box and the arm's reach before
the first one is sent; transit moves are asynchronous and stop when the wrist feels something. The wrist F/T is
zeroed at the stand-off, at rest, after settling, after checking that nothing touches the pad.

Every path out stops the arm (``drivers.motion`` and the ``finally`` blocks here), Ctrl-C included, and whatever
was recorded is kept.

Why one module of ~640 lines: one press's phases (transit, zero, tare, approach, contact, dwell, retract) share one
stream record, and keeping them together keeps every exit path next to the stop it must call.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, cast

import numpy as np

from drivers.arm import Arm, ArmState
from drivers.errors import ControlScriptStopped, DeviceError, DeviceTimeout, ProtectiveStop, RobotStateLost
from drivers.frames import TactileFrame
from drivers.motion import (
    DEFAULT_SETTLE_S,
    check_controller,
    force_limits,
    force_magnitude,
    guarded_move,
    move_to,
    press_frame,
    stop_arm,
    wait_until_at_rest,
)
from drivers.sensor import TactileSensor
from unitac_rig.errors import SafetyLimit, with_press_record
from unitac_rig.interrupts import raise_if_interrupted
from unitac_rig.rig.config import LimitsConfig, PressConfig
from unitac_rig.rig.poses import approach_direction, pose_from, press_force_n, press_rotation, tool_z
from unitac_rig.storage.press_record import PressRecord, press_id

log = logging.getLogger(__name__)

UNLOADED_FORCE_N = 3.0  # mean wrist force (since the last zero) below which the pad counts as unloaded, N
# The window whose mean decides "unloaded" before a zero: 25 readings at 500 Hz. A UR's wrist F/T noise is ~1.15 N
# white before its ~20 Hz filter, so the mean of 25 readings is off by ~0.23 N (1 sigma): 13 sigma below
# UNLOADED_FORCE_N. The window after the zero (run_press's settle_s, 0.2 s) sets the host offset and the press-force
# noise behind the contact threshold: the readings are correlated over ~8 ms, so a 0.1 s window misjudges the noise by
# up to 40 % and a fast approach then stops on noise (measured on the fast twin); it stays 0.2 s.
UNLOADED_CHECK_S = 0.05
ZEROED_FORCE_N = 2.5  # mean |F| right after zeroing must be below this, else the zero did not take, N (a zero
# taken from one filtered sample is off by its noise, ~0.5 N per axis on a UR; 2.5 N is ~4.5 sigma of that)
# First contact is declared at max(contact_force_n, CONTACT_NOISE_SIGMAS x the press-force noise measured at the
# stand-off). A UR's wrist F/T has ~0.5 N of noise per 500 Hz sample even after its filter, so a fixed 1 N trigger
# fires on noise millimetres before the pad touches (every fast approach did on the simulated rig).
CONTACT_NOISE_SIGMAS = 4.5
# Force ramp anti-windup: the set-point may lead the measured press force (mean of the last RAMP_MEAN_PERIODS
# control periods) by at most this, N. Without it a set-point ramping while nothing pushes back drives the
# admittance loop to its speed limit and the pad hits the object with the set-point already near the threshold.
RAMP_MAX_LEAD_N = 3.0
RAMP_MEAN_PERIODS = 10
PRESS_EXTRA_S = 5.0  # a press phase may last its travel budget at its speed plus this long, then it fails (timeout)
RETRACT_UNLOADED_N = 0.3  # the retract ends once the mean press force of the last RETRACT_HOLD_PERIODS is below this
RETRACT_HOLD_PERIODS = 10  # ... (20 ms at 500 Hz) and none of them is above UNLOADED_FORCE_N, and 1 mm is gained
TRANSIT_ACCEL_M_S2 = 0.5
HARD_LIMIT_CLEARANCE_N = 0.1  # force set-points sent to the controller stay at least this far under the hard limit
HOST_GAP_EVENT_S = 0.02  # controller-clock gaps between two reads longer than this are recorded (host stall)
ON_PLANE_M = 0.001  # the arm counts as on the press plane within 1 mm of its height
ON_RAY_DEG = 3.0  # ... and on a press ray within 3 degrees of it
ARC_STEP_DEG = 30.0  # crossings at the clearance radius are split into steps of at most this (chords stay outside)
SHOULDER_HEIGHT_M = 0.1625  # UR5e base-to-shoulder height: the reach sphere's centre is (0, 0, this) [UR5e datasheet]


class ZeroedArm:
    """An :class:`Arm` whose force readings have a host-side offset removed (the mean over an unloaded window)."""

    def __init__(self, arm: Arm, offset: np.ndarray) -> None:
        self._arm = arm
        self.offset = np.asarray(offset, dtype=np.float64)

    def read_state(self) -> ArmState:
        state = self._arm.read_state()
        return replace(state, tcp_force=np.asarray(state.tcp_force, dtype=np.float64) - self.offset)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._arm, name)


@dataclass(frozen=True)
class PressPlan:
    """Where one press starts and which way it goes (base frame)."""

    rotation_deg: float
    angle_deg: float
    start_pose: np.ndarray  # (6,) stand-off pose: where position moves end and the wrist F/T is zeroed
    direction: np.ndarray  # (3,) unit press direction
    contact_distance_m: float  # expected travel from the stand-off to first contact
    center_xy_m: tuple[float, float] = (0.0, 0.0)  # the object axis the press aims at (base frame)

    @property
    def press_id(self) -> str:
        return press_id(self.rotation_deg, self.angle_deg)


def make_plan(
    rotation_deg: float,
    angle_deg: float,
    center_m: tuple[float, float],
    press_height_m: float,
    support_distance_mm: float,
    standoff_mm: float,
) -> PressPlan:
    """Stand-off pose on the ray at ``angle_deg``; ``support_distance_mm``: how far the object reaches to the pad."""
    u = approach_direction(angle_deg)
    distance_m = (support_distance_mm + standoff_mm) / 1000.0
    position = np.array([center_m[0], center_m[1], press_height_m]) + u * distance_m
    direction = -u
    return PressPlan(
        rotation_deg=rotation_deg,
        angle_deg=angle_deg,
        start_pose=pose_from(position, press_rotation(direction)),
        direction=direction,
        contact_distance_m=standoff_mm / 1000.0,
        center_xy_m=(float(center_m[0]), float(center_m[1])),
    )


def with_standoff(plan: PressPlan, standoff_mm: float) -> PressPlan:
    """The same press with its stand-off pose moved along its ray to ``standoff_mm`` from the expected surface
    (the session's smaller stand-off once the object's placement is confirmed)."""
    shift_m = plan.contact_distance_m - standoff_mm / 1000.0
    position = np.asarray(plan.start_pose[:3], dtype=np.float64) + np.asarray(plan.direction) * shift_m
    start_pose = np.concatenate([position, np.asarray(plan.start_pose[3:], dtype=np.float64)])
    return replace(plan, start_pose=start_pose, contact_distance_m=standoff_mm / 1000.0)


def clearance_waypoints(here: np.ndarray, plan: PressPlan, clearance_m: float) -> list[np.ndarray]:
    """The poses (6,) to move through from ``here`` to ``plan.start_pose`` without sweeping the pad through the
    object; the last one is the stand-off pose.

    Unless the arm is already on the plan's ray at the press height, it first backs out horizontally (at its own
    height and orientation) to ``clearance_m`` from the object axis, crosses at that radius and the press height in
    steps of at most ``ARC_STEP_DEG`` (a straight chord between two far-apart points on the circle would cut in
    toward the object), and comes in along the new ray.
    """
    here = np.asarray(here, dtype=np.float64)
    target = np.asarray(plan.start_pose, dtype=np.float64)
    center = np.asarray(plan.center_xy_m, dtype=np.float64)
    outward = -np.asarray(plan.direction, dtype=np.float64)[:2]
    outward /= np.linalg.norm(outward)
    offset = here[:2] - center  # horizontal only: the height is not part of the distance from the axis
    radial = float(np.linalg.norm(offset))
    on_plane = abs(here[2] - target[2]) < ON_PLANE_M
    on_ray = radial > 1e-6 and float(np.dot(offset / radial, outward)) > math.cos(math.radians(ON_RAY_DEG))
    if on_plane and on_ray:
        return [target]
    waypoints = []
    out_xy = offset / radial if radial > 1e-6 else outward
    if radial < clearance_m:
        waypoints.append(np.concatenate([center + out_xy * clearance_m, [here[2]], here[3:]]))
    start_angle = math.atan2(out_xy[1], out_xy[0])
    turn = math.remainder(math.atan2(outward[1], outward[0]) - start_angle, 2 * math.pi)
    steps = max(1, math.ceil(abs(math.degrees(turn)) / ARC_STEP_DEG))
    for k in range(1, steps + 1):
        a = start_angle + turn * k / steps
        xy = center + clearance_m * np.array([math.cos(a), math.sin(a)])
        waypoints.append(np.concatenate([xy, [target[2]], target[3:]]))
    waypoints.append(target)
    return waypoints


def check_waypoint(pose: np.ndarray, limits: LimitsConfig, what: str) -> None:
    """Refuse a pose outside the workspace box or beyond the arm's reach (SafetyLimit naming the pose)."""
    lo, hi = np.asarray(limits.workspace_min_m), np.asarray(limits.workspace_max_m)
    p = np.asarray(pose[:3], dtype=np.float64)
    if not np.all(np.isfinite(p)) or np.any(p < lo) or np.any(p > hi):
        raise SafetyLimit(
            f"{what} {np.round(p, 4).tolist()} m is outside the workspace box {lo.tolist()}..{hi.tolist()}",
            hint="check [object] center_m / press_height_m and [limits] workspace in the rig file",
        )
    reach = float(np.linalg.norm(p - np.array([0.0, 0.0, SHOULDER_HEIGHT_M])))
    if reach > limits.max_reach_m:
        raise SafetyLimit(
            f"{what} {np.round(p, 4).tolist()} m is {reach:.3f} m from the shoulder, beyond the reach "
            f"limit {limits.max_reach_m} m",
            hint="move the object closer to the robot ([object] center_m) or check limits.max_reach_m",
        )


def transit_guard(arm: Arm, limits: LimitsConfig) -> Callable[[ArmState], None]:
    """An ``on_period`` for transit moves: stop with SafetyLimit when the wrist force grows by more than
    ``limits.move_force_n`` (N; the torque by that over 10 cm, N*m) over where the move started: the pad hit something.

    Growth, not any change: a move that starts with the pad still loaded (a session resumed after Ctrl-C stopped it
    mid-press) unloads on its way out, and that must not read as a collision.
    """
    start = np.asarray(arm.read_state().tcp_force, dtype=np.float64)
    start_force, start_torque = float(np.linalg.norm(start[:3])), float(np.linalg.norm(start[3:]))

    def guard(state: ArmState) -> None:
        raise_if_interrupted()
        wrench = np.asarray(state.tcp_force, dtype=np.float64)
        force, torque = float(np.linalg.norm(wrench[:3])), float(np.linalg.norm(wrench[3:]))
        if force - start_force > limits.move_force_n or torque - start_torque > 0.1 * limits.move_force_n:
            raise SafetyLimit(
                f"the wrist felt {force:.1f} N / {torque:.2f} N*m during a transit move at "
                f"{np.round(np.asarray(state.tcp_pose[:3]), 4).tolist()} m: the pad touched something",
                hint="check that nothing is in the way and that [object] center_m matches where the object stands",
            )

    return guard


def standoff_radius_m(plan: PressPlan) -> float:
    """Horizontal distance (m) of the plan's stand-off pose from the object's axis."""
    return float(np.linalg.norm(np.asarray(plan.start_pose[:2]) - np.asarray(plan.center_xy_m)))


def near_speed_m_s(limits: LimitsConfig, transit_speed_m_s: float) -> float:
    """Speed (m/s) of moves toward the object inside the near zone: ``limits.near_speed_mm_s``, never faster than
    the transit speed."""
    return min(transit_speed_m_s, limits.near_speed_mm_s / 1000.0)


def approach_legs(
    here: np.ndarray, waypoints: list[np.ndarray], plan: PressPlan, limits: LimitsConfig, transit_speed_m_s: float
) -> list[tuple[np.ndarray, float]]:
    """Each waypoint with the speed (m/s) to reach it: ``limits.near_speed_mm_s`` for any stretch that comes closer to
    the object's axis inside the near zone (the stand-off radius plus ``limits.near_zone_mm``, where a misplaced
    object may stand), the transit speed elsewhere. A segment that enters the zone is split where it enters.

    Why: a position move is bounded on the controller only by the RTDE watchdog. If the host freezes the moment
    the pad meets an object that is not where the rig file says, the move runs on for one watchdog period; at the
    near speed that is at most ``near_speed x (1 / watchdog_hz)`` of travel into it (docs/real-rig.md has the
    numbers). Moves away from the object keep the transit speed: they cannot drive into it.
    """
    center = np.asarray(plan.center_xy_m, dtype=np.float64)
    near_radius = standoff_radius_m(plan) + limits.near_zone_mm / 1000.0
    near_speed = near_speed_m_s(limits, transit_speed_m_s)
    legs: list[tuple[np.ndarray, float]] = []
    start = np.asarray(here, dtype=np.float64)
    for pose in waypoints:
        end = np.asarray(pose, dtype=np.float64)
        a, d = start[:2] - center, end[:2] - start[:2]
        dd = float(d @ d)
        t_min = float(np.clip(-(a @ d) / dd, 0.0, 1.0)) if dd > 1e-18 else 0.0
        r_start, r_min = float(np.linalg.norm(a)), float(np.linalg.norm(a + t_min * d))
        if r_min >= r_start - 1e-9 or r_min >= near_radius:
            legs.append((end, transit_speed_m_s))  # receding, or never inside the zone
        elif r_start <= near_radius:
            legs.append((end, near_speed))
        else:  # enters the zone on the way: split where |a + t d| = near_radius (the root before t_min)
            b, c = float(a @ d), float(a @ a) - near_radius**2
            t_in = (-b - math.sqrt(max(b * b - dd * c, 0.0))) / dd
            entry = np.concatenate([start[:3] + t_in * (end[:3] - start[:3]), end[3:]])
            legs += [(entry, transit_speed_m_s), (end, near_speed)]
        start = end
    return legs


def move_clear(arm: Arm, plan: PressPlan, clearance_m: float, speed_m_s: float, limits: LimitsConfig) -> None:
    """Move to ``plan.start_pose`` through :func:`clearance_waypoints`, each checked before the first is sent, each
    move asynchronous, at the speeds of :func:`approach_legs`, and stopped if the wrist feels something
    (:func:`transit_guard`)."""
    here = np.asarray(arm.read_state().tcp_pose, dtype=np.float64)
    waypoints = clearance_waypoints(here, plan, clearance_m)
    for k, pose in enumerate(waypoints):
        what = "stand-off pose" if k == len(waypoints) - 1 else "clearance waypoint"
        check_waypoint(pose, limits, f"{what} of press {plan.press_id}")
    for pose, speed in approach_legs(here, waypoints, plan, limits, speed_m_s):
        move_to(arm, pose, speed, TRANSIT_ACCEL_M_S2, on_period=transit_guard(arm, limits))


def retract_waypoint(plan: PressPlan, clearance_m: float) -> np.ndarray:
    """Where a retract after an abort on the plan's ray ends: the ray at the clearance radius, stand-off height."""
    outward = -np.asarray(plan.direction, dtype=np.float64)
    position = np.array([*plan.center_xy_m, plan.start_pose[2]]) + outward * clearance_m
    return np.concatenate([position, np.asarray(plan.start_pose[3:], dtype=np.float64)])


def check_session_plan(here: np.ndarray, plans: list[PressPlan], clearance_m: float, limits: LimitsConfig) -> int:
    """Check every waypoint of a whole session before its first motion: the first move from ``here``, every
    clearance waypoint and stand-off of every press and rotation, and where each press's retract would end.
    Straight moves between checked points stay inside (the workspace box and the reach sphere are convex).
    Raises SafetyLimit naming the first waypoint outside; -> the number of waypoints checked."""
    pose, checked = np.asarray(here, dtype=np.float64), 0
    for index, plan in enumerate(plans):
        waypoints = clearance_waypoints(pose, plan, clearance_m)
        named = [("clearance waypoint", p) for p in waypoints[:-1]] + [("stand-off pose", waypoints[-1])]
        named.append(("retract waypoint", retract_waypoint(plan, clearance_m)))
        for what, waypoint in named:
            check_waypoint(waypoint, limits, f"session plan (press {index + 1} of {len(plans)}): the {what} of press "
                                             f"{plan.press_id}")  # fmt: skip
            checked += 1
        pose = plan.start_pose
    return checked


def retract_from_object(
    arm: Arm,
    plan: PressPlan,
    limits: LimitsConfig,
    *,
    standoff_m: float,
    clearance_m: float,
    transit_speed_m_s: float,
    to_clearance: bool = True,
) -> list[np.ndarray]:
    """After an abort: pull the pad off whatever it touches, from wherever the arm IS, never toward a pose that was
    not reached; -> the poses moved to.

    1. Back along the pad's own axis (away from what it presses) to the plan's stand-off radius, and at least
       ``standoff_m`` when the wrist reads loaded (an object closer than the rig file says), at the near speed;
    2. (``to_clearance``) out horizontally, radially from the object's axis, to ``clearance_m`` at the transit speed.

    Both legs are force-guarded (:func:`transit_guard`: the force may fall, not grow) and clipped to the workspace
    box and reach (a leg that would leave them ends at their edge). The next press then starts with a fresh,
    checked move (:func:`move_clear`). Raises what the moves raise (SafetyLimit when the guard trips, the arm
    stopped).
    """
    state = arm.read_state()
    here = np.asarray(state.tcp_pose, dtype=np.float64)
    center = np.asarray(plan.center_xy_m, dtype=np.float64)
    radius = float(np.linalg.norm(here[:2] - center))
    loaded = float(np.linalg.norm(np.asarray(state.tcp_force, dtype=np.float64)[:3])) > UNLOADED_FORCE_N
    back_m = max(standoff_radius_m(plan) - radius, 0.0)
    if loaded:
        back_m = max(back_m, standoff_m)
    moved: list[np.ndarray] = []
    near_speed = near_speed_m_s(limits, transit_speed_m_s)
    if back_m > 2e-4:
        target = np.concatenate([here[:3] - tool_z(here) * back_m, here[3:]])
        here = _move_within_limits(arm, here, target, near_speed, limits, moved)
    radius = float(np.linalg.norm(here[:2] - center))
    if to_clearance and radius < clearance_m - 2e-4:
        outward = (here[:2] - center) / radius if radius > 1e-6 else -np.asarray(plan.direction)[:2]
        target = np.concatenate([center + outward * clearance_m, here[2:]])
        _move_within_limits(arm, here, target, transit_speed_m_s, limits, moved)
    return moved


def _move_within_limits(
    arm: Arm, here: np.ndarray, target: np.ndarray, speed_m_s: float, limits: LimitsConfig, moved: list[np.ndarray]
) -> np.ndarray:
    """A guarded move toward ``target``, shortened to the last point inside the workspace and reach; -> the end."""
    fraction = _inside_fraction(here, target, limits)
    end = np.concatenate([here[:3] + fraction * (target[:3] - here[:3]), target[3:]])
    if float(np.linalg.norm(end[:3] - here[:3])) < 2e-4:
        log.warning("a retract toward %s would leave the workspace at once: not moving", np.round(target[:3], 4))
        return here
    if fraction < 1.0:
        log.warning("a retract is shortened to %.0f %% to stay inside the workspace", 100 * fraction)
    move_to(arm, end, speed_m_s, TRANSIT_ACCEL_M_S2, on_period=transit_guard(arm, limits))
    moved.append(end)
    return end


def _inside_fraction(start: np.ndarray, end: np.ndarray, limits: LimitsConfig, steps: int = 64) -> float:
    """The largest fraction t of the segment start -> end (positions) whose points are all inside the workspace box
    and reach (both convex, so the inside part of the segment is one interval starting at ``start`` if ``start`` is
    inside); 0 when ``start`` itself is outside."""

    def inside(t: float) -> bool:
        p = start[:3] + t * (end[:3] - start[:3])
        try:
            check_waypoint(np.concatenate([p, end[3:]]), limits, "retract")
        except SafetyLimit:
            return False
        return True

    if inside(1.0):
        return 1.0
    if not inside(0.0):
        return 0.0
    lo, hi = 0.0, 1.0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if inside(mid) else (lo, mid)
    return lo


@dataclass
class TickInfo:
    """What the live panel shows, handed to ``on_tick`` once per control period."""

    press_id: str
    phase: str
    press_force_n: float
    latest_frame: TactileFrame | None


class _TravelLimit(Exception):
    """Raised inside the control loop when the pad went too far past first contact."""


@dataclass
class _Streams:
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
                raise _TravelLimit(f"{travel_mm:.1f} mm past first contact below {self.press.threshold_n} N")
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


def settle_frames(arm: Arm, sensor: TactileSensor, seconds: float) -> tuple[list[TactileFrame], np.ndarray]:
    """Wait ``seconds`` at rest; returns the frames seen and the mean wrench (6,) over the window (N, N*m).

    The mean, not the largest sample: a UR's F/T has ~1 N of sample noise, while a real contact shifts the mean.
    """
    frames, wrenches = _settle_window(arm, sensor, seconds)
    return frames, wrenches.mean(axis=0)


def _settle_window(arm: Arm, sensor: TactileSensor, seconds: float) -> tuple[list[TactileFrame], np.ndarray]:
    """Wait ``seconds`` at rest; -> (frames seen, every wrench read (K, 6) in N, N*m)."""
    sensor.poll()  # drop anything queued during the transit move
    frames: list[TactileFrame] = []
    forces = []
    for _ in range(max(1, round(seconds / arm.control_period_s))):
        arm.wait_period()
        forces.append(np.asarray(arm.read_state().tcp_force, dtype=np.float64))
        frames.extend(sensor.poll())
    return frames, np.asarray(forces)


def zero_wrist(
    arm: Arm,
    sensor: TactileSensor,
    settle_s: float,
    where: str,
    *,
    check_unloaded: bool = True,
    check_s: float | None = None,
) -> tuple[list[TactileFrame], np.ndarray]:
    """Zero the wrist F/T at rest after settling, refusing when the pad is loaded; -> (frames of both windows,
    wrenches (K, 6) of the ``settle_s`` window after the zero, whose mean is the host-side offset left over: a zero
    from one noisy sample is off). ``check_s``: the window before the zero (None: ``settle_s``).

    The unloaded check uses the mean force since the previous zero (a UR's F/T drifts by well under
    ``UNLOADED_FORCE_N`` between presses), so the session's first zero (``check_unloaded=False``) relies on the
    stand-off being clear of the object by construction. After zeroing, the window's mean must be near zero.
    """
    wait_until_at_rest(arm)
    before, mean_wrench = settle_frames(arm, sensor, settle_s if check_s is None else check_s)
    mean_force = float(np.linalg.norm(mean_wrench[:3]))
    if check_unloaded and mean_force > UNLOADED_FORCE_N:
        raise SafetyLimit(
            f"wrist reads {mean_force:.2f} N at {where}: the pad is touching something, refusing to zero the F/T",
            hint="check the object's position (object.center_m) and the stand-off in the rig file",
        )
    arm.zero_ft()
    frames, wrenches = _settle_window(arm, sensor, settle_s)
    left = float(np.linalg.norm(wrenches[:, :3].mean(axis=0)))
    if left > ZEROED_FORCE_N:
        raise SafetyLimit(
            f"wrist still reads {left:.2f} N after zeroing at {where}: the F/T zero did not take",
            hint="check the wrist force with `unitac-rig probe ur5e` and the payload set on the teach pendant",
        )
    return before + frames, wrenches


def run_press(
    arm: Arm,
    sensor: TactileSensor,
    plan: PressPlan,
    press: PressConfig,
    limits: LimitsConfig,
    *,
    on_tick: Callable[[TickInfo], None] | None = None,
    stall_timeout_s: float = 0.5,
    settle_s: float = 0.2,
    clearance_m: float = 0.09,
) -> PressRecord:
    """Do one press and return everything recorded (status complete, failed or aborted); the arm ends at rest at the
    stand-off.

    Raises SafetyLimit (hard force limit), ProtectiveStop, ControlScriptStopped, RobotStateLost and KeyboardInterrupt
    *after* stopping the arm, carrying the partial record in ``exc.press_record`` so the caller can keep it (Ctrl-C
    comes back as :class:`unitac_rig.errors.Interrupted`, a KeyboardInterrupt that carries it). A press that never
    touches anything ends ``aborted`` with reason ``no_contact`` (it is redone on resume, once the object is where it
    should be).
    """
    move_clear(arm, plan, clearance_m, press.transit_speed_mm_s / 1000.0, limits)
    frames, wrenches = zero_wrist(arm, sensor, settle_s, f"the stand-off of press {plan.press_id}",
                                  check_s=UNLOADED_CHECK_S)  # fmt: skip
    ft_offset = wrenches.mean(axis=0)
    arm = cast(Arm, ZeroedArm(arm, ft_offset))
    noise_n = float(np.std(-(wrenches[:, :3] @ plan.direction)))
    contact_threshold_n = max(press.contact_force_n, CONTACT_NOISE_SIGMAS * noise_n)
    if not frames:
        raise DeviceTimeout(f"{sensor.layout.name} sent no frames while settling before press {plan.press_id}")
    valid = [f for f in frames if f.valid] or frames
    stack = np.stack([f.values for f in valid]).astype(np.float64)
    # the median, not the mean: one frame damaged on the wire (a corrupt SLCAN line) must not shift the baseline
    baseline = np.median(stack, axis=0)
    tare = {"method": "host-median", "n_frames": len(valid), "spread": float(stack.std(axis=0).max())}

    streams = _Streams(arm, sensor, plan, press, limits, stall_timeout_s, on_tick, contact_threshold_n,
                       offset_along_press_n=float(np.dot(ft_offset[:3], plan.direction)))  # fmt: skip
    streams.event("start", f"strategy={press.strategy} speed={press.speed_mm_s} mm/s")
    streams.event("contact_threshold", f"{contact_threshold_n:.2f} N (press-force noise {noise_n:.3f} N rms)")
    streams.event("ft_zero", json_list(ft_offset))
    streams.event("tare", f"{tare['n_frames']} frames, spread {tare['spread']:.3g}")
    status, reason = "aborted", "interrupted"
    pending: BaseException | None = None
    try:
        reason = _press_strategy(arm, streams, plan, press, limits)
        status = "complete" if reason == "force" else ("aborted" if reason == "no_contact" else "failed")
        streams.event("stop", reason)
        streams.phase = "dwell"
        streams.hold(press.dwell_s)
        streams.phase = "retract"
        _retract(arm, streams, plan, press)
    except _TravelLimit as exc:
        status, reason = "failed", "travel"
        streams.event("stop", f"travel limit: {exc}")
        stop_arm(arm)
        _retract_quietly(arm, streams, plan, press)
    except (SafetyLimit, ProtectiveStop, DeviceError, KeyboardInterrupt) as exc:
        status, reason, pending = "aborted", _abort_reason(exc), exc
        detail = "interrupted by the operator" if isinstance(exc, KeyboardInterrupt) else f"{reason}: {exc}"
        streams.event("abort", detail)
        if not isinstance(exc, ProtectiveStop | ControlScriptStopped):  # the controller has already stopped the arm
            stop_arm(arm)
    if pending is None:
        try:  # back out to the stand-off, so the next transit starts clear of the object
            streams.phase = "return"
            here = np.asarray(arm.read_state().tcp_pose, dtype=np.float64)
            for pose, speed in approach_legs(here, [plan.start_pose], plan, limits, press.transit_speed_mm_s / 1000.0):
                move_to(arm, pose, speed, TRANSIT_ACCEL_M_S2, on_period=streams.recording(transit_guard(arm, limits)))
        except BaseException as exc:
            pending = exc
    record = _to_record(streams, plan, press, status, reason, baseline, tare, ft_offset)
    if pending is not None:
        raise with_press_record(pending, record)  # the same exception (or Ctrl-C as Interrupted, caused by it)
    return record


# Why a press was aborted, by exception type; the first match wins (RobotStateLost and DeviceTimeout are
# DeviceErrors, RobotStateLost is also a DeviceTimeout).
_ABORT_REASONS: tuple[tuple[type[BaseException], str], ...] = (
    (SafetyLimit, "hard_limit"),
    (ProtectiveStop, "protective_stop"),
    (ControlScriptStopped, "program_stopped"),
    (RobotStateLost, "robot_state_lost"),
    (DeviceTimeout, "stall"),
    (DeviceError, "device_error"),
    (KeyboardInterrupt, "interrupted"),
)


def _abort_reason(exc: BaseException) -> str:
    return next(reason for kind, reason in _ABORT_REASONS if isinstance(exc, kind))


def json_list(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.4f}" for v in np.asarray(values).ravel()) + "]"


def _press_strategy(arm: Arm, streams: _Streams, plan: PressPlan, press: PressConfig, limits: LimitsConfig) -> str:
    """Run the configured strategy; returns the stop reason ("force", "travel", "no_contact")."""
    backstop_m = plan.contact_distance_m + (limits.max_travel_after_contact_mm + 5.0) / 1000.0
    # in the controller's zero (see _Streams), and kept under the hard limit whatever the residual offset
    below_limit_n = limits.hard_force_n - HARD_LIMIT_CLEARANCE_N
    setpoint_n = min(press.threshold_n + press.setpoint_margin_n - streams.offset_along_press_n, below_limit_n)
    ceiling_n = max(setpoint_n, min(setpoint_ceiling_n(press, limits) - streams.offset_along_press_n, below_limit_n))
    arm.set_force_mode_parameters(press.force_mode_damping, press.force_mode_gain_scaling)
    bounds: dict[str, Any] = {
        "hard_limit_n": limits.hard_force_n,
        "hard_torque_nm": limits.hard_torque_nm,
        "on_period": streams.tick,
        "force_setpoint_n": setpoint_n,
        "setpoint_ceiling_n": ceiling_n,
    }
    # The dwell that follows the stop reads on at rest, so the stop itself need not wait for the lagging F/T.
    stop_settle_s = 0.0 if press.dwell_s >= DEFAULT_SETTLE_S else DEFAULT_SETTLE_S
    if press.strategy == "guarded":
        streams.phase = "press"
        result = guarded_move(arm, plan.direction, press.speed_mm_s / 1000.0, press.threshold_n,
                              max_travel_m=backstop_m, stop_samples=press.stop_samples,
                              max_duration_s=backstop_m / (press.speed_mm_s / 1000.0) + PRESS_EXTRA_S,
                              settle_s=stop_settle_s, **bounds)  # fmt: skip
        return _reason(result.reason, streams)
    # two-phase and force-ramp: fast to first contact (one reading over the contact threshold: a false alarm only
    # makes the rest of the approach slow). Two-phase goes on to its slow speed limit without stopping in between.
    streams.phase = "approach"
    result = guarded_move(arm, plan.direction, press.fast_speed_mm_s / 1000.0, streams.contact_threshold_n,
                          max_travel_m=backstop_m,
                          max_duration_s=backstop_m / (press.fast_speed_mm_s / 1000.0) + PRESS_EXTRA_S,
                          keep_moving=press.strategy == "two-phase", **bounds)  # fmt: skip
    if result.reason != "force":
        return _reason(result.reason, streams)
    streams.phase = "press"
    if press.strategy == "two-phase":
        # the rest of the travel budget (a false first-contact alarm far out must still reach the object)
        budget_m = max(backstop_m - result.travel_m, (limits.max_travel_after_contact_mm + 1.0) / 1000.0)
        result = guarded_move(arm, plan.direction, press.speed_mm_s / 1000.0, press.threshold_n,
                              max_travel_m=budget_m, stop_samples=press.stop_samples,
                              max_duration_s=budget_m / (press.speed_mm_s / 1000.0) + PRESS_EXTRA_S,
                              settle_s=stop_settle_s, **bounds)  # fmt: skip
        return _reason(result.reason, streams)
    return _force_ramp(arm, streams, plan, press)


def setpoint_ceiling_n(press: PressConfig, limits: LimitsConfig) -> float:
    """How high a settled press may raise the force set-point (N): threshold + ``setpoint_ceiling_margin_n``, but
    never past halfway from the first set-point to the hard limit (a tight hard limit keeps its margin)."""
    first = press.threshold_n + press.setpoint_margin_n
    return min(press.threshold_n + press.setpoint_ceiling_margin_n, max(first, 0.5 * (first + limits.hard_force_n)))


def _reason(guarded_reason: str, streams: _Streams) -> str:
    if guarded_reason == "hard_limit":
        raise SafetyLimit("the wrist force or torque passed the hard limit")
    if guarded_reason == "protective_stop":
        raise ProtectiveStop("the controller reported a protective stop")
    if guarded_reason == "travel" and streams.contact_pose is None:
        return "no_contact"
    return guarded_reason


def _force_ramp(arm: Arm, streams: _Streams, plan: PressPlan, press: PressConfig) -> str:
    """Force control along the press with a set-point rising at ``ramp_rate_n_s`` until the threshold is measured.

    The set-point is rate-limited from the force at the start, never leads the measured press force (mean of the
    last ``RAMP_MEAN_PERIODS`` readings) by more than ``RAMP_MAX_LEAD_N`` (while nothing pushes back the pad creeps
    at gain x lead instead of winding up to the speed limit), and never exceeds threshold + ``setpoint_margin_n``: the
    force a stalled host leaves the controller regulating toward.
    """
    task_frame = press_frame(np.asarray(streams.arm.read_state().tcp_pose[:3]), plan.direction)
    selection = np.array([0, 0, 1, 0, 0, 0], dtype=np.float64)
    limits = force_limits(press.speed_mm_s / 1000.0 * 4)
    ceiling = press.threshold_n + press.setpoint_margin_n
    setpoint = streams.press_force[-1] if streams.press_force else press.contact_force_n
    step_n = press.ramp_rate_n_s * arm.control_period_s
    max_periods = math.ceil((press.threshold_n / press.ramp_rate_n_s + 5.0) / arm.control_period_s)
    try:
        for _ in range(max_periods):
            measured = float(np.mean(streams.press_force[-RAMP_MEAN_PERIODS:])) if streams.press_force else 0.0
            setpoint = min(setpoint + step_n, measured + RAMP_MAX_LEAD_N, ceiling)
            target = setpoint - streams.offset_along_press_n  # in the controller's zero (see _Streams)
            arm.force_mode(task_frame, selection, np.array([0, 0, target, 0, 0, 0.0]), limits)
            arm.wait_period()
            state = arm.read_state()
            streams.tick(state)
            if state.protective_stop:
                raise ProtectiveStop("protective stop during force control")
            if float(np.mean(streams.press_force[-press.stop_samples :])) >= press.threshold_n:
                return "force"
        return "travel"
    finally:
        stop_arm(arm)


def _retract(arm: Arm, streams: _Streams, plan: PressPlan, press: PressConfig) -> None:
    """Back off along the ray at ``press.retract_speed_mm_s``, still recording, until the pad is unloaded (a held,
    filtered condition: the mean of the last ``RETRACT_HOLD_PERIODS`` readings, not one noisy sample) and 1 mm back;
    then stop recording."""
    speed = min(press.transit_speed_mm_s, press.retract_speed_mm_s) / 1000.0
    twist = np.concatenate([-plan.direction * speed, np.zeros(3)])
    start = np.asarray(arm.read_state().tcp_pose[:3])
    try:
        for _ in range(round(5.0 / arm.control_period_s)):
            arm.speed_linear(twist, 0.5)
            arm.wait_period()
            state = arm.read_state()
            streams.tick(state)
            back_mm = 1000.0 * float(np.dot(start - state.tcp_pose[:3], plan.direction))
            recent = streams.press_force[-RETRACT_HOLD_PERIODS:]
            if (
                back_mm > 1.0
                and len(recent) == RETRACT_HOLD_PERIODS
                and float(np.mean(recent)) < RETRACT_UNLOADED_N
                and max(recent) < UNLOADED_FORCE_N
            ):
                break
    finally:
        stop_arm(arm)
    streams.hold(0.02)


def contact_travel_mm(contact_pose: np.ndarray | None, plan: PressPlan) -> float:
    """Travel (mm) from the stand-off to where the press first felt the object (NaN: never): the stand-off distance
    when the object stands where the rig file says."""
    if contact_pose is None:
        return math.nan
    return 1000.0 * float(np.dot(np.asarray(contact_pose[:3]) - np.asarray(plan.start_pose[:3]), plan.direction))


def _retract_quietly(arm: Arm, streams: _Streams, plan: PressPlan, press: PressConfig) -> None:
    streams.phase = "retract"
    try:
        _retract(arm, streams, plan, press)
    except (_TravelLimit, SafetyLimit, DeviceTimeout):
        stop_arm(arm)


def _to_record(
    streams: _Streams,
    plan: PressPlan,
    press: PressConfig,
    status: str,
    reason: str,
    baseline: np.ndarray,
    tare: dict[str, Any],
    ft_offset: np.ndarray,
) -> PressRecord:
    frames = streams.frames
    layout = streams.sensor.layout
    n = len(frames)
    values = np.stack([f.values for f in frames]).astype(np.float32) if n else np.zeros((0, *layout.frame_shape))
    disp = None
    if layout.has_displacement:
        disp = np.zeros((n, *layout.frame_shape), np.float32)
        for i, f in enumerate(frames):
            if f.displacement_mm is not None:
                disp[i] = f.displacement_mm
    pf = np.asarray(streams.press_force)
    peak = float(pf.max()) if pf.size else 0.0
    t = np.asarray(streams.robot_t)
    return PressRecord(
        press_id=plan.press_id,
        rotation_deg=plan.rotation_deg,
        angle_deg=plan.angle_deg,
        status=status,
        reason=reason,
        robot_t_s=t,
        robot_force=np.asarray(streams.robot_force).reshape(-1, 6),
        robot_pose=np.asarray(streams.robot_pose).reshape(-1, 6),
        press_force_n=pf,
        tactile_t_s=np.array([f.host_t_ns / 1e9 for f in frames]),
        tactile_values=values,
        tactile_seq=np.array([-1 if f.seq is None else f.seq for f in frames], dtype=np.int64),
        tactile_device_t_us=np.array([-1 if f.device_t_us is None else f.device_t_us for f in frames], np.int64),
        tactile_valid=np.array([f.valid for f in frames], dtype=bool),
        tactile_displacement_mm=disp,
        tare_baseline=baseline,
        events=streams.events,
        attrs={
            "strategy": press.strategy,
            "speed_mm_s": press.speed_mm_s,
            "fast_speed_mm_s": press.fast_speed_mm_s,
            "ramp_rate_n_s": press.ramp_rate_n_s,
            "threshold_n": press.threshold_n,
            "force_setpoint_n": press.threshold_n + press.setpoint_margin_n,
            "stop_samples": press.stop_samples,
            "contact_threshold_n": streams.contact_threshold_n,
            "peak_force_n": peak,
            "overshoot_n": peak - press.threshold_n,
            "max_host_gap_s": streams.max_gap_s,
            "duration_s": float(t[-1] - t[0]) if t.size else 0.0,
            "ft_zero_offset": ft_offset.tolist(),
            "tare": tare,
            "contact_travel_mm": contact_travel_mm(streams.contact_pose, plan),
            "standoff_mm": 1000.0 * plan.contact_distance_m,  # where first contact was expected, mm
            "start_pose": np.asarray(plan.start_pose).tolist(),
            "direction": np.asarray(plan.direction).tolist(),
        },
    )
