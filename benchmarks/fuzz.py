"""A seeded fuzz campaign over every wire codec and the drivers' decode paths (issue 28).

Each target turns one seeded random draw into one input and feeds it to a codec (and, for the sensors, through the
driver's own decode path with the transport replaced by a fake that hands over the same bytes or messages). Per
target it counts:

* **crashes**: any exception other than the project's own error tree (ProtocolError for a codec, any UnitacError on
  a driver path, where a device error with a hint is an answer, not a crash);
* **hangs**: an input that takes more than ``hang_ms`` of CPU, twice in a row (the retry keeps a garbage-collector
  pause on a loaded box from counting);
* **wrong decodes**: a valid packet, message or command placed among garbage, damage or other packets that does not
  come out exactly as encoded, or anything a decoder accepts that breaks what the format allows (a uSkin frame
  flagged valid that mixes two cycles, a count outside 0..65535, a non-finite server time);
* **memory growth**: one long-lived decoder fed a share of the inputs back to back, traced with tracemalloc; the
  growth between a fifth of the way and the end.

Every input is drawn from ``numpy.random.default_rng((seed, target number, input number))``, so any single input can
be rebuilt from the numbers in the report (:func:`rebuild`). Input kinds: random bytes or messages, mutated valid
ones (bit flips, cuts, insertions, field swaps to extreme values), spliced valid streams, extreme values and length
fields, NaN/inf/huge numbers, deep JSON, non-UTF-8, and byte streams chunked at random sizes.

    python benchmarks/fuzz.py [--inputs 100000] [--seed 28] [--target NAME ...] [--write-docs]
    python benchmarks/fuzz.py --render-only          # the docs table again from docs/figures/fuzz.json
    python benchmarks/fuzz.py --show xela_ws 1234    # rebuild one input of a campaign (with --seed) and print it

Targets (benchmarks/lab/fuzz_targets.py): ``xela_can`` (FrameAssembler; UskinCanDriver's pump), ``xela_ws``
(decode_message; UskinXelaServerDriver's frame path), ``papillarray`` (PacketParser on chunked streams;
PapillArrayDriver's pump), ``papillarray_commands`` (CommandParser, encode_command) and ``rtde``
(RtdePackageParser and every package decoder). Writes docs/figures/fuzz.json; with ``--write-docs`` also the table
between the fuzz-table markers of docs/reliability.md. Exits 1 when anything was found. Run it niced on a shared
box: ``nice -n 10 python benchmarks/fuzz.py``.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import logging
import sys
import time
import tracemalloc
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lab.fuzz_targets import (
    Case,
    PapillArrayCommandTarget,
    PapillArrayTarget,
    Rng,
    RtdeTarget,
    Target,
    XelaCanTarget,
    XelaWsTarget,
)
from unitac_rig.bench import machine_info, replace_doc_section, write_json

HANG_MS = 50.0
MEMORY_SHARE = 0.05  # of the inputs fed back to back to one long-lived decoder under tracemalloc
MIN_MEMORY_INPUTS = 200
MAX_MEMORY_GROWTH_BYTES = 256 * 1024  # a decoder that keeps more than this after thousands of inputs is leaking
EXAMPLES_KEPT = 5


@dataclass
class Report:
    """What one target did with its inputs."""

    target: str
    description: str
    inputs: int = 0
    kinds: Counter[str] = field(default_factory=Counter)
    crashes: int = 0
    hangs: int = 0
    wrong_decodes: int = 0
    valid_embedded: int = 0  # valid packets/messages placed among garbage and damage
    valid_recovered: int = 0
    driver_inputs: int = 0  # inputs also run through the driver's decode path
    cpu_s: float = 0.0
    cpu_ms: list[float] = field(default_factory=list, repr=False)
    memory: dict[str, int] = field(default_factory=dict)
    examples: list[dict[str, Any]] = field(default_factory=list)

    def note(self, finding: str, index: int, case: Case, detail: str) -> None:
        if len(self.examples) < EXAMPLES_KEPT:
            self.examples.append({"finding": finding, "input": index, "kind": case.kind, "detail": detail[:300]})

    def as_dict(self) -> dict[str, Any]:
        cpu = np.array(self.cpu_ms) if self.cpu_ms else np.zeros(1)
        return {
            "target": self.target,
            "description": self.description,
            "inputs": self.inputs,
            "kinds": dict(sorted(self.kinds.items())),
            "crashes": self.crashes,
            "hangs": self.hangs,
            "wrong_decodes": self.wrong_decodes,
            "valid_embedded": self.valid_embedded,
            "valid_recovered": self.valid_recovered,
            "driver_inputs": self.driver_inputs,
            "cpu_s": round(self.cpu_s, 2),
            "cpu_ms_median": round(float(np.median(cpu)), 4),
            "cpu_ms_p99": round(float(np.percentile(cpu, 99)), 3),
            "cpu_ms_max": round(float(cpu.max()), 3),
            "memory": self.memory,
            "examples": self.examples,
        }


# ---- the campaign -----------------------------------------------------------------------------------------------

TARGETS: dict[str, Callable[[], Target]] = {
    "xela_can": XelaCanTarget,
    "xela_ws": XelaWsTarget,
    "papillarray": PapillArrayTarget,
    "papillarray_commands": PapillArrayCommandTarget,
    "rtde": RtdeTarget,
}


def _rng(seed: int, target_name: str, index: int) -> Rng:
    return np.random.default_rng((seed, list(TARGETS).index(target_name), index))


def rebuild(target_name: str, seed: int, index: int) -> Case:
    """The input numbered ``index`` of ``target_name`` in the campaign with ``seed`` (to rerun a finding)."""
    return TARGETS[target_name]().draw(_rng(seed, target_name, index))


def _cases(target: Target, seed: int, n: int) -> Iterator[tuple[int, Case, Rng]]:
    for index in range(n):
        rng = _rng(seed, target.name, index)
        yield index, target.draw(rng), rng


def run_target(
    name: str, n_inputs: int, seed: int, hang_ms: float = HANG_MS, memory_inputs: int | None = None
) -> Report:
    """Feed ``n_inputs`` inputs to one target, then ``memory_inputs`` (default: a share, at least
    :data:`MIN_MEMORY_INPUTS`; 0: none) back to back to a long-lived decoder under tracemalloc."""
    target = TARGETS[name]()
    report = Report(name, target.description)
    for index, case, rng in _cases(target, seed, n_inputs):
        report.inputs += 1
        report.kinds[case.kind] += 1
        outcome = _timed_check(target, case, rng)
        if outcome[0] == "crash":
            report.crashes += 1
            report.note("crash", index, case, outcome[1])
            continue
        cpu_ms, wrong, placed, recovered = outcome[1:]
        if cpu_ms > hang_ms:  # again, on the same input, before calling it a hang
            retry = _timed_check(target, target.draw(_rng(seed, name, index)), _rng(seed, name, index))
            cpu_ms = min(cpu_ms, retry[1] if retry[0] == "ok" else cpu_ms)
            if cpu_ms > hang_ms:
                report.hangs += 1
                report.note("hang", index, case, f"{cpu_ms:.1f} ms CPU")
        report.cpu_ms.append(cpu_ms)
        report.cpu_s += cpu_ms / 1000
        report.valid_embedded += placed
        report.valid_recovered += recovered
        if wrong:
            report.wrong_decodes += wrong
            report.note("wrong_decode", index, case, f"{wrong} wrong of {placed} placed")
    report.driver_inputs = getattr(target, "_driver_turn", 0) // 4
    if memory_inputs is None:
        memory_inputs = max(MIN_MEMORY_INPUTS, round(n_inputs * MEMORY_SHARE))
    if memory_inputs:
        report.memory = memory_growth(target, seed, memory_inputs)
    return report


def _timed_check(target: Target, case: Case, rng: Rng) -> tuple[Any, ...]:
    start = time.process_time()
    try:
        wrong, placed, recovered = target.check(case, rng)
    except target.allowed:
        wrong, placed, recovered = 0, 0, 0
        if case.expected:  # a valid input refused
            wrong = placed = len(case.expected) if isinstance(case.expected, list) else 1
    except Exception as exc:  # everything else is what the campaign looks for
        return ("crash", f"{type(exc).__name__}: {exc}")
    return ("ok", (time.process_time() - start) * 1000, wrong, placed, recovered)


def memory_growth(target: Target, seed: int, n: int) -> dict[str, int]:
    """Bytes one long-lived decoder holds after a fifth of ``n`` inputs and after all of them."""
    feed = target.stream()
    cases = [case for _, case, _ in _cases(target, seed + 1, n)]
    gc.collect()
    tracemalloc.start()
    try:
        fifth = max(1, n // 5)
        for case in cases[:fifth]:
            _quiet(feed, case, target.allowed)
        gc.collect()
        early = tracemalloc.get_traced_memory()[0]
        for case in cases[fifth:]:
            _quiet(feed, case, target.allowed)
        gc.collect()
        late, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return {
        "inputs": n,
        "after_fifth_bytes": early,
        "at_end_bytes": late,
        "growth_bytes": late - early,
        "peak_bytes": peak,
    }


def _quiet(feed: Callable[[Case], None], case: Case, allowed: tuple[type[BaseException], ...]) -> None:
    with contextlib.suppress(*allowed):
        feed(case)


def run_campaign(
    n_inputs: int,
    seed: int,
    targets: list[str] | None = None,
    hang_ms: float = HANG_MS,
    progress: Callable[[Report], None] | None = None,
    memory_inputs: int | None = None,
) -> dict[str, Any]:
    """Every target (or ``targets``) with ``n_inputs`` inputs each; a JSON-ready summary."""
    reports = []
    started = time.perf_counter()
    for name in targets or list(TARGETS):
        report = run_target(name, n_inputs, seed, hang_ms, memory_inputs)
        reports.append(report)
        if progress is not None:
            progress(report)
    rows = [r.as_dict() for r in reports]
    return {
        "benchmark": "fuzz",
        "seed": seed,
        "inputs_per_target": n_inputs,
        "hang_ms": hang_ms,
        "max_memory_growth_bytes": MAX_MEMORY_GROWTH_BYTES,
        "wall_s": round(time.perf_counter() - started, 1),
        "targets": rows,
        "totals": {
            "inputs": sum(r["inputs"] for r in rows),
            "crashes": sum(r["crashes"] for r in rows),
            "hangs": sum(r["hangs"] for r in rows),
            "wrong_decodes": sum(r["wrong_decodes"] for r in rows),
            "memory_growth_over_limit": sum(r["memory"].get("growth_bytes", 0) > MAX_MEMORY_GROWTH_BYTES for r in rows),
        },
    }


def markdown_table(result: dict[str, Any]) -> str:
    """The fuzz table of docs/reliability.md, from a campaign's JSON."""
    lines = [
        "| codec (and driver path) | inputs | crashes | hangs (> {:g} ms CPU) | wrong decodes | valid placed / "
        "recovered | CPU per input: median / max ms | memory growth (long-lived decoder) |".format(result["hang_ms"]),
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in result["targets"]:
        memory = row["memory"] or {"growth_bytes": 0, "inputs": 0}
        lines.append(
            f"| `{row['target']}`: {row['description']} | {row['inputs']:,} | {row['crashes']} | {row['hangs']} | "
            f"{row['wrong_decodes']} | {row['valid_embedded']:,} / {row['valid_recovered']:,} | "
            f"{row['cpu_ms_median']:.3f} / {row['cpu_ms_max']:.1f} | "
            f"{memory['growth_bytes'] / 1024:+.1f} KiB over {memory['inputs']:,} inputs |"
        )
    return "\n".join(lines)


ROOT = Path(__file__).resolve().parents[1]
OUTPUT = ROOT / "docs" / "figures" / "fuzz.json"
DOCS = ROOT / "docs" / "reliability.md"


def write_docs(result: dict[str, Any], docs: Path = DOCS) -> None:
    """Replace the table between the fuzz-table markers of ``docs`` with the one ``result`` gives."""
    totals = result["totals"]
    machine = result["machine"]
    summary = (
        f"Seed {result['seed']}, {result['inputs_per_target']:,} inputs per codec ({totals['inputs']:,} in all), "
        f"{result['wall_s'] / 60:.1f} min on {machine['cpus']} CPUs (load {machine['load_average_1min']} at the end):"
        f" {totals['crashes']} crashes, {totals['hangs']} hangs, {totals['wrong_decodes']} wrong decodes, "
        f"{totals['memory_growth_over_limit']} decoders growing past {result['max_memory_growth_bytes'] // 1024} KiB."
    )
    replace_doc_section(docs, "fuzz-table", f"{summary}\n\n{markdown_table(result)}")


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
    write_json(result, args.output)
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
