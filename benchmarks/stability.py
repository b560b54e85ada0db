"""Stability where the methods fail (docs/reliability.md, which gives every number and figure).

    python benchmarks/stability.py collection [--angles 9] [--trials 40] [--out docs/figures]
    python benchmarks/stability.py learning --run RUN [--out docs/figures] [--folds 10] [--face-mm 3]

``collection`` (~2 min on the 2-core box; OUT/stability_collection.json): where the collection method stops working,
in three figures. ``stability_soft.png``: soft (TPU) and stiff (PLA) prisms pressed on the simulated rig with the
travel allowed past first contact cut from 8 mm to 0.5 mm (what fails, the peak reached, what is recorded).
``stability_ramp.png``: synthetic linear ramps (rate r, 500 Hz) and tactile frames every T s at a random phase
through the real ``extract_press``: matching error and miss rate against r*T (N per frame) beside the analytic bound
(|error| <= r*T/2, mean r*T/4, miss rate >= 1 - 2*tol/(r*T)) and the simulated rig's matched targets.
``stability_material.png``: PLA against TPU (guarded presses at 2 mm/s, both sensors): matching error, overshoot past
10 N, travel past first contact.

``learning`` (OUT/stability_learning.json and stability_learning_{corners,materials,seeds}.png): where a trained
run's representation fails. 1. Per outline feature of the unseen object (default: the run's; the irregular prism's
corners of 80..160 deg): each test contact goes to the corner vertex within ``face_distance_mm`` (3 mm) of its
contact origin (where the ray from the prism axis toward the pad meets the outline), else to ``face``; per feature
the reconstruction NMAE/SSIM of every direction and baseline, the latent L1 between sensors and the contact-geometry
profile error (mm; the paper, Sec. IV-C, names the 80 deg corner). 2. PLA against TPU per shape and pooled.
3. The spread of every Table I cell over the run's seeds (population std, as ``metrics.json``'s ``table1_std``).
Metrics come from the project's code (``Evaluator``, ``table_rows``, ``contact_geometry``). Geometry is
cross-validated over ``--folds`` folds of approach directions (each holds out 10 %, as the paper's single split, so
every corner gets all its contacts), every seed and training sensor of a fold trained in one batched model; the
folds dominate the cost, ``--folds 0`` skips them.
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from unitac_rig.bench import default_out_dir, write_json
from unitac_rig.collection.session import collect_session
from unitac_rig.errors import DataError, UsageError
from unitac_rig.learning.contact_geometry import GeometryConfig, contact_profiles, fit_single_thread
from unitac_rig.learning.data import PairedDataset, object_shape_material
from unitac_rig.learning.engine import UNITAC_GROUP
from unitac_rig.learning.evaluate import Evaluator, table_rows
from unitac_rig.learning.paper import PAPER_GEOMETRY_MAE_MM, PAPER_TABLE1
from unitac_rig.learning.report import table_columns
from unitac_rig.learning.train import LoadedRun, load_run, load_test_set
from unitac_rig.plotting import new_figure, save_figure
from unitac_rig.rig.config import parse_rig_config
from unitac_rig.rig.objects import ObjectSpec, get_object, interior_angles_deg, pad_side_direction
from unitac_rig.sim.fast_rig import SimRig
from unitac_rig.storage.extraction import ExtractionSettings, extract_press
from unitac_rig.storage.press_record import PressRecord
from unitac_rig.storage.reader import read_presses
from unitac_rig.storage.recorder import session_path

if TYPE_CHECKING:
    from matplotlib.axes import Axes

# ==== collection: where the collection method stops working ====


THRESHOLD_N = 10.0


# ---- per-press measurements ----


def travel_curve(press: PressRecord) -> tuple[np.ndarray, np.ndarray]:
    """Pad travel along the press from the recorded first contact (mm) and the press force (N), up to the peak
    force; empty without a contact."""
    contact_t = [t for t, kind, _ in press.events if kind == "contact"]
    if not contact_t or press.robot_t_s.size == 0:
        return np.zeros(0), np.zeros(0)
    peak = int(np.argmax(press.press_force_n))
    i0 = min(int(np.searchsorted(press.robot_t_s, contact_t[0])), peak)
    direction = np.asarray(press.attrs["direction"], dtype=np.float64)
    travel = 1000.0 * (press.robot_pose[i0 : peak + 1, :3] - press.robot_pose[i0, :3]) @ direction
    return travel, press.press_force_n[i0 : peak + 1]


def travel_after_contact_mm(press: PressRecord) -> float:
    """Pad travel along the press from the recorded first contact to the peak force (mm); NaN without a contact."""
    travel, _ = travel_curve(press)
    return float(travel[-1]) if travel.size else float("nan")


def ramp_rate_n_s(press: PressRecord) -> float:
    """Median slope of the press force between 4 and 10 N on the loading ramp (N/s)."""
    peak = int(np.argmax(press.press_force_n))
    f, t = press.press_force_n[: peak + 1], press.robot_t_s[: peak + 1]
    inside = (f >= 4.0) & (f <= THRESHOLD_N)
    if inside.sum() < 3:
        return float("nan")
    return float(np.polyfit(t[inside], f[inside], 1)[0])


def frame_period_s(press: PressRecord) -> float:
    return float(np.median(np.diff(press.tactile_t_s))) if press.tactile_t_s.size > 2 else float("nan")


def press_summary(press: PressRecord) -> dict[str, Any]:
    ex = press.extraction
    matched_err = [] if ex is None else np.abs(ex.error_n[~ex.miss]).tolist()
    return {
        "press_id": press.press_id,
        "status": press.status,
        "reason": press.reason,
        "peak_force_n": float(press.attrs.get("peak_force_n", np.nan)),
        "overshoot_n": float(press.attrs.get("overshoot_n", np.nan)),
        "travel_after_contact_mm": travel_after_contact_mm(press),
        "ramp_rate_n_s": ramp_rate_n_s(press),
        "frame_period_s": frame_period_s(press),
        "targets_matched": 0 if ex is None else ex.n_matched,
        "targets_reached": 0 if ex is None else int(np.isfinite(ex.crossing_t_s).sum()),
        "abs_error_n": matched_err,
        "robot_samples": int(press.robot_t_s.size),
        "tactile_frames": int(press.tactile_t_s.size),
    }


def run_session(
    obj_id: str, sensor: str, angles: int, workdir: Path, *, seed: int = 0, **sections: dict[str, Any]
) -> list[PressRecord]:
    data: dict[str, Any] = {"press": {"angle_count": angles}}
    for key, value in sections.items():
        data[key] = {**data.get(key, {}), **value}
    config = parse_rig_config(data)
    out = workdir / f"{obj_id}-{sensor}-{len(list(workdir.iterdir()))}"
    with SimRig(config, seed=seed) as rig:
        collect_session(rig, get_object(obj_id), sensor, out)
    return read_presses(session_path(out, obj_id, sensor))


# ---- A. soft objects that cannot reach the threshold ----


def soft_objects(workdir: Path, angles: int) -> dict[str, Any]:
    limits_mm = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 8.0)
    rows = []
    curves: dict[str, dict[str, list[float]]] = {}
    for obj_id in ("hex_tpu", "hex_pla"):
        for limit in limits_mm:
            presses = run_session(obj_id, "uskin", angles, workdir, limits={"max_travel_after_contact_mm": limit})
            summaries = [press_summary(p) for p in presses]
            rows.append(
                {
                    "object": obj_id,
                    "max_travel_after_contact_mm": limit,
                    "presses": len(summaries),
                    "failed_travel": sum(s["reason"] == "travel" for s in summaries),
                    "complete": sum(s["status"] == "complete" for s in summaries),
                    "peak_force_n": [s["peak_force_n"] for s in summaries],
                    "targets_reached": [s["targets_reached"] for s in summaries],
                    "targets_matched_in_failed": sum(
                        s["targets_matched"] for s in summaries if s["status"] == "failed"
                    ),
                    "streams_kept": all(s["robot_samples"] > 0 and s["tactile_frames"] > 0 for s in summaries),
                }
            )
            if limit == max(limits_mm):
                travel, force = travel_curve(presses[len(presses) // 2])
                curves[obj_id] = {"travel_mm": travel.tolist(), "force_n": force.tolist()}
    return {"limits_mm": list(limits_mm), "rows": rows, "curves": curves}


# ---- B. steep ramps against the frame period ----


def ramp_sweep(trials: int, seed: int = 0) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    settings = ExtractionSettings()
    tol = settings.tolerance_n
    periods_s = (0.001, 0.002, 0.004, 0.01, 0.02)
    rates = np.round(np.geomspace(2.0, 2000.0, 16), 3)
    robot_dt = 0.002
    rows = []
    for period in periods_s:
        for rate in rates:
            errors: list[float] = []  # as the extraction reports them (against the smoothed wrist force)
            true_errors: list[float] = []  # against the true force at the chosen frame
            misses = reached = false_matches = 0
            for _ in range(trials):
                t0 = rng.uniform(0.0, robot_dt)  # the ramp starts anywhere between two force samples
                ramp_end = 12.0 / rate
                robot_t = np.arange(0.0, ramp_end + 0.3, robot_dt)
                force = np.clip((robot_t - t0) * rate, 0.0, 12.0)
                frame_t = np.arange(rng.uniform(0.0, period), robot_t[-1], period)
                ex = extract_press(robot_t, force, frame_t, None, settings)
                reached += int(np.isfinite(ex.crossing_t_s).sum())
                misses += int(ex.miss.sum())
                errors.extend(np.abs(ex.error_n[np.isfinite(ex.error_n)]).tolist())
                chosen = ex.frame_index >= 0
                truth = np.clip((frame_t[ex.frame_index[chosen]] - t0) * rate, 0.0, 12.0) - ex.targets_n[chosen]
                true_errors.extend(np.abs(truth).tolist())
                false_matches += int(((np.abs(truth) > tol) & ~ex.miss[chosen]).sum())
            err = np.asarray(errors)
            true_err = np.asarray(true_errors)
            rows.append(
                {
                    "frame_period_s": period,
                    "ramp_rate_n_s": float(rate),
                    "n_per_frame": float(rate * period),
                    "targets": trials * len(settings.targets_n),
                    "reached": reached,
                    "miss_rate": misses / (trials * len(settings.targets_n)),
                    "false_match_rate": false_matches / max(1, trials * len(settings.targets_n) - misses),
                    "mean_abs_error_n": float(err.mean()) if err.size else None,
                    "max_abs_error_n": float(err.max()) if err.size else None,
                    "mean_abs_true_error_n": float(true_err.mean()) if true_err.size else None,
                    "max_abs_true_error_n": float(true_err.max()) if true_err.size else None,
                    "bound_max_n": float(rate * period / 2),
                    "bound_mean_n": float(rate * period / 4),
                    "bound_miss_rate": float(max(0.0, 1.0 - 2.0 * tol / (rate * period))),
                }
            )
    return {"tolerance_n": tol, "smoothing_samples": settings.smoothing_samples, "rows": rows}


# ---- C. PLA against TPU ----


def materials(workdir: Path, angles: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for shape in ("circle", "square", "hex"):
        for material in ("pla", "tpu"):
            for sensor in ("uskin", "papillarray"):
                presses = run_session(f"{shape}_{material}", sensor, angles, workdir)
                out[f"{shape}_{material}/{sensor}"] = [press_summary(p) for p in presses]
    return out


def material_stats(sessions: dict[str, Any]) -> dict[str, Any]:
    stats = {}
    for material in ("pla", "tpu"):
        summaries = [s for key, ss in sessions.items() if key.split("/")[0].endswith(material) for s in ss]
        complete = [s for s in summaries if s["status"] == "complete"]
        err = np.concatenate([s["abs_error_n"] for s in complete]) if complete else np.zeros(0)
        reached = sum(s["targets_reached"] for s in complete)
        matched = sum(s["targets_matched"] for s in complete)

        def q(values: list[float] | np.ndarray) -> dict[str, float]:
            a = np.asarray(values, dtype=np.float64)
            a = a[np.isfinite(a)]
            return {"median": float(np.median(a)), "p95": float(np.percentile(a, 95)), "max": float(a.max())}

        stats[material] = {
            "presses": len(summaries),
            "complete": len(complete),
            "abs_error_n": q(err),
            "overshoot_n": q([s["overshoot_n"] for s in complete]),
            "travel_after_contact_mm": q([s["travel_after_contact_mm"] for s in complete]),
            "ramp_rate_n_s": q([s["ramp_rate_n_s"] for s in complete]),
            "miss_rate_of_reached": 1.0 - matched / reached if reached else None,
        }
    return stats


# ---- figures ----


def draw(result: dict[str, Any], out_dir: Path) -> list[Path]:
    paths = []
    # A
    soft = result["soft"]
    fig = new_figure(10, 3.8, layout="tight")
    ax1, ax2 = fig.subplots(1, 2)
    for obj_id, curve in soft["curves"].items():
        ax1.plot(curve["travel_mm"], curve["force_n"], label=obj_id)
    for limit in soft["limits_mm"][:-1]:
        ax1.axvline(limit, color="0.8", lw=0.8, zorder=0)
    ax1.axhline(THRESHOLD_N, color="C3", ls="--", lw=1, label="threshold")
    ax1.set(xlabel="travel past first contact (mm)", ylabel="press force (N)", title="force against travel (0 deg)")
    ax1.legend()
    for obj_id, marker in (("hex_tpu", "o"), ("hex_pla", "s")):
        rows = [r for r in soft["rows"] if r["object"] == obj_id]
        limits = [r["max_travel_after_contact_mm"] for r in rows]
        ax2.plot(limits, [r["failed_travel"] / r["presses"] for r in rows], marker=marker, label=f"{obj_id}: failed")
        ax2.plot(
            limits,
            [np.median(r["peak_force_n"]) / THRESHOLD_N for r in rows],
            marker=marker,
            ls=":",
            label=f"{obj_id}: median peak / 10 N",
        )
    ax2.set(xlabel="travel limit past first contact (mm)", ylabel="fraction", xscale="log", title="outcome")
    ax2.set_xticks(soft["limits_mm"], [f"{v:g}" for v in soft["limits_mm"]])
    ax2.minorticks_off()
    ax2.legend(fontsize=7)
    paths.append(save_figure(fig, out_dir / "stability_soft.png"))

    # B
    ramp = result["ramp"]
    rows = ramp["rows"]
    x = np.geomspace(0.002, 40.0, 200)
    tol = ramp["tolerance_n"]
    fig = new_figure(10, 3.8, layout="tight")
    ax1, ax2 = fig.subplots(1, 2)
    periods = sorted({r["frame_period_s"] for r in rows})
    for k, period in enumerate(periods):
        sel = [r for r in rows if r["frame_period_s"] == period and r["mean_abs_error_n"] is not None]
        kw = {"color": f"C{k}", "label": f"T = {period * 1000:g} ms"}
        xs = [r["n_per_frame"] for r in sel]
        ax1.plot(xs, [r["mean_abs_true_error_n"] for r in sel], "o", ms=3, **kw)
        ax1.plot(xs, [r["max_abs_true_error_n"] for r in sel], "^", ms=3, color=f"C{k}")
        ax1.plot(xs, [r["max_abs_error_n"] for r in sel], "_", ms=5, color=f"C{k}")
        ax2.plot(xs, [r["miss_rate"] for r in sel], "o", ms=3, **kw)
        ax2.plot(xs, [r["false_match_rate"] for r in sel], "x", ms=4, color=f"C{k}")
    ax1.plot(x, x / 4, "k-", lw=1, label="r T / 4 (mean, bound)")
    ax1.plot(x, x / 2, "k--", lw=1, label="r T / 2 (max, bound)")
    ax1.axhline(tol, color="C3", lw=0.8, ls=":", label=f"tolerance {tol} N")
    sim = result["sim_points"]
    ax1.plot([p[0] for p in sim], [p[1] for p in sim], "x", color="0.3", ms=3, label="simulated rig, matched")
    ax1.set(
        xscale="log",
        yscale="log",
        xlabel="ramp rate x frame period, r T (N per frame)",
        ylabel="|matching error| (N)",
        title="true error: mean (o), max (^); reported max (-)",
    )
    ax1.legend(fontsize=6)
    ax2.plot(x, np.clip(1 - 2 * tol / x, 0, 1), "k--", lw=1, label="1 - 2 tol / (r T)")
    ax2.set(
        xscale="log",
        xlabel="r T (N per frame)",
        ylabel="fraction of the 25 targets",
        title="misses (o); matched but truly off > tol (x)",
    )
    ax2.legend(fontsize=6)
    paths.append(save_figure(fig, out_dir / "stability_ramp.png"))

    # C
    sessions = result["materials"]["sessions"]
    fig = new_figure(11, 3.6, layout="tight")
    axes = fig.subplots(1, 3)
    for ax, key, label in (
        (axes[0], "abs_error_n", "|matching error| (N)"),
        (axes[1], "overshoot_n", "overshoot past 10 N (N)"),
        (axes[2], "travel_after_contact_mm", "travel past first contact (mm)"),
    ):
        groups, names = [], []
        for material in ("pla", "tpu"):
            for sensor in ("uskin", "papillarray"):
                ss = [
                    s
                    for k, v in sessions.items()
                    if k.split("/")[0].endswith(material) and k.endswith(sensor)
                    for s in v
                    if s["status"] == "complete"
                ]
                values = np.concatenate([s[key] for s in ss]) if key == "abs_error_n" else [s[key] for s in ss]
                groups.append(np.asarray(values, dtype=np.float64))
                names.append(f"{material.upper()}\n{sensor}")
        ax.boxplot(groups, showfliers=True)
        ax.set_xticks(range(1, len(names) + 1), names, fontsize=7)
        ax.set_ylabel(label)
    fig.suptitle("PLA against TPU, guarded presses at the default speed (simulated rig)")
    paths.append(save_figure(fig, out_dir / "stability_material.png"))
    return paths


def run_collection(args: argparse.Namespace) -> None:
    args.out.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        soft = soft_objects(workdir, max(3, args.angles // 2))
        sessions = materials(workdir, args.angles)
    sim_points = [
        (s["ramp_rate_n_s"] * s["frame_period_s"], e)
        for ss in sessions.values()
        for s in ss
        if s["status"] == "complete"
        for e in s["abs_error_n"]
    ]
    smoothing_window_s = ExtractionSettings().smoothing_samples * 0.002
    result = {
        # the centred moving average keeps a crossing exact only while the force is linear over +-W/2 around it: the
        # last target (10 N) below a 12 N top stays exact up to r = 2 * (12 - 10) / W
        "smoothing_window_s": smoothing_window_s,
        "smoothing_limit_rate_n_s": 2 * (12.0 - 10.0) / smoothing_window_s,
        "command": f"python benchmarks/stability.py collection --angles {args.angles} --trials {args.trials}",
        "soft": soft,
        "ramp": ramp_sweep(args.trials),
        "materials": {"sessions": sessions, "stats": material_stats(sessions)},
        "sim_points": sim_points,
    }
    result["wall_s"] = round(time.monotonic() - started, 1)
    json_path = write_json(result, args.out / "stability_collection.json")
    for path in [json_path, *draw(result, args.out)]:
        print(path)
    print(json.dumps(material_stats(sessions), indent=1))
    print(f"wall {result['wall_s']} s")


# ==== learning: where the learned representation fails ====


FACE_DISTANCE_MM = 3.0  # a contact origin farther than this from every corner vertex is on a face
DEFAULT_GEOMETRY_FOLDS = 10  # each fold holds out 10% of the directions, like the paper's single split
PAPER_FAILING_CORNER_DEG = 80.0
PAPER_REMARKS = {
    "geometry": "Sec. IV-C: the 80 deg corner (pointing left) produces a minimal contact surface; few activated "
    "taxels and sparse shear make local contact identification ambiguous",
    "reconstruction": "Fig. 4 caption: poor reconstructions of the unseen object often occur when the press hits a "
    "sharp edge with a small contact area",
}
METRICS = ("nmae", "ssim")
MATERIALS = ("PLA", "TPU")


# ---- Outline features ----


@dataclass(frozen=True)
class OutlineFeature:
    """A corner of the outline (``vertex``: 0-based index into ``outer_mm``, interior angle in deg) or the faces."""

    kind: str  # "corner" or "face"
    vertex: int | None = None
    interior_angle_deg: float | None = None

    @property
    def vertex_label(self) -> str | None:
        """1-based vertex name, as the object's drawings count them (V3 is the irregular prism's 80 deg tip)."""
        return None if self.vertex is None else f"V{self.vertex + 1}"

    @property
    def name(self) -> str:
        """``"corner 80 (V3)"`` or ``"face"``; the vertex keeps two corners of the same angle apart."""
        if self.kind == "face" or self.interior_angle_deg is None:
            return "face"
        return f"corner {round(self.interior_angle_deg)} ({self.vertex_label})"


FACE = OutlineFeature("face")


@dataclass(frozen=True)
class FeatureHit:
    """Which feature a press hits: its contact origin (mm, CAD frame) and distance to the nearest corner (mm)."""

    feature: OutlineFeature
    origin_mm: np.ndarray
    corner_distance_mm: float


def outline_features(spec: ObjectSpec) -> list[OutlineFeature]:
    """The object's corners, sharpest first (ties by vertex), then ``face``."""
    angles = interior_angles_deg(spec.outer_mm)
    corners = [OutlineFeature("corner", int(i), float(angles[i])) for i in spec.corner_vertices()]
    corners.sort(key=lambda f: (round(f.interior_angle_deg or 0.0, 1), f.vertex))
    return [*corners, FACE]


def feature_at_point(spec: ObjectSpec, point_mm: np.ndarray, face_distance_mm: float = FACE_DISTANCE_MM) -> FeatureHit:
    """The feature at a point of the outline: the nearest corner within ``face_distance_mm`` (mm), else ``face``."""
    point = np.asarray(point_mm, dtype=np.float64)
    corners = spec.corner_vertices()
    if corners.size == 0:
        return FeatureHit(FACE, point, math.inf)
    distances = np.linalg.norm(spec.outer_mm[corners] - point, axis=1)
    nearest = int(np.argmin(distances))
    distance = float(distances[nearest])
    if distance > face_distance_mm:
        return FeatureHit(FACE, point, distance)
    vertex = int(corners[nearest])
    angle = float(interior_angles_deg(spec.outer_mm)[vertex])
    return FeatureHit(OutlineFeature("corner", vertex, angle), point, distance)


def feature_of_press(
    spec: ObjectSpec, angle_deg: float, rotation_deg: float, face_distance_mm: float = FACE_DISTANCE_MM
) -> FeatureHit:
    """The feature a press at approach ``angle_deg`` on the object turned by ``rotation_deg`` hits (both deg)."""
    origin = spec.outline_hit(pad_side_direction(angle_deg, rotation_deg))
    return feature_at_point(spec, origin, face_distance_mm)


def assign_features(
    spec: ObjectSpec,
    angle_deg: np.ndarray,
    rotation_deg: np.ndarray,
    face_distance_mm: float = FACE_DISTANCE_MM,
) -> tuple[list[OutlineFeature], np.ndarray, np.ndarray]:
    """(features, index into features per contact (M,), distance to the nearest corner per contact (M,) mm)."""
    features = outline_features(spec)
    position = {f: i for i, f in enumerate(features)}
    cache: dict[tuple[float, float], FeatureHit] = {}
    index = np.empty(len(angle_deg), dtype=int)
    distance = np.empty(len(angle_deg))
    for i, (angle, rotation) in enumerate(zip(angle_deg, rotation_deg, strict=True)):
        key = (float(angle), float(rotation))
        if key not in cache:
            cache[key] = feature_of_press(spec, key[0], key[1], face_distance_mm)
        index[i] = position[cache[key].feature]
        distance[i] = cache[key].corner_distance_mm
    return features, index, distance


# ---- Statistics over members ----


def spread(per_member: Iterable[float]) -> dict[str, Any]:
    """Mean, population std, min and max of one number over the run's members (seeds), plus the values."""
    values = np.asarray(list(per_member), dtype=np.float64)
    if values.size == 0 or not np.all(np.isfinite(values)):
        return {"mean": None, "std": None, "min": None, "max": None, "members": values.tolist()}
    return {
        "mean": float(values.mean()),
        "std": float(values.std()),
        "min": float(values.min()),
        "max": float(values.max()),
        "members": values.tolist(),
    }


def _member_means(values: torch.Tensor, mask: np.ndarray) -> np.ndarray:
    """(members, M) per-frame values -> (members,) means over the frames ``mask`` selects."""
    return values[:, torch.from_numpy(mask)].double().mean(dim=1).numpy()


# ---- The report ----


def stability_report(
    run_dir: Path | str,
    *,
    object_id: str | None = None,
    face_distance_mm: float = FACE_DISTANCE_MM,
    geometry_folds: int = DEFAULT_GEOMETRY_FOLDS,
    geometry_config: GeometryConfig | None = None,
    figures_dir: Path | str | None = None,
    nmae_normaliser: str | None = None,
    ssim_range: str | None = None,
) -> dict[str, Any]:
    """Per-feature errors on ``object_id`` (default: the run's unseen object), PLA vs TPU and the seed spread, as a
    JSON-ready dict. ``geometry_folds`` = 0 skips the (slowest) contact-geometry part. With ``figures_dir`` the three
    figures are drawn there and their file names listed under ``"figures"``. The metric options default to the
    run's own; others re-score the same models (no retraining)."""
    if geometry_folds < 0 or geometry_folds == 1:
        raise UsageError(
            f"geometry folds must be 0 (skip) or at least 2, got {geometry_folds}", hint="the default is 10"
        )
    run = load_run(Path(run_dir)).scored_under(nmae_normaliser, ssim_range)
    test = load_test_set(Path(run_dir))
    evaluator = Evaluator.for_run(run, test)  # scored under the given (default: the run's) metric options
    scores, latent_distance = evaluator.per_frame(run.engine), evaluator.latent_distance(run.engine)
    columns = [c for c in table_columns(run.sensors, set(scores)) if c in scores]

    object_id = object_id or _default_object(run, test)
    spec = get_object(object_id)
    rows = np.flatnonzero(test.object_id == object_id)
    if rows.size == 0:
        raise DataError(
            f"no test contacts of object {object_id!r} in this run",
            hint=f"objects in the run's test data: {', '.join(test.objects)}",
        )
    features, feature_index, corner_distance = assign_features(
        spec, test.angle_deg[rows], test.rotation_deg[rows], face_distance_mm
    )

    report: dict[str, Any] = {
        "run": str(run_dir),
        "object": object_id,
        "sensors": list(run.sensors),
        "seeds": list(run.engine.seeds),
        "epochs": int(run.payload["epoch"]),
        "simulated": bool(test.simulated),
        "face_distance_mm": face_distance_mm,
        "paper_failing_corner_deg": PAPER_FAILING_CORNER_DEG,
        "paper_remarks": dict(PAPER_REMARKS),
        "columns": columns,
    }
    report["features"] = _feature_table(spec, features, feature_index, corner_distance, test, rows)
    report["reconstruction"] = _reconstruction_by_feature(
        scores, latent_distance, columns, features, feature_index, rows, len(test)
    )
    report["geometry"] = (
        _geometry_by_feature(run, test, rows, object_id, features, feature_index, geometry_folds, geometry_config)
        if geometry_folds
        else None
    )
    report["materials"] = _materials(scores, columns, test, run.unseen_objects)
    report["seed_spread"] = _seed_spread(scores, columns, test, run.unseen_objects)
    report["figures"] = {}
    if figures_dir is not None:
        report["figures"] = {k: p.name for k, p in plot_stability(report, Path(figures_dir)).items()}
    return report


def _default_object(run: LoadedRun, test: PairedDataset) -> str:
    present = set(test.object_id.tolist())
    for object_id in run.unseen_objects:
        if object_id in present:
            return object_id
    raise DataError(
        "the run's test data holds no unseen object to break down by corner",
        hint="collect the irregular prism (irregular_pla) with every sensor, or pass an object id",
    )


def _feature_table(
    spec: ObjectSpec,
    features: Sequence[OutlineFeature],
    feature_index: np.ndarray,
    corner_distance: np.ndarray,
    test: PairedDataset,
    rows: np.ndarray,
) -> list[dict[str, Any]]:
    out = []
    for k, feature in enumerate(features):
        members = feature_index == k
        directions = set(
            zip(test.rotation_deg[rows][members].tolist(), test.angle_deg[rows][members].tolist(), strict=True)
        )
        out.append(
            {
                "name": feature.name,
                "kind": feature.kind,
                "vertex": feature.vertex_label,
                "interior_angle_deg": feature.interior_angle_deg,
                "vertex_mm": None if feature.vertex is None else spec.outer_mm[feature.vertex].tolist(),
                "test_contacts": int(members.sum()),
                "directions": len(directions),
                "max_corner_distance_mm": _finite_or_none(corner_distance[members].max()) if members.any() else None,
            }
        )
    return out


def _finite_or_none(value: float) -> float | None:
    """JSON has no infinity: an object without corners has no corner distance."""
    return float(value) if math.isfinite(value) else None


def _reconstruction_by_feature(
    scores: dict[str, dict[str, torch.Tensor]],
    latent_distance: torch.Tensor | None,
    columns: Sequence[str],
    features: Sequence[OutlineFeature],
    feature_index: np.ndarray,
    rows: np.ndarray,
    n_test: int,
) -> dict[str, Any]:
    """{feature name or "whole object": {column: {metric: spread}, "latent_l1": spread}}; empty features -> None."""
    groups: list[tuple[str, np.ndarray]] = [(f.name, rows[feature_index == k]) for k, f in enumerate(features)]
    groups.append(("whole object", rows))
    out: dict[str, Any] = {}
    for name, picked in groups:
        if picked.size == 0:
            out[name] = None
            continue
        mask = np.zeros(n_test, dtype=bool)
        mask[picked] = True
        entry: dict[str, Any] = {
            column: {metric: spread(_member_means(scores[column][metric], mask)) for metric in METRICS}
            for column in columns
        }
        entry["latent_l1"] = spread(_member_means(latent_distance, mask)) if latent_distance is not None else None
        out[name] = entry
    return out


def _direction_folds(directions: Sequence[tuple[int, int]], folds: int, seed: int, object_id: str) -> np.ndarray:
    """Fold number (0..folds-1) of each contact; all forces of one (rotation, angle) direction share a fold."""
    units = sorted(set(directions))
    if len(units) < folds:
        raise DataError(
            f"object {object_id} has {len(units)} approach directions, too few for {folds} geometry folds",
            hint="use fewer --folds or collect more angles",
        )
    rng = np.random.default_rng([seed, zlib.crc32(object_id.encode()), folds])
    order = rng.permutation(len(units))
    fold_of_unit = {}
    for fold, chunk in enumerate(np.array_split(order, folds)):
        for i in chunk:
            fold_of_unit[units[int(i)]] = fold
    return np.array([fold_of_unit[d] for d in directions], dtype=int)


def _geometry_by_feature(
    run: LoadedRun,
    test: PairedDataset,
    rows: np.ndarray,
    object_id: str,
    features: Sequence[OutlineFeature],
    feature_index: np.ndarray,
    folds: int,
    config: GeometryConfig | None,
) -> dict[str, Any]:
    """Out-of-fold profile errors (mm) of every ``<train>_to_<test>`` scenario and member, grouped by feature."""
    config = config or GeometryConfig()
    subset, truth, valid, directions = contact_profiles(test, rows, object_id, config)
    fold_of = _direction_folds(directions, folds, run.config.split_seed, object_id)

    sensors = run.sensors
    members = run.engine.members
    latents = {  # (members, M_object, latent) per sensor
        s: run.engine.encode(UNITAC_GROUP, s, torch.from_numpy(run.normaliser.normalise(s, subset.values[s]))).numpy()
        for s in sensors
    }
    # one stacked model per fold: slot (member m, training sensor s)
    slots = [(m, s) for m in range(members) for s in sensors]
    error = {  # (members, M_object) mean |predicted - true| over the profile points, mm; NaN where not tested
        f"{a}_to_{b}": np.full((members, len(subset)), np.nan) for a in sensors for b in sensors
    }
    # reference without the latent: predict the training folds' mean profile for every contact
    mean_profile_error = np.full(len(subset), np.nan)
    for fold in range(folds):
        train_rows = valid & (fold_of != fold)
        test_rows = np.flatnonzero(valid & (fold_of == fold))
        if test_rows.size == 0 or not train_rows.any():
            continue
        mean_profile = truth[train_rows].mean(axis=0)
        mean_profile_error[test_rows] = np.abs(truth[test_rows] - mean_profile).mean(axis=1)
        model = fit_single_thread(
            [latents[s][m][train_rows] for m, s in slots],
            truth[train_rows],
            config,
            [config.dropout_for(s) for _, s in slots],
            seed=run.engine.seeds[0] * 1000 + fold,
        )
        for test_sensor in sensors:
            stacked = torch.from_numpy(np.stack([latents[test_sensor][m][test_rows] for m, _ in slots]))
            with torch.no_grad():
                predicted = model(stacked).numpy()  # (slots, T, points)
            for k, (m, train_sensor) in enumerate(slots):
                per_contact = np.abs(predicted[k] - truth[test_rows]).mean(axis=1)
                error[f"{train_sensor}_to_{test_sensor}"][m, test_rows] = per_contact

    def summarise(mask: np.ndarray) -> dict[str, Any] | None:
        tested = mask & valid
        if not tested.any():
            return None
        out: dict[str, Any] = {
            "contacts": int(tested.sum()),
            "mean_abs_depth_mm": float(np.abs(truth[tested]).mean()),
            "mean_profile_mae_mm": float(np.nanmean(mean_profile_error[tested])),
        }
        for name, values in error.items():
            out[name] = spread(values[:, tested].mean(axis=1))
        return out

    per_feature = {f.name: summarise(feature_index == k) for k, f in enumerate(features)}
    return {
        "folds": folds,
        "protocol": f"{folds}-fold cross-validation over the object's approach directions; each contact's error "
        "is the mean |predicted - true| depth over the profile points (mm) from the fold that held it out",
        "profile_points": config.points,
        "profile_span_mm": config.span_mm,
        "epochs": config.epochs,
        "scenarios": list(error),
        "reference": "mean_profile_mae_mm: the error of predicting the training folds' mean profile for every "
        "contact (no latent); mean_abs_depth_mm: mean |true depth| over the profile points, how far the surface "
        "departs from the pad plane through the contact origin",
        "paper_mae_mm": {name: PAPER_GEOMETRY_MAE_MM.get(name) for name in error},
        "left_out_contacts": int((~valid).sum()),
        "whole_object": summarise(np.ones(len(subset), dtype=bool)),
        "per_feature": per_feature,
    }


def _materials(
    scores: dict[str, dict[str, torch.Tensor]], columns: Sequence[str], test: PairedDataset, unseen: Sequence[str]
) -> dict[str, Any]:
    """PLA against TPU: per shape printed in both (the two Table I rows and TPU - PLA) and pooled over shapes."""
    seen_objects = [o for o in test.objects if o not in unseen]
    by_shape: dict[str, dict[str, str]] = {}
    for object_id in seen_objects:
        shape, material = object_shape_material(object_id)
        if material in MATERIALS:
            by_shape.setdefault(shape, {})[material] = object_id

    def compare(masks: dict[str, np.ndarray], paper: dict[str, dict[str, tuple[float, float]] | None]) -> dict:
        entry: dict[str, Any] = {}
        for column in columns:
            entry[column] = {}
            for m_index, metric in enumerate(METRICS):
                per_material = {mat: _member_means(scores[column][metric], masks[mat]) for mat in MATERIALS}
                cell: dict[str, Any] = {mat: spread(per_material[mat]) for mat in MATERIALS}
                cell["tpu_minus_pla"] = spread(per_material["TPU"] - per_material["PLA"])
                paper_values = {mat: (paper[mat] or {}).get(column) for mat in MATERIALS}
                if all(v is not None for v in paper_values.values()):
                    pla, tpu = (float(paper_values[mat][m_index]) for mat in MATERIALS)  # type: ignore[index]
                    cell["paper"] = {"PLA": pla, "TPU": tpu, "tpu_minus_pla": tpu - pla}
                else:
                    cell["paper"] = None
                entry[column][metric] = cell
        return entry

    per_shape: dict[str, Any] = {}
    pairs = {shape: ids for shape, ids in sorted(by_shape.items()) if set(ids) == set(MATERIALS)}
    for shape, ids in pairs.items():
        masks = {mat: test.object_id == ids[mat] for mat in MATERIALS}
        paper = {mat: PAPER_TABLE1.get(ids[mat]) for mat in MATERIALS}
        per_shape[shape] = {"objects": ids, "contacts": {m: int(masks[m].sum()) for m in MATERIALS}}
        per_shape[shape].update(compare(masks, paper))

    pooled: dict[str, Any] | None = None
    material_objects = {mat: [ids[mat] for ids in by_shape.values() if mat in ids] for mat in MATERIALS}
    if all(material_objects.values()):
        masks = {mat: np.isin(test.object_id, material_objects[mat]) for mat in MATERIALS}
        paper_pooled: dict[str, dict[str, tuple[float, float]] | None] = {}
        for mat in MATERIALS:
            rows = [PAPER_TABLE1.get(o) for o in material_objects[mat]]
            # the paper's per-object test sets are the same size, so a plain mean over its rows is the pooled value
            if all(r is not None for r in rows):
                paper_pooled[mat] = {
                    c: tuple(float(np.mean([r[c][i] for r in rows if r])) for i in range(2))  # type: ignore[misc]
                    for c in columns
                    if all(r is not None and c in r for r in rows)
                }
            else:
                paper_pooled[mat] = None
        pooled = {"objects": material_objects, "contacts": {m: int(masks[m].sum()) for m in MATERIALS}}
        pooled.update(compare(masks, paper_pooled))
    return {"per_shape": per_shape, "pooled": pooled}


def _seed_spread(
    scores: dict[str, dict[str, torch.Tensor]], columns: Sequence[str], test: PairedDataset, unseen: Sequence[str]
) -> dict[str, Any]:
    """Every Table I cell (rows as ``metrics.json``) over the run's members: {row: {column: {metric: spread}}}."""
    out: dict[str, Any] = {}
    for row, mask in table_rows(test, tuple(unseen)):
        out[row] = {}
        for column in columns:
            out[row][column] = {}
            for m_index, metric in enumerate(METRICS):
                cell = spread(_member_means(scores[column][metric], mask))
                paper = PAPER_TABLE1.get(row, {}).get(column)
                cell["paper"] = None if paper is None else float(paper[m_index])
                out[row][column][metric] = cell
    return out


# ---- the three figures: errors per outline feature of the unseen object, PLA against TPU, the spread over seeds --
CORNERS_PNG = "stability_learning_corners.png"
MATERIALS_PNG = "stability_learning_materials.png"
SEEDS_PNG = "stability_learning_seeds.png"


def _value(cell: dict[str, Any] | None, key: str = "mean") -> float:
    if cell is None or cell.get(key) is None:
        return math.nan
    return float(cell[key])


def _label(column: str) -> str:
    return column.replace("_to_", " → ").replace("papillarray", "papill")


def plot_stability(report: dict[str, Any], out_dir: Path) -> dict[str, Path]:
    """The three figures of a :func:`stability_report` dict; returns {"corners"|"materials"|"seeds": path}."""
    out_dir = Path(out_dir)
    drawn = {"corners": _plot_corners(report, out_dir / CORNERS_PNG)}
    if report["materials"]["pooled"] is not None:
        drawn["materials"] = _plot_materials(report, out_dir / MATERIALS_PNG)
    drawn["seeds"] = _plot_seeds(report, out_dir / SEEDS_PNG)
    return drawn


def _grouped_bars(ax: Axes, names: Sequence[str], series: dict[str, tuple[list[float], list[float]]]) -> None:
    """Bars per name (x) and series (colour), error bars = std over seeds."""
    width = 0.8 / max(1, len(series))
    x = np.arange(len(names))
    for i, (label, (means, stds)) in enumerate(series.items()):
        ax.bar(x + (i - (len(series) - 1) / 2) * width, means, width, yerr=stds, capsize=2, label=label)
    ax.set_xticks(x)
    ax.set_xticklabels(names, fontsize=8)


def _plot_corners(report: dict[str, Any], path: Path) -> Path:
    features = [f for f in report["features"] if f["test_contacts"] > 0]
    names = [f["name"] for f in features]
    ticks = [f"{f['name']}\n{f['test_contacts']} contacts" for f in features]
    recon = report["reconstruction"]
    geometry = report["geometry"]
    panels = 3 if geometry is not None else 2
    fig = new_figure(max(9.0, 1.6 * len(names)), 3.6 * panels, layout="tight")
    axes = fig.subplots(panels, 1, squeeze=False)
    for ax, metric in zip(axes[:, 0], METRICS, strict=False):
        series = {
            _label(c): (
                [_value((recon[n] or {}).get(c, {}).get(metric)) for n in names],
                [_value((recon[n] or {}).get(c, {}).get(metric), "std") for n in names],
            )
            for c in report["columns"]
        }
        _grouped_bars(ax, ticks, series)
        ax.set_ylabel(f"reconstruction {metric.upper()}")
        whole = recon["whole object"]
        for j, c in enumerate(report["columns"]):
            ax.axhline(_value(whole[c][metric]), color=f"C{j}", lw=0.7, ls=":")
    # headroom above the tallest bar, so the legend (right) and the paper's remark (left) cover no bar
    axes[0, 0].set_ylim(top=axes[0, 0].get_ylim()[1] * 1.45)
    axes[0, 0].legend(fontsize=7, ncol=3, title="dotted: whole object", title_fontsize=7, loc="upper right")
    if geometry is not None:
        ax = axes[2, 0]
        per_feature = geometry["per_feature"]
        series = {
            _label(s): (
                [_value((per_feature[n] or {}).get(s)) for n in names],
                [_value((per_feature[n] or {}).get(s), "std") for n in names],
            )
            for s in geometry["scenarios"]
        }
        _grouped_bars(ax, ticks, series)
        for k, paper in enumerate(geometry["paper_mae_mm"].values()):
            if paper is not None:
                ax.axhline(paper, color=f"C{k}", lw=0.8, ls="--")
        reference = [_value(per_feature[n], "mean_profile_mae_mm") for n in names]
        ax.scatter(
            np.arange(len(names)), reference, marker="_", s=900, color="k", zorder=3, label="mean profile, no latent"
        )
        ax.set_ylabel("geometry profile MAE (mm)")
        ax.set_ylim(top=max(ax.get_ylim()[1], float(np.nanmax(np.asarray(reference, dtype=float)))) * 1.3)
        ax.legend(fontsize=7, ncol=3, title="dashed: paper, whole object", title_fontsize=7)
    failing = [
        i
        for i, f in enumerate(features)
        if f["interior_angle_deg"] is not None
        and round(f["interior_angle_deg"]) == round(report["paper_failing_corner_deg"])
    ]
    for ax in axes[:, 0]:
        for i in failing:
            ax.axvspan(i - 0.45, i + 0.45, color="red", alpha=0.08, zorder=0)
    if failing:
        _paper_note(axes[0, 0], failing[0], "paper: poor reconstructions at sharp edges\nwith a small contact area")
        _paper_note(
            axes[-1, 0],
            failing[0],
            "paper (Sec. IV-C): geometry estimation\nambiguous at the 80° corner"
            if geometry is not None
            else "paper: 80° corner",
        )
    seeds = len(report["seeds"])
    fig.suptitle(
        f"{report['object']}: errors by the outline feature the press hits (corner = contact origin within "
        f"{report['face_distance_mm']:g} mm of the vertex); bars: mean over {seeds} seed(s), error bars: std",
        fontsize=9,
    )
    return save_figure(fig, path)


def _paper_note(ax: Axes, x: float, text: str) -> None:
    """A dark-red remark at the top of the panel, beside bar ``x``."""
    ax.annotate(
        text,
        (x, 1.0),
        xycoords=("data", "axes fraction"),
        xytext=(4, -4),
        textcoords="offset points",
        fontsize=7,
        color="darkred",
        va="top",
    )


def _plot_materials(report: dict[str, Any], path: Path) -> Path:
    materials = report["materials"]
    pooled = materials["pooled"]
    columns = report["columns"]
    fig = new_figure(13.0, 4.2, layout="tight")
    axes = fig.subplots(1, 2)
    x = np.arange(len(columns))
    markers = ["o", "s", "^", "D", "v"]
    for ax, metric in zip(axes, METRICS, strict=True):
        for i, mat in enumerate(MATERIALS):
            offset = (i - 0.5) * 0.38
            means = [_value(pooled[c][metric][mat]) for c in columns]
            stds = [_value(pooled[c][metric][mat], "std") for c in columns]
            ax.bar(x + offset, means, 0.36, yerr=stds, capsize=2, color=f"C{i}", alpha=0.7, label=f"{mat} (pooled)")
            for k, (shape, entry) in enumerate(materials["per_shape"].items()):
                ax.scatter(
                    x + offset,
                    [_value(entry[c][metric][mat]) for c in columns],
                    marker=markers[k % len(markers)],
                    color="k",
                    s=14,
                    zorder=3,
                    label=shape if i == 0 else None,
                )
            paper = [(pooled[c][metric]["paper"] or {}).get(mat, math.nan) for c in columns]
            ax.scatter(
                x + offset,
                paper,
                marker="_",
                color="red",
                s=160,
                zorder=4,
                label="paper (mean of its rows)" if i == 0 else None,
            )
        ax.set_xticks(x)
        ax.set_xticklabels([_label(c) for c in columns], fontsize=8, rotation=20)
        ax.set_ylabel(metric.upper())
        ax.set_title(f"{metric.upper()}: PLA vs TPU (seen objects' held-out angles)", fontsize=9)
    axes[0].legend(fontsize=7)
    return save_figure(fig, path)


def _plot_seeds(report: dict[str, Any], path: Path) -> Path:
    """Heatmaps of each Table I cell's spread over seeds: colour = (max - min) relative to the mean for NMAE, and
    (max - min) for SSIM; text = mean ± std and [min, max]."""
    table = report["seed_spread"]
    rows = list(table)
    columns = report["columns"]
    fig = new_figure(1.9 * len(columns) + 2.5, 2 * (0.75 * len(rows) + 1.2), layout="tight")
    axes = fig.subplots(2, 1)
    for ax, metric in zip(axes, METRICS, strict=True):
        text_values = np.empty((len(rows), len(columns)), dtype=object)
        colour = np.full((len(rows), len(columns)), np.nan)
        for i, row in enumerate(rows):
            for j, column in enumerate(columns):
                cell = table[row][column][metric]
                mean, low, high = _value(cell), _value(cell, "min"), _value(cell, "max")
                width = high - low
                colour[i, j] = 100.0 * width / abs(mean) if metric == "nmae" and mean else width
                digits = 4 if metric == "nmae" else 3
                text = f"{mean:.{digits}f}±{_value(cell, 'std'):.{digits}f}\n[{low:.{digits}f}, {high:.{digits}f}]"
                if cell.get("paper") is not None:
                    text += f"\npaper {cell['paper']:.3f}"
                text_values[i, j] = text
        image = ax.imshow(colour, cmap="Oranges", aspect="auto", vmin=0.0)
        for i in range(len(rows)):
            for j in range(len(columns)):
                ax.text(j, i, text_values[i, j], ha="center", va="center", fontsize=6.5)
        ax.set_xticks(range(len(columns)))
        ax.set_xticklabels([_label(c) for c in columns], fontsize=8, rotation=20)
        ax.set_yticks(range(len(rows)))
        ax.set_yticklabels(rows, fontsize=8)
        label = "(max - min) / mean over seeds (%)" if metric == "nmae" else "max - min over seeds"
        fig.colorbar(image, ax=ax, fraction=0.04, label=label)
        ax.set_title(f"{metric.upper()}: mean ± std [min, max] over seeds, and the paper's value", fontsize=9)
    seeds = report["seeds"]
    fig.suptitle(f"Table I spread over {len(seeds)} seed(s) {seeds} (population std)", fontsize=9)
    return save_figure(fig, path)


def _fmt(cell: dict[str, Any] | None) -> str:
    if cell is None or cell.get("mean") is None:
        return "-"
    return f"{cell['mean']:.3f}±{cell['std']:.3f}"


def print_summary(report: dict[str, Any]) -> None:
    columns = report["columns"]
    print(f"\nobject {report['object']}, seeds {report['seeds']}, {report['epochs']} epochs")
    print("\nreconstruction NMAE by feature (mean±std over seeds):")
    print(f"{'feature':<18}{'contacts':>9}  " + "  ".join(f"{c:>24}" for c in columns))
    contacts = {f["name"]: f["test_contacts"] for f in report["features"]}
    for name, entry in report["reconstruction"].items():
        if entry is None:
            continue
        cells = "  ".join(f"{_fmt(entry[c]['nmae']):>24}" for c in columns)
        print(f"{name:<18}{contacts.get(name, sum(contacts.values())):>9}  {cells}")
    geometry = report["geometry"]
    if geometry is not None:
        print(f"\ncontact-geometry profile MAE (mm) by feature, {geometry['folds']}-fold:")
        scenarios = geometry["scenarios"]
        print(f"{'feature':<18}{'|depth|':>7}{'no-latent':>10}  " + "  ".join(f"{s:>26}" for s in scenarios))
        rows = {**geometry["per_feature"], "whole object": geometry["whole_object"]}
        for name, entry in rows.items():
            if entry is None:
                continue
            cells = "  ".join(f"{_fmt(entry[s]):>26}" for s in scenarios)
            print(f"{name:<18}{entry['mean_abs_depth_mm']:>7.2f}{entry['mean_profile_mae_mm']:>10.3f}  {cells}")
    pooled = report["materials"]["pooled"]
    if pooled is not None:
        print("\nPLA vs TPU (pooled seen objects' held-out angles), NMAE:")
        for c in columns:
            cell = pooled[c]["nmae"]
            paper = cell["paper"]
            paper_text = "" if paper is None else f"   paper {paper['PLA']:.3f} vs {paper['TPU']:.3f}"
            print(
                f"  {c:<28} PLA {_fmt(cell['PLA'])}  TPU {_fmt(cell['TPU'])}  diff {_fmt(cell['tpu_minus_pla'])}"
                f"{paper_text}"
            )
    widest = max(
        (
            ((cell["nmae"]["max"] - cell["nmae"]["min"]) / cell["nmae"]["mean"], row, column)
            for row, cells in report["seed_spread"].items()
            for column, cell in cells.items()
            if cell["nmae"]["mean"]
        ),
        default=None,
    )
    if widest is not None:
        share, row, column = widest
        print(f"\nwidest seed spread of a Table I NMAE cell: {100 * share:.1f}% of its mean ({row}, {column})")


def run_learning(args: argparse.Namespace) -> None:
    began = time.perf_counter()
    report = stability_report(
        args.run,
        object_id=args.object,
        face_distance_mm=args.face_mm,
        geometry_folds=args.folds,
        geometry_config=GeometryConfig(epochs=args.geometry_epochs),
        figures_dir=args.out,
        nmae_normaliser=args.nmae_normaliser,
        ssim_range=args.ssim_range,
    )
    report["wall_seconds"] = time.perf_counter() - began
    json_path = write_json(report, args.out / "stability_learning.json")
    print_summary(report)
    print(f"\n{report['wall_seconds']:.0f} s; wrote {json_path} and {', '.join(report['figures'].values())}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    out = argparse.ArgumentParser(add_help=False)
    out.add_argument("--out", type=Path, default=default_out_dir())
    commands = parser.add_subparsers(dest="command", required=True)
    collection = commands.add_parser(
        "collection", parents=[out], help="soft objects, steep ramps, PLA against TPU (simulated rig)"
    )
    collection.add_argument("--angles", type=int, default=9, help="approach angles per simulated session")
    collection.add_argument("--trials", type=int, default=40, help="random frame phases per (ramp rate, frame period)")
    learning = commands.add_parser(
        "learning", parents=[out], help="errors per outline feature, per material, over seeds of a run"
    )
    learning.add_argument("--run", type=Path, required=True, help="a `unitac-rig train` output folder")
    learning.add_argument("--object", default=None, help="object to break down (default: the run's unseen object)")
    learning.add_argument("--folds", type=int, default=DEFAULT_GEOMETRY_FOLDS, help="geometry folds (0: skip)")
    learning.add_argument("--face-mm", type=float, default=FACE_DISTANCE_MM, help="corner radius of a feature (mm)")
    learning.add_argument("--geometry-epochs", type=int, default=GeometryConfig().epochs)
    learning.add_argument("--nmae-normaliser", default=None, help="NMAE normaliser (default: the run's)")
    learning.add_argument("--ssim-range", default=None, help="SSIM range (default: the run's)")
    args = parser.parse_args()
    (run_collection if args.command == "collection" else run_learning)(args)


if __name__ == "__main__":
    main()
