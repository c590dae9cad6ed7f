"""lvcore.execution.restart: a resumable command replaces itself by a fresh run of its command line once its
memory mappings pass a share of the kernel's limit, and not before."""
import subprocess
import sys
import textwrap

import pytest

from lvcore.execution import restart


def test_mapping_share_is_a_share_of_the_limit():
    share = restart.mapping_share()
    if share is None:
        pytest.skip("/proc does not tell the mappings here")
    assert 0.0 < share < 1.0


def test_below_the_share_nothing_happens(monkeypatch):
    said = []
    monkeypatch.setattr(restart.os, "execv", lambda *a: pytest.fail("restarted below the share"))
    restart.restart_when_mappings_high(said.append, share=1.0)
    assert said == []


def test_above_the_share_the_same_command_line_runs_again(tmp_path):
    """A child restarts itself once (share 0: always above), the second run sees the restart count and stops."""
    script = tmp_path / "child.py"
    script.write_text(textwrap.dedent("""
        import os, sys
        from lvcore.execution import restart
        n = int(os.environ.get(restart.RESTARTS_ENV, "0"))
        print("run", n, sys.argv[1:], flush=True)
        if n == 0:
            restart.restart_when_mappings_high(lambda m: print(m, flush=True), share=0.0)
            print("not restarted", flush=True)
    """))
    out = subprocess.run([sys.executable, str(script), "--keep", "this"], capture_output=True, text=True,
                         timeout=120)
    if "not restarted" in out.stdout and restart.mapping_share() is None:
        pytest.skip("/proc does not tell the mappings here")
    lines = out.stdout.splitlines()
    assert out.returncode == 0, out.stderr
    assert lines[0] == "run 0 ['--keep', 'this']"
    assert "restarting it (restart 1)" in lines[1]
    assert lines[2] == "run 1 ['--keep', 'this']"
    assert "not restarted" not in out.stdout
