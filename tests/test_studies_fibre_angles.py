"""Fibre-angle sweeps run the real simulator and keep failures; the page runs."""
import json

import numpy as np
import pytest

from lvcore.app import PAGES_DIR
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
    from lvcore.core.forward import ForwardBatch

    class Failed:  # a forward model of the angles whose every point fails (test double)
        input_names = ("alpha_endo", "alpha_epi")

        def evaluate(self, inputs):
            return ForwardBatch(np.full((1, 25), np.nan), [False], ("diverged (test double)",))

    m = angle_map([-60, 0], [60], forward=Failed())
    assert np.isnan(m.lvv_ml).all() and len(m.failures) == 2
    assert m.failures[0].message == "diverged (test double)"


def test_page_runs_a_sweep():
    from streamlit.testing.v1 import AppTest

    at = AppTest.from_file(str(PAGES_DIR / "3_Fibre_angles.py"), default_timeout=300)
    at.run()
    assert not at.exception
    at.multiselect[0].set_value(["(-60°, 90°)"]).run()
    at.button[0].click().run()
    assert not at.exception
    assert len(at.dataframe) == 1


def test_emulator_angle_map_is_one_batched_prediction():
    """The emulator map equals point-by-point predictions and is laid out like angle_map."""
    from test_inference_calibrate import _random_emulator

    from lvcore.emulator.model import ExtrapolationWarning
    from lvcore.exceptions import EmulatorError
    from lvcore.studies.fibre_angles import emulator_angle_map

    emu = _random_emulator("angles", angles=True)  # UNTRAINED: the plumbing only
    theta = {"a": 0.7, "b": 2.0, "af": 1.2, "bf": 4.0}
    h = [0.3, -0.2, 0.1, 0.0, 0.5]
    endo, epi = [-90.0, -45.0, 0.0], [0.0, 90.0]
    amap = emulator_angle_map(emu, endo, epi, theta=theta, edp_mmhg=10.0, h=h)
    assert amap.lvv_ml.shape == (2, 3) and amap.mean_strain.shape == (2, 3) and len(amap.runs) == 6
    assert not amap.failures
    one = np.asarray(emu.predict(**theta, alpha_endo=-45.0, alpha_epi=90.0, edp=10.0,
                                 **{f"h{i + 1}": v for i, v in enumerate(h)}))
    assert amap.lvv_ml[1, 1] == pytest.approx(one[0], rel=1e-12)
    assert amap.mean_strain[1, 1] == pytest.approx(np.mean(one[1:]), rel=1e-12)
    run = amap.runs[4]  # row-major over alpha_epi, then alpha_endo
    assert (run.alpha_endo, run.alpha_epi) == (-45.0, 90.0) and "emulator 'angles'" in run.message
    np.testing.assert_allclose(run.strains, one[1:], rtol=1e-12)
    with pytest.warns(ExtrapolationWarning, match="edp"):
        emulator_angle_map(emu, endo, epi, theta=theta, edp_mmhg=30.0, h=h)
    # no θ given: the chapter's θ̃ (conditions.THETA_TILDE), as given explicitly
    from lvcore.domain.conditions import THETA_TILDE

    default = emulator_angle_map(emu, endo, epi, edp_mmhg=10.0, h=h)
    np.testing.assert_array_equal(default.lvv_ml, emulator_angle_map(emu, endo, epi, theta=THETA_TILDE,
                                                                      edp_mmhg=10.0, h=h).lvv_ml)
    with pytest.raises(EmulatorError, match="5 PC scores"):
        emulator_angle_map(emu, endo, epi, h=[0.1])
    with pytest.raises(EmulatorError, match="fibre angles"):
        emulator_angle_map(_random_emulator(), endo, epi)


def _n_values(array_json) -> int:
    """Length of an array in plotly's JSON: a list, or (plotly >= 6) a typed array {"dtype", "bdata"}."""
    if isinstance(array_json, dict):
        import base64

        return len(base64.b64decode(array_json["bdata"])) // np.dtype(array_json["dtype"]).itemsize
    return len(array_json)


def test_emulator_angle_sweep_matches_the_map_at_the_same_points():
    """The live strain chart's runs are the map's runs at the chapter's pairs (one batched prediction)."""
    from test_inference_calibrate import _random_emulator

    from lvcore.exceptions import EmulatorError
    from lvcore.domain.conditions import CHAPTER_ANGLE_PAIRS
    from lvcore.studies.fibre_angles import emulator_angle_map, emulator_angle_sweep

    emu = _random_emulator("angles", angles=True)  # UNTRAINED: the plumbing only
    theta = {"a": 0.7, "b": 2.0, "af": 1.2, "bf": 4.0}
    runs = emulator_angle_sweep(emu, CHAPTER_ANGLE_PAIRS, theta=theta, edp_mmhg=10.0)
    assert [(r.alpha_endo, r.alpha_epi) for r in runs] == list(CHAPTER_ANGLE_PAIRS)
    for r in runs:
        one = emulator_angle_map(emu, [r.alpha_endo], [r.alpha_epi], theta=theta, edp_mmhg=10.0).runs[0]
        assert r.converged and r.lvv_ml == pytest.approx(one.lvv_ml, rel=1e-12)
        np.testing.assert_allclose(r.strains, one.strains, rtol=1e-12)
    with pytest.raises(EmulatorError, match="fibre angles"):
        emulator_angle_sweep(_random_emulator())


def test_page_draws_the_live_emulator_map(tmp_path, monkeypatch):
    """With an emulator named 'angles' on the search path the map tab offers it and draws without a button."""
    from streamlit.testing.v1 import AppTest
    from test_inference_calibrate import _random_emulator

    from lvcore.emulator import io as eio

    eio.save_emulator(_random_emulator("angles", angles=True), tmp_path / "angles")  # UNTRAINED test double
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    monkeypatch.setattr(eio, "ASSETS_DIR", tmp_path / "no-bundled-emulators")
    at = AppTest.from_file(str(PAGES_DIR / "3_Fibre_angles.py"), default_timeout=300)
    at.run()
    assert not at.exception
    radio = at.radio[0]
    assert "`angles` emulator (live)" in radio.options
    radio.set_value("`angles` emulator (live)").run()
    assert not at.exception and not at.warning
    # live charts (lvcore.app.live_chart): a component kept mounted, its figure updated in place
    assert not at.get("plotly_chart")
    figs = [json.loads(c.proto.json_args)["figure"] for c in at.get("component_instance")]
    assert len(figs) == 2
    # both maps (LVV, mean strain) in one figure: one redraw per slider move
    assert [t["type"] for t in figs[0]["data"]] == ["heatmap", "heatmap"]
    # the chapter's four angle pairs' regional strains (Fig 9.5), from the emulator
    assert [t["type"] for t in figs[1]["data"]] == ["bar"] * 4
    assert all(_n_values(t["y"]) == 24 for t in figs[1]["data"])
    edp = next(s for s in at.sidebar.slider if "EDP" in s.label)
    edp.set_value(30.0).run()  # outside the emulator's training box: said, not hidden
    assert any("outside the training box" in w.value for w in at.warning)
