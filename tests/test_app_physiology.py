"""Physiology outputs on the Calibration page (AppTest): posterior EDV/V0 with its typical range, the assumed EDP,
and the FE EDPVR band against the Klotz et al. (2006) normal curve on request."""
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


def test_calibration_results_show_edv_ratio_and_the_edpvr(calibration_page, monkeypatch):  # noqa: F811
    from lvcore.app.physiology_panel import reference_volume_ml

    v0 = reference_volume_ml([0, 0, 0, 0, 0])
    _stand_in_calibrate(monkeypatch, 2.3 * v0)  # EDV/V0 ~2.3 at 8 mmHg: above the typical 1.66-1.99
    at = calibration_page()
    at.file_uploader(key="up_measured").upload("m.csv", _csv("S1", 2.3 * v0), "text/csv")
    at.file_uploader(key="up_geometry").upload("h.json", b'{"h": [0, 0, 0, 0, 0]}', "application/json")
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
    summaries = [d.value for d in at.dataframe if "meaning" in d.value.columns]
    assert summaries and "a_f" in list(summaries[0].index) and "af" not in list(summaries[0].index)
    assert any("**a_f**" in m.value for m in at.markdown) and not any("**af**" in m.value for m in at.markdown)
    import json as _json

    for chart in at.get("plotly_chart"):
        spec = _json.loads(chart.proto.spec)
        labels = [dim.get("label", "") for t in spec["data"] for dim in t.get("dimensions", [])]
        titles = [a.get("text", "") for a in spec["layout"].get("annotations", [])]
        assert not [t for t in labels + titles if t.split(" ")[0] in ("af", "bf")], (labels, titles)
    # the EDPVR runs only on request (FE, fast mesh)
    n_charts = len(at.get("plotly_chart"))
    (button,) = [b for b in at.button if b.label.startswith("Simulate the EDPVR")]
    button.click().run(timeout=600)
    assert not at.exception, at.exception
    label, curve = at.session_state["cal_edpvr"]
    assert curve.volumes_ml.shape == (8, len(curve.pressures_mmhg)) and curve.n_failed == 0
    assert np.all(np.diff(curve.volumes_ml, axis=1) > 0)
    assert len(at.get("plotly_chart")) == n_charts + 1


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
