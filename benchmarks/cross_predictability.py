"""How much of one sensor's reading the other sensor's reading determines, on the simulated scene alone.

A cross-sensor model (UniTac-NV's p -> u and u -> p directions) can only rebuild what the source sensor's frame says
about the target sensor's frame. This module measures that ceiling without the autoencoder: for matched contacts
(same object, approach angle and press force) of the noise-free scene, a small MLP is fitted from the whole source
frame to the whole target frame on most approach angles and scored on held-out ones, per force channel, as R^2 (the
fraction of the channel's variance over the held-out contacts that it explains; 1 = fully determined, 0 = no better
than the channel's mean). A channel with a low ceiling is one the other sensor's frame does not carry.

The scene's seeded errors are switched one at a time (:data:`VARIANTS`) to say which of them takes information away,
e.g. a centring error drawn per session (each sensor saw its own object placement) against one per placement (the
paper's procedure: the object stays, the sensor is swapped).

    python benchmarks/cross_predictability.py [--quick] [--seeds 0,1] [--out docs/figures]

On the six seen objects, fitted on 82 of the 91 approach angles and scored on the 9 held out. Writes
OUT/cross_predictability.json and OUT/cross_predictability.png. About 2-3 min per variant and rig seed on one core;
``--quick`` uses 31 angles, 500 steps and the first two variants, and only prints.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.bench import default_out_dir, machine_info, write_json
from unitac_rig.rig.objects import MATERIALS, get_object
from unitac_rig.sim.fast_rig import seeded_scene
from unitac_rig.sim.scene import SceneParams
from unitac_rig.sim.sensor_models import UskinModel, UskinParams

SEEN_OBJECTS = ("circle_pla", "square_pla", "hex_pla", "circle_tpu", "square_tpu", "hex_tpu")
TARGET_FORCES_N = np.linspace(4.0, 10.0, 25)  # the paper's 25 matching targets
CHANNELS = ("x", "y", "z")
DIRECTIONS = (("uskin", "papillarray"), ("papillarray", "uskin"))
TEST_EVERY = 10  # every 10th approach angle held out (9 of 91, the paper's 10 %)

# name -> (scene parameter changes, material field changes, placement shared by both sensors)
VARIANTS: dict[str, tuple[dict[str, Any], dict[str, dict[str, Any]], bool]] = {
    "placement per session (before)": ({}, {}, False),
    "placement shared (now)": ({}, {}, True),
    "no centring error": ({"centring_error_mm": 0.0}, {}, True),
    "no pad pitch": ({"pad_pitch_deg": 0.0, "pad_pitch_sd_deg": 0.0}, {}, True),
    "no skin bulge": ({"skin_bulge_mm": 0.0}, {}, True),
    "no TPU drag": ({}, {"TPU": {"skin_drag_mm": 0.0}}, True),
}


def paired_scene_frames(
    scene_params: SceneParams,
    *,
    shared_placement: bool,
    seed: int = 0,
    angles: int = 91,
    objects: Sequence[str] = SEEN_OBJECTS,
    materials: dict[str, dict[str, Any]] | None = None,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Matched noise-free frames of both sensors: ``({"uskin": (n, 24, 3) counts, "papillarray": (n, 9, 3) N},
    angle index (n,))``, n = objects x angles x 25 forces. Seeded as the simulated rig seeds its scenes; with
    ``shared_placement`` False each sensor's scene draws its own centring error (the rig before the fix)."""
    uskin = UskinModel(UskinParams(), np.random.default_rng([seed, 2]))
    sweep = np.linspace(-45.0, 45.0, angles)
    frames: dict[str, list[np.ndarray]] = {"uskin": [], "papillarray": []}
    for object_id in objects:
        obj = get_object(object_id)
        if materials and obj.material in materials:
            obj = replace(obj, material_params=replace(MATERIALS[obj.material], **materials[obj.material]))
        for sensor in frames:
            scene = seeded_scene(obj, 0.0, sensor, seed=seed, params=scene_params, shared_placement=shared_placement)
            loads = np.stack(
                [scene.loads_at_force(float(a), float(f)).forces_n for a in sweep for f in TARGET_FORCES_N]
            )
            frames[sensor].append(uskin.signal_counts(loads) if sensor == "uskin" else loads)
    angle_index = np.tile(np.repeat(np.arange(angles), len(TARGET_FORCES_N)), len(objects))
    return {sensor: np.concatenate(parts) for sensor, parts in frames.items()}, angle_index


def channel_r2(target: np.ndarray, estimate: np.ndarray) -> list[float]:
    """R^2 of each force channel (last axis), pooled over frames and taxels: 1 - SSE / SST about the channel's mean.
    NaN for a channel that does not vary (its variance under 1e-9 of the frame's: nothing to explain)."""
    frame_sst = float(np.sum((target - target.mean(axis=tuple(range(target.ndim - 1)))) ** 2))
    out = []
    for c in range(target.shape[-1]):
        t, e = target[..., c], estimate[..., c]
        sst = float(np.sum((t - t.mean()) ** 2))
        out.append(float("nan") if sst <= 1e-9 * frame_sst else 1.0 - float(np.sum((t - e) ** 2)) / sst)
    return out


def fit_and_predict(
    source: np.ndarray, target: np.ndarray, test: np.ndarray, *, seed: int = 0, steps: int = 2000, width: int = 128
) -> np.ndarray:
    """A two-hidden-layer MLP (ReLU, ``width`` units) from the flattened source frame to the flattened target frame,
    both standardised per value, fitted full-batch with Adam (lr 1e-3, MSE) on the rows where ``test`` is False;
    returns its estimate of the target on the test rows, in the target's units and shape."""
    import torch

    torch.manual_seed(seed)
    x = source.reshape(len(source), -1)
    y = target.reshape(len(target), -1)
    x_mean, x_sd = x[~test].mean(0), x[~test].std(0) + 1e-9
    y_mean, y_sd = y[~test].mean(0), y[~test].std(0) + 1e-9
    xt = torch.tensor((x - x_mean) / x_sd, dtype=torch.float32)
    yt = torch.tensor((y[~test] - y_mean) / y_sd, dtype=torch.float32)
    train_rows = torch.from_numpy(np.flatnonzero(~test))
    net = torch.nn.Sequential(
        torch.nn.Linear(x.shape[1], width),
        torch.nn.ReLU(),
        torch.nn.Linear(width, width),
        torch.nn.ReLU(),
        torch.nn.Linear(width, y.shape[1]),
    )
    optimiser = torch.optim.Adam(net.parameters(), lr=1e-3)
    for _ in range(steps):
        optimiser.zero_grad()
        loss = torch.mean((net(xt[train_rows]) - yt) ** 2)
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        estimate = net(xt[torch.from_numpy(np.flatnonzero(test))]).numpy().astype(np.float64)
    return (estimate * y_sd + y_mean).reshape(target[test].shape)


def cross_ceiling(
    frames: dict[str, np.ndarray], angle_index: np.ndarray, *, fit_seeds: Sequence[int] = (0,), steps: int = 2000
) -> dict[str, dict[str, float]]:
    """``{"uskin_to_papillarray": {"x": R^2, ...}, ...}``: held-out R^2 per channel, mean over ``fit_seeds``."""
    test = angle_index % TEST_EVERY == TEST_EVERY // 2
    out: dict[str, dict[str, float]] = {}
    for source, target in DIRECTIONS:
        scores = np.array(
            [
                channel_r2(
                    frames[target][test], fit_and_predict(frames[source], frames[target], test, seed=s, steps=steps)
                )
                for s in fit_seeds
            ]
        )
        out[f"{source}_to_{target}"] = {c: float(v) for c, v in zip(CHANNELS, scores.mean(axis=0), strict=True)}
    return out


def run_cross_predictability(
    *,
    variants: Sequence[str] = tuple(VARIANTS),
    rig_seeds: Sequence[int] = (0, 1),
    angles: int = 91,
    steps: int = 2000,
    on_variant: Callable[[str, dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Every variant's ceiling, per rig seed (a seed is one draw of the placement and mount errors) and their mean."""
    import time

    results: dict[str, Any] = {}
    for name in variants:
        scene_changes, materials, shared = VARIANTS[name]
        t0 = time.perf_counter()
        per_seed = []
        for seed in rig_seeds:
            frames, angle_index = paired_scene_frames(
                replace(SceneParams(), **scene_changes),
                shared_placement=shared,
                seed=seed,
                angles=angles,
                materials=materials,
            )
            per_seed.append(cross_ceiling(frames, angle_index, fit_seeds=(seed,), steps=steps))
        mean = {
            direction: {c: float(np.mean([s[direction][c] for s in per_seed])) for c in CHANNELS}
            for direction in per_seed[0]
        }
        results[name] = {"per_seed": per_seed, "mean": mean, "seconds": time.perf_counter() - t0}
        if on_variant is not None:
            on_variant(name, results[name])
    return {
        "what": "held-out R^2 per channel of an MLP from one sensor's frame to the other's, noise-free scene alone",
        "objects": list(SEEN_OBJECTS),
        "angles": angles,
        "forces_n": [float(f) for f in TARGET_FORCES_N],
        "test": f"every {TEST_EVERY}th approach angle",
        "model": f"MLP 2x128 ReLU, Adam 1e-3, {steps} full-batch steps, standardised inputs and outputs",
        "rig_seeds": list(rig_seeds),
        "machine": machine_info(),
        "variants": results,
    }


def plot_cross_predictability(doc: dict[str, Any], path: Any) -> Any:
    """Grouped bars: per direction, each variant's R^2 on x, y and z ("n/a" where the target channel is constant)."""
    from unitac_rig.plotting import new_figure, save_figure

    names = list(doc["variants"])
    floor = 0.8
    fig = new_figure(12.0, 4.8)
    axes = fig.subplots(1, 2, sharey=True)
    width = 0.8 / len(names)
    for ax, (source, target) in zip(axes, DIRECTIONS, strict=True):
        direction = f"{source}_to_{target}"
        for i, name in enumerate(names):
            cells = [doc["variants"][name]["mean"][direction][c] for c in CHANNELS]  # NaN is null once in JSON
            values = np.array([np.nan if v is None else v for v in cells], dtype=float)
            x = np.arange(3) + (i - (len(names) - 1) / 2) * width
            ax.bar(x, np.nan_to_num(values, nan=floor), width, label=name if ax is axes[0] else None)
            for xi, v in zip(x, values, strict=True):
                if np.isnan(v):
                    ax.text(xi, floor + 0.005, "n/a", rotation=90, ha="center", va="bottom", fontsize=7)
        ax.set_xticks(np.arange(3), [f"{c} channel" for c in CHANNELS])
        ax.set_title(f"{source} frame -> {target} frame (held-out angles)", fontsize=10)
        ax.set_ylim(floor, 1.0)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("R^2 (fraction of the channel's variance)")
    fig.legend(loc="outside lower center", ncol=len(names), fontsize=8, frameon=False)
    fig.suptitle(f"What one sensor's frame determines of the other's, noise-free scene (axis from {floor})")
    return save_figure(fig, path)


def _line(name: str, result: dict[str, Any]) -> str:
    cells = [
        f"{direction.replace('papillarray', 'p').replace('uskin', 'u').replace('_to_', '->')} "
        + "/".join(f"{result['mean'][direction][c]:.3f}" for c in CHANNELS)
        for direction in result["mean"]
    ]
    return f"{name:32s} " + "   ".join(cells) + f"   ({result['seconds']:.0f} s)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="31 angles, 500 steps, two variants; print only")
    parser.add_argument("--seeds", default="0,1", help="comma-separated simulated rig seeds (default 0,1)")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    print("R^2 on held-out angles, x/y/z, mean over rig seeds", flush=True)
    doc = run_cross_predictability(
        variants=list(VARIANTS)[:2] if args.quick else list(VARIANTS),
        rig_seeds=seeds,
        angles=31 if args.quick else 91,
        steps=500 if args.quick else 2000,
        on_variant=lambda name, result: print(_line(name, result), flush=True),
    )
    if args.quick:
        return
    json_path = write_json(doc, args.out / "cross_predictability.json")
    png_path = plot_cross_predictability(doc, args.out / "cross_predictability.png")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
