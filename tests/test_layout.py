"""Modules with one job: no module of lvcore over 700 lines, no function (or method) over 120 lines.

A function's length runs from its first decorator (or ``def``) to its last line, docstring included; a
module's is its number of lines. The checks read the source with :mod:`ast` and never import it.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "lvcore"
MAX_MODULE_LINES = 700
MAX_FUNCTION_LINES = 120

def module_lines(path: Path) -> int:
    """Number of lines of a source file."""
    return len(path.read_text(encoding="utf-8").splitlines())


def long_functions(path: Path, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int, int]]:
    """``(name, first line, length)`` of every function or method in ``path`` longer than ``limit`` lines."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            first = min([node.lineno] + [d.lineno for d in node.decorator_list])
            length = node.end_lineno - first + 1
            if length > limit:
                out.append((node.name, first, length))
    return out


def _modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def test_no_module_is_over_the_line_limit():
    over = {p.relative_to(ROOT).as_posix(): n for p in _modules() if (n := module_lines(p)) > MAX_MODULE_LINES}
    assert not over, (f"modules over {MAX_MODULE_LINES} lines: {over}; split each into modules with one job "
                      "(keep the public names importable from the old path)")


def test_no_function_is_over_the_line_limit():
    over = [f"{p.relative_to(ROOT).as_posix()}:{line} {name} ({n} lines)"
            for p in _modules() for name, line, n in long_functions(p)]
    assert not over, (f"functions over {MAX_FUNCTION_LINES} lines: {over}; split each into named steps")


@pytest.mark.parametrize("n_lines, expect", [(MAX_MODULE_LINES, False), (MAX_MODULE_LINES + 1, True)])
def test_the_module_limit_can_fail(tmp_path, n_lines, expect):
    path = tmp_path / "big.py"
    path.write_text("x = 1\n" * n_lines)
    assert (module_lines(path) > MAX_MODULE_LINES) is expect


@pytest.mark.parametrize("body_lines, expect", [(MAX_FUNCTION_LINES - 2, False), (MAX_FUNCTION_LINES - 1, True)])
def test_the_function_limit_can_fail(tmp_path, body_lines, expect):
    """A decorated method of ``body_lines`` statements: decorator + ``def`` + body is the length checked."""
    body = "".join(f"        x{i} = {i}\n" for i in range(body_lines))
    path = tmp_path / "long.py"
    path.write_text(f"class A:\n    @staticmethod\n    def f():\n{body}")
    found = long_functions(path)
    assert bool(found) is expect
    if expect:
        assert found == [("f", 2, MAX_FUNCTION_LINES + 1)]
