"""Bad inputs: the one line each gets, and its exit status (issue 28 item 7, issue 31 items 1-2).

    python benchmarks/bad_inputs.py [--out docs/figures] [--doc docs/reliability.md]

Runs every input through the real CLI in-process on a scratch directory and records the exit status, the lines on
stderr (there must be exactly one, starting with ``error:``) and whether any recorded file changed. Writes
OUT/bad_inputs.json and the input table between the ``bad-inputs`` markers of the doc. About a minute.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import hashlib
import io
import math
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from unitac_rig.bench import default_out_dir, machine_info, replace_doc_section, write_json
from unitac_rig.cli import main as cli_main
from unitac_rig.learning.run import CHECKPOINT_FORMAT, checkpoint_path

Setup = Callable[[Path], list[str]]


def run_cli(args: list[str]) -> tuple[int, list[str]]:
    err = io.StringIO()
    code = 0
    sys.argv[0] = "unitac-rig"  # typer names the program in its own usage errors
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            cli_main(args)
    except SystemExit as exc:
        code = int(exc.code or 0)
    return code, [line for line in err.getvalue().splitlines() if line.strip()]


def _hashes(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != "_writer.lock"
    }


def _rig(text: str | bytes) -> Setup:
    def setup(work: Path) -> list[str]:
        rig = work / "rig.toml"
        if isinstance(text, bytes):
            rig.write_bytes(text)
        else:
            rig.write_text(text)
        return ["collect", "--object", "hex_tpu", "--rig", str(rig), "--data", str(work / "data"), "--no-live"]

    return setup


def _collect(*extra: str) -> Setup:
    return lambda work: ["collect", "--object", "hex_tpu", "--data", str(work / "data"), "--no-live", *extra]


def _directory_rig(work: Path) -> list[str]:
    (work / "rig.toml").mkdir()
    return ["collect", "--object", "hex_tpu", "--rig", str(work / "rig.toml"), "--data", str(work / "data")]


def _extract(*extra: str) -> Setup:
    return lambda work: ["extract", str(work / "data"), *extra]


def _deep_manifest(work: Path) -> list[str]:
    (work / "export").mkdir()
    (work / "export" / "manifest.json").write_text("[" * 100_000 + "]" * 100_000)
    return ["verify", str(work / "export")]


def _added_file(work: Path) -> list[str]:
    run_cli(["export", str(work / "data"), "--out", str(work / "export")])
    (work / "export" / "raw" / "notes.txt").write_text("added after export")
    return ["verify", str(work / "export")]


def _frames(work: Path) -> Path:
    np.save(work / "frames.npy", np.zeros((2, 24, 3), dtype=np.float32))
    return work / "frames.npy"


def _nan_checkpoint(work: Path) -> list[str]:
    (work / "run").mkdir()
    weights = torch.zeros(4, 72)
    weights[0, 0] = math.nan
    torch.save(
        {
            "format": CHECKPOINT_FORMAT,
            "version": 2,
            "engine": {"parameters": {"uskin.enc.0": {"weight": weights, "bias": torch.zeros(4)}}},
        },
        checkpoint_path(work / "run"),
    )
    return ["translate", str(work / "run"), str(_frames(work)), "--from", "uskin", "--to", "papillarray"]


def _pickled_checkpoint(work: Path) -> list[str]:
    (work / "run").mkdir()
    torch.save(
        {"format": CHECKPOINT_FORMAT, "made": datetime.date(2025, 1, 1)},
        checkpoint_path(work / "run"),
        _use_new_zipfile_serialization=False,
    )
    return ["translate", str(work / "run"), str(_frames(work)), "--from", "uskin", "--to", "papillarray"]


def _other_rig(work: Path) -> list[str]:
    (work / "lab_b.toml").write_text('name = "lab-b"\n')
    return [
        "collect",
        "--object",
        "circle_pla",
        "--sensor",
        "uskin",
        "--rig",
        str(work / "lab_b.toml"),
        "--data",
        str(work / "data"),
        "--angles",
        "2",
        "--no-live",
    ]


INPUTS: list[tuple[str, Setup]] = [
    ("rig file `angle_min_deg = nan`", _rig("[press]\nangle_min_deg = nan\n")),
    ("rig file `angle_max_deg = 1e30`", _rig("[press]\nangle_max_deg = 1e30\n")),
    ("rig file with a 10,000-deep array", _rig("a = " + "[" * 10_000 + "]" * 10_000 + "\n")),
    ("rig file that is not UTF-8", _rig(b"\xff\xfename = 'x'\n")),
    ("rig file that is a directory", _directory_rig),
    ("`collect --seed -1`", _collect("--seed", "-1")),
    ("`collect --angles 1e30`", _collect("--angles", "1e30")),
    ("`collect --angles 1000000000`", _collect("--angles", "1000000000")),
    ("`collect --max-presses -1`", _collect("--max-presses", "-1")),
    ("`extract --tolerance -1`", _extract("--tolerance", "-1")),
    ("`extract --latency nan`", _extract("--latency", "nan")),
    ("`extract --smoothing 0`", _extract("--smoothing", "0")),
    ("`verify` on a 100,000-deep manifest.json", _deep_manifest),
    ("`verify` on an export with a file added", _added_file),
    ("checkpoint with NaN weights (`translate`)", _nan_checkpoint),
    ("checkpoint holding pickled objects, legacy torch format (`translate`)", _pickled_checkpoint),
    ("`collect` into a session recorded on another rig", _other_rig),
]


def controller_row() -> dict[str, Any]:
    """Not a command line: an RTDE client asking the simulated controller for NaN Hz."""
    from protocols import rtde
    from protocols.rtde import ControllerVersion
    from unitac_rig.sim.twin.rtde_session import RtdeSession

    session = RtdeSession("bench", controller_version=ControllerVersion(5, 11, 0, 0), max_frequency_hz=500.0)
    (package,) = rtde.RtdePackageParser().feed(rtde.encode_setup_outputs(math.nan, ["timestamp"]))
    session.handle(package)
    return {
        "input": "RTDE client asks the simulated controller for NaN Hz",
        "exit": None,
        "lines": [f"(no error: streams at {1 / session.period_s:g} Hz, its limit, as for any rate it cannot run)"],
        "one_line": True,
        "unchanged": True,
    }


def record(root: Path) -> Path:
    data = root / "data"
    for sensor in ("uskin", "papillarray"):
        code, lines = run_cli(
            ["collect", "--object", "circle_pla", "--sensor", sensor, "--data", str(data), "--angles", "2", "--no-live"]
        )
        if code != 0:
            raise RuntimeError(f"recording failed: {lines}")
    return data


def table(rows: list[dict[str, Any]]) -> str:
    lines = ["| Input | The one line the user gets | Exit |", "|---|---|---|"]
    for row in rows:
        text = " / ".join(row["lines"]).removeprefix("error: ").replace("|", "\\|")
        lines.append(f"| {row['input']} | `{text}` | {'-' if row['exit'] is None else row['exit']} |")
    bad = [r["input"] for r in rows if not r["one_line"] or not r["unchanged"]]
    lines += ["", f"{len(rows)} inputs; more than one line or a changed file: {', '.join(bad) if bad else 'none'}."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON")
    parser.add_argument("--doc", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "reliability.md")
    args = parser.parse_args()
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        pristine = record(Path(tmp) / "pristine")
        for name, setup in INPUTS:
            work = Path(tempfile.mkdtemp(dir=tmp))
            shutil.copytree(pristine, work / "data")
            argv = setup(work)
            before = _hashes(work / "data")
            code, lines = run_cli(argv)
            lines = [line.replace(f"{work}/", "") for line in lines]  # the scratch folder, not the user's
            one = len(lines) == 1 and lines[0].startswith("error: ")
            rows.append(
                {
                    "input": name,
                    "argv": argv[:1],
                    "exit": code,
                    "lines": lines,
                    "one_line": one,
                    "unchanged": _hashes(work / "data") == before,
                }
            )
            print(f"{code}  {name}: {' / '.join(lines)}")
    rows.append(controller_row())
    path = write_json({"machine": machine_info(), "inputs": rows}, args.out / "bad_inputs.json")
    replace_doc_section(args.doc, "bad-inputs", table(rows))
    print(f"wrote {path} and the table in {args.doc}")


if __name__ == "__main__":
    main()
