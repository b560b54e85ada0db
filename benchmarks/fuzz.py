"""Fuzz every wire codec and the drivers' decode paths with seeded generated inputs (issue 28).

    python benchmarks/fuzz.py [--inputs 100000] [--seed 28] [--target NAME ...] [--write-docs]
    python benchmarks/fuzz.py --render-only          # the docs table again from docs/figures/fuzz.json
    python benchmarks/fuzz.py --show xela_ws 1234    # rebuild one input of a campaign (with --seed) and print it

Targets: ``xela_can`` (FrameAssembler; UskinCanDriver's pump), ``xela_ws`` (decode_message; UskinXelaServerDriver's
frame path), ``papillarray`` (PacketParser on chunked streams; PapillArrayDriver's pump), ``papillarray_commands``
(CommandParser, encode_command) and ``rtde`` (RtdePackageParser and every package decoder). Reports crashes
(anything outside the project's error tree), hangs (over 50 ms CPU for one input, twice), wrong decodes of valid
packets placed among garbage and damage, and memory growth of one long-lived decoder (tracemalloc). The method is in
:mod:`lab.fuzz`.

Writes docs/figures/fuzz.json; with ``--write-docs`` also the table between the fuzz markers of docs/reliability.md.
Exits 1 when anything was found. Run it niced on a shared box: ``nice -n 10 python benchmarks/fuzz.py``.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from lab.fuzz import (
    HANG_MS,
    MAX_MEMORY_GROWTH_BYTES,
    TARGETS,
    Report,
    markdown_table,
    rebuild,
    run_campaign,
)
from unitac_rig.bench import machine_info

ROOT = Path(__file__).resolve().parents[1]
OUTPUT = ROOT / "docs" / "figures" / "fuzz.json"
DOCS = ROOT / "docs" / "reliability.md"
TABLE_START = "<!-- fuzz-table:start (benchmarks/fuzz.py --write-docs) -->"
TABLE_END = "<!-- fuzz-table:end -->"


def write_docs(result: dict, docs: Path = DOCS) -> None:
    """Replace the table between the fuzz markers of ``docs`` with the one ``result`` gives."""
    text = docs.read_text()
    if TABLE_START not in text or TABLE_END not in text:
        raise SystemExit(f"{docs} has no fuzz table markers ({TABLE_START} ... {TABLE_END})")
    head, rest = text.split(TABLE_START, 1)
    _, tail = rest.split(TABLE_END, 1)
    totals = result["totals"]
    machine = result["machine"]
    summary = (
        f"Seed {result['seed']}, {result['inputs_per_target']:,} inputs per codec ({totals['inputs']:,} in all), "
        f"{result['wall_s'] / 60:.1f} min on {machine['cpus']} CPUs (load {machine['load_average_1min']} at the end):"
        f" {totals['crashes']} crashes, {totals['hangs']} hangs, {totals['wrong_decodes']} wrong decodes, "
        f"{totals['memory_growth_over_limit']} decoders growing past {result['max_memory_growth_bytes'] // 1024} KiB."
    )
    docs.write_text(f"{head}{TABLE_START}\n{summary}\n\n{markdown_table(result)}\n{TABLE_END}{tail}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--inputs", type=int, default=100_000, help="inputs per codec (default 100000)")
    parser.add_argument("--seed", type=int, default=28, help="campaign seed (default 28)")
    parser.add_argument("--target", action="append", choices=list(TARGETS), help="only these codecs (repeatable)")
    parser.add_argument("--hang-ms", type=float, default=HANG_MS, help="CPU ms per input that counts as a hang")
    parser.add_argument("--output", type=Path, default=OUTPUT, help="where the JSON goes")
    parser.add_argument("--write-docs", action="store_true", help="regenerate the table in docs/reliability.md")
    parser.add_argument("--render-only", action="store_true", help="only regenerate the table from --output")
    parser.add_argument("--show", nargs=2, metavar=("TARGET", "INDEX"), help="print one input of the campaign")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)  # the drivers' warnings about fuzzed packets are the point, not news
    if args.inputs < 1:
        parser.error("--inputs must be at least 1")
    if args.show:
        name, index = args.show
        if name not in TARGETS:
            parser.error(f"--show: unknown target {name!r} (one of {', '.join(TARGETS)})")
        case = rebuild(name, args.seed, int(index))
        print(f"{name} input {index} (seed {args.seed}), kind {case.kind}:\n{case.data!r}\nexpected: {case.expected!r}")
        return 0
    if args.render_only:
        write_docs(json.loads(args.output.read_text()))
        print(f"wrote the fuzz table of {DOCS.relative_to(ROOT)} from {args.output}")
        return 0

    def progress(report: Report) -> None:
        row = report.as_dict()
        print(
            f"{row['target']:>22}: {row['inputs']:,} inputs, {row['crashes']} crashes, {row['hangs']} hangs, "
            f"{row['wrong_decodes']} wrong decodes, {row['valid_recovered']:,}/{row['valid_embedded']:,} valid "
            f"recovered, max {row['cpu_ms_max']:.1f} ms CPU, memory {row['memory']['growth_bytes']:+,} B",
            flush=True,
        )
        for example in row["examples"]:
            print(f"{'':>24}{example}", flush=True)

    result = run_campaign(args.inputs, args.seed, args.target, args.hang_ms, progress)
    result["machine"] = machine_info()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.output}")
    if args.write_docs:
        write_docs(result)
        print(f"wrote the fuzz table of {DOCS.relative_to(ROOT)}")
    totals = result["totals"]
    found = totals["crashes"] + totals["hangs"] + totals["wrong_decodes"] + totals["memory_growth_over_limit"]
    if found:
        print(f"found: {totals} (memory limit {MAX_MEMORY_GROWTH_BYTES:,} B)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
