"""Figures of the simulated press scene for docs/simulator.md (run: ``python benchmarks/sim_figures.py``).

* ``sim_taxel_maps_uskin.png`` / ``sim_taxel_maps_papillarray.png``: per object (rows) and approach angle (columns),
  what each taxel feels at 10 N (colour = normal force, arrows = shear), with the outline and press rays on the left;
* ``sim_force_travel.png``: press force against travel past first touch, PLA against TPU, both sensors;
* ``sim_readings.png``: the same 10 N presses in wire units (uSkin counts minus baseline, PapillArray N and mm),
  noise included, as a driver would see them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes

from drivers.layouts import PAPILLARRAY, USKIN, SensorLayout
from unitac_rig.bench import default_out_dir
from unitac_rig.plotting import draw_taxel_map, new_figure, save_figure
from unitac_rig.rig.objects import ObjectSpec, list_objects, pad_side_direction
from unitac_rig.sim.scene import PressScene
from unitac_rig.sim.sensor_models import PapillArrayModel, UskinModel

ANGLES_DEG = (-45, -20, 0, 20, 45)
FORCE_N = 10.0


def draw_outline(ax: Axes, obj: ObjectSpec, rotation_deg: float, angles: tuple[int, ...]) -> None:
    """The object's outline as mounted (base axes, mm) with the press rays of ``angles``."""
    outline = obj.outer_rotated_mm(rotation_deg)
    closed = np.vstack([outline, outline[:1]])
    ax.fill(closed[:, 0], closed[:, 1], color="0.85", edgecolor="0.2")
    for angle in angles:
        r = float(np.linalg.norm(obj.outline_hit(pad_side_direction(angle, rotation_deg))))
        a = np.radians(angle)
        u = np.array([np.sin(a), -np.cos(a)])
        tip, tail, label = u * r, u * (r + 14), u * (r + 17)
        arrow = {"arrowstyle": "->", "color": "C3", "lw": 0.8}
        ax.annotate("", xy=(tip[0], tip[1]), xytext=(tail[0], tail[1]), arrowprops=arrow)
        ax.text(label[0], label[1], f"{angle}", fontsize=6, ha="center", va="center")
    ax.set_aspect("equal")
    ax.set_xlim(-45, 45)
    ax.set_ylim(-45, 35)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"{obj.id} (rot {rotation_deg:g})", fontsize=8)


def taxel_maps(layout: SensorLayout, out: Path) -> Path:
    objects = list_objects()
    fig = new_figure(1.6 * (len(ANGLES_DEG) + 1) + 0.8, 1.45 * len(objects) + 0.4)
    axes = fig.subplots(len(objects), len(ANGLES_DEG) + 1)
    vmax = 5.0 if layout is PAPILLARRAY else 2.2
    frames, travels = {}, {}
    for obj in objects:
        scene = PressScene(obj, 0.0, layout)
        for angle in ANGLES_DEG:
            frames[obj.id, angle] = scene.loads_at_force(angle, FORCE_N).forces_n
            travels[obj.id, angle] = scene.travel_at_force_mm(angle, FORCE_N)
    longest = max(float(np.hypot(f[:, 0], f[:, 1]).max()) for f in frames.values())
    arrow_scale = longest / (0.9 * layout.pitch_mm)  # the largest shear in the figure draws 0.9 pitch long
    mappable = None
    for row, obj in enumerate(objects):
        draw_outline(axes[row, 0], obj, 0.0, ANGLES_DEG)
        for col, angle in enumerate(ANGLES_DEG, start=1):
            mappable = draw_taxel_map(
                axes[row, col],
                layout,
                frames[obj.id, angle],
                vmin=0.0,
                vmax=vmax,
                arrow_scale=arrow_scale,
                title=f"{angle} deg, {travels[obj.id, angle]:.2f} mm",
            )
    assert mappable is not None
    fig.colorbar(mappable, ax=axes[:, 1:], shrink=0.5, label="normal force per taxel (N)")
    fig.suptitle(
        f"{layout.model}: taxel loads at {FORCE_N:g} N, travel past touch in titles (colour = normal; red arrows = "
        f"shear, one pitch = {arrow_scale * layout.pitch_mm:.2f} N)",
        fontsize=9,
    )
    return save_figure(fig, out)


def force_travel(out: Path) -> Path:
    travel = np.linspace(0.0, 6.0, 300)
    fig = new_figure(10, 5.2)
    axes = fig.subplots(2, 3, sharex=True, sharey=True)
    shapes = (("circle", 0), ("square", 0), ("square", 45), ("hex", 0), ("hex", 30), ("irregular", 0))
    catalogue = {o.id: o for o in list_objects()}
    for ax, (shape, angle) in zip(axes.flat, shapes, strict=True):
        for material, style in (("pla", "-"), ("tpu", "--")):
            obj = catalogue.get(f"{shape}_{material}")
            if obj is None:
                continue
            for layout, colour in ((USKIN, "C0"), (PAPILLARRAY, "C1")):
                scene = PressScene(obj, 0.0, layout)
                ax.plot(travel, scene.force_curve(angle, travel), style, color=colour, label=f"{obj.id} {layout.name}")
        ax.axhline(FORCE_N, color="0.6", lw=0.8)
        ax.set_title(f"{shape} at {angle} deg", fontsize=9)
        ax.set_ylim(0, 20)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    for ax in axes[-1]:
        ax.set_xlabel("travel past first touch (mm)")
    for ax in axes[:, 0]:
        ax.set_ylabel("press force (N)")
    fig.suptitle("Force against travel: PLA (solid) is stiff, hollow TPU (dashed) travels several mm", fontsize=10)
    return save_figure(fig, out)


def readings(out: Path) -> Path:
    cases = (("square_pla", 0), ("square_pla", 45), ("square_tpu", 0), ("circle_tpu", 0), ("irregular_pla", 20))
    fig = new_figure(2.0 * len(cases), 5.6)
    axes = fig.subplots(3, len(cases))
    rng = np.random.default_rng(7)
    catalogue = {o.id: o for o in list_objects()}
    for col, (object_id, angle) in enumerate(cases):
        obj = catalogue[object_id]
        uskin = UskinModel(rng=rng)
        scene_u = PressScene(obj, 0.0, USKIN)
        counts = uskin.sample(scene_u.loads_at_force(angle, FORCE_N)).values - uskin.baseline_counts
        m = draw_taxel_map(
            axes[0, col],
            USKIN,
            counts,
            vmin=-500,
            vmax=5500,
            arrow_scale=700,
            title=f"{object_id} {angle} deg\nuSkin counts - baseline",
        )
        papill = PapillArrayModel(rng=rng)
        scene_p = PressScene(obj, 0.0, PAPILLARRAY)
        sample = papill.sample(scene_p.loads_at_force(angle, FORCE_N))
        assert sample.displacement_mm is not None
        m2 = draw_taxel_map(
            axes[1, col],
            PAPILLARRAY,
            sample.values - papill.offset_n,
            vmin=0,
            vmax=5.5,
            arrow_scale=0.5,
            title="PapillArray N (biased)",
        )
        m3 = draw_taxel_map(
            axes[2, col],
            PAPILLARRAY,
            sample.displacement_mm - papill.offset_mm,
            vmin=0,
            vmax=1.0,
            arrow_scale=0.12,
            title="PapillArray mm (biased)",
        )
    fig.colorbar(m, ax=axes[0, :], shrink=0.8, label="counts")
    fig.colorbar(m2, ax=axes[1, :], shrink=0.8, label="N")
    fig.colorbar(m3, ax=axes[2, :], shrink=0.8, label="mm")
    fig.suptitle("Readings in wire units at 10 N, noise included (one seeded sample each)", fontsize=10)
    return save_figure(fig, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=default_out_dir())
    args = parser.parse_args()
    written = [
        taxel_maps(USKIN, args.out / "sim_taxel_maps_uskin.png"),
        taxel_maps(PAPILLARRAY, args.out / "sim_taxel_maps_papillarray.png"),
        force_travel(args.out / "sim_force_travel.png"),
        readings(args.out / "sim_readings.png"),
    ]
    for path in written:
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
