"""The Emulator page renders metrics, parity/residual plots and live sliders (Streamlit AppTest)."""

import numpy as np
import pytest

from campaign_double import closed_form
import lvcore.emulator.io as eio
from lvcore.app import PAGES_DIR
from lvcore.emulator.io import save_emulator
from lvcore.emulator.training import TrainingConfig, train_emulator

PAGE = PAGES_DIR / "4_Emulator.py"


@pytest.fixture()
def emulator_dir(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    lo, hi = np.array([0.1, 0.5, 0.1, 0.5]), np.array([10.0, 20.0, 10.0, 20.0])
    x = np.exp(np.log(lo) + rng.random((120, 4)) * np.log(hi / lo))
    y = np.array([closed_form(*r) for r in x])
    emu = train_emulator(x[:100], y[:100], x[100:], y[100:], input_names=("a", "b", "af", "bf"), name="demo",
                         lower=lo, upper=hi, config=TrainingConfig(architectures=((20, 20),), max_epochs=30),
                         source={"forward": ["campaign_double:forward"], "resolution": ["fast"]})
    save_emulator(emu, tmp_path / "demo", validation={"inputs": x[100:], "outputs": y[100:],
                                                        "predictions": np.asarray(emu.apply(x[100:]))})
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    monkeypatch.setattr(eio, "ASSETS_DIR", tmp_path / "no-bundled-emulators")  # only the test double is listed
    return tmp_path / "demo"


def test_page_renders_with_an_emulator(emulator_dir):
    from streamlit.testing.v1 import AppTest

    at = AppTest.from_file(str(PAGE), default_timeout=60).run()
    assert not at.exception, at.exception
    assert any("TEST DOUBLE" in w.value for w in at.warning)
    controls = list(at.main.slider) + list(at.main.select_slider)  # the shared sidebar aside
    assert len(controls) == 4
    assert {c.label for c in controls} == {"a (kPa)", "b (–)", "a_f (kPa)", "b_f (–)"}  # units in the labels
    assert at.metric[0].value == "100"
    first = at.main.select_slider[0] if len(at.main.select_slider) else at.main.slider[0]  # log inputs: log stops
    first.set_value(first.options[-3] if len(at.main.select_slider) else 2.0).run()
    assert not at.exception
    assert any("Emulator: LVV" in m.value for m in at.markdown)
    assert len(at.get("plotly_chart")) == 2


def test_page_labels_the_shipped_below_spec_demo(tmp_path, monkeypatch):
    from streamlit.testing.v1 import AppTest

    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    monkeypatch.setattr(eio, "ASSETS_DIR", tmp_path / "no-bundled-emulators")  # no spec emulators on the search path
    demo = eio.BELOW_SPEC_DIR / "chapter"
    assert demo.is_dir(), "the below-spec demonstration emulator ships in assets/emulators-below-spec"
    at = AppTest.from_file(str(PAGE), default_timeout=60).run()
    assert not at.exception
    assert any("below spec" in o for o in at.selectbox[0].options)
    at.selectbox[0].select(next(o for o in at.selectbox[0].options if o.startswith("chapter (below spec"))).run()
    assert any("BELOW SPEC" in w.value for w in at.warning)
    controls = list(at.main.slider) + list(at.main.select_slider)  # the shared sidebar aside
    assert len(controls) == 10   # 9 inputs and the geometry's scale
    labels = {c.label for c in controls}
    assert "EDP (mmHg)" in labels or any(lab.startswith("h1: PC score 1") for lab in labels), labels
    # exact scaling on the page: the geometry s * reconstruct(h) has the same strains and s^3 times the LVV
    lvv = lambda: float(next(m.value for m in at.markdown if "Emulator: LVV" in m.value)  # noqa: E731
                        .split("LVV **")[1].split(" mL")[0])
    v1 = lvv()
    at.slider(key="in_scale").set_value(1.5).run()
    assert not at.exception, at.exception
    assert lvv() == pytest.approx(1.5 ** 3 * v1, rel=2e-3)   # the page prints one decimal
    assert any("Reference cavity V₀" in c.value and "scale 1.50" in c.value for c in at.caption)


def test_live_check_starts_at_the_shared_sidebar(emulator_dir):
    """The live check ignored the shared sidebar's θ (issue 27): it starts there now, and follows it."""
    from streamlit.testing.v1 import AppTest

    at = AppTest.from_file(str(PAGE), default_timeout=60).run()
    assert not at.exception, at.exception
    for name, label, k in (("a", "a (kPa)", -8), ("bf", "b_f (–)", -12)):
        value = at.select_slider(key=f"shared_{name}").options[k]  # inside the test emulator's box
        at.select_slider(key=f"shared_{name}").set_value(value).run()
        assert not at.exception, at.exception
        (live,) = [c for c in at.main.select_slider if c.label == label]
        assert float(live.value) == pytest.approx(float(value))
