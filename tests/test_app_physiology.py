"""Physiology outputs on the Calibration page (AppTest): posterior EDV/V0 with its typical range, the assumed EDP,
and on request the derived quantities of lvcore.inference.derived: the FE EDPVR band with the measured point's
99 % predictive interval against the Klotz et al. (2006) normal curve, the identified combination, stress and
contraction."""
from __future__ import annotations

import time

import numpy as np

from test_app_uploads import _csv, calibration_page  # noqa: F401 (fixture)

THETA = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}


def _stand_in_calibrate(monkeypatch, lvv_draws_ml, theta=THETA):
    import arviz as az
    import pandas as pd

    from lvcore.inference import calibrate as cal

    class Conv:
        converged, n_divergent, max_rhat, min_ess_bulk, min_ess_tail, rounds, failing = True, 0, 1.0, 1000.0, 1000.0, 1, ()

        def message(self):
            return "converged (stand-in)"

    def stand_in(y, forward, model, **kw):
        rng = np.random.default_rng(0)
        post = {k: v * np.exp(0.05 * rng.standard_normal((2, 50))) for k, v in theta.items()}
        eta = np.zeros((2, 50, 25))
        eta[..., 0] = rng.normal(lvv_draws_ml, 2.0, (2, 50))
        eta[..., 1:] = -0.15
        idata = az.from_dict(posterior={**post, "eta": eta}, posterior_predictive={"y_rep": eta.copy()},
                             observed_data={"y": np.asarray(y)})
        return cal.CalibrationResult(model, "nuts", idata, Conv(), pd.DataFrame({"mean": [float(np.mean(post[k])) for k in THETA]}, index=list(THETA)),
                                     0.5,
                                     {"min": 1.0})

    monkeypatch.setattr(cal, "calibrate", stand_in)


def _run(at):
    at.button[0].click().run(timeout=60)
    deadline = time.time() + 60
    while time.time() < deadline and not at.session_state["calibration_job"]["done"]:
        time.sleep(0.2)
    at.run(timeout=120)
    assert not at.exception, at.exception
    return at


def test_calibration_results_show_edv_ratio_and_the_derived_edpvr(calibration_page, monkeypatch):  # noqa: F811
    """A scaled subject (scale 1.1, the .npy bug of issue 49): the panel runs lvcore.inference.derived on request
    with the emulator's resolution and base, and shows one V₀ (the derived one) in the caption, the table and
    the figure, the band with the measured point's 99 % predictive interval and the Klotz curve, the derived
    quantities, and no error box."""
    import json as _json

    from lvcore.app import physiology_panel
    from lvcore.app.physiology_panel import reference_volume_ml

    monkeypatch.setattr(physiology_panel, "N_EDPVR_DRAWS", 6)
    monkeypatch.delenv(physiology_panel.DRAWS_ENV, raising=False)
    scale = 1.1
    v0 = reference_volume_ml([0, 0, 0, 0, 0], scale)
    _stand_in_calibrate(monkeypatch, 2.3 * v0)  # EDV/V0 ~2.3 at 8 mmHg: above the typical 1.66-1.99
    at = calibration_page()
    at.file_uploader(key="up_measured").upload("m.csv", _csv("S1", 2.3 * v0), "text/csv")
    at.file_uploader(key="up_geometry").upload("h.json", b'{"h": [0, 0, 0, 0, 0], "scale": 1.1}',
                                               "application/json")
    at.run()
    at.multiselect[0].set_value(["iid"]).run()
    _run(at)
    assert any("EDP assumed: 8 mmHg" in c.value and "typical EDV/V₀ at 8 mmHg: 1.66–1.99" in c.value
               for c in at.caption)
    table = [d.value for d in at.dataframe if "EDV/V₀ median" in d.value.columns]
    assert len(table) == 1
    assert float(table[0]["EDV/V₀ median"].iloc[0]) == __import__("pytest").approx(2.3, abs=0.02)
    assert any("unusual result: EDV/V₀ = 2.3" in w.value for w in at.warning)
    # one spelling of the fibre stiffness wherever a user reads it: a_f (as on the sliders), never "af"
    summaries = [d.value for d in at.dataframe if "meaning" in d.value.columns and "contraction" not in d.value.columns]
    assert summaries and "a_f" in list(summaries[0].index) and "af" not in list(summaries[0].index)
    assert any("**a_f**" in m.value for m in at.markdown) and not any("**af**" in m.value for m in at.markdown)

    for chart in at.get("plotly_chart"):
        spec = _json.loads(chart.proto.spec)
        labels = [dim.get("label", "") for t in spec["data"] for dim in t.get("dimensions", [])]
        titles = [a.get("text", "") for a in spec["layout"].get("annotations", [])]
        assert not [t for t in labels + titles if t.split(" ")[0] in ("af", "bf")], (labels, titles)
    # the EDPVR runs only on request; the button says how many draws and how long
    n_charts = len(at.get("plotly_chart"))
    (button,) = [b for b in at.button if b.label.startswith("Compute the EDPVR")]
    assert "6 posterior draws" in button.label and "minute" in button.label
    button.click().run(timeout=600)
    assert not at.exception, at.exception
    errors = [e.value for e in at.error if not e.value.startswith("CONSISTENCY: ")]
    assert not errors, errors
    stored = at.session_state["cal_edpvr"]
    record = stored["record"]
    assert record["n_draws"] == 6 and record["edpvr_check"]["n_failed_solves"] == 0
    med = [r["median"] for r in record["edpvr"]]
    assert [r["pressure_mmhg"] for r in record["edpvr"]] == [0, 5, 10, 15, 20, 25, 30] and np.all(np.diff(med) > 0)
    # the scaled subject: V0 is the FE cavity of the 1.1x shape (scaling identity), not of the unscaled one
    derived_v0 = med[0]
    assert derived_v0 == __import__("pytest").approx(v0, rel=0.03)
    assert derived_v0 == __import__("pytest").approx(scale ** 3 * reference_volume_ml([0, 0, 0, 0, 0]), rel=0.03)
    assert "default" in record["edpvr_check"]["source"]   # the emulator's training resolution, not "fast"
    # one V0 everywhere: the caption, the EDV/V0 table and the figure's subtitle use the derived V0
    v0_text = f"V₀ = {derived_v0:.1f} mL"
    assert any(v0_text in c.value and "FE reference" in c.value for c in at.caption)
    assert len(at.get("plotly_chart")) == n_charts + 1
    spec = _json.loads(at.get("plotly_chart")[-1].proto.spec)
    assert v0_text in spec["layout"]["title"]["text"]
    names = [t.get("name", "") for t in spec["data"]]
    assert any(n.startswith("posterior 90% band (6 draws)") for n in names)
    assert {"posterior median", "99% predictive interval at the EDP", "measured (EDV, EDP)",
            "Klotz et al. 2006 normal"} <= set(names)
    # the check of the measured point: inside the band (success) or the CONSISTENCY flag text (error)
    check = record["edpvr_check"]
    if check["inside"]:
        assert any("inside the band" in s.value for s in at.success)
    else:
        assert any(e.value.startswith("CONSISTENCY: the EDPVR of the posterior misses") for e in at.error)
    md = " ".join(m.value for m in at.markdown)
    assert "Identified combination" in md and "log_a" in md and "fibre stretch 1.10" in md
    assert "mean end-diastolic fibre stretch" in md and "Emulator-to-FE offset" in md
    contraction = [d.value for d in at.dataframe if "contraction" in d.value.columns]
    assert contraction and list(contraction[0]["parameter"]) == ["a", "b", "a_f", "b_f"]


def test_edpvr_of_a_scaled_geometry_is_the_scaled_edpvr(monkeypatch):
    """run_edpvr on a scaled PC-score geometry (no mesh file written): every volume is scale³ times the unscaled
    one (the scaling identity); the draw count comes from LVCORE_EDPVR_DRAWS when set."""
    import arviz as az
    from test_inference_calibrate import _random_emulator

    from lvcore.app import physiology_panel as pp
    from lvcore.emulator.forward import emulator_forward
    from lvcore.geometry.scaling import ScaledForward

    monkeypatch.setenv(pp.DRAWS_ENV, "3")
    assert pp.edpvr_draws() == 3
    monkeypatch.setenv(pp.DRAWS_ENV, "many")
    assert pp.edpvr_draws() == pp.N_EDPVR_DRAWS == 100
    monkeypatch.setenv(pp.DRAWS_ENV, "2")
    emu = _random_emulator()
    rng = np.random.default_rng(0)
    post = {k: v * np.exp(0.05 * rng.standard_normal((2, 20))) for k, v in THETA.items()}
    eta = np.zeros((2, 20, 25))
    eta[..., 0] = 150.0
    idata = az.from_dict(posterior={**post, "eta": eta})
    recs = {}
    for s in (1.0, 1.2):
        setup = pp.Setup.of(emu, ScaledForward(emulator_forward(emu, np.zeros(5)), s), edp_mmhg=8.0,
                            angles=(-60.0, 60.0), measured_lvv_ml=150.0, h=np.zeros(5), scale=s)
        recs[s] = pp.run_edpvr(idata, setup)
        assert recs[s]["n_draws"] == 2 and recs[s]["edpvr_check"]["n_failed_solves"] == 0
    for r1, r2 in zip(recs[1.0]["edpvr"], recs[1.2]["edpvr"]):
        assert r2["median"] == __import__("pytest").approx(1.2 ** 3 * r1["median"], rel=1e-6)
    level, text = pp.check_text(recs[1.0])
    assert level in ("success", "error") and ("inside the band" in text or text.startswith("CONSISTENCY: "))


def test_posterior_piled_on_a_prior_bound_turns_the_banner_amber(calibration_page, monkeypatch):  # noqa: F811
    """The iid posterior of a and af at the prior's lower bound 0.05 had a green banner (issue 27)."""
    from lvcore.inference.models import MODEL_LABELS

    label = MODEL_LABELS["iid"]
    piled = {**THETA, "a": 0.0507, "af": 0.052}
    for theta, amber in ((THETA, False), (piled, True)):
        _stand_in_calibrate(monkeypatch, 150.0, theta)
        at = calibration_page()
        at.file_uploader(key="up_measured").upload("m.csv", _csv("S1", 150.0), "text/csv")
        at.file_uploader(key="up_geometry").upload("h.json", b'{"h": [0, 0, 0, 0, 0]}', "application/json")
        at.run()
        at.multiselect[0].set_value(["iid"]).run()
        _run(at)
        banners = [w.value for w in at.warning if w.value.startswith(label)] + \
                  [s.value for s in at.success if s.value.startswith(label)]
        assert banners, [w.value for w in at.warning]
        bound = [b for b in banners if "piled on the prior's lower bound 0.05" in b]
        if amber:
            assert bound and any(b.startswith(label) for b in (w.value for w in at.warning))
            assert "a: posterior piled" in bound[0] and "af: posterior piled" in bound[0]
        else:
            assert not bound
