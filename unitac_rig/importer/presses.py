"""From one UniTac-NV recording to this project's presses: conventions, segmentation, windows, angles, duplicates.

The axis and grid mapping is docs/import.md's ("Axes and grid"). One press = one run of their segmentation rule,
widened backwards to the start of its loading ramp (their -5 N threshold alone would cut the 4..5 N targets) and
forwards by a short unloading margin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.layouts import SensorLayout
from unitac_rig.importer.conventions import AUTHORS_PROCESSED_STEPS, ImportConventions, TactileMapping
from unitac_rig.importer.parsing import ProcessedArrays, RawColumns
from unitac_rig.storage.extraction import extract_press
from unitac_rig.storage.press_record import PressRecord, press_id


@dataclass
class Streams:
    """One recording in our units and axes, ready to cut into presses (one row per tactile sample)."""

    t_s: np.ndarray  # (N,) s since the first kept sample
    rows: np.ndarray  # (N,) where each sample came from: CSV data-row number or .npz index
    seq: np.ndarray  # (N,) int64, -1 where unknown
    values: np.ndarray  # (N, n_taxels, 3) raw in the layout's units (processed files: already tared)
    displacement_mm: np.ndarray | None  # (N, n_taxels, 3) PapillArray only
    ft: np.ndarray  # (N, 6) N, N*m after the F/T rotation
    pose: np.ndarray  # (N, 6) m, rad
    tare_baseline: np.ndarray  # (n_taxels, 3)
    displacement_tare_mm: np.ndarray | None
    tare_method: str
    authors_selected: np.ndarray | None = None  # processed files: the authors' peak index per press
    authors_angle: np.ndarray | None = None  # processed files: the authors' angle per press, degrees

    @property
    def press_force_n(self) -> np.ndarray:
        """Force along the press, N: -Fz, positive while pressing."""
        return -self.ft[:, 2]


def rotate_ft(ft: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rotate Fx, Fy and Mx, My by ``angle_deg`` about z (Fz, Mz unchanged)."""
    ft = np.array(ft, dtype=np.float64, copy=True)
    if angle_deg == 0:
        return ft
    theta = np.deg2rad(angle_deg)
    c, s = np.cos(theta), np.sin(theta)
    for ix, iy in ((0, 1), (3, 4)):
        x, y = ft[:, ix].copy(), ft[:, iy].copy()
        ft[:, ix] = x * c - y * s
        ft[:, iy] = x * s + y * c
    return ft


def to_our_frame(matrices: np.ndarray, mapping: TactileMapping) -> np.ndarray:
    """``(N, rows, cols, 3)`` in their harmonised axes -> ``(N, rows*cols, 3)`` in ours (see the module docstring)."""
    grid = np.asarray(matrices, dtype=np.float64)
    if mapping.flip_rows:
        grid = grid[:, ::-1]
    if mapping.flip_cols:
        grid = grid[:, :, ::-1]
    grid = grid * np.asarray(mapping.axis_signs, dtype=np.float64)
    return np.ascontiguousarray(grid.reshape(grid.shape[0], -1, 3))


def _tactile(
    force: np.ndarray, disp: np.ndarray | None, layout: SensorLayout, conv: ImportConventions, flip_xy: bool
) -> tuple[np.ndarray, np.ndarray | None]:
    """Their force and displacement matrices in our frame: PapillArray x/y negated when ``flip_xy``, then the
    sensor's :class:`TactileMapping`; the displacement only for a layout that has one."""
    sign = np.array([-1.0, -1.0, 1.0]) if flip_xy and layout.name == "papillarray" else np.ones(3)
    mapping = conv.tactile_mapping[layout.name]
    values = to_our_frame(np.asarray(force, dtype=np.float64) * sign, mapping)
    if disp is None or not layout.has_displacement:
        return values, None
    return values, to_our_frame(np.asarray(disp, dtype=np.float64) * sign, mapping)


def streams_from_raw(raw: RawColumns, layout: SensorLayout, conv: ImportConventions) -> Streams:
    """Apply the authors' preprocessing rules (as conventions) to a raw CSV's columns; raw values stay raw.

    Raises ValueError when fewer samples than the baseline needs remain after dropping the first rows.
    """
    keep = raw.rows >= conv.drop_first_rows
    if int(keep.sum()) < conv.baseline_samples:
        raise ValueError(
            f"only {int(keep.sum())} usable samples after dropping the first {conv.drop_first_rows} rows; "
            f"the baseline needs {conv.baseline_samples}"
        )
    disp = raw.displacement[keep] if raw.displacement is not None else None
    values, displacement = _tactile(raw.force[keep], disp, layout, conv, conv.papillarray_flip_xy)
    t = raw.time_s[keep]
    n_base = conv.baseline_samples
    return Streams(
        t_s=t - t[0],
        rows=raw.rows[keep],
        seq=raw.seq[keep],
        values=values,
        displacement_mm=displacement,
        ft=rotate_ft(raw.ft[keep], conv.ft_rotation_deg),
        pose=raw.pose[keep],
        tare_baseline=values[:n_base].mean(axis=0),
        displacement_tare_mm=displacement[:n_base].mean(axis=0) if displacement is not None else None,
        tare_method=f"mean of the first {n_base} samples after dropping {conv.drop_first_rows} rows (authors' rule)",
    )


def streams_from_processed(arrays: ProcessedArrays, layout: SensorLayout, conv: ImportConventions) -> Streams:
    """A processed file: the authors already dropped rows, subtracted the baseline, rotated the F/T and flipped the
    PapillArray; only the difference to our conventions is applied here, and the tare is zero."""
    flip = conv.papillarray_flip_xy != AUTHORS_PROCESSED_STEPS["papillarray_flip_xy"]
    values, displacement = _tactile(arrays.force, arrays.displacement, layout, conv, flip)
    n = values.shape[0]
    return Streams(
        t_s=arrays.time_s,
        rows=np.arange(n, dtype=np.int64),
        seq=np.full(n, -1, np.int64),
        values=values,
        displacement_mm=displacement,
        ft=rotate_ft(arrays.ft, conv.ft_rotation_deg - float(AUTHORS_PROCESSED_STEPS["ft_rotation_deg"])),
        pose=arrays.pose,
        tare_baseline=np.zeros((layout.n_taxels, 3)),
        displacement_tare_mm=np.zeros((layout.n_taxels, 3)) if displacement is not None else None,
        tare_method="already subtracted by the authors' script (mean of their first 100 samples); tare is zero",
        authors_selected=arrays.selected,
        authors_angle=arrays.angle,
    )


# ---------------------------------------------------------------------------------------------------------------------
# segmentation


@dataclass(frozen=True)
class Run:
    """A contiguous run of samples inside the press band: ``[start, stop)``; ``peak`` = most negative Fz in it."""

    start: int
    stop: int
    peak: int


def segment_presses(fz_n: np.ndarray, band_n: tuple[float, float], min_samples: int) -> list[Run]:
    """The authors' rule: runs with ``low < Fz < high`` (strict) of at least ``min_samples`` samples; peak = first
    index of the minimum Fz in the run."""
    fz = np.asarray(fz_n, dtype=np.float64)
    inside = (fz > band_n[0]) & (fz < band_n[1])
    if not inside.any():
        return []
    edges = np.diff(np.concatenate([[0], inside.astype(np.int8), [0]]))
    starts = np.nonzero(edges == 1)[0]
    stops = np.nonzero(edges == -1)[0]
    return [
        Run(int(start), int(stop), int(start + np.argmin(fz[start:stop])))
        for start, stop in zip(starts, stops, strict=True)
        if stop - start >= min_samples
    ]


def press_window(
    t_s: np.ndarray,
    press_force_n: np.ndarray,
    run: Run,
    earliest: int,
    latest: int,
    conv: ImportConventions,
) -> tuple[int, int, bool]:
    """Sample range ``[lo, hi)`` of one press and whether the ramp start (force <= ramp_start_n) was found.

    The window reaches back from the run to the last sample whose press force is at most ``ramp_start_n``, no
    further than ``max_pre_margin_s`` and not before ``earliest``; it ends ``post_margin_s`` after the run, not at or
    after ``latest``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    force = np.asarray(press_force_n, dtype=np.float64)
    reach = int(np.searchsorted(t, t[run.start] - conv.max_pre_margin_s, side="left"))
    lo_limit = max(earliest, reach, 0)
    quiet = np.nonzero(force[lo_limit : run.start] <= conv.ramp_start_n)[0]
    found = quiet.size > 0
    lo = lo_limit + int(quiet[-1]) if found else lo_limit
    end_t = t[run.stop - 1] + conv.post_margin_s
    hi = int(np.searchsorted(t, end_t, side="right"))
    hi = max(run.stop, min(hi, latest))
    return lo, hi, found


def approach_angle_deg(x_m: float, y_m: float, conv: ImportConventions) -> float:
    """The authors' approach angle (unrounded), degrees: atan2(y - cy, x - cx) + offset."""
    cx, cy = conv.object_centre_m
    return float(np.degrees(np.arctan2(y_m - cy, x_m - cx)) + conv.angle_offset_deg)


def nominal_angle_deg(raw_angle_deg: float) -> int:
    """Rounded like the authors' Python ``round``: to the nearest integer, ties to even."""
    return int(np.round(raw_angle_deg))


# ---------------------------------------------------------------------------------------------------------------------
# presses


@dataclass
class PressCandidate:
    """A press cut out of a recording, with what duplicate resolution and reporting need."""

    record: PressRecord
    run: Run
    window: tuple[int, int]
    raw_angle_deg: float
    peak_force_n: float

    @property
    def press_id(self) -> str:
        return self.record.press_id

    def describe(self, rows: np.ndarray) -> str:
        a, b = self.window
        return (
            f"{self.press_id} (rows {int(rows[a])}-{int(rows[b - 1])}, peak {self.peak_force_n:.2f} N, "
            f"angle {self.raw_angle_deg:+.2f} deg, {self.record.status})"
        )


def build_presses(
    streams: Streams,
    layout: SensorLayout,
    rotation_deg: float,
    conv: ImportConventions,
    source_attrs: dict[str, object],
) -> list[PressCandidate]:
    """Segment ``streams`` with the authors' rule and turn each run into a PressRecord with its extraction."""
    force = streams.press_force_n
    runs = segment_presses(streams.ft[:, 2], conv.press_fz_band_n, conv.min_press_samples[layout.name])
    settings = conv.extraction.to_settings()
    out = []
    for k, run in enumerate(runs):
        earliest = runs[k - 1].stop if k > 0 else 0
        latest = runs[k + 1].start if k + 1 < len(runs) else streams.t_s.size
        lo, hi, ramp_found = press_window(streams.t_s, force, run, earliest, latest, conv)
        t = streams.t_s[lo:hi]
        raw_angle = approach_angle_deg(streams.pose[run.peak, 0], streams.pose[run.peak, 1], conv)
        angle = nominal_angle_deg(raw_angle)
        peak_force = float(force[run.peak])
        if np.any(np.diff(t) < 0):
            status, reason = "failed", "time_not_increasing"
        elif peak_force >= conv.complete_peak_n:
            status, reason = "complete", "force"
        else:
            status, reason = "failed", "peak_below_threshold"
        valid = np.ones(t.size, bool)
        extraction = extract_press(t, force[lo:hi], t, valid, settings) if reason != "time_not_increasing" else None
        attrs: dict[str, object] = dict(source_attrs)
        attrs.update(
            {
                "source_rows": [int(streams.rows[lo]), int(streams.rows[hi - 1])],
                "peak_row": int(streams.rows[run.peak]),
                "band_samples": run.stop - run.start,
                "raw_angle_deg": raw_angle,
                "peak_force_n": peak_force,
                "threshold_n": conv.complete_peak_n,
                "overshoot_n": peak_force - conv.complete_peak_n,
                "duration_s": float(t[-1] - t[0]),
                "ramp_start_found": ramp_found,
                "tare_method": streams.tare_method,
            }
        )
        if streams.displacement_tare_mm is not None:
            attrs["displacement_tare_mm"] = streams.displacement_tare_mm.tolist()
        events = [
            (float(streams.t_s[run.start]), "band_enter", f"Fz < {conv.press_fz_band_n[1]:g} N"),
            (float(streams.t_s[run.peak]), "peak", f"{peak_force:.2f} N"),
            (float(streams.t_s[run.stop - 1]), "band_exit", ""),
        ]
        record = PressRecord(
            press_id=press_id(rotation_deg, angle),
            rotation_deg=rotation_deg,
            angle_deg=float(angle),
            status=status,
            reason=reason,
            robot_t_s=t,
            robot_force=streams.ft[lo:hi],
            robot_pose=streams.pose[lo:hi],
            press_force_n=force[lo:hi],
            tactile_t_s=t,
            tactile_values=streams.values[lo:hi],
            tactile_seq=streams.seq[lo:hi],
            tactile_device_t_us=np.full(t.size, -1, np.int64),
            tactile_valid=valid,
            tare_baseline=streams.tare_baseline,
            tactile_displacement_mm=streams.displacement_mm[lo:hi] if streams.displacement_mm is not None else None,
            events=events,
            attrs=attrs,
            extraction=extraction,
        )
        out.append(PressCandidate(record, run, (lo, hi), raw_angle, peak_force))
    return out


def resolve_duplicates(candidates: list[PressCandidate]) -> tuple[list[PressCandidate], list[PressCandidate]]:
    """Keep one press per (rotation, angle): the one closest to the nominal pattern.

    Preference: a complete press over a failed one, then the smallest distance between its measured angle and the
    nominal 1-degree angle, then the earlier press. Returns ``(kept in time order, dropped)``.
    """
    by_id: dict[str, list[PressCandidate]] = {}
    for cand in candidates:
        by_id.setdefault(cand.press_id, []).append(cand)
    kept, dropped = [], []
    for group in by_id.values():
        ranked = sorted(
            group,
            key=lambda c: (
                c.record.status != "complete",
                abs(c.raw_angle_deg - c.record.angle_deg),
                c.run.start,
            ),
        )
        kept.append(ranked[0])
        dropped.extend(ranked[1:])
    kept.sort(key=lambda c: c.run.start)
    dropped.sort(key=lambda c: c.run.start)
    return kept, dropped
