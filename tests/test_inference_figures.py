"""Calibration figures and the Calibration page (AppTest)."""

import numpy as np
import pytest

from lvcore.app import PAGES_DIR
from lvcore.inference import diagnostics, samplers
from lvcore.viz import inference_figures as figs

PAGE = PAGES_DIR / "5_Calibration.py"


@pytest.fixture(scope="module")
def idata():
    """InferenceData built from random draws (no sampling) to exercise the figure builders."""
    rng = np.random.default_rng(0)
    c, d = 2, 50
    s = {n: np.exp(rng.normal(0, 0.2, (c, d))) for n in ("a", "b", "af", "bf")}
    s.update(sigma_s2=np.full((c, d), 9e-4) * np.exp(rng.normal(0, 0.1, (c, d))), v=rng.normal(0, 0.01, (c, d)),
             disc=rng.normal(0, 0.02, (c, d, 24)), eta=np.r_[130.0, np.full(24, -0.15)] + rng.normal(0, 0.01, (c, d, 25)))
    run = samplers.SamplerRun("hmc_gibbs", "discrepancy", s, {"diverging": np.zeros((c, d), bool)}, 1.0)
    y = np.r_[128.0, np.full(24, -0.14)]
    return diagnostics.to_inference_data(run, y, convergence=diagnostics.check_convergence(run)), y


def test_figures_build(idata, tmp_path):
    idata, y = idata
    assert len(figs.trace_figure(idata, ["a", "b"]).data) == 4
    assert len(figs.rank_figure(idata, ["a"]).data) == 2
    assert figs.diagnostics_table(idata, ["a", "b"]).shape[0] == 2
    assert len(figs.pair_figure(idata).data[0].dimensions) == 4
    fig = figs.predictive_density_figure({"iii": idata}, y)
    assert len(fig.data) == 25  # one density per output
    heat = figs.discrepancy_figure(idata)
    assert np.asarray(heat.data[0].z).shape == (4, 6)
    p = figs.write_html(fig, tmp_path / "f.html")
    assert p.stat().st_size > 1000
    pp = np.asarray(idata.posterior_predictive["y_rep"])
    assert pp.shape == (2, 50, 25) and np.std(pp[..., 1:]) > 0.02  # noise sigma_S added


def _row_gaps_px(fig):
    """Pixels between consecutive stacked subplots, and whether the upper one shows x tick labels."""
    h = fig.layout.height
    plot = h - fig.layout.margin.t - fig.layout.margin.b
    axes = sorted((k for k in fig.layout if k.startswith("yaxis")), key=lambda k: -fig.layout[k].domain[1])
    out = []
    for upper, lower in zip(axes, axes[1:]):
        gap = (fig.layout[upper].domain[0] - fig.layout[lower].domain[1]) * plot
        xa = fig.layout["xaxis" + upper[5:]]
        ticks = xa.showticklabels is not False and not xa.matches
        out.append((gap, ticks))
    return out


@pytest.mark.parametrize("builder", [figs.trace_figure, figs.rank_figure])
def test_stacked_subplot_titles_clear_the_ticks_above(idata, builder):
    """Each subplot title (about 20 px) fits between its plot and the one above (and that one's tick labels)."""
    idata, _ = idata
    fig = builder(idata, ["a", "b", "af", "bf", "sigma_s2", "v"])
    for gap, ticks in _row_gaps_px(fig):
        assert gap >= 24 + (18 if ticks else 0), (builder.__name__, gap, ticks)
    assert fig.layout["xaxis" + str(6)].title.text  # the shared x axis is titled under the last row


def test_parameter_meanings_fit_a_table_cell():
    from lvcore.inference.models import PARAMETER_HELP, parameter_meaning

    assert parameter_meaning("a") == "isotropic stiffness of the Holzapfel-Ogden law"
    assert all(0 < len(parameter_meaning(n)) <= 48 for n in PARAMETER_HELP)


def test_page_without_emulator_says_how_to_build(tmp_path, monkeypatch):
    from streamlit.testing.v1 import AppTest

    import lvcore.emulator.io as eio
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    monkeypatch.setattr(eio, "ASSETS_DIR", tmp_path / "none")
    at = AppTest.from_file(str(PAGE), default_timeout=60).run()
    assert not at.exception, at.exception
    if at.info:  # no below-spec emulator in this checkout either
        assert "build_emulators.py" in at.info[0].value


def test_page_renders_controls_with_an_emulator(tmp_path, monkeypatch):
    from streamlit.testing.v1 import AppTest

    from lvcore.emulator.io import save_emulator
    from test_inference_calibrate import _random_emulator

    save_emulator(_random_emulator(), tmp_path / "chapter")
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    at = AppTest.from_file(str(PAGE), default_timeout=60).run()
    assert not at.exception, at.exception
    # the emulator selector (the page's Cohort section has selectors of its own)
    assert any("chapter" in str(o) for box in at.selectbox for o in box.options)
    assert at.button[0].label == "Run calibration"
    assert len(at.multiselect) == 1


def test_page_runs_a_short_calibration_and_reports_honestly(tmp_path, monkeypatch):
    """A short run: the banner states divergences/R-hat/ESS (amber: 50 draws cannot reach ESS 400), the
    posterior is drawn over its prior with the SYNTHETIC truth, and no timer reruns the page afterwards."""
    import time

    from streamlit.testing.v1 import AppTest

    from lvcore.emulator.io import save_emulator
    from test_inference_calibrate import _random_emulator

    save_emulator(_random_emulator(), tmp_path / "chapter")
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    at = AppTest.from_file(str(PAGE), default_timeout=120).run()
    at.multiselect[0].set_value(["iid"])
    at.number_input[0].set_value(2)
    at.number_input[1].set_value(50)
    at.number_input[2].set_value(50)
    at.button[0].click().run()
    assert not at.exception, at.exception
    t0 = time.time()
    while not at.session_state["calibration_job"]["done"] and time.time() - t0 < 240:
        time.sleep(2)
    at.run()
    at.run()
    assert not at.exception, at.exception
    job = at.session_state["calibration_job"]
    assert job["done"] and not job["error"], job.get("error")
    banners = [w.value for w in at.warning] + [s.value for s in at.success]
    assert any("divergences" in b and "R-hat" in b and "ESS" in b for b in banners), banners
    assert any("ESS" in w.value for w in at.warning)  # 2 x 50 draws: amber, never green
    assert any("hidden generating value" in c.value for c in at.caption)
    tables = [df.value for df in at.dataframe if "meaning" in df.value.columns]
    assert tables and all(tables[0]["meaning"].str.len() <= 48)  # short meanings: the column is not clipped
    at.number_input[1].set_value(100).run()  # warm-up 50 -> 100: the shown result is stale
    assert any("Inputs changed, re-run" in w.value and "warm-up" in w.value for w in at.warning)
