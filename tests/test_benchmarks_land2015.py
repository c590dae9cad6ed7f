"""benchmarks/land2015.py --pulse-python: the plumbing to FEniCS pulse, with a stand-in interpreter.

pulse itself (legacy dolfin) is not in the test environment; the stand-in
checks what the harness hands over (the mesh of the benchmark geometry) and
answers like ``benchmarks/pulse_land2015.py``.
"""
from __future__ import annotations

import stat
import sys

import pytest
from repo_scripts import load_script

pytest.importorskip("gmsh")


def _bench():
    return load_script("benchmarks/land2015.py")


def _stand_in(tmp_path, body: str) -> str:
    exe = tmp_path / "fake_pulse_python"
    exe.write_text(f"#!{sys.executable}\nimport json, sys\nimport numpy as np\n{body}\n")
    exe.chmod(exe.stat().st_mode | stat.S_IEXEC)
    return str(exe)


def test_pulse_runs_drop_the_compiling_solve_and_read_the_mesh(tmp_path):
    body = """
script, mesh, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
assert script.endswith("pulse_land2015.py")
d = np.load(mesh)
pts, cells = d["points"], d["cells"]
assert cells.shape[1] == 4 and abs(pts[:, 2].max() - 5.0) < 1e-9 and abs(pts[:, 2].min() + 20.0) < 1e-6
for i in range(n):
    print(json.dumps({"dofs": 100, "setup_s": 0.1, "solve_s": 50.0 + 10 * i, "endo_apex_z": -26.6,
                      "epi_apex_z": -28.3}))
"""
    runs = _bench()._pulse_runs(_stand_in(tmp_path, body), 4.0, 2)
    assert [r["solve_s"] for r in runs] == [60.0, 70.0]  # the first (form compilation) is dropped
    assert all(r["size_mm"] == 4.0 for r in runs)


def test_a_failing_pulse_says_why(tmp_path):
    exe = _stand_in(tmp_path, 'sys.stderr.write("ImportError: No module named dolfin"); sys.exit(1)')
    with pytest.raises(RuntimeError, match="No module named dolfin"):
        _bench()._pulse_runs(exe, 4.0, 1)
