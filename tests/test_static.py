"""Static checks that catch bugs no test may reach: pyflakes' errors (not its style warnings) in every Python file
of the repository: a name used before it is assigned in its function (a local that shadows a module), an undefined
name, an ``__all__`` entry that does not exist, a duplicate argument."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("lvcore", "pages", "scripts", "benchmarks", "tests")


def _errors(path: Path) -> list[str]:
    from pyflakes import checker, messages

    bugs = (messages.UndefinedName, messages.UndefinedLocal, messages.UndefinedExport, messages.DuplicateArgument,
            messages.ReturnOutsideFunction, messages.YieldOutsideFunction, messages.ContinueOutsideLoop,
            messages.BreakOutsideLoop, messages.TooManyExpressionsInStarredAssignment,
            messages.TwoStarredExpressions, messages.PercentFormatInvalidFormat, messages.StringDotFormatInvalidFormat)
    source = path.read_text(encoding="utf-8")
    found = checker.Checker(ast.parse(source, filename=str(path)), filename=str(path)).messages
    return [f"{path.relative_to(ROOT)}:{m.lineno}: {m.message % m.message_args}" for m in found if isinstance(m, bugs)]


def _files() -> list[Path]:
    return [p for folder in FOLDERS for p in sorted((ROOT / folder).rglob("*.py")) if "__pycache__" not in p.parts]


def test_no_pyflakes_error_in_the_repository():
    errors = [e for p in _files() for e in _errors(p)]
    assert not errors, "\n".join(errors)


def test_the_check_finds_a_local_that_shadows_a_module():
    """The bug it was written for (fibre_angles, 2026-12-02): a local named like the module it reads first."""
    bad = ROOT / "build" / "static_check_example.py"
    bad.parent.mkdir(exist_ok=True)
    bad.write_text("from lvcore.domain import conditions\n\n\ndef f(theta=None):\n"
                   "    theta = dict(conditions.THETA_TILDE if theta is None else theta)\n"
                   "    conditions = {**theta}\n    return conditions\n")
    try:
        errors = _errors(bad)
    finally:
        bad.unlink()
    assert len(errors) == 1 and "referenced before assignment" in errors[0], errors
