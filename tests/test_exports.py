"""lvcore._exports: the deprecation shims for moved names, renamed keywords and moved modules."""
from __future__ import annotations

import importlib
import re
import subprocess
import sys
import types
import warnings

import pytest

from lvcore._exports import MOVED_MODULES, moved_names, renamed_keywords


def test_a_moved_name_forwards_to_its_new_home_with_a_deprecation_warning():
    old = types.ModuleType("old_home")
    old.__getattr__ = moved_names("old_home", {"KPA": "lvcore.domain.units:KPA_PER_MMHG"})
    with pytest.warns(DeprecationWarning, match=r"old_home\.KPA is deprecated; use lvcore\.domain\.units\.KPA_PER_MMHG"):
        from lvcore.domain.units import KPA_PER_MMHG

        assert old.__getattr__("KPA") == KPA_PER_MMHG
    with pytest.raises(AttributeError, match="has no attribute 'other'"):
        old.__getattr__("other")


def test_a_renamed_keyword_is_accepted_under_its_old_name_with_a_deprecation_warning():
    @renamed_keywords(edp="edp_mmhg")
    def f(x, *, edp_mmhg=8.0):
        """Docstring kept."""
        return x, edp_mmhg

    assert f.__doc__ == "Docstring kept." and f.__name__ == "f"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert f(1, edp_mmhg=10.0) == (1, 10.0) and f(1) == (1, 8.0)  # the new name: no warning
    with pytest.warns(DeprecationWarning, match=r"f\(edp=\.\.\.\) is deprecated; use edp_mmhg="):
        assert f(1, edp=12.0) == (1, 12.0)
    with pytest.raises(TypeError, match="got 'edp_mmhg' and its old name 'edp'"):
        f(1, edp=12.0, edp_mmhg=10.0)


@pytest.mark.parametrize("old", sorted(MOVED_MODULES))
def test_a_moved_module_imports_from_its_old_path_as_the_same_module_with_a_deprecation_warning(old, monkeypatch):
    import lvcore

    new = MOVED_MODULES[old]
    module = importlib.import_module(new)
    parent, _, name = old.rpartition(".")
    monkeypatch.delitem(sys.modules, old, raising=False)  # as in a fresh process: the old path not imported yet
    monkeypatch.delattr(lvcore, name, raising=False)
    with pytest.warns(DeprecationWarning, match=rf"the module {re.escape(old)} moved to {re.escape(new)}; "
                                                rf"import {re.escape(new)}"):
        assert importlib.import_module(old) is module
    assert sys.modules[old] is module and getattr(lvcore, name) is module
    assert module.__name__ == module.__spec__.name == new  # the alias leaves the module's own identity alone
    monkeypatch.delitem(sys.modules, old)
    monkeypatch.delattr(lvcore, name)
    with pytest.warns(DeprecationWarning, match=re.escape(new)):
        exec(f"from {parent} import {name} as imported", namespace := {})
    assert namespace["imported"] is module


def test_new_paths_import_without_warnings_and_unknown_old_paths_still_fail():
    """In a fresh process with DeprecationWarning as an error: every moved module imports at its new path (and
    lvcore itself imports clean); a name that never existed is still a ModuleNotFoundError."""
    code = ("import importlib, lvcore._exports as e\n"
            "for new in e.MOVED_MODULES.values(): importlib.import_module(new)\n"
            "try:\n    import lvcore.no_such_module\nexcept ModuleNotFoundError:\n    print('ok')\n")
    out = subprocess.run([sys.executable, "-W", "error::DeprecationWarning", "-c", code], capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "ok"


def test_the_repository_imports_moved_modules_at_their_new_paths():
    """The old paths are for users' code: nothing in lvcore, the pages, scripts, benchmarks or tests imports one."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    old_leaves = {old.rpartition(".")[2] for old in MOVED_MODULES}
    found = []
    for folder in ("lvcore", "pages", "scripts", "benchmarks", "tests"):
        for path in sorted((root / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module] + [f"{node.module}.{a.name}" for a in node.names
                                             if node.module == "lvcore" and a.name in old_leaves]
                else:
                    continue
                if any(n == old or n.startswith(old + ".") for n in names for old in MOVED_MODULES):
                    found.append(f"{path.relative_to(root)}:{node.lineno}")
    assert not found, f"import the new paths (lvcore._exports.MOVED_MODULES) in {found}"
