"""Safety benchmark: true peak force against host stall length (and host death), before and after the force bound
moved to the controller, plus each strategy's overshoot and force-matching error.

Everything runs on the fast twin, whose simulated controller goes on executing its last command while the host is
frozen or dead (``benchmarks/safety_worker.py``, one process per version). The same worker runs against this
checkout ("after") and against an older commit unpacked with ``git archive`` ("before", by default f419c22, the code
issue 11 reviewed), so both columns come from one measurement. Forces are the simulator's ground truth, not the
wrist's noisy reading.

* Stall: the host freezes for 0, 50, 100, 200, 500 or 1000 ms the first time the true press force passes a trigger;
  the triggers sweep the press (first touch, 2, 5, 8, 9, 9.5 N) and the worst one counts ("the worst moment").
* Death: the host stops for good at the trigger (no stop command); the controller runs on alone for 2 s.
* Sessions: a short sweep per strategy and sensor: recorded and true overshoot over the 10 N threshold, |matching
  error| of the 25 targets, misses.

    python benchmarks/bench_safety.py [--quick] [--jobs 2] [--out docs/figures] [--before f419c22] [--after-only]
        [--twin] [--twin-only]

Writes OUT/bench_safety.json and
OUT/bench_safety.png. About 30-40 min on 2 idle cores; ``--quick`` takes a few minutes. ``--twin`` adds the
real-time twin (the hardware path with the real ur_rtde clients): a collecting process killed with kill -9
mid-press, before and after, and a 5-angle session per strategy (about 10 min more); ``--twin-only`` runs just that
part and adds it to an existing JSON.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unitac_rig.bench import default_out_dir, machine_info, write_json

BEFORE_COMMIT = "f419c22"  # the commit issue 11's review checked
STRATEGIES = ("guarded", "two-phase", "force-ramp")
STALLS_S = (0.0, 0.05, 0.1, 0.2, 0.5, 1.0)
TRIGGERS_N = (0.05, 2.0, 5.0, 8.0, 9.0, 9.5)
HARD_LIMIT_N = 25.0  # the rig file's default limits.hard_force_n
GOAL_DEFAULT_EXCESS_N = 0.5  # issue 11: stalls up to 100 ms add at most this on the default strategy
GOAL_REST_S = 0.2  # issue 11: host death -> arm at rest within this of the last write
WORKER = Path(__file__).with_name("safety_worker.py")
REPO = Path(__file__).resolve().parents[1]
# Runs the worker file against whatever checkout PYTHONPATH names: the editable install's finder is dropped, and the
# working directory is not the repository, so neither can shadow the checkout under test.
_RUNNER = (
    "import sys, runpy; "
    "sys.meta_path[:] = [f for f in sys.meta_path if not getattr(f, '__module__', '').startswith('__editable__')]; "
    f"runpy.run_path({str(WORKER)!r}, run_name='__main__')"
)


@dataclass(frozen=True)
class SafetyPlan:
    strategies: tuple[str, ...] = STRATEGIES
    stalls_s: tuple[float, ...] = STALLS_S
    triggers_n: tuple[float, ...] = TRIGGERS_N
    seeds: tuple[int, ...] = (0, 1)
    object_id: str = "square_pla"  # stiff: the worst case for a stall (the table pressed it)
    angle_deg: float = 0.0
    session_object: str = "hex_tpu"
    session_sensors: tuple[str, ...] = ("uskin", "papillarray")
    session_angles: int = 13
    versions: tuple[str, ...] = ("before", "after")
    jobs: int = 2


def quick_plan() -> SafetyPlan:
    """A smoke run (a few minutes on 2 cores)."""
    return SafetyPlan(
        strategies=("guarded", "two-phase"),
        stalls_s=(0.0, 0.2),
        triggers_n=(0.05, 9.0),
        seeds=(0,),
        session_sensors=("uskin",),
        session_angles=3,
    )


@dataclass
class Checkout:
    """Where a version's packages live (``None``: this checkout)."""

    name: str
    path: Path | None
    commit: str | None = None
    _tmp: Any = field(default=None, repr=False)


def before_checkout(commit: str = BEFORE_COMMIT) -> Checkout:
    """``commit`` unpacked into a temporary folder with ``git archive`` (read-only on the repository)."""
    tmp = tempfile.TemporaryDirectory(prefix="unitac-before-")
    archive = subprocess.run(["git", "-C", str(REPO), "archive", commit], check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", tmp.name], input=archive.stdout, check=True)
    return Checkout("before", Path(tmp.name), commit, tmp)


def run_cases(cases: Sequence[dict[str, Any]], checkout: Checkout, jobs: int = 2) -> list[dict[str, Any]]:
    """Run ``cases`` through the worker against ``checkout`` in ``jobs`` processes; -> one result per case."""
    env = {**os.environ, "PYTHONPATH": str(checkout.path or REPO)}
    chunks = [list(cases[i::jobs]) for i in range(jobs) if cases[i::jobs]]

    def run(chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
        proc = subprocess.run(
            [sys.executable, "-c", _RUNNER],
            input=json.dumps(chunk),
            capture_output=True,
            text=True,
            env=env,
            cwd=tempfile.gettempdir(),
            check=False,
        )
        if proc.returncode != 0:
            raise RuntimeError(f"safety worker ({checkout.name}) failed: {proc.stderr[-2000:]}")
        return [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        return [r for part in pool.map(run, chunks) for r in part]


def stall_cases(plan: SafetyPlan) -> list[dict[str, Any]]:
    cases = []
    for strategy in plan.strategies:
        for seed in plan.seeds:
            for stall in (*plan.stalls_s, None):  # None = host death
                triggers = plan.triggers_n if stall != 0.0 else plan.triggers_n[:1]  # no stall: nothing to place
                for trigger in triggers:
                    cases.append(
                        {
                            "strategy": strategy,
                            "stall_s": stall,
                            "trigger_n": trigger,
                            "seed": seed,
                            "object_id": plan.object_id,
                            "angle_deg": plan.angle_deg,
                        }
                    )
    return cases


def session_cases(plan: SafetyPlan) -> list[dict[str, Any]]:
    return [
        {
            "kind": "session",
            "strategy": s,
            "sensor": sensor,
            "object_id": plan.session_object,
            "angles": plan.session_angles,
            "seed": 0,
        }
        for s in plan.strategies
        for sensor in plan.session_sensors
    ]


def summarize_stalls(results: list[dict[str, Any]], plan: SafetyPlan) -> dict[str, Any]:
    """Per strategy and stall length: the worst true peaks over triggers and seeds; death: peaks and rest times."""
    out: dict[str, Any] = {}
    for strategy in plan.strategies:
        mine = [r for r in results if r["strategy"] == strategy and r.get("triggered", True)]
        no_stall = [r["peak_press_n"] for r in mine if r["stall_s"] == 0.0]
        reference = float(np.median(no_stall)) if no_stall else float("nan")
        rows = []
        for stall in (*plan.stalls_s, None):
            cell = [r for r in mine if r["stall_s"] == stall]
            if not cell:
                continue
            worst = max(cell, key=lambda r: r["peak_press_n"])
            row: dict[str, Any] = {
                "stall_s": stall,
                "label": "death" if stall is None else f"{1000 * stall:g} ms",
                "worst_peak_press_n": worst["peak_press_n"],
                "worst_peak_abs_n": max(r["peak_abs_n"] for r in cell),
                "median_peak_press_n": float(np.median([r["peak_press_n"] for r in cell])),
                "worst_trigger_n": worst["trigger_n"],
                "excess_over_no_stall_n": worst["peak_press_n"] - reference,
                "statuses": sorted({f"{r['status']}:{r['reason']}" for r in cell}),
            }
            if stall is None:
                rests = [r.get("rest_after_last_write_s") for r in cell]
                known = [float(v) for v in rests if v is not None]
                row["max_rest_after_last_write_s"] = None if len(known) < len(rests) else max(known)
                row["still_moving_cases"] = sum(v is None for v in rests)
                row["protective_stops"] = sum(bool(r.get("protective_stop")) for r in cell)
            rows.append(row)
        out[strategy] = {"no_stall_median_peak_n": reference, "rows": rows}
    return out


def summarize_sessions(results: list[dict[str, Any]], threshold_n: float = 10.0) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for strategy in sorted({r["strategy"] for r in results}):
        presses = [p for r in results if r["strategy"] == strategy for p in r["presses"]]
        complete = [p for p in presses if p["status"] == "complete"]
        errors = [e for p in complete for e in p["abs_errors_n"]]
        out[strategy] = {
            "presses": len(presses),
            "complete": len(complete),
            "recorded_overshoot_median_n": _median([p["recorded_peak_n"] - threshold_n for p in complete]),
            "true_overshoot_median_n": _median([p["true_peak_n"] - threshold_n for p in complete]),
            "true_overshoot_max_n": max((p["true_peak_n"] - threshold_n for p in complete), default=None),
            "match_error_median_n": _median(errors),
            "match_error_p95_n": float(np.percentile(errors, 95)) if errors else None,
            "misses": sum(p["misses"] for p in presses),
            "targets": sum(p["targets"] for p in presses),
            "press_duration_median_s": _median([p["duration_s"] for p in complete]),
        }
    return out


def _median(values: Sequence[float]) -> float | None:
    return float(np.median(values)) if len(values) else None


def run(plan: SafetyPlan, before_commit: str = BEFORE_COMMIT) -> dict[str, Any]:
    """Measure every version in ``plan.versions``; -> a JSON-ready document."""
    doc: dict[str, Any] = {
        "machine": machine_info(),
        "plan": plan.__dict__,
        "before_commit": before_commit,
        "versions": {},
    }
    for name in plan.versions:
        checkout = before_checkout(before_commit) if name == "before" else Checkout("after", None)
        try:
            stalls = run_cases(stall_cases(plan), checkout, plan.jobs)
            sessions = run_cases(session_cases(plan), checkout, plan.jobs)
        finally:
            if checkout._tmp is not None:
                checkout._tmp.cleanup()
        doc["versions"][name] = {
            "stalls": summarize_stalls(stalls, plan),
            "sessions": summarize_sessions(sessions),
            "raw_stalls": stalls,
        }
    doc["goals"] = goals(doc)
    return doc


def goals(doc: dict[str, Any]) -> dict[str, Any]:
    """Issue 11's targets, checked on the "after" version."""
    after = doc["versions"].get("after")
    if after is None:
        return {}
    stalls = after["stalls"]
    below_hard = all(row["worst_peak_abs_n"] < HARD_LIMIT_N for s in stalls.values() for row in s["rows"])
    default = stalls.get("guarded", {"rows": []})
    short = [r["excess_over_no_stall_n"] for r in default["rows"] if r["stall_s"] is not None and r["stall_s"] <= 0.1]
    deaths = [r for s in stalls.values() for r in s["rows"] if r["stall_s"] is None]
    return {
        "peak_below_hard_limit_for_every_strategy_and_stall": below_hard,
        "default_strategy_worst_excess_up_to_100ms_n": max(short) if short else None,
        "default_strategy_excess_goal_met": bool(short) and max(short) <= GOAL_DEFAULT_EXCESS_N,
        "death_max_rest_after_last_write_s": max(
            (r["max_rest_after_last_write_s"] for r in deaths if r["max_rest_after_last_write_s"] is not None),
            default=None,
        ),
        "death_rest_goal_met": bool(deaths)
        and all(
            r["max_rest_after_last_write_s"] is not None and r["max_rest_after_last_write_s"] <= GOAL_REST_S
            for r in deaths
        ),
    }


def draw(doc: dict[str, Any], path: Path) -> Path:
    """Left: worst true peak press force vs stall length per strategy, before (dashed) and after (solid), host death
    as the last column, the hard limit as a line. Right: true overshoot and median |matching error| per strategy."""
    from unitac_rig.plotting import new_figure, save_figure  # matplotlib loads slowly: only when drawing

    colours = {"guarded": "tab:blue", "two-phase": "tab:orange", "force-ramp": "tab:green"}
    twin = doc.get("twin")
    fig = new_figure(18 if twin else 13, 5)
    axes = fig.subplots(1, 3 if twin else 2, gridspec_kw={"width_ratios": [1.4, 1, 1] if twin else [1.4, 1]})
    left, right = axes[0], axes[1]
    labels: list[str] = []
    for name, style in (("before", "--"), ("after", "-")):
        version = doc["versions"].get(name)
        if version is None:
            continue
        for strategy, summary in version["stalls"].items():
            rows = summary["rows"]
            labels = [r["label"] for r in rows]
            peaks = [r["worst_peak_abs_n"] for r in rows]
            left.plot(
                range(len(rows)), peaks, style, marker="o", color=colours.get(strategy), label=f"{strategy} ({name})"
            )
    left.axhline(HARD_LIMIT_N, color="red", lw=1)
    left.text(0.02, HARD_LIMIT_N * 1.05, "hard limit 25 N", color="red", transform=left.get_yaxis_transform())
    left.set_yscale("log")
    left.set_xticks(range(len(labels)), labels)
    left.set_xlabel("host stall at the worst moment (death: the host never comes back)")
    left.set_ylabel("true peak |F| on the object, N (worst over triggers and seeds)")
    left.set_title("Peak force vs host stall, fast twin")
    left.legend(fontsize=8, ncol=2)
    left.grid(alpha=0.3, which="both")
    strategies = list(doc["versions"].get("after", doc["versions"].get("before", {})).get("sessions", {}))
    x = np.arange(len(strategies))
    width = 0.2
    for k, (name, metric, hatch) in enumerate(
        (
            ("before", "true_overshoot_median_n", None),
            ("after", "true_overshoot_median_n", None),
            ("before", "match_error_median_n", "//"),
            ("after", "match_error_median_n", "//"),
        )
    ):
        version = doc["versions"].get(name)
        if version is None:
            continue
        values = [version["sessions"].get(s, {}).get(metric) or 0.0 for s in strategies]
        what = "true overshoot" if "overshoot" in metric else "median |matching error|"
        right.bar(
            x + (k - 1.5) * width,
            values,
            width,
            hatch=hatch,
            alpha=0.5 if name == "before" else 0.9,
            color="grey" if name == "before" else "tab:blue",
            label=f"{what} ({name})",
        )
    right.set_xticks(x, strategies)
    right.set_ylabel("N")
    right.set_title("Overshoot over 10 N and matching error, per strategy")
    right.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2)
    right.grid(alpha=0.3, axis="y")
    if twin:
        _draw_twin_deaths(axes[2], twin, colours)
    return save_figure(fig, path)


def _draw_twin_deaths(ax: Any, twin: dict[str, Any], colours: dict[str, str]) -> None:
    """kill -9 mid-press on the real-time twin: true peak |F| over the next 3 s, before and after, per strategy."""
    deaths = twin["deaths"]
    strategies = list(dict.fromkeys(d["strategy"] for d in deaths))
    x = np.arange(len(strategies))
    for k, name in enumerate(("before", "after")):
        rows = {d["strategy"]: d for d in deaths if d["version"] == name}
        values = [rows[s]["peak_abs_n"] if s in rows else 0.0 for s in strategies]
        bars = ax.bar(
            x + (k - 0.5) * 0.38,
            values,
            0.38,
            color=[colours.get(s, "grey") for s in strategies],
            alpha=0.45 if name == "before" else 0.95,
            label=name,
        )
        for bar, s in zip(bars, strategies, strict=True):
            row = rows.get(s)
            if row is None:
                continue
            rest = row["rest_after_last_write_s"]
            note = "moving\nafter 3 s" if rest is None else f"rest\n{1000 * rest:.0f} ms"
            ax.annotate(
                note, (bar.get_x() + bar.get_width() / 2, bar.get_height()), ha="center", va="bottom", fontsize=7
            )
    ax.axhline(HARD_LIMIT_N, color="red", lw=1)
    ax.set_yscale("log")
    ax.set_xticks(x, strategies)
    ax.set_ylabel("true peak |F| within 3 s of the kill, N")
    ax.set_title("kill -9 mid-press, real-time twin (real ur_rtde)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both", axis="y")


# ---- the real-time twin: the hardware path (real ur_rtde clients) against the controller twin -------------------

TWIN_FIRST, TWIN_LAST = 160, 179  # loopback addresses this benchmark may take
TWIN_PRESSING_N = 5.0  # the signal lands when the true force passes this (mid-press)
_TWIN_RUNNER = (
    "import sys, runpy; "
    "sys.meta_path[:] = [f for f in sys.meta_path if not getattr(f, '__module__', '').startswith('__editable__')]; "
    "runpy.run_module('unitac_rig', run_name='__main__', alter_sys=True)"
)


def _twin_rig_file(host: str, strategy: str) -> str:
    """A rig file both versions accept (the old one knows none of the new fields), pointing at the twin."""
    return (
        f'name = "twin"\n[arm]\nhost = "{host}"\nfrequency_hz = 500.0\n'
        f'[sensors.uskin]\ntype = "uskin-xela-server"\nurl = "ws://{host}:5000"\n'
        f"[object]\ncenter_m = [-0.15, 0.625]\npress_height_m = 0.2\n"
        f'[press]\nstrategy = "{strategy}"\n'
    )


def _collect(checkout: Checkout, rig_file: Path, data: Path, angles: int) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(checkout.path or REPO), "PYTHONUNBUFFERED": "1"}
    cmd = [
        sys.executable,
        "-c",
        _TWIN_RUNNER,
        "collect",
        "--rig",
        str(rig_file),
        "--object",
        "circle_pla",
        "--sensor",
        "uskin",
        "--angles",
        str(angles),
        "--data",
        str(data),
        "--no-live",
    ]
    return subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tempfile.gettempdir()
    )


def twin_host_death(checkout: Checkout, strategy: str, watch_s: float = 3.0) -> dict[str, Any]:
    """kill -9 of a collecting process the moment the true force passes ``TWIN_PRESSING_N``; what the controller
    twin's ground truth saw over the next ``watch_s``: peak |F|, rest time after the last write, who stopped it."""
    import time

    from unitac_rig.sim.twin import ControllerParams
    from unitac_rig.sim.twin.handle import first_free_loopback
    from unitac_rig.sim.twin.rig import RigTwin

    host = first_free_loopback(TWIN_FIRST, TWIN_LAST)
    with (
        tempfile.TemporaryDirectory() as tmp,
        RigTwin("circle_pla", host=host, seed=1, params=ControllerParams(unlock_delay_s=0.5)) as rig,
    ):
        rig_file = Path(tmp) / "twin.toml"
        rig_file.write_text(_twin_rig_file(host, strategy))
        proc = _collect(checkout, rig_file, Path(tmp) / "data", angles=3)
        try:
            deadline = time.monotonic() + 120
            while rig.controller.truth().force_n < TWIN_PRESSING_N:
                if proc.poll() is not None or time.monotonic() > deadline:
                    _, err = proc.communicate()
                    raise RuntimeError(f"collect ({checkout.name}) never pressed: {err[-1500:]}")
                time.sleep(0.001)
            rig.controller.reset_peak()
            proc.kill()
            seen = []
            end = time.monotonic() + watch_s
            while time.monotonic() < end:
                seen.append(rig.controller.truth())
                time.sleep(0.002)
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.communicate()
        last = seen[-1]
        moving = [t.controller_t_s for t in seen if not t.at_rest]
        rest = (max(moving) if moving else seen[0].controller_t_s) - last.last_input_t_s if last.at_rest else None
        return {
            "version": checkout.name,
            "strategy": strategy,
            "peak_abs_n": last.peak_force_n,
            "rest_after_last_write_s": rest,
            "still_moving_after_s": None if last.at_rest else watch_s,
            "watchdog_trips": last.watchdog_trips,
            "protective_stops": last.protective_stops,
        }


def twin_session(strategy: str, angles: int = 5) -> dict[str, Any]:
    """A short session of ``strategy`` through the hardware path against the twin (this checkout): recorded peaks
    and matching errors from the session file, and each press's true peak from the twin's ground truth."""
    import threading
    import time

    from unitac_rig.sim.twin import ControllerParams
    from unitac_rig.sim.twin.handle import first_free_loopback
    from unitac_rig.sim.twin.rig import RigTwin
    from unitac_rig.storage.reader import read_presses
    from unitac_rig.storage.recorder import session_path

    host = first_free_loopback(TWIN_FIRST, TWIN_LAST)
    with (
        tempfile.TemporaryDirectory() as tmp,
        RigTwin("circle_pla", host=host, seed=1, params=ControllerParams(unlock_delay_s=0.5)) as rig,
    ):
        rig_file = Path(tmp) / "twin.toml"
        rig_file.write_text(_twin_rig_file(host, strategy))
        peaks: list[float] = []
        stop = threading.Event()

        def follow() -> None:  # one true peak per contact: presses are separated by stretches of no force
            current = 0.0
            while not stop.is_set():
                force = rig.controller.truth().force_n
                if force > 0.5:
                    current = max(current, force)
                elif current > 0.0:
                    peaks.append(current)
                    current = 0.0
                time.sleep(0.002)

        thread = threading.Thread(target=follow, name="bench-truth", daemon=True)
        thread.start()
        began = time.monotonic()
        try:
            proc = _collect(Checkout("after", None), rig_file, Path(tmp) / "data", angles)
            _, err = proc.communicate(timeout=600)
        finally:
            stop.set()
            thread.join()
        if proc.returncode != 0:
            raise RuntimeError(f"twin session ({strategy}) failed: {err[-1500:]}")
        presses = read_presses(session_path(Path(tmp) / "data", "circle_pla", "uskin"))
        errors = [
            abs(float(e))
            for p in presses
            if p.extraction is not None
            for e, m in zip(p.extraction.error_n, p.extraction.miss, strict=True)
            if not m
        ]
        return {
            "strategy": strategy,
            "presses": len(presses),
            "complete": sum(p.status == "complete" for p in presses),
            "wall_s": time.monotonic() - began,
            "recorded_overshoot_median_n": _median([float(p.attrs["peak_force_n"]) - 10.0 for p in presses]),
            "true_overshoot_median_n": _median([p - 10.0 for p in peaks]),
            "true_overshoot_max_n": max((p - 10.0 for p in peaks), default=None),
            "match_error_median_n": _median(errors),
            "misses": sum(int(np.sum(p.extraction.miss)) for p in presses if p.extraction is not None),
            "targets": 25 * len(presses),
        }


def run_twin(plan: SafetyPlan, before_commit: str = BEFORE_COMMIT) -> dict[str, Any]:
    """The real-time twin part: host death (kill -9) per strategy and version, and a short session per strategy."""
    out: dict[str, Any] = {"deaths": [], "sessions": {}}
    for name in plan.versions:
        checkout = before_checkout(before_commit) if name == "before" else Checkout("after", None)
        try:
            for strategy in plan.strategies:
                out["deaths"].append(twin_host_death(checkout, strategy))
        finally:
            if checkout._tmp is not None:
                checkout._tmp.cleanup()
    for strategy in plan.strategies:
        out["sessions"][strategy] = twin_session(strategy)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="smoke run: two strategies, two stalls, one seed")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes per version")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON and PNG")
    parser.add_argument("--before", default=BEFORE_COMMIT, help="the commit measured as 'before'")
    parser.add_argument("--after-only", action="store_true", help="skip the 'before' column")
    parser.add_argument("--twin", action="store_true", help="also kill -9 and short sessions on the real-time twin")
    parser.add_argument("--twin-only", action="store_true", help="only the real-time twin part, added to OUT's JSON")
    args = parser.parse_args()
    plan = quick_plan() if args.quick else SafetyPlan()
    plan = dataclasses.replace(plan, jobs=args.jobs, versions=("after",) if args.after_only else plan.versions)
    json_file = args.out / "bench_safety.json"
    doc = json.loads(json_file.read_text()) if args.twin_only else run(plan, before_commit=args.before)
    if args.twin or args.twin_only:
        doc["twin"] = run_twin(plan, before_commit=args.before)
        for death in doc["twin"]["deaths"]:
            print(
                f"  twin kill -9 ({death['version']}, {death['strategy']}): peak {death['peak_abs_n']:.1f} N, "
                f"rest {death['rest_after_last_write_s']} s after the last write"
            )
        for strategy, s in doc["twin"]["sessions"].items():
            print(
                f"  twin session {strategy}: {s['complete']}/{s['presses']} complete, true overshoot "
                f"{s['true_overshoot_median_n']} N, |matching error| {s['match_error_median_n']} N"
            )
    for name, version in doc["versions"].items():
        print(f"== {name}")
        for strategy, summary in version["stalls"].items():
            cells = ", ".join(f"{r['label']}: {r['worst_peak_abs_n']:.1f} N" for r in summary["rows"])
            print(f"  {strategy:10s} worst true |F| by stall: {cells}")
        for strategy, s in version["sessions"].items():
            print(
                f"  {strategy:10s} true overshoot {s['true_overshoot_median_n']} N, |matching error| median "
                f"{s['match_error_median_n']} N, misses {s['misses']}/{s['targets']}"
            )
    print("goals:", doc["goals"])
    json_path = write_json(doc, json_file)
    png_path = draw(doc, args.out / "bench_safety.png")
    print(f"wrote {json_path} and {png_path}")


if __name__ == "__main__":
    main()
