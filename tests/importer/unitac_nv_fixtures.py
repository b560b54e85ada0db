"""Builders of small files in exactly the UniTac-NV formats, with values simple enough to work out by hand.

A recording is sampled every 10 ms. The press force f (N, = -Fz) is 0 while quiet; a press ramps it up in 0.1 N
steps (f = k / 10 at sample k of the press) to its peak, back down linearly over 50 samples, then rests 100 samples.

Tactile model (their axes, before any convention):

* uSkin raw counts at taxel (r, c), axis k: ``32000 + 100 r + 10 c + k`` plus ``(100 + 10 (6 r + c)) f`` on z,
  ``5 f`` on x and ``-5 f`` on y; rows 0..9 carry an extra +500 (junk the import must drop), rows from
  ``QUIET + 10`` on an extra +7 (drift after the baseline window);
* PapillArray N at pillar (r, c): ``0.01 (3 r + c)`` on every axis plus ``f / 9`` on z, ``0.02 f`` on x and
  ``0.01 f`` on y; displacement mm = force / 6.

Wrist F/T (their frame): ``[0.1 f, 0, -f, 0, 0.02 f, 0]``. Pose: ``x = -0.15 + 0.1 sin(a)``, ``y = 0.625 - 0.1 cos(a)``
for a press at angle ``a`` (so their angle formula gives back ``a``), z = 0.2, rotation vector (0, 3.14, 0).
"""

from __future__ import annotations

import csv
import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np

QUIET = 120  # samples before the first press (10 dropped + 100 baseline + 10)
PERIOD_S = 0.01
T0 = dt.datetime(2025, 2, 3, 15, 44, 24)
USKIN_GRID = (4, 6)
PAPILLARRAY_GRID = (3, 3)


@dataclass(frozen=True)
class Press:
    angle_deg: float
    peak_n: float = 10.5


def force_profile(presses: list[Press], rest: int = 100) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Press force per sample (N), the angle per sample (deg) and each press's peak sample index."""
    force = [np.zeros(QUIET)]
    angle = [np.full(QUIET, presses[0].angle_deg if presses else 0.0)]
    peaks = []
    at = QUIET
    for press in presses:
        steps = round(press.peak_n * 10)
        up = np.arange(steps + 1) / 10.0
        down = np.linspace(press.peak_n, 0.0, 51)[1:]
        segment = np.concatenate([up, down, np.zeros(rest)])
        peaks.append(at + steps)
        at += segment.size
        force.append(segment)
        angle.append(np.full(segment.size, press.angle_deg))
    return np.concatenate(force), np.concatenate(angle), peaks


def uskin_counts(force: np.ndarray) -> np.ndarray:
    n = force.size
    r, c = np.meshgrid(np.arange(4), np.arange(6), indexing="ij")
    base = 32000.0 + 100 * r[..., None] + 10 * c[..., None] + np.arange(3)
    out = np.broadcast_to(base, (n, 4, 6, 3)).copy()
    out[..., 2] += (100.0 + 10 * (6 * r + c)) * force[:, None, None]
    out[..., 0] += 5.0 * force[:, None, None]
    out[..., 1] -= 5.0 * force[:, None, None]
    out[:10] += 500.0
    out[QUIET - 10 :] += 7.0
    return out


def papillarray_newtons(force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = force.size
    r, c = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    base = np.repeat((0.01 * (3 * r + c))[..., None], 3, axis=2)
    out = np.broadcast_to(base, (n, 3, 3, 3)).copy()
    out[..., 2] += force[:, None, None] / 9.0
    out[..., 0] += 0.02 * force[:, None, None]
    out[..., 1] += 0.01 * force[:, None, None]
    return out, out / 6.0


def ft_and_pose(force: np.ndarray, angle_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    zero = np.zeros_like(force)
    ft = np.stack([0.1 * force, zero, -force, zero, 0.02 * force, zero], axis=1)
    a = np.radians(angle_deg)
    pose = np.stack(
        [-0.15 + 0.1 * np.sin(a), 0.625 - 0.1 * np.cos(a), np.full_like(a, 0.2), zero, zero + 3.14, zero], axis=1
    )
    return ft, pose


def recording(sensor: str, presses: list[Press]) -> dict[str, np.ndarray]:
    """All columns of a synthetic session in their raw units and axes."""
    force, angle, peaks = force_profile(presses)
    if sensor == "uskin":
        matrices = uskin_counts(force)
        displacement = np.zeros_like(matrices)
    else:
        matrices, displacement = papillarray_newtons(force)
    ft, pose = ft_and_pose(force, angle)
    return {
        "force_n": force,
        "matrices": matrices,
        "displacement": displacement,
        "ft": ft,
        "pose": pose,
        "peaks": np.asarray(peaks),
    }


def time_strings(n: int) -> list[str]:
    return [(T0 + dt.timedelta(microseconds=10_000 * i)).strftime("%Y-%m-%d %H:%M:%S.%f") for i in range(n)]


def write_raw_csv(path: Path, sensor: str, presses: list[Press]) -> dict[str, np.ndarray]:
    """Write a raw session CSV the way the authors' recorder did (stringified nested lists)."""
    rec = recording(sensor, presses)
    path.parent.mkdir(parents=True, exist_ok=True)
    n = rec["force_n"].size
    times = time_strings(n)
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["Time", "Seq", "Force", "Displacement", "FT", "EE Pose"])
        for i in range(n):
            writer.writerow(
                [
                    times[i],
                    1000 + i,
                    str(rec["matrices"][i].tolist()),
                    str(rec["displacement"][i].tolist()),
                    str(rec["ft"][i].tolist()),
                    str(rec["pose"][i].tolist()),
                ]
            )
    return rec


def write_processed_npz(path: Path, sensor: str, presses: list[Press]) -> dict[str, np.ndarray]:
    """Write a processed file as their script would: drop 10 rows, rotate F/T 45 deg, flip PapillArray x/y,
    subtract the mean of the first 100 samples, zero the time, one peak index and angle per press."""
    rec = recording(sensor, presses)
    keep = slice(10, None)
    matrices = rec["matrices"][keep].copy()
    displacement = rec["displacement"][keep].copy()
    if sensor == "papillarray":
        matrices[..., :2] *= -1
        displacement[..., :2] *= -1
    matrices -= matrices[:100].mean(axis=0)
    displacement -= displacement[:100].mean(axis=0)
    ft = rec["ft"][keep].copy()
    h = np.sqrt(0.5)
    fx, fy, mx, my = ft[:, 0].copy(), ft[:, 1].copy(), ft[:, 3].copy(), ft[:, 4].copy()
    ft[:, 0], ft[:, 1] = fx * h - fy * h, fy * h + fx * h
    ft[:, 3], ft[:, 4] = mx * h - my * h, my * h + mx * h
    n = matrices.shape[0]
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(
        path,
        times=np.arange(n) * PERIOD_S,
        sensor_matrices_force=matrices,
        sensor_matrices_displacement=displacement,
        ft_values=ft,
        end_effector_poses=rec["pose"][keep],
        selected=rec["peaks"] - 10,
        angle=np.asarray([round(p.angle_deg) for p in presses], np.int64),
    )
    return rec
