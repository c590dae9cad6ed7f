"""Land et al. (2015) benchmark problems 1 (beam) and 2 (LV inflation), Guccione law, follower pressure
(lvcore.mechanics.verification)."""
import pytest

from lvcore.mechanics.case import Case
from lvcore.mechanics.simulate import simulate
from lvcore.mechanics.verification import P1_TIP_POINT, problem1_case, problem2_case


def test_problem_cases_validate_as_the_stated_problems():
    beam = Case.from_dict(problem1_case((20, 2, 2)))
    assert beam.probes == (P1_TIP_POINT,) and beam.load.pressure_kpa == pytest.approx(0.004)
    assert beam.material.law == "guccione"
    lv = Case.from_dict(problem2_case("accurate"))
    assert lv.load.pressure_kpa == pytest.approx(10.0) and lv.geometry.base_z() == pytest.approx(5.0)
    assert lv.material.law == "guccione"


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
