"""lvcore.conditions: each condition has one home, and the two sets of angles/EDP are used where they belong."""
from __future__ import annotations

import ast
import re
from pathlib import Path

from lvcore import conditions
from lvcore.core.space import build_case
from lvcore.mechanics.case import Case
from lvcore.parallel import THREAD_VARIABLES

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


def _defined(pattern: str) -> list[str]:
    rx = re.compile(pattern, re.M)
    return [str(p.relative_to(ROOT)) for p in SOURCES if rx.search(p.read_text())]


def test_no_second_home_for_a_constant():
    assert _defined(r"^\s*SIGMA_S\s*=\s*0\.03\b") == ["lvcore/conditions.py"]
    # θ̃ written out in code (a tuple or a dict of its values) only as THETA_TILDE
    assert _defined(r"^\s*[A-Za-z_]\w*\s*=\s*\(0\.60?, 1\.30?, 1\.00?, 3\.60?\)") == []
    assert _defined(r"\{\s*\"a\": 0\.60?, \"b\": 1\.30?, \"af\": 1\.00?, \"bf\": 3\.60?\s*\}") == ["lvcore/conditions.py"]
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
    """Every script, benchmark, test and lvcore module pins threads through lvcore.parallel.pin_threads: none names a
    thread variable itself (a dict key, a keyword, a setdefault or loop over the names), except to read it."""
    offenders = []
    for path in [*SOURCES, *sorted((ROOT / "benchmarks").glob("*.py")), *sorted((ROOT / "scripts").glob("*.py")),
                 *sorted((ROOT / "tests").glob("*.py")), ROOT / "app.py"]:
        if path == ROOT / "lvcore" / "parallel.py":
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
    assert not offenders, f"call lvcore.parallel.pin_threads() instead of setting the thread variables: {offenders}"
