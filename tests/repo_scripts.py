"""Load a script of the repository (``benchmarks/``, ``scripts/``) as a module, for tests of its functions.

The scripts are not part of the installed package; the tests that exercise them
read them from the checkout beside ``tests/``.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load_script(relative_path: str):
    """The module of ``ROOT / relative_path`` (e.g. ``"benchmarks/land2015.py"``), freshly executed."""
    path = ROOT / relative_path
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
