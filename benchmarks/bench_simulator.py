"""Simulator speed and fidelity: how fast the press scene runs, and what its fidelity settings cost and buy.

Run: ``python benchmarks/bench_simulator.py`` (add ``--quick`` for a smoke run). Writes
``docs/figures/sim_bench.json`` and ``docs/figures/sim_bench.png`` and prints a summary.

1. Campaign, scene alone: the paper's whole campaign (7 objects x 2 sensors, the irregular prism at 4 rotations:
   1820 presses). Each press approaches from 2 mm before touch at 5 mm/s until the scene's press force reaches 10 N,
   holds 0.1 s and retracts 2 mm; the wrench is asked at 500 Hz and the taxel loads at 100 Hz, as the simulated arm
   and sensors do. Reports presses per wall second and simulated seconds per wall second.
2. Same, with the sensor output models (noise, counts) through :class:`SceneSensorSource`.
3. With the simulated arm and ``guarded_move`` for one object, both sensors.
4. Fidelity: the uSkin section step (mm) and the per-ray table size against the cost of building a ray and the
   change in taxel loads and travel at 10 N relative to the finest setting.
"""

from __future__ import annotations

import argparse
import functools
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from drivers.clock import VirtualClock
from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from unitac_rig.bench import default_out_dir, machine_info, write_json
from unitac_rig.collection.guarded_motion import guarded_move
from unitac_rig.plotting import new_figure, save_figure
from unitac_rig.rig.objects import get_object, list_objects
from unitac_rig.sim.arm import SimArm
from unitac_rig.sim.scene import PressScene, SceneParams
from unitac_rig.sim.sensor_models import model_for
from unitac_rig.sim.source import SceneSensorSource

ARM_HZ, SENSOR_HZ = 500, 100
SPEED_MM_S, STANDOFF_MM, HOLD_S, STOP_N = 5.0, 2.0, 0.1, 10.0


class _Counts:
    def __init__(self) -> None:
        self.presses = self.wrench_calls = self.taxel_calls = 0
        self.simulated_s = 0.0


def run_press(
    scene: PressScene, angle: int, source: SceneSensorSource | None, pose_box: list[np.ndarray], counts: _Counts
) -> None:
    """Approach, stop at 10 N on the scene's force, hold, retract: 500 Hz wrench, 100 Hz taxel loads."""
    dt = 1.0 / ARM_HZ
    step_mm = SPEED_MM_S * dt
    every = ARM_HZ // SENSOR_HZ
    start = scene.pose_at_travel(angle, -STANDOFF_MM)
    a = math.radians(angle)
    direction_m = np.array([-math.sin(a), math.cos(a), 0.0, 0.0, 0.0, 0.0]) * 1e-3
    ticks = 0

    def tick(travel_mm: float) -> float:
        nonlocal ticks
        pose = start + direction_m * travel_mm
        wrench = scene.wrench_on_tool(pose)
        counts.wrench_calls += 1
        if ticks % every == 0:
            if source is not None:
                pose_box[0] = pose
                source.sample(ticks)
            else:
                scene.taxel_loads(pose)
            counts.taxel_calls += 1
        ticks += 1
        return -float(wrench[:3] @ direction_m[:3]) * 1e3

    travel = 0.0
    while tick(travel) < STOP_N and travel < 30.0:
        travel += step_mm
    for _ in range(round(HOLD_S * ARM_HZ)):
        tick(travel)
    for _ in range(round(STANDOFF_MM / step_mm) + round(travel / step_mm)):
        travel -= step_mm
        tick(travel)
    counts.presses += 1
    counts.simulated_s += ticks * dt


def campaign(angles: list[int], with_sensor_models: bool) -> dict[str, Any]:
    """Run every press of the campaign kinematically against the scene; returns counts and timings."""
    counts = _Counts()
    wall0 = time.perf_counter()
    for obj in list_objects():
        for layout in (USKIN, PAPILLARRAY):
            for rotation in obj.rotations_deg:
                scene = PressScene(obj, rotation, layout)
                pose_box: list[np.ndarray] = [np.zeros(6)]
                source = None
                if with_sensor_models:
                    source = SceneSensorSource(scene, model_for(layout), functools.partial(_first, pose_box))
                for angle in angles:
                    run_press(scene, angle, source, pose_box, counts)
    wall = time.perf_counter() - wall0
    calls = counts.wrench_calls + counts.taxel_calls
    return {
        "presses": counts.presses,
        "simulated_s": counts.simulated_s,
        "wall_s": wall,
        "presses_per_wall_s": counts.presses / wall,
        "simulated_s_per_wall_s": counts.simulated_s / wall,
        "wrench_calls": counts.wrench_calls,
        "taxel_calls": counts.taxel_calls,
        "us_per_call": wall / calls * 1e6,
    }


def _first(box: list[np.ndarray]) -> np.ndarray:
    return box[0]


def with_sim_arm(angles: list[int]) -> dict[str, Any]:
    """Presses through SimArm + guarded_move (the real press path's motion code)."""
    presses, sim_s, peaks = 0, 0.0, []
    wall0 = time.perf_counter()
    for layout in (USKIN, PAPILLARRAY):
        scene = PressScene(get_object("hex_pla"), 0.0, layout)
        for angle in angles:
            clock = VirtualClock()
            arm = SimArm(
                scene,
                clock=clock,
                rng=np.random.default_rng(angle + 100),
                start_pose=scene.pose_at_travel(angle, -STANDOFF_MM),
            )
            try:
                arm.zero_ft()
                a = math.radians(angle)
                result = guarded_move(
                    arm,
                    np.array([-math.sin(a), math.cos(a), 0.0]),
                    SPEED_MM_S * 1e-3,
                    STOP_N,
                    max_travel_m=0.02,
                    hard_limit_n=40.0,
                )
            finally:
                arm.close()
            peaks.append(result.peak_press_force_n)
            presses += 1
            sim_s += clock.now_ns() * 1e-9
    wall = time.perf_counter() - wall0
    return {
        "object": "hex_pla",
        "presses": presses,
        "simulated_s": sim_s,
        "wall_s": wall,
        "presses_per_wall_s": presses / wall,
        "simulated_s_per_wall_s": sim_s / wall,
        "recorded_peak_n_mean": float(np.mean(peaks)),
        "recorded_peak_n_range": [float(np.min(peaks)), float(np.max(peaks))],
    }


def _loads_at_10n(params: SceneParams, layout: SensorLayout, angles: list[int]) -> tuple[np.ndarray, np.ndarray, float]:
    """Taxel loads and travel at 10 N for every object and angle, and the mean ray-build time (ms)."""
    loads, travel, builds, build_s = [], [], 0, 0.0
    for obj in list_objects():
        scene = PressScene(obj, 0.0, layout, params=params)
        for angle in angles:
            t0 = time.perf_counter()
            scene.touch_distance_mm(angle)  # builds the ray's table
            build_s += time.perf_counter() - t0
            builds += 1
            loads.append(scene.loads_at_force(angle, STOP_N).forces_n)
            travel.append(scene.travel_at_force_mm(angle, STOP_N))
    return np.array(loads), np.array(travel), build_s / builds * 1e3


def fidelity(angles: list[int], steps: list[float], points: list[int]) -> dict[str, Any]:
    """Each setting against the finest value of that setting, the other one at its default."""
    references = {
        "section_step_mm": SceneParams(section_step_mm=min(steps) / 4),
        "table_points": SceneParams(table_points=max(points) * 4),
    }
    results: dict[str, Any] = {
        "reference": {"section_step_mm": min(steps) / 4, "table_points": max(points) * 4},
        "angles_deg": angles,
    }
    for layout in (USKIN, PAPILLARRAY):
        rows = []
        settings = [("section_step_mm", s) for s in steps] if layout is USKIN else []
        settings += [("table_points", p) for p in points]
        reference_results = {name: _loads_at_10n(ref, layout, angles) for name, ref in references.items()}
        for name, value in settings:
            ref_loads, ref_travel, _ = reference_results[name]
            loads, travel, build_ms = _loads_at_10n(replace(SceneParams(), **{name: value}), layout, angles)  # type: ignore[arg-type]
            diff = np.abs(loads - ref_loads)
            rows.append(
                {
                    "setting": name,
                    "value": value,
                    "ray_build_ms": build_ms,
                    "max_taxel_error_n": float(diff.max()),
                    "mean_taxel_error_n": float(diff.mean()),
                    "max_travel_error_mm": float(np.abs(travel - ref_travel).max()),
                }
            )
        results[layout.name] = rows
    return results


def plot(report: dict[str, Any], out: Path) -> Path:
    fig = new_figure(11, 4)
    ax_step, ax_points, ax_travel = fig.subplots(1, 3)
    panels = (
        (ax_step, "section_step_mm", "max_taxel_error_n", "max |taxel load - finest| at 10 N (N)"),
        (ax_points, "table_points", "max_taxel_error_n", "max |taxel load - finest| at 10 N (N)"),
        (ax_travel, "table_points", "max_travel_error_mm", "max |travel to 10 N - finest| (mm)"),
    )
    for layout_name, colour in (("uskin", "C0"), ("papillarray", "C1")):
        rows = report["fidelity"][layout_name]
        for ax, setting, metric, _ in panels:
            chosen = [r for r in rows if r["setting"] == setting]
            if not chosen:
                continue
            x = [r["ray_build_ms"] for r in chosen]
            y = [max(r[metric], 1e-7) for r in chosen]
            ax.loglog(x, y, "o-", color=colour, label=layout_name)
            for r, xi, yi in zip(chosen, x, y, strict=True):
                ax.annotate(f"{r['value']:g}", (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points")
    default = SceneParams()
    titles = (
        f"uSkin section step (mm), default {default.section_step_mm:g}",
        f"table points per ray, default {default.table_points}",
        "table points: travel to 10 N",
    )
    for (ax, _, _, ylabel), title in zip(panels, titles, strict=True):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("time to build one press ray (ms)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    camp = report["campaign_scene"]
    fig.suptitle(
        f"Scene fidelity vs speed (errors floored at 1e-7). Campaign ({camp['presses']} presses, "
        f"{camp['simulated_s']:.0f} simulated s): {camp['wall_s']:.1f} s wall, {camp['simulated_s_per_wall_s']:.0f}x "
        "real time (scene alone)",
        fontsize=9,
    )
    return save_figure(fig, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer angles: a smoke run, not numbers to report")
    parser.add_argument("--out", type=Path, default=default_out_dir())
    args = parser.parse_args()
    angles = list(range(-45, 46, 15 if args.quick else 1))
    sweep_angles = list(range(-45, 46, 15 if args.quick else 5))
    report: dict[str, Any] = {
        "host": machine_info(),
        "settings": {"arm_hz": ARM_HZ, "sensor_hz": SENSOR_HZ, "speed_mm_s": SPEED_MM_S, "stop_n": STOP_N},
    }
    report["campaign_scene"] = campaign(angles, with_sensor_models=False)
    report["campaign_scene_and_sensor_models"] = campaign(angles, with_sensor_models=True)
    report["sim_arm_guarded_move"] = with_sim_arm(sweep_angles)
    report["fidelity"] = fidelity(sweep_angles, [0.05, 0.1, 0.25, 0.5, 1.0, 2.0], [25, 50, 100, 200, 400])
    write_json(report, args.out / "sim_bench.json")
    plot(report, args.out / "sim_bench.png")
    for key in ("campaign_scene", "campaign_scene_and_sensor_models", "sim_arm_guarded_move"):
        r = report[key]
        print(
            f"{key}: {r['presses']} presses, {r['simulated_s']:.0f} simulated s in {r['wall_s']:.1f} s wall "
            f"({r['presses_per_wall_s']:.0f} presses/s, {r['simulated_s_per_wall_s']:.0f}x real time)"
        )
    for layout_name in ("uskin", "papillarray"):
        for r in report["fidelity"][layout_name]:
            print(
                f"  {layout_name:12s} {r['setting']:16s} {r['value']:>6g}: build {r['ray_build_ms']:.2f} ms/ray, "
                f"max taxel error {r['max_taxel_error_n']:.4f} N, max travel error {r['max_travel_error_mm']:.4f} mm"
            )
    print(f"wrote {args.out / 'sim_bench.json'} and {args.out / 'sim_bench.png'}")


if __name__ == "__main__":
    main()
