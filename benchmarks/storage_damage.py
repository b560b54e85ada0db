"""Storage damage: what each command does with a session damaged the ways labs see, and how much data is lost.

    python benchmarks/storage_damage.py [--seeds 12] [--out docs/figures] [--doc docs/reliability.md]

Records a small dataset on the simulated rig (circle_pla and irregular_pla, both sensors, 5 angles), then for each
case damages a fresh copy and runs ``inspect``, ``extract``, ``train`` (1 epoch), ``export`` (then ``verify``) and
``collect`` through the real CLI, in-process. For each it records the exit status, the one error line or the
repairs it reported, how many recorded presses were lost or altered afterwards (raw streams, tare, events and
status compared with the undamaged recording), and for ``export`` whether its manifest certified a file that
differs from the recording. "20 random bits" repeats on ``--seeds`` seeds with ``inspect`` and ``export``.

Writes OUT/storage_damage.json and the storage-damage table between the ``storage-damage`` markers of the doc.
About 16 minutes with --seeds 4 on a 2-core box at a load of about 10 (fewer --seeds: faster); --cases reruns
some cases only.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import logging
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py

from lab.damage import (
    copy_press_over,
    delete_press_file,
    flip_bits,
    flip_bits_in_dataset,
    flip_seal_name,
    press_ids,
    raw_contents,
    swap_journal_entries,
    swap_press_files,
)
from unitac_rig.bench import default_out_dir, machine_info, markdown_table, replace_doc_section, write_json
from unitac_rig.cli import main as cli_main
from unitac_rig.storage.integrity import check_session
from unitac_rig.storage.recorder import journal_dir, session_path

OBJECTS = ("circle_pla", "irregular_pla")
ANGLES = "5"
TARGET = ("circle_pla", "uskin")  # the session every case damages
COMMANDS = ("inspect", "extract", "train", "export", "collect")


class _Capture(logging.Handler):
    """The readers' repair warnings and the recorder's notes (which collect prints as ``recovered: ...``)."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.levelno >= logging.WARNING or record.name == "unitac_rig.storage.recorder":
            self.lines.append(record.getMessage())


def run_cli(args: list[str]) -> tuple[int, str, list[str]]:
    """(exit status, stderr, repair notes) of ``unitac-rig ARGS`` run in-process."""
    handler = _Capture()
    logging.getLogger().addHandler(handler)
    recorder_log = logging.getLogger("unitac_rig.storage.recorder")
    recorder_log.setLevel(logging.INFO)
    err = io.StringIO()
    code = 0
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            cli_main(args)
    except SystemExit as exc:
        code = int(exc.code or 0)
    finally:
        logging.getLogger().removeHandler(handler)
        recorder_log.setLevel(logging.NOTSET)
    notes = list(dict.fromkeys(handler.lines))  # a reader logs the recorder's notes again, with the path
    return code, err.getvalue().strip(), notes


def collect_args(obj: str, sensor: str, data: Path) -> list[str]:
    return ["collect", "--object", obj, "--sensor", sensor, "--data", str(data), "--angles", ANGLES, "--no-live"]


def record_dataset(root: Path) -> Path:
    data = root / "pristine"
    for obj in OBJECTS:
        for sensor in ("uskin", "papillarray"):
            code, err, _ = run_cli(collect_args(obj, sensor, data))
            if code != 0:
                raise RuntimeError(f"recording the dataset failed: {err}")
    return data


def command_args(command: str, data: Path, work: Path) -> list[str]:
    train = ["train", "--data", str(data), "--out", str(work / "run"), "--epochs", "1"]
    return {
        "inspect": ["inspect", str(data)],
        "extract": ["extract", str(data)],
        "train": [*train, "--no-report", "--no-baselines"],
        "export": ["export", str(data), "--out", str(work / "export")],
        "collect": collect_args(*TARGET, data),
    }[command]


# -- the damage cases: each changes a fresh copy of the dataset; CASES: name -> (the table's label, the damage) ----

CASES: dict[str, tuple[str, Callable[[Path], None]]] = {}


def case(label: str) -> Callable[[Callable[[Path], None]], Callable[[Path], None]]:
    def register(damage: Callable[[Path], None]) -> Callable[[Path], None]:
        CASES[damage.__name__] = (label, damage)
        return damage

    return register


def _target(data: Path) -> Path:
    return session_path(data, *TARGET)


@case("20 flipped bits: raw arrays of 3 presses changed, tactile/values of 2 unreadable; journal intact")
def review_bits(data: Path) -> None:
    """The review's case: 20 bits changing raw arrays of 3 presses and the compressed tactile/values of 2."""
    path = _target(data)
    pids = press_ids(path)
    spots = [
        (pids[0], "robot/t_s"),
        (pids[1], "robot/press_force_n"),
        (pids[2], "tactile/seq"),
        (pids[3], "tactile/values"),
        (pids[4], "tactile/values"),
    ]
    for seed, (pid, dataset) in enumerate(spots):
        flip_bits_in_dataset(path, f"presses/{pid}/{dataset}", 4, seed)


@case("a press damaged in the session file and in its journal entry")
def both_copies(data: Path) -> None:
    pid = press_ids(_target(data))[2]
    flip_bits_in_dataset(_target(data), f"presses/{pid}/robot/press_force_n", 4, 0)
    flip_bits_in_dataset(journal_dir(data, *TARGET) / f"{pid}.h5", "press/robot/press_force_n", 4, 1)


@case("a damaged press, no journal (files copied without .journal/)")
def no_journal(data: Path) -> None:
    shutil.rmtree(data / ".journal")
    pid = press_ids(_target(data))[1]
    flip_bits_in_dataset(_target(data), f"presses/{pid}/tactile/values", 4, 0)


@case("session file truncated to a third; journal intact")
def truncated(data: Path) -> None:
    path = _target(data)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 3])


@case("journal entry torn (1.5 kB left); session file intact")
def torn_journal(data: Path) -> None:
    entry = journal_dir(data, *TARGET) / f"{press_ids(_target(data))[0]}.h5"
    entry.write_bytes(entry.read_bytes()[:1500])


@case("a foreign HDF5 file under the session's name; journal intact")
def foreign(data: Path) -> None:
    _target(data).unlink()
    with h5py.File(_target(data), "w") as f:
        f["something_else"] = [1.0, 2.0, 3.0]


@case("journal header (_session.json) cut short")
def broken_header(data: Path) -> None:
    (journal_dir(data, *TARGET) / "_session.json").write_text('{"object": "circle_pla", "sens')


@case("every checksum and the root seal stripped, schema_version 1 (one format is read: damage)")
def checksums_stripped(data: Path) -> None:
    """Every checksum and the root seal removed (what schema 1 wrote): only schema 3 is read, so this is damage."""
    for path in data.glob("*__*.h5"):
        with h5py.File(path, "a") as f:
            f.attrs["schema_version"] = 1
            del f.attrs["attrs_sha256"]
            for g in f["presses"].values():
                del g.attrs["checksums"]


# -- issue 41: a press intact but in the wrong place, the journal's own damage, a vanished session, a killed extract


@case("irregular_pla's press file copied over circle_pla's file of that press")
def other_object_press(data: Path) -> None:
    copy_press_over(data, ("irregular_pla", TARGET[1]), TARGET)


@case("a uSkin press file copied over the PapillArray session's file of that press")
def other_sensor_press(data: Path) -> None:
    copy_press_over(data, (TARGET[0], "uskin"), (TARGET[0], "papillarray"))


@case("two press files of the session swapped")
def swapped_press_files(data: Path) -> None:
    swap_press_files(data, *TARGET)


@case("two journal entries swapped, then a press file deleted")
def journal_swapped_then_deleted(data: Path) -> None:
    swap_journal_entries(data, *TARGET)
    delete_press_file(data, *TARGET, 0)


@case("the session file deleted (its press files and journal stay)")
def session_deleted(data: Path) -> None:
    _target(data).unlink()


@case("3 bits flipped in a journal entry")
def journal_entry_flipped(data: Path) -> None:
    entry = journal_dir(data, *TARGET) / f"{press_ids(_target(data))[1]}.h5"
    flip_bits_in_dataset(entry, "press/robot/press_force_n", 3, 0)


@case("a journal entry deleted")
def journal_entry_deleted(data: Path) -> None:
    (journal_dir(data, *TARGET) / f"{press_ids(_target(data))[1]}.h5").unlink()


@case("the journal's _session.json deleted")
def header_deleted(data: Path) -> None:
    (journal_dir(data, *TARGET) / "_session.json").unlink()


@case("one bit flipped in the root seal's attribute name (attrs_sha256 reads as absent)")
def seal_name_flipped(data: Path) -> None:
    flip_seal_name(_target(data))


@case("extract killed right after its session file's rename, then a press file deleted")
def extract_killed(data: Path) -> None:
    """extract killed right after its session file's rename (press files and session NEW, journal OLD), then a
    press file deleted: the repair must give the press the NEW extraction."""
    import os

    from unitac_rig.storage import reextract
    from unitac_rig.storage.extraction import ExtractionSettings

    presses = len(press_ids(_target(data)))
    real, done = os.replace, [0]

    def killed(src: Any, dst: Any) -> None:
        if done[0] >= presses + 1:
            raise KeyboardInterrupt
        done[0] += 1
        real(src, dst)

    reextract.os.replace = killed  # type: ignore[assignment]
    try:
        reextract.reextract_sessions([_target(data)], ExtractionSettings(tolerance_n=0.45))
    except KeyboardInterrupt:
        pass
    finally:
        reextract.os.replace = real
    delete_press_file(data, *TARGET, 0)


def _lost(pristine: Path, data: Path) -> tuple[int, int]:
    """(presses lost or altered, presses recorded) over every session, against the undamaged recording."""
    lost = total = 0
    for path in sorted(pristine.glob("*__*.h5")):
        before, after = raw_contents(path), raw_contents(data / path.name)
        total += len(before)
        lost += sum(after.get(pid) != digest for pid, digest in before.items())
    return lost, total


def _in_step(data: Path) -> bool:
    """Whether every press of the target session carries the extraction its session file's settings say (a press
    restored from an older journal copy would not), where the file says any."""
    try:
        with h5py.File(_target(data), "r") as f:
            root = f.attrs.get("extraction_settings")
            if root is None:
                return True
            settings = json.loads(root)
            return all(json.loads(g["extraction"].attrs["settings"]) == settings for g in f["presses"].values())
    except Exception:  # a refused, still damaged file: nothing was certified from it
        return True


def _certified_damage(pristine: Path, export: Path) -> bool:
    """Whether an export's manifest lists a raw session that differs from what was recorded."""
    manifest = export / "manifest.json"
    if not manifest.is_file():
        return False
    for entry in json.loads(manifest.read_text())["sessions"]:
        copy = export / entry["file"]
        if raw_contents(copy) != raw_contents(pristine / copy.name) or check_session(copy).needs_repair:
            return True
    return False


def _summary(code: int, err: str, notes: list[str], work: Path) -> str:
    if code != 0:
        line = err.splitlines()[-1].removeprefix("error: ") if err else ""
        return f"exit {code}: `{_clip(line.replace(str(work) + '/', ''), 170)}`"
    if any("read without verification" in n for n in notes):
        return "exit 0, reads them and says `not verified` (no checksums)"
    repairs = list(dict.fromkeys(_short(n) for n in notes))
    if not repairs:
        return "exit 0"
    verbs = ("rewritten", "replaced", "restored", "rebuilt", "dropped", "moved aside")
    said = "repaired" if any(verb in note for note in repairs for verb in verbs) else "warned"
    return f"exit 0, {said}: {'; '.join(repairs)}"


def _clip(text: str, width: int) -> str:
    return text if len(text) <= width else text[: text.rfind(" ", 0, width)] + " …"


def _short(note: str) -> str:
    """A repair note without paths, press ids and parenthesised detail, so equal repairs read once."""
    import re

    note = re.sub(r"^/\S+: ", "", note)
    note = re.sub(r"/\S+/data/", "", note)  # a file of the damaged copy: its name is enough
    note = re.sub(r"rot\d{3}_ang[+-]\d+(\.h5)?", "X", note)
    note = re.sub(r"press X \((complete|failed|aborted)\)", "press X", note)
    while re.search(r"\([^()]*\)", note):
        note = re.sub(r" ?\([^()]*\)", "", note)
    note = re.sub(r"\S+\.broken-\S+", "`*.broken-*.h5`", note)
    return _clip(" ".join(note.split()), 120)


def run_case(pristine: Path, root: Path, damage: Callable[[Path], None], command: str) -> dict[str, Any]:
    work = Path(tempfile.mkdtemp(dir=root))
    data = work / "data"
    shutil.copytree(pristine, data)
    damage(data)
    started = time.perf_counter()
    code, err, notes = run_cli(command_args(command, data, work))
    result: dict[str, Any] = {
        "exit": code,
        "error": err.splitlines()[-1] if err else "",
        "notes": notes,
        "seconds": round(time.perf_counter() - started, 2),
    }
    lost, total = _lost(pristine, data)
    result.update(lost=lost, presses=total, summary=_summary(code, err, notes, work), in_step=_in_step(data))
    if command == "export":
        result["certified_damage"] = _certified_damage(pristine, work / "export")
        if (work / "export").is_dir():
            result["verify_exit"] = run_cli(["verify", str(work / "export")])[0]
    shutil.rmtree(work, ignore_errors=True)
    return result


def random_bits(pristine: Path, root: Path, seeds: int) -> dict[str, Any]:
    """20 random bits anywhere in the target file, ``seeds`` times: inspect then export on each copy."""
    outcomes: dict[str, Any] = {
        "repaired": 0,
        "refused": 0,
        "untouched": 0,
        "passed_on_damaged": 0,
        "export_certified_damage": 0,
        "lost": 0,
        "seeds": seeds,
    }
    for seed in range(seeds):
        work = Path(tempfile.mkdtemp(dir=root))
        data = work / "data"
        shutil.copytree(pristine, data)
        flip_bits(_target(data), 20, seed)
        code, _, notes = run_cli(command_args("inspect", data, work))
        lost, _ = _lost(pristine, data)
        if code != 0:
            outcomes["refused"] += 1
        elif notes:
            outcomes["repaired"] += 1
        else:
            outcomes["untouched"] += 1  # the bits fell where nothing is read (free space, padding)
        if code == 0 and lost:
            outcomes["passed_on_damaged"] += 1
        outcomes["lost"] += lost
        run_cli(command_args("export", data, work))
        outcomes["export_certified_damage"] += int(_certified_damage(pristine, work / "export"))
        shutil.rmtree(work, ignore_errors=True)
    return outcomes


def table(doc: dict[str, Any]) -> str:
    rows = []
    for case in doc["cases"].values():
        cells, lost = [], []
        for command in COMMANDS:
            r = case["commands"][command]
            cell = r["summary"] + ("" if r.get("in_step", True) else "; **extraction out of step with the session**")
            if command == "export" and "verify_exit" in r:
                cell += f"; manifest certifies damage: {'**yes**' if r['certified_damage'] else 'no'}"
            cells.append(cell.replace("|", "\\|"))
            if r["lost"]:
                lost.append(f"`{command}`: {r['lost']} of {r['presses']} presses")
        counts = {r["lost"] for r in case["commands"].values()}
        if len(counts) == 1 and counts != {0}:
            r = next(iter(case["commands"].values()))
            lost = [f"{r['lost']} of {r['presses']} presses, whatever the command"]
        rows.append([case["label"], *cells, "; ".join(lost) or "none"])
    rb = doc["random_bits"]
    header = ["Damage", *(f"`{c}`" for c in COMMANDS), "data lost"]
    lines = markdown_table(header, ["---"] * (len(COMMANDS) + 2), rows)
    lines += [
        "",
        "Data lost: recorded presses (raw streams, tare, events, status) that cannot be read back as recorded "
        f"afterwards (missing or different), against the undamaged recording ({', '.join(doc['objects'])}, both "
        f"sensors, {doc['angles']} angles). A press damaged in every copy is lost whatever the command: the readers "
        "leave it as it was and refuse; `collect` drops it and presses it again (new data), keeping the damaged "
        "copies aside.",
        "",
        f"20 random bits anywhere in `{doc['target']}.h5`, {rb['seeds']} seeds, `inspect` then `export`: "
        f"{rb['repaired']} repaired from the journal, {rb['refused']} refused with one line, {rb['untouched']} "
        f"where the bits changed nothing that is read; passed on damaged: {rb['passed_on_damaged']}; export "
        f"manifests certifying damage: {rb['export_certified_damage']}; presses lost: {rb['lost']}. "
        f"({doc['seconds']:.0f} s on {doc['machine']['cpus']} CPUs at a load average of "
        f"{doc['machine']['load_average_1min']}.)",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=12, help="seeds of the 20-random-bits case")
    parser.add_argument("--out", type=Path, default=default_out_dir(), help="folder for the JSON")
    parser.add_argument("--doc", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "reliability.md")
    parser.add_argument("--table-only", action="store_true", help="redraw the table from OUT/storage_damage.json")
    parser.add_argument(
        "--cases",
        nargs="+",
        choices=sorted(CASES),
        help="rerun only these cases, merged into OUT/storage_damage.json (the random bits and the rest as they were)",
    )
    args = parser.parse_args()
    if args.table_only:
        replace_doc_section(
            args.doc, "storage-damage", table(json.loads((args.out / "storage_damage.json").read_text()))
        )
        return
    logging.getLogger().setLevel(logging.WARNING)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        pristine = record_dataset(root)
        doc: dict[str, Any] = {
            "machine": machine_info(),
            "objects": list(OBJECTS),
            "angles": int(ANGLES),
            "target": "__".join(TARGET),
            "cases": {},
        }
        if args.cases:
            doc = json.loads((args.out / "storage_damage.json").read_text())
        for key, (label, damage) in CASES.items():
            if args.cases and key not in args.cases:
                continue
            results = {command: run_case(pristine, root, damage, command) for command in COMMANDS}
            doc["cases"][key] = {"label": label, "commands": results}
            print(f"{key}: " + ", ".join(f"{c} {r['exit']}" for c, r in results.items()))
        if not args.cases:
            doc["random_bits"] = random_bits(pristine, root, args.seeds)
        print(f"random bits: {doc['random_bits']}")
    if not args.cases:
        doc["seconds"] = round(time.perf_counter() - started, 1)
    path = write_json(doc, args.out / "storage_damage.json")
    replace_doc_section(args.doc, "storage-damage", table(doc))
    print(f"wrote {path} and the table in {args.doc} ({doc['seconds']} s)")


if __name__ == "__main__":
    main()
