"""Storage: bytes written to disk per session, the single-file layout (before) against press files (after).

    python benchmarks/storage_bytes.py [--before 6641b69] [--out docs/figures]

1. Records a few real presses per sensor on the simulated rig (``collect --object hex_tpu --angles 6``).
2. Replays them, cycled over a session's plan (91 angles per rotation, four rotations for 364 presses), through the
   ``SessionWriter`` of each code version, one subprocess per session: *before* is the commit ``--before`` (the
   single-file writer that copied the whole session file per press), checked out in a temporary git worktree;
   *after* is this checkout. Each subprocess reports its own ``/proc/self/io`` (``write_bytes``: bytes it caused to
   be written to the storage layer, including files deleted before writeback, which ``cancelled_write_bytes`` counts
   separately; ``wchar``: bytes passed to write calls) and CPU time from opening the writer to its last press.
3. Measures sessions of 10, 40 and 91 presses before (the 364-press session is extrapolated from the exact quadratic
   through those three: copy-on-write writes sum_k size(k)), and of 40, 91 and 364 presses after, for both sensors;
   then a campaign: 12 seen-object sessions of 91 presses and 2 irregular-object sessions of 364 (half of each per
   sensor, as ``campaign`` collects them).

Final size is the session as users see it (session file and press files; for the old layout the one file); the
journal (the repair copy, the same size again) is reported beside it. Writes OUT/storage_bytes.json and
OUT/storage_bytes.png. About 3 minutes on a loaded 2-core box. Linux only (``/proc/self/io``).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from lab.versions import ROOT, checkout, run_worker
from unitac_rig.bench import default_out_dir, machine_info, write_json
from unitac_rig.plotting import new_figure, save_figure

BEFORE_COMMIT = "6641b69"  # the last commit whose recorder copied the whole session file for every press
OBJECT = "hex_tpu"
SENSORS = ("uskin", "papillarray")
SOURCE_ANGLES = 6
BEFORE_SIZES = (10, 40, 91)
AFTER_SIZES = (40, 91, 364)
CAMPAIGN = {"seen sessions of 91 presses": (91, 12), "irregular sessions of 364 presses": (364, 2)}
GOAL_RATIO_40 = 4.0  # issue 27: a 40-press session writes at most 4x its final size

# Run in a subprocess with the code version under test first on sys.path: replays SOURCE into a new session.
REPLAY = r"""
import json, sys, time
from pathlib import Path

def io():
    return {k: int(v) for k, v in (line.split(": ") for line in Path("/proc/self/io").read_text().splitlines())}

source, data, count = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
import unitac_rig
from unitac_rig.storage.reader import read_presses, read_session_info
from unitac_rig.storage.press_record import press_id
from unitac_rig.storage.recorder import SessionWriter

info = read_session_info(source)
presses = read_presses(source)
rotations = (0.0, 90.0, 180.0, 270.0)[: max(1, -(-count // 91))]
plan = [(r, a) for r in rotations for a in range(-45, 46)][:count]
attrs = dict(info.attrs)
attrs.pop("schema_version", None)
attrs.pop("attrs_sha256", None)
attrs["planned_presses"] = [press_id(r, a) for r, a in plan]
attrs["rotations_deg"] = list(rotations)
start, cpu = io(), time.process_time()
writer = SessionWriter(data, info.object_id, info.sensor, attrs)
for i, (rotation, angle) in enumerate(plan):
    rec = presses[i % len(presses)]
    rec.press_id, rec.rotation_deg, rec.angle_deg = press_id(rotation, angle), float(rotation), float(angle)
    writer.write_press(rec)
writer.close()
end, cpu = io(), time.process_time() - cpu
code = str(Path(unitac_rig.__file__).parents[1])
print(json.dumps({"io": {k: end[k] - start[k] for k in end}, "cpu_s": cpu, "code": code}))
"""


def _tree_bytes(root: Path, *, journal: bool) -> int:
    """Bytes of the files under ``root``: the journal only, or everything else (the session as users see it)."""
    total = 0
    for path in root.rglob("*"):
        if path.is_file() and (".journal" in path.parts) == journal and path.name != "_writer.lock":
            total += path.stat().st_size
    return total


def record_source(tmp: Path, sensor: str) -> Path:
    """A few real presses of ``sensor`` on the simulated rig, as one self-contained session file."""
    from unitac_rig.storage.reader import snapshot_session
    from unitac_rig.storage.recorder import session_path

    data = tmp / f"source-{sensor}"
    cmd = [
        sys.executable,
        "-m",
        "unitac_rig",
        "collect",
        "--object",
        OBJECT,
        "--sensor",
        sensor,
        "--angles",
        str(SOURCE_ANGLES),
        "--data",
        str(data),
        "--no-live",
    ]
    subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=600)
    single = tmp / f"source-{sensor}.h5"
    snapshot_session(session_path(data, OBJECT, sensor), single)
    return single


def replay(code: Path, source: Path, count: int, data: Path) -> dict[str, Any]:
    """Write ``count`` presses from ``source`` with the SessionWriter of the checkout ``code``; what it cost."""
    out = run_worker(code, ["-c", REPLAY, str(source), str(data), str(count)], timeout=1800)
    if Path(out["code"]).resolve() != code.resolve():
        raise RuntimeError(f"replay imported unitac_rig from {out['code']}, not from {code}")
    session = _tree_bytes(data, journal=False)
    journal = _tree_bytes(data, journal=True)
    io = out["io"]
    return {
        "presses": count,
        "write_bytes": io["write_bytes"],
        "cancelled_write_bytes": io["cancelled_write_bytes"],
        "wchar": io["wchar"],
        "session_bytes": session,
        "journal_bytes": journal,
        "written_per_session_byte": io["write_bytes"] / session,
        "written_per_byte_on_disk": io["write_bytes"] / (session + journal),
        "cpu_s": round(out["cpu_s"], 3),
    }


def quadratic(rows: list[dict[str, Any]], key: str, n: float) -> float:
    """``key`` at ``n`` presses from the exact quadratic through the measured rows (copy-on-write: sum of sizes)."""
    x = np.array([r["presses"] for r in rows], dtype=float)
    y = np.array([r[key] for r in rows], dtype=float)
    return float(np.polyval(np.polyfit(x, y, 2), n))


def per_session(rows: list[dict[str, Any]], n: int, key: str) -> tuple[float, bool]:
    """(``key`` for an n-press session, measured?): the measured row, else the quadratic through the rows."""
    for r in rows:
        if r["presses"] == n:
            return float(r[key]), True
    return quadratic(rows, key, n), False


def campaign(results: dict[str, dict[str, list[dict[str, Any]]]]) -> dict[str, Any]:
    """Bytes written by a campaign (half of each kind of session per sensor), before and after."""
    out: dict[str, Any] = {}
    for version in ("before", "after"):
        total = session_total = 0.0
        parts = []
        for what, (n, sessions) in CAMPAIGN.items():
            for sensor in SENSORS:
                rows = results[sensor][version]
                written, measured = per_session(rows, n, "write_bytes")
                size, _ = per_session(results[sensor]["after"], n, "session_bytes")
                count = sessions // len(SENSORS)
                total += count * written
                session_total += count * size
                parts.append(
                    {
                        "sessions": what,
                        "sensor": sensor,
                        "count": count,
                        "write_bytes_each": written,
                        "measured": measured,
                    }
                )
        out[version] = {"write_bytes": total, "parts": parts}
    out["session_bytes"] = session_total
    return out


def figure(doc: dict[str, Any], path: Path) -> None:
    fig = new_figure(11, 4.2, layout="tight")
    axes = fig.subplots(1, 2)
    ax = axes[0]
    for sensor, style in zip(SENSORS, ("-", "--"), strict=True):
        res = doc["results"][sensor]
        n = np.arange(1, 365)
        before = [quadratic(res["before"], "write_bytes", float(k)) / 1e6 for k in n]
        ax.plot(n, before, style, color="tab:red", label=f"before ({sensor}; 364: extrapolated)")
        xs = [r["presses"] for r in res["before"]]
        ax.plot(xs, [r["write_bytes"] / 1e6 for r in res["before"]], "o", color="tab:red")
        xa = [r["presses"] for r in res["after"]]
        ax.plot(
            xa, [r["write_bytes"] / 1e6 for r in res["after"]], style + "o", color="tab:blue", label=f"after ({sensor})"
        )
        ax.plot(
            xa, [r["session_bytes"] / 1e6 for r in res["after"]], style, color="0.5", label=f"session size ({sensor})"
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("presses in the session")
    ax.set_ylabel("bytes written, MB")
    ax.set_title("bytes written per session")
    ax.legend(fontsize=7)
    ax = axes[1]
    camp = doc["campaign"]
    values = [camp["before"]["write_bytes"] / 1e9, camp["after"]["write_bytes"] / 1e9, camp["session_bytes"] / 1e9]
    ax.bar(["before", "after", "campaign's data"], values, color=["tab:red", "tab:blue", "0.6"])
    for i, v in enumerate(values):
        ax.text(i, v, f"{v:.2f} GB", ha="center", va="bottom", fontsize=8)
    ax.set_ylabel("GB")
    ax.set_title("a campaign: 12 x 91 + 2 x 364 presses")
    fig.suptitle("storage: single-file copy-on-write (before) vs one file per press (after), simulated rig")
    save_figure(fig, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", default=BEFORE_COMMIT, help="git revision of the single-file writer")
    parser.add_argument("--out", type=Path, default=default_out_dir())
    args = parser.parse_args()
    started = time.monotonic()
    results: dict[str, dict[str, list[dict[str, Any]]]] = {}
    with tempfile.TemporaryDirectory(prefix="storage-bytes-") as tmp_name:
        tmp = Path(tmp_name)
        with checkout(args.before) as worktree:
            for sensor in SENSORS:
                source = record_source(tmp, sensor)
                results[sensor] = {"before": [], "after": []}
                for version, code, sizes in (("before", worktree, BEFORE_SIZES), ("after", ROOT, AFTER_SIZES)):
                    for n in sizes:
                        row = replay(code, source, n, tmp / f"{version}-{sensor}-{n}")
                        results[sensor][version].append(row)
                        print(
                            f"{sensor} {version} {n:3d} presses: wrote {row['write_bytes'] / 1e6:8.1f} MB for a "
                            f"{row['session_bytes'] / 1e6:6.1f} MB session ({row['written_per_session_byte']:.2f}x"
                            f"; journal {row['journal_bytes'] / 1e6:.1f} MB), {row['cpu_s']:.1f} CPU-s"
                        )
    camp = campaign(results)
    after_40 = {s: next(r for r in results[s]["after"] if r["presses"] == 40) for s in SENSORS}
    doc = {
        "benchmark": "storage_bytes",
        "machine": machine_info(),
        "before_commit": args.before,
        "object": OBJECT,
        "source_presses_per_sensor": SOURCE_ANGLES,
        "results": results,
        "campaign": camp,
        "goal": {
            "ratio_40_presses_at_most": GOAL_RATIO_40,
            "ratio_40_presses": {s: r["written_per_session_byte"] for s, r in after_40.items()},
            "met": all(r["written_per_session_byte"] <= GOAL_RATIO_40 for r in after_40.values()),
        },
        "wall_s": round(time.monotonic() - started, 1),
    }
    before_gb, after_gb = camp["before"]["write_bytes"] / 1e9, camp["after"]["write_bytes"] / 1e9
    print(
        f"campaign: before {before_gb:.2f} GB, after {after_gb:.2f} GB, for {camp['session_bytes'] / 1e9:.2f} GB "
        f"of sessions; goal met: {doc['goal']['met']}"
    )
    print(f"wrote {write_json(doc, args.out / 'storage_bytes.json')}")
    figure(doc, args.out / "storage_bytes.png")
    print(f"wrote {args.out / 'storage_bytes.png'}")


if __name__ == "__main__":
    main()
