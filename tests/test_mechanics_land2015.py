"""Land et al. (2015) benchmark problems 1 (beam) and 2 (LV inflation), Guccione law, follower pressure."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from land2015 import problem1_case, problem2_case  # noqa: E402

from lvcore.mechanics.simulate import simulate  # noqa: E402


@pytest.mark.slow
def test_problem1_beam_tip():
    r = simulate(problem1_case((20, 2, 2)))
    assert r.converged, r.message
    x, y, z = r.probes[0]
    assert 4.151 <= z <= 4.185  # spread of the converged submissions
    assert y == pytest.approx(0.5, abs=1e-6)  # symmetry
    assert 9.1 < x < 9.25


@pytest.mark.slow
def test_problem2_lv_inflation_accurate_preset():
    r = simulate(problem2_case("accurate"))
    assert r.converged, r.message
    assert r.cavity_volume_mm3[0] == pytest.approx(2492, rel=2e-3)
    # the issue asks for +-0.1 mm and aims at +-0.05 mm: the graded accurate preset meets the aim
    assert r.apex_endocardium[2] == pytest.approx(-26.612, abs=0.05)
    assert r.apex_epicardium[2] == pytest.approx(-28.279, abs=0.05)
    assert r.cavity_volume_mm3[1] == pytest.approx(10734, rel=0.01)
    # the apex stays on the axis
    assert abs(r.apex_endocardium[0]) < 1e-8 and abs(r.apex_endocardium[1]) < 1e-8
