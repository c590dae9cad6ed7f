"""The ``lvcore`` command (lvcore.cli): every sub-command module is wired in, and a broken one fails loudly."""
import argparse
import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

import lvcore
from lvcore import cli
from lvcore.studies import cli as study_cli


def _commands_of(register) -> set[str]:
    sub = argparse.ArgumentParser().add_subparsers()
    register(sub)
    return set(sub.choices)


def _modules_defining(function: str) -> set[str]:
    """Every module in lvcore's sub-packages that defines ``function`` at top level (read from the source)."""
    root = Path(lvcore.__file__).parent
    pattern = re.compile(rf"^def {function}\(", re.MULTILINE)
    return {".".join(("lvcore",) + path.relative_to(root).with_suffix("").parts)
            for path in root.glob("*/*.py") if pattern.search(path.read_text(encoding="utf-8"))}


def test_every_cli_module_is_registered():
    assert set(cli.COMMAND_MODULES) == _modules_defining("register")
    assert set(study_cli.STUDY_MODULES) == _modules_defining("add_study_parser")


def test_help_lists_every_subcommand_of_every_module():
    proc = subprocess.run([sys.executable, "-m", "lvcore.cli", "--help"], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    expected = set()
    for name in cli.COMMAND_MODULES:
        commands = _commands_of(importlib.import_module(name).register)
        assert commands, f"{name}.register adds no sub-command"
        expected |= commands
    assert expected >= {"simulate", "geometry", "campaign", "design", "emulator", "calibrate", "study"}
    for command in expected:
        assert command in proc.stdout, f"'lvcore --help' does not list '{command}'"


def test_study_help_lists_every_study(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["study", "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for name in study_cli.STUDY_MODULES:
        for study in _commands_of(importlib.import_module(name).add_study_parser):
            assert study in out, f"'lvcore study --help' does not list '{study}'"
    assert "geometry-operators" in out and "fibre-discrepancy" in out


@pytest.mark.parametrize("table,name", [(cli, "COMMAND_MODULES"), (study_cli, "STUDY_MODULES")])
def test_a_missing_command_module_fails_loudly(monkeypatch, table, name):
    monkeypatch.setattr(table, name, getattr(table, name) + ("lvcore.no_such_module",))
    with pytest.raises(ModuleNotFoundError, match="lvcore.no_such_module"):
        cli.build_parser()
