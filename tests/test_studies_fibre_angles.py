"""Fibre-angle sweeps run the real simulator and keep failures; the page runs."""
from pathlib import Path

import numpy as np
import pytest

from lvcore.studies.fibre_angles import angle_case, angle_map, angle_sweep, strain_table


@pytest.fixture(scope="module")
def runs():
    return angle_sweep([(-60.0, 90.0), (-30.0, 60.0)], resolution="fast")


def test_sweep_changes_strains_and_volume(runs):
    assert all(r.converged for r in runs)
    base, other = runs
    assert base.alpha_endo == -60.0 and other.alpha_epi == 60.0
    assert np.all(base.strains < 0) and np.all(other.strains < 0)
    # the fibre angles move the regional strains by more than the solver's noise
    assert np.max(np.abs(base.strains - other.strains)) > 1e-3
    assert len(strain_table(runs)) == 2
    assert "EDV" in base.label


def test_case_matches_schema():
    case = angle_case(-30, 60, edp_mmhg=10, resolution="fast")
    from lvcore.mechanics.case import Case

    c = Case.from_dict(case)
    assert c.fibres.alpha_endo_deg == -30 and c.fibres.alpha_epi_deg == 60


def test_failures_are_kept_as_nan():
    class Failed:
        converged = False
        message = "diverged (test double)"

    m = angle_map([-60, 0], [60], simulate_fn=lambda case: Failed())
    assert np.isnan(m.lvv_ml).all() and len(m.failures) == 2
    assert m.failures[0].message == "diverged (test double)"


def test_page_runs_a_sweep():
    from streamlit.testing.v1 import AppTest

    at = AppTest.from_file(str(Path(__file__).parents[1] / "pages" / "3_Fibre_angles.py"), default_timeout=300)
    at.run()
    assert not at.exception
    at.multiselect[0].set_value(["(-60°, 90°)"]).run()
    at.button[0].click().run()
    assert not at.exception
    assert len(at.dataframe) == 1
