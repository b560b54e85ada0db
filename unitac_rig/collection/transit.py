"""Where the pad goes between presses: each press's plan (stand-off pose and direction), the clearance waypoints
around the object, the near zone's slower legs, force-guarded transit moves, and the retract after an abort.

Position moves never end closer to the object than the stand-off (``object.standoff_mm``, at least
``limits.min_standoff_mm``); every waypoint is checked against the workspace box and the arm's reach before the first
one is sent; transit moves are asynchronous and stop when the wrist feels something. What runs from the stand-off to
the object is the press strategy's (unitac_rig/collection/strategy.py), under the checks of every press.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from drivers.arm import Arm, ArmState
from drivers.errors import ControlScriptStopped, ProtectiveStop
from unitac_rig.collection.guarded_motion import check_controller, force_magnitude, move_to
from unitac_rig.errors import SafetyLimit
from unitac_rig.interrupts import raise_if_interrupted
from unitac_rig.rig.config import LimitsConfig, RigConfig
from unitac_rig.rig.poses import approach_direction, pose_from, press_rotation, tool_z
from unitac_rig.storage.press_record import press_id

log = logging.getLogger(__name__)

UNLOADED_FORCE_N = 3.0  # mean wrist force (since the last zero) below which the pad counts as unloaded, N
TRANSIT_ACCEL_M_S2 = 0.5
ON_PLANE_M = 0.001  # the arm counts as on the press plane within 1 mm of its height
ON_RAY_DEG = 3.0  # ... and on a press ray within 3 degrees of it
ARC_STEP_DEG = 30.0  # crossings at the clearance radius are split into steps of at most this (chords stay outside)
BACKSTOP_EXTRA_MM = 5.0  # a press's travel budget from the stand-off: the contact distance + max travel + this, mm
SHOULDER_HEIGHT_M = 0.1625  # UR5e base-to-shoulder height: the reach sphere's centre is (0, 0, this) [UR5e datasheet]


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
    start_force, start_torque = force_magnitude(arm.read_state())

    def guard(state: ArmState) -> None:
        raise_if_interrupted()
        force, torque = force_magnitude(state)
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


def move_clear(arm: Arm, plan: PressPlan, clearance_m: float, speed_m_s: float, limits: LimitsConfig) -> int:
    """Move to ``plan.start_pose`` through :func:`clearance_waypoints`, each checked before the first is sent, each
    move asynchronous, at the speeds of :func:`approach_legs`, and stopped if the wrist feels something
    (:func:`transit_guard`); -> the number of waypoints."""
    here = np.asarray(arm.read_state().tcp_pose, dtype=np.float64)
    waypoints = clearance_waypoints(here, plan, clearance_m)
    for k, pose in enumerate(waypoints):
        what = "stand-off pose" if k == len(waypoints) - 1 else "clearance waypoint"
        check_waypoint(pose, limits, f"{what} of press {plan.press_id}")
    for pose, speed in approach_legs(here, waypoints, plan, limits, speed_m_s):
        move_to(arm, pose, speed, TRANSIT_ACCEL_M_S2, on_period=transit_guard(arm, limits))
    return len(waypoints)


def retract_waypoint(plan: PressPlan, clearance_m: float) -> np.ndarray:
    """Where a retract after an abort on the plan's ray ends: the ray at the clearance radius, stand-off height."""
    outward = -np.asarray(plan.direction, dtype=np.float64)
    position = np.array([*plan.center_xy_m, plan.start_pose[2]]) + outward * clearance_m
    return np.concatenate([position, np.asarray(plan.start_pose[3:], dtype=np.float64)])


def backstop_m(plan: PressPlan, limits: LimitsConfig) -> float:
    """A press's travel budget from its stand-off (m): the expected contact distance + ``limits.max_travel_after_
    contact_mm`` + ``BACKSTOP_EXTRA_MM``; the strategy's last move may go ``max_travel_after_contact_mm`` beyond."""
    return plan.contact_distance_m + (limits.max_travel_after_contact_mm + BACKSTOP_EXTRA_MM) / 1000.0


def press_travel_end(plan: PressPlan, limits: LimitsConfig) -> np.ndarray:
    """The farthest pose (6,) a press can reach from its stand-off: the backstop plus one more travel budget."""
    reach_m = backstop_m(plan, limits) + limits.max_travel_after_contact_mm / 1000.0
    position = np.asarray(plan.start_pose[:3], dtype=np.float64) + np.asarray(plan.direction) * reach_m
    return np.concatenate([position, np.asarray(plan.start_pose[3:], dtype=np.float64)])


def check_session_plan(
    here: np.ndarray,
    plans: list[PressPlan],
    clearance_m: float,
    limits: LimitsConfig,
    confirmed_standoff_mm: float | None = None,
) -> int:
    """Check every pose a session can reach before its first motion: where the arm is now (an arm outside the box
    is refused before it moves), the first move from ``here``, every clearance waypoint and stand-off of every press
    and rotation, the shorter stand-off once the placement is confirmed (``confirmed_standoff_mm``), the whole press
    travel (:func:`press_travel_end`), and where each press's retract would end. Straight moves between checked
    points stay inside (the workspace box and the reach sphere are convex). Raises SafetyLimit naming the first pose
    outside; -> the number of poses checked."""
    pose, checked = np.asarray(here, dtype=np.float64), 1
    check_waypoint(pose, limits, "the arm's start pose (where it is now, before any motion)")
    for index, plan in enumerate(plans):
        waypoints = clearance_waypoints(pose, plan, clearance_m)
        named = [("clearance waypoint", p) for p in waypoints[:-1]] + [("stand-off pose", waypoints[-1])]
        if confirmed_standoff_mm is not None:
            named.append(("confirmed stand-off pose", with_standoff(plan, confirmed_standoff_mm).start_pose))
        named.append(("press travel end", press_travel_end(plan, limits)))
        named.append(("retract waypoint", retract_waypoint(plan, clearance_m)))
        for what, waypoint in named:
            check_waypoint(
                waypoint,
                limits,
                f"session plan (press {index + 1} of {len(plans)}): the {what} of press {plan.press_id}",
            )
            checked += 1
        pose = plan.start_pose
    return checked


def retract_from_object(
    arm: Arm, plan: PressPlan, config: RigConfig, *, to_clearance: bool = True, best_effort: bool = False
) -> list[np.ndarray]:
    """After an abort: pull the pad off whatever it touches, from wherever the arm IS, never toward a pose that was
    not reached; -> the poses moved to.

    1. Back along the pad's own axis (away from what it presses) to the plan's stand-off radius, and at least
       ``object.standoff_mm`` when the wrist reads loaded (an object closer than the rig file says), at the near speed;
    2. (``to_clearance``) out horizontally, radially from the object's axis, to ``object.clearance_mm`` at the
       transit speed.

    Both legs are force-guarded (:func:`transit_guard`: the force may fall, not grow) and clipped to the workspace
    box and reach (a leg that would leave them ends at their edge). The next press then starts with a fresh,
    checked move (:func:`move_clear`). Raises what the moves raise (SafetyLimit when the guard trips, the arm
    stopped).

    ``best_effort`` (a session stopping, so it never leaves the pad loaded): not when the controller stopped on its
    own (protective stop, program stopped: the operator decides on the pendant), and a failure is logged, not raised
    (the arm is stopped by then; the next run starts with a checked move from wherever the arm is). A second Ctrl-C
    still ends it (the move stopped the arm on its way out).
    """
    if best_effort:
        try:
            check_controller(arm.read_state(), "the retract")
            return retract_from_object(arm, plan, config, to_clearance=to_clearance)
        except (ProtectiveStop, ControlScriptStopped) as exc:
            log.info("not retracting after press %s: %s", plan.press_id, exc)
        except KeyboardInterrupt:
            raise
        except Exception:
            log.exception("retracting from the object after press %s failed; the arm is stopped", plan.press_id)
        return []
    limits, transit_speed_m_s = config.limits, config.press.transit_speed_mm_s / 1000.0
    standoff_m, clearance_m = config.object.standoff_mm / 1000.0, config.object.clearance_mm / 1000.0
    state = arm.read_state()
    here = np.asarray(state.tcp_pose, dtype=np.float64)
    center = np.asarray(plan.center_xy_m, dtype=np.float64)
    radius = float(np.linalg.norm(here[:2] - center))
    loaded = force_magnitude(state)[0] > UNLOADED_FORCE_N
    back_m = max(standoff_radius_m(plan) - radius, 0.0)
    if loaded:
        back_m = max(back_m, standoff_m)
    moved: list[np.ndarray] = []
    near_speed = near_speed_m_s(limits, transit_speed_m_s)
    if back_m > 2e-4:
        target = np.concatenate([here[:3] - tool_z(here) * back_m, here[3:]])
        here = move_within_limits(arm, here, target, near_speed, limits, moved)
    radius = float(np.linalg.norm(here[:2] - center))
    if to_clearance and radius < clearance_m - 2e-4:
        outward = (here[:2] - center) / radius if radius > 1e-6 else -np.asarray(plan.direction)[:2]
        target = np.concatenate([center + outward * clearance_m, here[2:]])
        move_within_limits(arm, here, target, transit_speed_m_s, limits, moved)
    return moved


def move_within_limits(
    arm: Arm, here: np.ndarray, target: np.ndarray, speed_m_s: float, limits: LimitsConfig, moved: list[np.ndarray]
) -> np.ndarray:
    """A guarded move toward ``target``, shortened to the last point inside the workspace and reach; -> the end
    (``here`` when it cannot move at all). The end is appended to ``moved``."""
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
