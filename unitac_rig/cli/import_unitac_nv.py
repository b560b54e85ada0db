"""``unitac-rig import-unitac-nv``: turn the published UniTac-NV dataset into this project's session files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from unitac_rig.errors import DataError, UsageError

if TYPE_CHECKING:  # the importer and rich load when the command runs, not when the CLI starts
    from rich.console import Console

    from unitac_rig.importer.pipeline import FileReport, ImportReport


def import_unitac_nv_command(
    source: Path = typer.Argument(
        ...,
        help="Folder holding 'UniTac-NV Dataset', 'arbitrary_obj' and/or 'UniTac-NV Dataset Processed' (or one file).",
    ),
    data: Path = typer.Option(..., "--data", help="Dataset directory to write the session files into."),
    conventions: Path | None = typer.Option(
        None, "--conventions", help="TOML file overriding the import conventions (see docs/import.md)."
    ),
    mode: str = typer.Option("auto", "--mode", help="auto (raw where present), raw, or processed."),
    processed: bool = typer.Option(False, "--processed", help="Same as --mode processed."),
    show_conventions: bool = typer.Option(
        False, "--show-conventions", help="Print the effective conventions as TOML and exit."
    ),
) -> None:
    """Import the dataset published by the UniTac-NV authors (download it by hand first, see docs/import.md)."""
    from rich.console import Console

    from unitac_rig.importer.conventions import load_conventions
    from unitac_rig.importer.pipeline import import_unitac_nv

    console = Console(highlight=False, soft_wrap=True, markup=False)
    conv = load_conventions(conventions)
    if show_conventions:
        typer.echo(conv.to_toml(), nl=False)
        return
    if not source.exists():
        raise UsageError(f"SOURCE {source} does not exist", hint="unzip the UniTac-NV download and pass its folder")
    mode = "processed" if processed else mode  # checked by the importer (a usage error, exit 2)
    console.print(
        f"conventions: {conventions or 'defaults'} (F/T rotated {conv.ft_rotation_deg:g} deg, PapillArray x/y "
        f"{'flipped' if conv.papillarray_flip_xy else 'kept'}, press band {conv.press_fz_band_n[0]:g} < Fz < "
        f"{conv.press_fz_band_n[1]:g} N, baseline {conv.baseline_samples} samples after dropping "
        f"{conv.drop_first_rows} rows)"
    )

    result = import_unitac_nv(source, data, conv, mode=mode, on_file=lambda report: _show_file(console, report))
    if not result.sessions:
        raise UsageError(
            f"no UniTac-NV files found under {source}",
            hint="expected e.g. 'UniTac-NV Dataset/hexagonal_PLA/xela/sensor_data_*.csv' (see docs/import.md)",
        )
    console.print("")
    outcomes = _show_totals(console, result)
    failed = outcomes.count("failed")
    if failed:
        raise DataError(
            f"{failed} of {len(outcomes)} files could not be imported (see above)",
            hint="the rest was imported; fix or remove those files and rerun to add them",
        )


def _show_file(console: Console, report: FileReport) -> None:
    """One imported (or skipped) file and what was dropped from it."""
    where = f"{report.relative} -> {report.object_id}__{report.sensor}"
    if report.outcome == "imported":
        line = (
            f"  {where}: {report.presses_found} presses found, {report.complete} complete, "
            f"{report.targets_matched} targets matched, {report.written} written"
        )
        if report.already_written:
            line += f" ({report.already_written} already there from an interrupted run)"
        console.print(line)
    else:
        console.print(f"  {where}: {report.outcome}: {report.message}")
    if report.bad_rows:
        listed = ", ".join(f"row {row} ({reason})" for row, reason in report.bad_rows[:5])
        more = f" and {len(report.bad_rows) - 5} more" if len(report.bad_rows) > 5 else ""
        console.print(f"    {len(report.bad_rows)} rows could not be parsed and were dropped: {listed}{more}")
    for text in report.duplicates:
        console.print(f"    dropped {text}")
    for note in report.notes:
        console.print(f"    note: {note}")


def _show_totals(console: Console, result: ImportReport) -> list[str]:
    """One line per session written and the totals; -> the outcome of every file."""
    written = [s for s in result.sessions if s.path.exists()]
    for s in written:
        console.print(
            f"{s.object_id}__{s.sensor}: {s.presses} presses, {s.complete} complete, "
            f"{s.targets_matched}/{s.targets_total} targets matched ({s.path})"
        )
    presses, complete, matched, targets = (
        sum(getattr(s, name) for s in written) for name in ("presses", "complete", "targets_matched", "targets_total")
    )
    outcomes = [f.outcome for f in result.files]
    counts = ", ".join(f"{outcomes.count(o)} {o}" for o in dict.fromkeys(outcomes))
    console.print(
        f"total: {len(written)} sessions, {presses} presses, {complete} complete, "
        f"{matched}/{targets} targets matched; files: {counts}"
    )
    if result.superseded:
        console.print(f"{len(result.superseded)} processed files not used: their sessions have raw files")
    if result.ignored:
        console.print(f"{len(result.ignored)} files ignored (not UniTac-NV sessions), e.g. {result.ignored[0]}")
    return outcomes
