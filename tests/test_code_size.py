"""The size rule a newcomer can rely on (docs/architecture.md): no module over 800 lines and no function over 90
lines in the product (``unitac_rig/``, ``drivers/``, ``protocols/``). A module or function that grows past it is
split by what it does, not exempted here."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("unitac_rig", "drivers", "protocols")
MAX_MODULE_LINES = 800
MAX_FUNCTION_LINES = 90


def product_modules() -> list[Path]:
    """The wheel's modules (the measuring code in benchmarks/ is outside them)."""
    return sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def oversized(path: Path, root: Path = ROOT) -> list[str]:
    """What in ``path`` breaks the rule, one line each, named relative to ``root`` (empty when nothing does)."""
    text = path.read_text(encoding="utf-8")
    found = []
    lines = text.count("\n")
    if lines > MAX_MODULE_LINES:
        found.append(f"{path.relative_to(root)}: {lines} lines")
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            length = (node.end_lineno or node.lineno) - node.lineno + 1
            if length > MAX_FUNCTION_LINES:
                found.append(f"{path.relative_to(root)}:{node.lineno} {node.name}: {length} lines")
    return found


def test_the_rule_sees_an_oversized_function_and_module(tmp_path: Path) -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    path = tmp_path / "probe.py"
    path.write_text(f"def long():\n{body}\n" + "\n" * MAX_MODULE_LINES, encoding="utf-8")
    found = oversized(path, tmp_path)
    assert any("long: 91 lines" in line for line in found)
    assert any(line.endswith(f"{MAX_FUNCTION_LINES + 1 + MAX_MODULE_LINES} lines") for line in found)


def test_no_product_module_or_function_is_over_the_size_rule() -> None:
    modules = product_modules()
    assert len(modules) > 100  # the walk found the product
    found = [line for path in modules for line in oversized(path)]
    assert not found, "split these by what they do:\n" + "\n".join(found)
