"""The benchmarks ``unitac-rig bench`` runs (press, recorder, inference), and what every measuring script shares:
the machine's description, the JSON writer, the Markdown table and the regenerated doc section.

Each benchmark module measures and returns a JSON-ready dict and draws its figure; printing belongs to the callers.
Simulated time (virtual clock) is reported as-is; wall-clock figures are reported next to the hardware rate they
must beat, as ratios, because the machine's speed would otherwise decide the number.
"""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path
from typing import Any

import numpy as np


def machine_info() -> dict[str, Any]:
    """The box a benchmark ran on: CPU count, model, Python and numpy versions, load average (1 min)."""
    model = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {
        "cpus": os.cpu_count(),
        "cpu_model": model,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(),
        "load_average_1min": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
    }


def jsonable(value: Any, digits: int | None = None) -> Any:
    """numpy scalars/arrays to Python; non-finite floats to None (JSON has no inf/NaN); with ``digits``, floats to
    that many significant digits (committed JSON stays small and its diffs readable)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v, digits) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), digits)
    if isinstance(value, np.generic):
        return jsonable(value.item(), digits)
    if isinstance(value, float):
        if not np.isfinite(value):
            return None
        return value if digits is None else float(f"{value:.{digits}g}")
    return value


def write_json(doc: dict[str, Any], path: Path) -> Path:
    """Write ``doc`` as indented JSON (inf/NaN as null), creating the folder; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(jsonable(doc), indent=1) + "\n")
    return path


def default_out_dir() -> Path:
    """docs/figures of the checkout this package lives in, else ./bench-out."""
    docs = Path(__file__).resolve().parents[2] / "docs" / "figures"
    return docs if docs.is_dir() else Path("bench-out")


def replace_doc_section(doc_path: Path, name: str, body: str, markers: tuple[str, str] = ("begin", "end")) -> None:
    """Put ``body`` between ``<!-- name:begin -->`` and ``<!-- name:end -->`` (the words: ``markers``) in a Markdown
    file, keeping every line around them (appended with the markers when they are missing): how a benchmark
    regenerates its part of the docs."""
    doc_path = Path(doc_path)
    text = doc_path.read_text(encoding="utf-8")
    begin, end = (f"<!-- {name}:{marker} -->" for marker in markers)
    block = f"{begin}\n{body}\n{end}"
    if begin in text and end in text:
        text = text[: text.index(begin)] + block + text[text.index(end) + len(end) :]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    doc_path.write_text(text, encoding="utf-8")


def markdown_table(header: list[str], align: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table's lines: ``header`` cells, one ``align`` marker per column (``---``, ``---:``), ``rows``."""
    return [
        "| " + " | ".join(header) + " |",
        "|" + "|".join(align) + "|",
        *("| " + " | ".join(row) + " |" for row in rows),
    ]
