"""lvcore.app.freshness: results carry their inputs and grey out when the inputs change (pure + AppTest)."""
import numpy as np
from streamlit.testing.v1 import AppTest

from lvcore.app import PAGES_DIR
from lvcore.app.freshness import changed_inputs, describe

FIBRE_PAGE = str(PAGES_DIR / "3_Fibre_angles.py")


def test_changed_inputs_names_what_moved():
    old = {"a (kPa)": 0.6, "EDP (mmHg)": 8.0, "pairs": [(-60.0, 90.0)]}
    assert changed_inputs(old, dict(old)) == []
    assert changed_inputs(old, {**old, "a (kPa)": 0.65}) == ["a (kPa)"]
    assert changed_inputs(old, {**old, "pairs": [(-60.0, 90.0), (-30.0, 60.0)]}) == ["pairs"]
    assert changed_inputs(old, {"a (kPa)": 0.6, "EDP (mmHg)": 8.0}) == ["pairs"]


def test_describe_lists_every_input():
    text = describe({"a (kPa)": 0.6, "mesh": "fast"})
    assert "a (kPa) 0.6" in text and "mesh fast" in text


def test_describe_never_prints_python_literals():
    """Issue 49: the Report page said "static PNG/SVG True"; booleans and None read as words."""
    text = describe({"live calibration": True, "static": False, "subject": None, "pairs": (True, None)})
    assert text == "live calibration yes; static no; subject –; pairs (yes, –)"
    assert describe({"reference_volume_ml": None, "measures": {}, "models": []}) == (
        "reference_volume_ml –; measures none; models none")  # no None, no {} in a settings line


def test_fibre_sweep_greys_out_after_a_sidebar_slider_moves(monkeypatch):
    import lvcore.studies.fibre_angles as fa

    def fake_sweep(pairs, **kw):  # the page's wiring, not the simulator, is under test
        return [fa.AngleRun(alpha_endo=e, alpha_epi=p, converged=True, message="", lvv_ml=150.0 + kw["theta"]["a"],
                            strains=np.full(24, -0.1)) for e, p in pairs]

    monkeypatch.setattr(fa, "angle_sweep", fake_sweep)
    at = AppTest.from_file(FIBRE_PAGE, default_timeout=120).run()
    assert not at.exception, at.exception
    next(b for b in at.button if b.label == "Run sweep").click().run()
    assert not at.exception, at.exception
    assert any(c.value.startswith("Computed with:") and "a (kPa) 0.6" in c.value for c in at.caption)
    assert not any("Inputs changed" in w.value for w in at.warning)
    from lvcore.app.controls import THETA_RANGES, log_options

    stops = log_options(*THETA_RANGES["a"], 0.6)
    at.sidebar.select_slider[0].set_value(stops[stops.index(0.6) + 1]).run()  # a: 0.60 -> the next log stop
    assert any("Inputs changed, re-run" in w.value and "a (kPa)" in w.value for w in at.warning)
    assert any("a (kPa) 0.6;" in c.value for c in at.caption)  # still credited to the inputs it ran with


def test_fibre_page_stiffness_sliders_are_log_scaled_with_units():
    at = AppTest.from_file(FIBRE_PAGE, default_timeout=120).run()
    labels = [s.label for s in at.sidebar.select_slider]
    assert labels[:4] == ["a (kPa)", "b (–)", "a_f (kPa)", "b_f (–)"]
    opts = [float(o) for o in at.sidebar.select_slider[0].options]
    ratios = np.diff(np.log(opts))
    assert ratios.max() < 3 * np.median(ratios)  # geometric stops, not 0.05-kPa steps


def test_live_map_and_background_fe_verification(monkeypatch):
    import time

    import lvcore.studies.fibre_angles as fa
    from lvcore.emulator.io import available_emulators

    # a missing bundled emulator is a failure, not a skip (README: tests never skip for missing bundled data)
    assert "angles" in available_emulators(), "the bundled 'angles' emulator is missing (python scripts/build_emulators.py)"

    def fake_sweep(pairs, **kw):
        time.sleep(0.5)
        return [fa.AngleRun(alpha_endo=e, alpha_epi=p, converged=True, message="", lvv_ml=151.0,
                            strains=np.full(24, -0.1)) for e, p in pairs]

    monkeypatch.setattr(fa, "angle_sweep", fake_sweep)
    at = AppTest.from_file(FIBRE_PAGE, default_timeout=120).run()
    at.radio[0].set_value(next(o for o in at.radio[0].options if "emulator" in o)).run()
    assert not at.exception, at.exception
    assert len(at.get("component_instance")) == 2  # the live map (one figure, both maps) and strain chart
    next(b for b in at.button if b.label == "Verify with the FE simulator").click().run()
    assert not at.exception, at.exception
    t0 = time.time()
    while not at.session_state["angle_verify"]["done"] and time.time() - t0 < 30:
        time.sleep(0.2)
    at.run()
    assert not at.exception, at.exception
    assert any("FE simulator (" in m.value and "151.0 mL" in m.value for m in at.markdown)
