"""lvcore.domain.conditions: each condition has one home, and the two sets of angles/EDP are used where they belong."""
from __future__ import annotations

import ast
import functools
import importlib
import re
from pathlib import Path

import pytest

from lvcore.domain import conditions
from lvcore.mechanics.case_inputs import build_case
from lvcore.mechanics.case import Case
from lvcore.execution.parallel import THREAD_VARIABLES

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [*sorted((ROOT / "lvcore").rglob("*.py")), *sorted((ROOT / "pages").glob("*.py"))]


def test_simulator_defaults_and_chapter_conditions_are_named_apart_and_used_where_they_belong():
    assert conditions.SIMULATOR_DEFAULT_ANGLES == (-60.0, 90.0) and conditions.CHAPTER_ANGLES == (-60.0, 60.0)
    # a case file that names no fibres gets the simulator's defaults
    case = Case.from_dict({"geometry": {"kind": "default", "resolution": "fast"},
                           "material": {"law": "holzapfel-ogden", **conditions.THETA_TILDE},
                           "load": {"pressure": 8, "units": "mmHg"}})
    assert (case.fibres.alpha_endo_deg, case.fibres.alpha_epi_deg) == conditions.SIMULATOR_DEFAULT_ANGLES
    # the core's case builder (campaigns, the emulators' training spaces) fills in the chapter's conditions
    built = build_case(dict(conditions.THETA_TILDE))
    assert (built["fibres"]["alpha_endo"], built["fibres"]["alpha_epi"]) == conditions.CHAPTER_ANGLES
    assert built["load"] == {"pressure": conditions.CHAPTER_EDP, "units": "mmHg"}


@functools.lru_cache(maxsize=None)
def _text(path: Path) -> str:
    return path.read_text()


@functools.lru_cache(maxsize=None)
def _tree(path: Path) -> ast.Module:
    """The parsed source, shared by the checks below (read-only)."""
    return ast.parse(_text(path))


def _defined(pattern: str) -> list[str]:
    rx = re.compile(pattern, re.M)
    return [str(p.relative_to(ROOT)) for p in SOURCES if rx.search(_text(p))]


def test_no_second_home_for_a_constant():
    assert _defined(r"^\s*SIGMA_S\s*=\s*0\.03\b") == ["lvcore/domain/conditions.py"]
    # θ̃ written out in code (a tuple or a dict of its values) only as THETA_TILDE
    assert _defined(r"^\s*[A-Za-z_]\w*\s*=\s*\(0\.60?, 1\.30?, 1\.00?, 3\.60?\)") == []
    assert _defined(r"\{\s*\"a\": 0\.60?, \"b\": 1\.30?, \"af\": 1\.00?, \"bf\": 3\.60?\s*\}") == ["lvcore/domain/conditions.py"]
    assert _defined(r"^MODEL_LABELS\s*=") == ["lvcore/inference/models.py"]
    # the app's set-up: one function, called once by the entry script
    assert [p for p in _defined(r"\bpin_threads\(") if p.startswith(("lvcore/app", "pages"))] == \
        ["lvcore/app/process.py"]
    assert [p for p in _defined(r"use_host_devices\(") if p.startswith(("lvcore/app", "pages"))] == \
        ["lvcore/app/process.py"]


def _reads_environment(call: ast.AST) -> bool:
    """``os.environ.get(NAME)``, ``env.get(NAME)`` or ``os.getenv(NAME)``: reading a variable, not setting it."""
    return isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute) and call.func.attr in ("get", "getenv")


def test_only_pin_threads_writes_the_thread_variables():
    """Every script, benchmark, test and lvcore module pins threads through lvcore.execution.parallel.pin_threads: none names a
    thread variable itself (a dict key, a keyword, a setdefault or loop over the names), except to read it."""
    offenders = []
    for path in [*SOURCES, *sorted((ROOT / "benchmarks").glob("*.py")), *sorted((ROOT / "scripts").glob("*.py")),
                 *sorted((ROOT / "tests").glob("*.py")), ROOT / "app.py"]:
        if path == ROOT / "lvcore" / "execution" / "parallel.py":
            continue
        text = path.read_text()
        if not any(v in text for v in THREAD_VARIABLES):
            continue
        tree = ast.parse(text)
        reads = {id(c.args[0]) for c in ast.walk(tree) if _reads_environment(c) and c.args}
        for node in ast.walk(tree):
            named = node.value if isinstance(node, ast.Constant) else node.arg if isinstance(node, ast.keyword) else None
            if named in THREAD_VARIABLES and id(node) not in reads:
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno if hasattr(node, 'lineno') else '?'}")
    assert not offenders, f"call lvcore.execution.parallel.pin_threads() instead of setting the thread variables: {offenders}"




def _strings_outside_docstrings(path: Path) -> list[ast.Constant]:
    """The string literals of ``path`` (f-strings' literal parts too) that are not docstrings."""
    tree = _tree(path)
    docs = {id(node.body[0].value) for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body
            and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return [n for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs]


def test_no_second_home_for_angle_pairs_material_values_or_the_case_writer():
    # the angle pairs of the chapter's studies: conditions.CHAPTER_ANGLE_PAIRS / FIBRE_DISCREPANCY_ANGLE_PAIRS
    assert _defined(r"\(-30\.0, 60\.0\)") == ["lvcore/domain/conditions.py"]
    assert not re.search(r"-?\b60\.0\b", (ROOT / "pages" / "3_Fibre_angles.py").read_text())
    # the Holzapfel–Ogden terms held at population values: conditions.HO_FIXED, also in the Simulator page's caption
    assert _defined(r"\b0\.69\b") == ["lvcore/domain/conditions.py"]
    # the one writer of cases from named inputs
    assert _defined(r"^def build_case\(") == ["lvcore/mechanics/case_inputs.py"]
    # and lvcore itself uses neither through its old home (the shims are for users' code)
    assert _defined(r"from lvcore\.core\.space import [^\n]*\bbuild_case|\bunits\.HO_FIXED|"
                    r"from lvcore(\.domain)?\.units import [^\n]*HO_FIXED|self\.space\.case\(") == []
    # labels derive σ_S's value from conditions.SIGMA_S (docstrings may quote the chapter)
    label = re.compile(r"σ_S ?/ ?0\.03|truth 0\.03|noise 0\.03")
    assert [f"{p.relative_to(ROOT)}:{n.lineno}" for p in SOURCES for n in _strings_outside_docstrings(p)
            if label.search(n.value)] == []


@pytest.mark.parametrize("module, name, home", [
    ("lvcore.domain.units", "HO_FIXED", "lvcore.domain.conditions"),
    ("lvcore.studies.fibre_angles", "CHAPTER_ANGLE_PAIRS", "lvcore.domain.conditions"),
    ("lvcore.core.space", "build_case", "lvcore.mechanics.case_inputs"),
])
def test_a_moved_name_still_reads_with_a_deprecation_warning(module, name, home):
    old, new = importlib.import_module(module), importlib.import_module(home)
    with pytest.warns(DeprecationWarning, match=rf"{re.escape(module)}\.{name} is deprecated; use {re.escape(home)}"):
        assert getattr(old, name) is getattr(new, name)


def test_the_fibre_discrepancy_angle_sets_moved_to_conditions():
    from lvcore.studies import fibre_discrepancy

    with pytest.warns(DeprecationWarning, match=r"fibre_discrepancy\.ANGLE_SETS is deprecated; use "
                                                r"lvcore\.domain\.conditions\.FIBRE_DISCREPANCY_ANGLE_PAIRS"):
        assert fibre_discrepancy.ANGLE_SETS == conditions.FIBRE_DISCREPANCY_ANGLE_PAIRS


def test_the_angle_pairs_are_the_chapters():
    assert conditions.CHAPTER_ANGLE_PAIRS == ((-60.0, 90.0), (-60.0, 60.0), (-30.0, 60.0), (0.0, 90.0))
    # the fibre-discrepancy data: every pair but the emulator's training angles (the model's own)
    assert conditions.FIBRE_DISCREPANCY_ANGLE_PAIRS == ((-60.0, 90.0), (-30.0, 60.0), (0.0, 90.0))
    assert conditions.CHAPTER_ANGLES not in conditions.FIBRE_DISCREPANCY_ANGLE_PAIRS


def test_one_spelling_per_concept():
    """The input names ``edp``, ``af``, ``bf`` are written once (lvcore.domain.outputs: EDP_NAME, THETA_NAMES) and the labels
    users read (``a_f``, ``b_f``) once (lvcore.domain.outputs.DISPLAY_NAMES); a pressure passed as a parameter
    is ``edp_mmhg`` (a ``bool`` parameter ``edp`` is a page's "show the EDP slider" flag). Widget keys are exempt."""
    homes = dict.fromkeys(("edp", "a_f", "b_f"), "lvcore/domain/outputs.py")
    offenders = []
    for path in SOURCES:
        where = str(path.relative_to(ROOT))
        tree = _tree(path)
        widget_keys = {id(k.value) for k in ast.walk(tree) if isinstance(k, ast.keyword) and k.arg == "key"}
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and node.value in homes and homes[node.value] != where \
                    and id(node) not in widget_keys:
                offenders.append(f"{where}:{node.lineno} writes {node.value!r}")
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                offenders += [f"{where}:{node.lineno} {node.name}({a.arg}=...): call it edp_mmhg"
                              for a in node.args.args + node.args.kwonlyargs
                              if a.arg == "edp" and not (a.annotation is not None and ast.unparse(a.annotation) == "bool")]
    assert not offenders, offenders
