"""The one registry of the studies (lvcore.studies.registry): every study module is in it, everything that lists the
studies is derived from it, and no result file's name is written outside it."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from lvcore.studies import registry
from lvcore.studies.registry import STUDIES, StudyModule

ROOT = Path(__file__).resolve().parents[1]
STUDIES_DIR = ROOT / "lvcore" / "studies"
#: A module that defines one of these at top level offers a study's interface, so it must be a registered study.
STUDY_INTERFACE = re.compile(r"^(def (add_study_parser|figures|tables|load)\(|TITLES\s*[:=])", re.MULTILINE)


def study_module_names() -> set[str]:
    return {p.stem for p in STUDIES_DIR.glob("*.py")}


def unregistered(names, accounted) -> list[str]:
    """Modules of ``names`` the registry does not account for (``accounted``: :func:`registry.modules`)."""
    return sorted(set(names) - set(accounted))


def result_file_literals(source: str, files, path: str = "<string>") -> list[str]:
    """``path:line: file`` for every string literal of ``source`` (docstrings and f-string parts included) that
    names one of ``files`` (a whole file name: ``mismatch.json`` is not found in ``bo_mismatch.json``)."""
    pattern = re.compile(r"(?<![\w.-])(" + "|".join(re.escape(f) for f in files) + r")(?![\w.-]*\w)")
    hits = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            hits += [f"{path}:{node.lineno}: {m}" for m in pattern.findall(node.value)]
    return hits


def test_every_module_of_lvcore_studies_is_registered():
    missing = unregistered(study_module_names(), registry.modules())
    assert not missing, (f"lvcore/studies/{missing[0]}.py is in no entry of lvcore.studies.registry.STUDIES: add "
                         "it as a study, as a part of one (Study.parts), or to registry.SHARED")
    assert not set(registry.modules()) - study_module_names(), "the registry names a module that does not exist"


def test_the_registration_check_can_fail():
    assert unregistered({"bo_fibres", "new_study"}, registry.modules()) == ["new_study"]


def test_a_module_with_a_study_interface_is_a_registered_study():
    studies = {s.module for s in STUDIES.values()}
    for path in sorted(STUDIES_DIR.glob("*.py")):
        if path.stem not in studies:
            found = STUDY_INTERFACE.search(path.read_text(encoding="utf-8"))
            assert found is None, (f"{path.name} defines {found.group(0)!r}, a study's interface, but is not a "
                                   "study of lvcore.studies.registry")


@pytest.mark.parametrize("name", list(STUDIES))
def test_each_study_module_has_the_interface_its_entry_declares(name):
    s = STUDIES[name]
    mod = s.load_module()
    assert isinstance(mod, StudyModule), f"{s.module_name} lacks TITLES, tables, figures or source_line"
    assert set(s.report_items) <= set(mod.TITLES), f"{name}: report items not in TITLES"
    assert hasattr(mod, "add_study_parser") == s.cli, f"{name}: add_study_parser present iff the entry has a CLI"
    if s.result_file:
        assert mod.RESULT_FILE == s.result_file and callable(mod.load) and mod.COMMAND
        assert (ROOT / "assets" / "studies" / s.result_file).is_file(), f"no shipped {s.result_file}"
    elif s.inputs:
        assert callable(mod.load) and all(i in STUDIES for i in s.inputs)
    else:
        assert callable(mod.compute), f"{name}: a study without a result file computes its result"
    assert s.tab or s.report, f"{name} is shown nowhere (no report section, no Studies page tab)"


def test_everything_that_lists_the_studies_is_derived_from_the_registry():
    from lvcore.report import build
    from lvcore.studies import cli, findings, results

    assert cli.STUDY_MODULES == tuple(s.module_name for s in STUDIES.values() if s.cli)
    assert results.RESULT_FILES == {s.name: s.result_file for s in STUDIES.values() if s.result_file}
    assert findings.SOURCES == {STUDIES[n].module: STUDIES[n].result_file for n in STUDIES["findings"].inputs}
    assert [(x.study, x.label, x.names) for x in build.SECTIONS] == [
        (s.module, s.report, s.report_items) for s in STUDIES.values() if s.report]
    tabs = registry.tabs()
    assert sorted(s.name for studies in tabs.values() for s in studies) == sorted(
        s.name for s in STUDIES.values() if s.tab)
    assert all(s.tab == label for label, studies in tabs.items() for s in studies)


def test_the_package_lists_every_study():
    import lvcore.studies as pkg

    for s in STUDIES.values():
        assert s.module in pkg.__all__, f"lvcore.studies.__all__ misses {s.module}"
        assert getattr(pkg, s.module) is s.load_module()
    assert "registry" in pkg.__all__


def test_the_studies_page_draws_its_tabs_from_the_registry():
    page = (ROOT / "pages" / "6_Studies.py").read_text(encoding="utf-8")
    assert "registry.tabs()" in page
    for s in STUDIES.values():
        if s.tab:
            assert s.tab not in page, f"the tab label {s.tab!r} is written in the page; it belongs to the registry"


def test_no_result_file_name_outside_the_registry():
    files = [s.result_file for s in STUDIES.values() if s.result_file]
    sources = sorted((ROOT / "lvcore").rglob("*.py")) + sorted((ROOT / "pages").glob("*.py"))
    hits = []
    for path in sources:
        if path != STUDIES_DIR / "registry.py":
            hits += result_file_literals(path.read_text(encoding="utf-8"), files, str(path.relative_to(ROOT)))
    assert not hits, ("a result file's name is written outside lvcore/studies/registry.py (use the study's "
                      "RESULT_FILE or registry.result_file): " + "; ".join(hits[:10]))


def test_the_literal_check_can_fail():
    files = ["mismatch.json", "operators.json"]
    src = 'X = "bo_mismatch.json"\ndef f():\n    """Reads operators.json."""\n    return f"{d}/mismatch.json"\n'
    assert result_file_literals(src, files) == ["<string>:3: operators.json", "<string>:4: mismatch.json"]
    assert result_file_literals('Y = "operators.json.tmp1"', files) == []
