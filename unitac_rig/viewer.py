"""``unitac-rig view``: a recorded session, or a live sensor, in the Rerun viewer (the viewer LeRobot's own dataset
visualiser uses). Needs the ``view`` extra (``pip install "unitac-rig[view]"``, rerun-sdk).

Entities, on the ``host_time`` timeline (seconds of the rig host's clock, the one both streams were stamped with):

* ``tactile/<sensor>/frame``: each tactile frame, tare-subtracted, as a ``rows x cols x 3`` tensor (taxel grid,
  channels x, y, z) in the sensor's units; ``tactile/<sensor>/z``: the normal channel as a ``rows x cols`` image;
* ``arm/force/{fx,fy,fz}`` and ``arm/press_force_n``: the wrist force (N, base axes, after the press's F/T zero);
* ``arm/pad``: the pad's pose (the TCP's translation and rotation in the base frame) as a 3-D transform;
* ``tactile/<sensor>/matched``: at each force-matched frame, the target force it was matched to (N);
* ``press``: a text line at each press's first frame (press id, status, reason).

Arm samples go in with ``send_columns`` (one call per press and entity), frames one by one.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.errors import UsageError

TIMELINE = "host_time"


def _rerun() -> Any:
    try:
        import rerun
    except ImportError as exc:
        raise UsageError("unitac-rig view needs the Rerun SDK", hint='pip install "unitac-rig[view]"') from exc
    return rerun


def _grid(sensor: str, n_taxels: int) -> tuple[int, int]:
    from unitac_rig.rig.sensors import SENSORS

    spec = SENSORS.get(sensor)
    return (spec.layout.rows, spec.layout.cols) if spec is not None else (n_taxels, 1)


def log_frame(rec: Any, sensor: str, t_s: float, tared: np.ndarray) -> None:
    """One tare-subtracted frame (n_taxels, 3) at host time ``t_s``."""
    rr = _rerun()
    rows, cols = _grid(sensor, tared.shape[0])
    grid = np.asarray(tared, np.float32).reshape(rows, cols, 3)
    rec.set_time(TIMELINE, duration=float(t_s))
    rec.log(f"tactile/{sensor}/frame", rr.Tensor(grid, dim_names=["row", "col", "channel_xyz"]))
    rec.log(f"tactile/{sensor}/z", rr.Image(np.ascontiguousarray(grid[:, :, 2])))


def log_session(rec: Any, session: Path) -> dict[str, int]:
    """Every press of ``session`` into ``rec``; returns what was logged (presses, frames, arm samples, matched)."""
    from unitac_rig.storage.reader import read_presses, read_session_info
    from unitac_rig.storage.rosbag import quaternions

    rr = _rerun()
    sensor = read_session_info(session).sensor
    counts = {"presses": 0, "frames": 0, "arm_samples": 0, "matched": 0}
    for press in read_presses(session):
        t = np.asarray(press.tactile_t_s, np.float64)
        tared = np.asarray(press.tactile_values, np.float32) - np.asarray(press.tare_baseline, np.float32)[None]
        if t.size:
            rec.set_time(TIMELINE, duration=float(t[0]))
            rec.log("press", rr.TextLog(f"{press.press_id}: {press.status} ({press.reason})"))
        for k in range(t.size):
            log_frame(rec, sensor, float(t[k]), tared[k])
        robot_t = np.asarray(press.robot_t_s, np.float64)
        if robot_t.size:
            times = [rr.TimeColumn(TIMELINE, duration=robot_t)]
            force = np.asarray(press.robot_force, np.float64).reshape(-1, 6)
            for i, axis in enumerate(("fx", "fy", "fz")):
                rec.send_columns(f"arm/force/{axis}", indexes=times, columns=rr.Scalars.columns(scalars=force[:, i]))
            press_force = np.asarray(press.press_force_n, np.float64)
            rec.send_columns("arm/press_force_n", indexes=times, columns=rr.Scalars.columns(scalars=press_force))
            pose = np.asarray(press.robot_pose, np.float64).reshape(-1, 6)
            pad = rr.Transform3D.columns(translation=pose[:, :3], quaternion=quaternions(pose[:, 3:]))
            rec.send_columns("arm/pad", indexes=times, columns=pad)
        ex = press.extraction
        if ex is not None:
            hit = np.flatnonzero(~np.asarray(ex.miss, bool) & (np.asarray(ex.frame_index) >= 0))
            if hit.size:
                when = t[np.asarray(ex.frame_index, np.int64)[hit]]
                targets = rr.Scalars.columns(scalars=np.asarray(ex.targets_n, np.float64)[hit])
                rec.send_columns(
                    f"tactile/{sensor}/matched", indexes=[rr.TimeColumn(TIMELINE, duration=when)], columns=targets
                )
            counts["matched"] += int(hit.size)
        counts["presses"] += 1
        counts["frames"] += int(t.size)
        counts["arm_samples"] += int(robot_t.size)
    return counts


def log_stream(
    rec: Any,
    sensor_name: str,
    driver: Any,
    *,
    tare_frames: int,
    max_frames: int | None,
    duration_s: float | None,
    should_stop: Callable[[], bool],
) -> int:
    """Live frames of ``driver`` (``poll_wait``), tared on the first ``tare_frames`` (median), until ``max_frames``
    were logged, ``duration_s`` passed or ``should_stop()``; returns the frames logged."""
    import time

    tare: list[np.ndarray] = []
    baseline: np.ndarray | None = None
    logged = 0
    deadline = None if duration_s is None else time.monotonic() + duration_s
    while not should_stop() and (max_frames is None or logged < max_frames):
        if deadline is not None and time.monotonic() >= deadline:
            break
        for frame in driver.poll_wait(0.1):
            if baseline is None:
                if frame.valid:
                    tare.append(np.asarray(frame.values, np.float32))
                if len(tare) >= tare_frames:
                    baseline = np.median(np.stack(tare), axis=0).astype(np.float32)
                continue
            if max_frames is not None and logged >= max_frames:
                break
            log_frame(rec, sensor_name, frame.host_t_ns / 1e9, np.asarray(frame.values, np.float32) - baseline)
            logged += 1
    return logged
