"""Start-up of ``lvcore``: the top-level help imports no command module and no JAX; JAX's settings still apply."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from lvcore import cli

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("jax", "numpy", "scipy", "arviz", "pandas", "h5py", "matplotlib", "streamlit")


#: What importing lvcore (in this test process) put into the environment: not inherited by the probes.
JAX_VARIABLES = ("JAX_ENABLE_X64", "JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
                 "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES")


def _python(code: str, **env) -> str:
    base = {k: v for k, v in os.environ.items() if k not in JAX_VARIABLES}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300,
                         env={**base, **env})
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout.strip().splitlines()[-1]


def test_top_level_help_is_the_full_parsers_without_importing_the_commands():
    # the same text as the parser that imports every command module (each command's line, exit codes)
    assert cli.build_parser(commands_only=True).format_help() == cli.build_parser().format_help()
    assert sorted(cli.COMMAND_HELP) == sorted(cli.COMMANDS)
    # and in a fresh process `lvcore --help` loads none of the heavy libraries nor any command module
    code = ("import sys, contextlib, io, json; from lvcore.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
            "    try: main(['--help'])\n"
            "    except SystemExit: pass\n"
            f"print(json.dumps([[m for m in {HEAVY!r} if m in sys.modules], "
            "[m for m in sys.modules if m.endswith('.cli') and m != 'lvcore.cli'], 'exit codes' in out.getvalue()]))")
    loaded, commands, has_help = json.loads(_python(code))
    assert loaded == [] and commands == [] and has_help


@pytest.mark.parametrize("argv, message", [(["nonsense"], "invalid choice"), ([], "required: command")])
def test_a_missing_or_unknown_command_is_refused_by_the_top_level_parser(capsys, argv, message):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_a_named_command_still_gets_its_own_options(capsys):
    with pytest.raises(SystemExit):
        cli.main(["design", "--help"])
    assert "--space" in capsys.readouterr().out


@pytest.mark.parametrize("jax_first", [False, True])
def test_importing_lvcore_sets_float64_and_the_compilation_cache_before_or_after_jax(tmp_path, jax_first):
    """Without JAX imported, lvcore puts its settings where JAX reads them on import; with JAX, sets them now."""
    code = ("import sys; import jax\n" if jax_first else "import sys\n") + (
        "import lvcore; imported = 'jax' in sys.modules\n"
        "import jax, jax.numpy as jnp, json\n"
        "print(json.dumps([imported, str(jnp.ones(1).dtype), jax.config.jax_compilation_cache_dir, "
        "jax.config.jax_persistent_cache_min_compile_time_secs]))")
    env = {"LVCORE_JAX_CACHE": str(tmp_path / "cache"), "JAX_ENABLE_X64": "0"}  # lvcore overrides a 0 (float64)
    imported, dtype, cache_dir, min_s = json.loads(_python(code, **env))
    assert imported == jax_first  # importing lvcore does not import JAX
    assert dtype == "float64"
    assert cache_dir == str(tmp_path / "cache") and (tmp_path / "cache").is_dir()
    assert min_s == 0.0  # every program is cached, the small ones too


def test_the_cache_can_be_switched_off(tmp_path):
    code = "import lvcore, jax, json; print(json.dumps(jax.config.jax_compilation_cache_dir))"
    assert json.loads(_python(code, LVCORE_JAX_CACHE="off")) is None
    # also where the parent process (an lvcore with the cache on) passed its cache folder on
    assert json.loads(_python(code, LVCORE_JAX_CACHE="off", JAX_COMPILATION_CACHE_DIR=str(tmp_path))) is None
