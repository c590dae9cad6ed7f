"""The layers contract (`[tool.importlinter]` in pyproject.toml): kept, able to fail, and the README's table."""
from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

from importlinter.cli import lint_imports

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"


def _contract() -> dict:
    (contract,) = tomllib.loads(PYPROJECT.read_text())["tool"]["importlinter"]["contracts"]
    return contract


def _layers(contract: dict) -> list[list[str]]:
    return [[m.strip() for m in layer.split("|")] for layer in contract["layers"]]


def _config(tmp_path: Path, layers: list[str]) -> str:
    lines = ["[tool.importlinter]", 'root_package = "lvcore"', "", "[[tool.importlinter.contracts]]",
             'id = "layers"', 'name = "lvcore layers"', 'type = "layers"', 'containers = ["lvcore"]',
             "exhaustive = true", "layers = [" + ", ".join(f'"{x}"' for x in layers) + "]"]
    path = tmp_path / "contract.toml"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def test_the_layers_contract_is_kept():
    assert lint_imports(str(PYPROJECT), no_cache=True, no_logo=True) == 0


def test_the_contract_covers_every_subpackage_and_module():
    contract = _contract()
    assert contract["type"] == "layers" and contract["exhaustive"] is True and contract["containers"] == ["lvcore"]
    listed = {m for layer in _layers(contract) for m in layer}
    children = {p.stem for p in (ROOT / "lvcore").glob("*.py") if p.stem != "__init__"} \
        | {p.parent.name for p in (ROOT / "lvcore").glob("*/__init__.py")}
    assert listed == children, (f"add {sorted(children - listed)} to a layer of [tool.importlinter] in pyproject.toml "
                                f"(and to README.md's Architecture table); remove {sorted(listed - children)}")


def test_the_contract_can_fail(tmp_path):
    """Put the interface (core) above the simulator that implements it: lint-imports must report a broken contract;
    and a contract that forgets a module is broken too (exhaustive)."""
    layers = list(_contract()["layers"])
    i_mech = next(i for i, x in enumerate(layers) if "mechanics" in x)
    i_core = next(i for i, x in enumerate(layers) if "core" in x.split(" | "))
    swapped = list(layers)
    swapped[i_mech], swapped[i_core] = layers[i_core], layers[i_mech]
    assert lint_imports(_config(tmp_path, swapped), no_cache=True, no_logo=True) == 1
    missing = [x.replace(" | resources", "") for x in layers]
    assert lint_imports(_config(tmp_path, missing), no_cache=True, no_logo=True) == 1


def test_readme_architecture_table_matches_the_contract():
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Architecture"):]
    section = section[: section.index("\n## ", 3)]
    rows = [line for line in section.splitlines() if line.startswith("| `")]
    readme = [[m.strip() for m in re.match(r"\| `([^`]*)`", row).group(1).replace("\\|", "|").split("|")]
              for row in rows]
    assert readme == _layers(_contract()), ("README.md's Architecture table must list the layers of [tool.importlinter] "
                                            "in pyproject.toml, one row per layer, in order")


def test_studies_do_not_import_viz_at_module_level():
    """Figures are drawn only when asked for: a study module's top level never imports lvcore.viz (or plotly)."""
    offenders = []
    for path in sorted((ROOT / "lvcore" / "studies").glob("*.py")):
        for node in ast.parse(path.read_text()).body:
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            if any(n.startswith(("lvcore.viz", "plotly")) for n in names):
                offenders.append(f"{path.name}:{node.lineno}")
    assert not offenders, offenders
