"""Never zero a loaded wrist (docs/real-rig.md, "Safety" item 8, has the measurements and the reasoning).

``zeroFtSensor`` under load makes the load read as zero, and the press then adds its threshold on top. So the zero
(:func:`zero_wrist`) is refused on a loaded pad, against two references kept here: the session's **last unloaded
zero** (the wrench read right after a zero that was checked unloaded, written next to the journal so a resume after
``kill -9`` has it), and a **back-off probe** (:func:`unload_wrist`) that needs no zero: a translation changes only the
contact part of a wrist reading, so the arm backs along the pad's axis in guarded steps until a step changes nothing.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.arm import Arm
from drivers.frames import TactileFrame
from drivers.sensor import TactileSensor
from unitac_rig.collection.guarded_motion import wait_until_at_rest
from unitac_rig.collection.transit import UNLOADED_FORCE_N, move_within_limits
from unitac_rig.errors import SafetyLimit
from unitac_rig.rig.config import LimitsConfig
from unitac_rig.rig.poses import tool_z

log = logging.getLogger(__name__)

ZERO_FILE = "_wrist_zero.json"  # in the session's journal directory: the last unloaded zero's reading
UNLOAD_STEP_MM = 3.0  # each back-off step, mm
UNLOAD_MAX_MM = 45.0  # give up (refuse) when the reading still falls after this much back-off, mm
UNLOAD_WINDOW_S = 0.1  # the mean wrench is read over this window at rest, s
# A step that changes the mean |F| by less than this found the pad free, N: two 0.1 s means of a UR's filtered reading
# differ by ~0.17 N (1 sigma), so 0.5 N is ~3 sigma; a contact softer than 0.17 N/mm would go unseen.
PROBE_CHANGE_N = 0.5
UNLOAD_SPEED_MM_S = 10.0  # back-off speed (away from the object: the near speed's default), mm/s

# The window whose mean decides "unloaded" before a zero: 25 readings at 500 Hz. A UR's wrist F/T noise is ~1.15 N
# white before its ~20 Hz filter, so the mean of 25 readings is off by ~0.23 N (1 sigma): 13 sigma below
# UNLOADED_FORCE_N. The window after the zero (run_press's settle_s, 0.2 s) sets the host offset and the press-force
# noise behind the contact threshold: the readings are correlated over ~8 ms, so a 0.1 s window misjudges the noise by
# up to 40 % and a fast approach then stops on noise (measured on the fast twin); it stays 0.2 s.
UNLOADED_CHECK_S = 0.05
ZEROED_FORCE_N = 2.5  # mean |F| right after zeroing must be below this, else the zero did not take, N (a zero
# taken from one filtered sample is off by its noise, ~0.5 N per axis on a UR; 2.5 N is ~4.5 sigma of that)


def read_zero(journal: Path) -> np.ndarray | None:
    """The remembered unloaded reading (6,) [N, N*m], None when the session has none (or it cannot be read)."""
    try:
        data = json.loads((Path(journal) / ZERO_FILE).read_text())
        wrench = np.asarray(data["wrench"], dtype=np.float64)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return wrench if wrench.shape == (6,) and np.all(np.isfinite(wrench)) else None


def write_zero(journal: Path, wrench: np.ndarray) -> None:
    """Remember ``wrench`` (6,) as the session's last unloaded reading (atomic replace; best effort: a full disk must
    not stop a session, the back-off probe does not need it)."""
    path = Path(journal) / ZERO_FILE
    tmp = path.with_suffix(".tmp")
    try:
        tmp.write_text(json.dumps({"wrench": [float(v) for v in np.asarray(wrench).ravel()]}))
        os.replace(tmp, path)
    except OSError as exc:
        log.warning("cannot remember the wrist's unloaded zero in %s: %s", path, exc)
        with contextlib.suppress(OSError):
            tmp.unlink()


def settle_window(arm: Arm, sensor: TactileSensor | None, seconds: float) -> tuple[list[TactileFrame], np.ndarray]:
    """Wait ``seconds`` at rest one control period at a time; -> (the sensor's frames seen, every wrench read
    (K, 6) in N, N*m)."""
    if sensor is not None:
        sensor.poll()  # drop anything queued during the transit move
    frames: list[TactileFrame] = []
    forces = []
    for _ in range(max(1, round(seconds / arm.control_period_s))):
        arm.wait_period()
        forces.append(np.asarray(arm.read_state().tcp_force, dtype=np.float64))
        if sensor is not None:
            frames.extend(sensor.poll())
    return frames, np.asarray(forces)


def rest(arm: Arm, sensor: TactileSensor, seconds: float) -> None:
    """Stand still for ``seconds`` (the rig file's ``press.rest_s``; 0: not at all), one control period at a time as
    :func:`settle_window` waits; the frames seen meanwhile are not kept."""
    if seconds > 0:
        settle_window(arm, sensor, seconds)


def zero_wrist(
    arm: Arm,
    sensor: TactileSensor,
    settle_s: float,
    where: str,
    *,
    check_s: float | None = None,
    reference: np.ndarray | None = None,
) -> tuple[list[TactileFrame], np.ndarray]:
    """Zero the wrist F/T at rest after settling, refusing when the pad is loaded; -> (frames of both windows,
    wrenches (K, 6) of the ``settle_s`` window after the zero, whose mean is the host-side offset left over: a zero
    from one noisy sample is off). ``check_s``: the window before the zero (None: ``settle_s``).

    The unloaded check compares the mean wrench with ``reference`` (6,), an unloaded reading (the session's first
    zero passes the free reading its back-off found, collection/wrist.py); without one, with the controller's zero,
    which the last zero set on an unloaded pad (a UR's F/T drifts by well under ``UNLOADED_FORCE_N`` between
    presses). There is no way to skip it: a zero under load is what pressed a resumed pad to 28-30 N. After zeroing,
    the window's mean must be near zero.
    """
    wait_until_at_rest(arm)
    before, wrenches = settle_window(arm, sensor, settle_s if check_s is None else check_s)
    # the mean, not the largest sample: a UR's F/T has ~1 N of sample noise, while a real contact shifts the mean
    mean_force = force_n(wrenches.mean(axis=0), reference)
    if mean_force > UNLOADED_FORCE_N:
        raise SafetyLimit(
            f"wrist reads {mean_force:.2f} N at {where}: the pad is touching something, refusing to zero the F/T",
            hint="check the object's position (object.center_m) and the stand-off in the rig file",
        )
    arm.zero_ft()
    frames, wrenches = settle_window(arm, sensor, settle_s)
    left = force_n(wrenches.mean(axis=0))
    if left > ZEROED_FORCE_N:
        raise SafetyLimit(
            f"wrist still reads {left:.2f} N after zeroing at {where}: the F/T zero did not take",
            hint="check the wrist force with `unitac-rig probe ur5e` and the payload set on the teach pendant",
        )
    return before + frames, wrenches


def force_n(wrench: np.ndarray, reference: np.ndarray | None = None) -> float:
    """|F| (N) of ``wrench`` minus ``reference`` (6,) (an unloaded reading; None: the controller's zero)."""
    w = np.asarray(wrench, dtype=np.float64)[:3]
    if reference is not None:
        w = w - np.asarray(reference, dtype=np.float64)[:3]
    return float(np.linalg.norm(w))


@dataclass(frozen=True)
class Unloaded:
    """What the back-off found: the load the pad was under (N, how much |F| fell), how far it backed (mm), the
    reading at the free pose (6,)."""

    load_n: float
    backed_mm: float
    free_reading: np.ndarray

    @property
    def was_loaded(self) -> bool:
        return self.load_n > PROBE_CHANGE_N

    def describe(self) -> str:
        return (
            f"the pad was loaded with {self.load_n:.1f} N at the start (the wrist reading fell that much while the arm "
            f"backed {self.backed_mm:.0f} mm along the pad's axis); unloaded before zeroing the wrist"
        )


def unload_wrist(arm: Arm, limits: LimitsConfig, *, zero: np.ndarray | None = None) -> Unloaded:
    """Back the pad off along its axis until a step changes nothing (see the module docstring); -> what it found.

    Raises SafetyLimit (one line with the measured load) when the reading still falls after ``UNLOAD_MAX_MM``, or
    when the arm cannot back off (the workspace edge) while the remembered zero says the pad is loaded.
    """
    wait_until_at_rest(arm)
    first = settle_window(arm, None, UNLOAD_WINDOW_S)[1].mean(axis=0)
    off_zero = math.nan if zero is None else force_n(first, zero)
    previous, backed_mm = first, 0.0
    speed = min(UNLOAD_SPEED_MM_S, limits.near_speed_mm_s) / 1000.0
    while True:
        here = np.asarray(arm.read_state().tcp_pose, dtype=np.float64)
        target = np.concatenate([here[:3] - tool_z(here) * UNLOAD_STEP_MM / 1000.0, here[3:]])
        end = move_within_limits(arm, here, target, speed, limits, [])
        step_mm = 1000.0 * float(np.linalg.norm(end[:3] - here[:3]))
        if step_mm < 0.2:  # at the workspace's edge: the remembered zero alone decides
            if not math.isnan(off_zero) and off_zero > UNLOADED_FORCE_N:
                raise SafetyLimit(
                    f"the wrist reads {off_zero:.1f} N off the last unloaded zero and the arm cannot back off along "
                    "the pad's axis (workspace edge): refusing to zero a loaded wrist",
                    hint="move the pad clear of the object (freedrive on the pendant), then run the same command",
                )
            note = "no remembered zero" if math.isnan(off_zero) else f"{off_zero:.1f} N off the remembered zero"
            log.warning("cannot back off to check the wrist is unloaded (workspace edge); %s", note)
            break
        backed_mm += step_mm
        wait_until_at_rest(arm)
        now = settle_window(arm, None, UNLOAD_WINDOW_S)[1].mean(axis=0)
        change = force_n(now, previous)
        previous = now
        if change < PROBE_CHANGE_N:
            break
        if backed_mm >= UNLOAD_MAX_MM:
            raise SafetyLimit(
                f"the pad is still loaded after backing {backed_mm:.0f} mm along its axis: the wrist reading fell by "
                f"{force_n(first, now):.1f} N and still falls ({change:.1f} N in the last step); refusing to zero it",
                hint="move the pad clear of the object (freedrive on the pendant), then run the same command",
            )
    result = Unloaded(force_n(first, previous), backed_mm, previous)
    if result.was_loaded:
        log.warning("%s", result.describe())
    elif not math.isnan(off_zero) and off_zero > UNLOADED_FORCE_N:
        log.warning(
            "the wrist reads %.1f N off the session's last unloaded zero, but backing off changes nothing: the "
            "controller's F/T zero changed (a restart or a zero from the pendant), not a load",
            off_zero,
        )
    return result


def load_left_note(arm: Arm, zero: np.ndarray | None) -> str:
    """``"; the pad is left loaded: X N on the wrist"`` (or ``"; the pad is left unloaded (X N on the wrist)"``)
    against the unloaded reading ``zero`` (6,), appended to every way out of a fault so the operator knows whether the
    pad still presses on something; empty when no zero is known or the arm cannot be read. One filtered reading: it
    works with the program stopped (nothing else can be asked then)."""
    if zero is None:
        return ""
    try:
        load = force_n(np.asarray(arm.read_state().tcp_force, dtype=np.float64), zero)
    except Exception as exc:  # the arm is gone (a lost stream): say nothing rather than mask what happened
        log.info("cannot read the load left on the pad: %s", exc)
        return ""
    if load <= UNLOADED_FORCE_N:
        return f"; the pad is left unloaded ({load:.1f} N on the wrist)"
    return f"; the pad is left loaded: {load:.1f} N on the wrist"
