"""Layering: the mechanics (simulator) layer never imports the viz layer."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import lvcore.mechanics

MECHANICS = Path(lvcore.mechanics.__file__).resolve().parent
FORBIDDEN = "lvcore.viz"


def _is_viz(name: str) -> bool:
    return name == FORBIDDEN or name.startswith(FORBIDDEN + ".")


def _viz_imports(path: Path) -> list[str]:
    """Imports of lvcore.viz in ``path`` (one entry per statement): import statements at any
    depth, ``from lvcore import viz``, and module names in strings (``importlib.import_module``)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            hit = any(_is_viz(a.name) for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            hit = _is_viz(node.module) or any(_is_viz(f"{node.module}.{a.name}") for a in node.names)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            hit = _is_viz(node.value)
        else:
            hit = False
        if hit:
            found.append(f"{path.name}:{node.lineno}")
    return found


def test_checker_finds_viz_imports(tmp_path):
    """The check can fail: it flags every form of importing lvcore.viz."""
    bad = tmp_path / "bad.py"
    bad.write_text("import lvcore.viz.figures\nfrom lvcore.viz.figures import strain_heatmap\n"
                   "from lvcore import viz\n\ndef f():\n    from lvcore.viz import mesh3d\n"
                   "    import importlib\n    return importlib.import_module('lvcore.viz.figures')\n")
    assert len(_viz_imports(bad)) == 5


def test_no_mechanics_module_imports_viz():
    files = sorted(MECHANICS.glob("*.py"))
    assert len(files) > 10
    offenders = [hit for f in files for hit in _viz_imports(f)]
    assert not offenders, f"lvcore.mechanics must not import lvcore.viz: {offenders}"


def test_importing_every_mechanics_module_loads_no_viz():
    names = [f"lvcore.mechanics.{f.stem}" for f in sorted(MECHANICS.glob("*.py")) if f.stem != "__init__"]
    code = ("import importlib, sys\n"
            f"for n in {names!r}: importlib.import_module(n)\n"
            "print(sorted(m for m in sys.modules if m.startswith('lvcore.viz')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
