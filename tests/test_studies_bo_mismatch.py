"""F6 as a real test: data with a known mismatch, fixed vs free angles on one common objective scale."""
import json
from pathlib import Path

import numpy as np
import pytest

from lvcore.domain.conditions import HO_FIXED, SIMULATOR_DEFAULT_ANGLES
from lvcore.studies import bo_fibres
from lvcore.studies import bo_mismatch as bm
from lvcore.studies.mismatch import bundled_volunteers
from lvcore.studies.results import bundled_studies_dir
from lvcore.testing.analytic import AnalyticForward

DOCS = Path(__file__).resolve().parents[1] / "docs" / "studies.md"


@pytest.fixture(scope="module")
def hv1():
    return bundled_volunteers(["HV1"])[0]


def test_data_cases_carry_exactly_their_mismatch(hv1):
    nominal = bm.data_case(hv1, None)
    angles, sheet, base = (bm.data_case(hv1, k) for k in ("angles", "sheet", "base"))
    assert nominal["fibres"] == dict(zip(("alpha_endo", "alpha_epi"), SIMULATOR_DEFAULT_ANGLES))
    assert angles["fibres"] == {"alpha_endo": -30.0, "alpha_epi": 80.0}
    assert {k: v for k, v in angles.items() if k != "fibres"} == {k: v for k, v in nominal.items() if k != "fibres"}
    assert sheet["material"]["as"] == pytest.approx(8 * HO_FIXED["as"]) and sheet["fibres"] == nominal["fibres"]
    assert base["boundary"]["base"] == "clamped" and nominal["boundary"]["base"] == "sliding"
    assert nominal["geometry"]["kind"] == "pca" and nominal["material"]["a"] == hv1.theta["a"]
    with pytest.raises(bm.LVCoreError, match="--kinds"):
        bm.data_case(hv1, "pericardium")


def test_model_forward_matches_the_nominal_data_conditions(hv1):
    fwd = bm.model_forward(hv1, "fixed")
    assert fwd.base == "sliding" and fwd.warm_start
    assert (fwd.conditions["alpha_endo"], fwd.conditions["alpha_epi"]) == SIMULATOR_DEFAULT_ANGLES
    assert [fwd.conditions[f"h{i + 1}"] for i in range(len(hv1.h))] == list(hv1.h)
    assert set(bm.model_forward(hv1, "free").input_names) == {"a", "b", "af", "bf", "alpha_endo", "alpha_epi"}


def _state(Y):
    return {"Y": np.asarray(Y).tolist()}


def test_the_comparison_uses_one_scale_for_both_modes():
    """Same outputs -> same common objective, although each mode's own design scale differs."""
    rng = np.random.default_rng(0)
    measured = np.r_[120.0, np.full(24, -0.15)]
    y_best = measured + np.r_[4.0, rng.normal(0, 0.01, 24)]
    wide = measured + rng.normal(0, 1, (6, 25)) * np.r_[40.0, np.full(24, 0.1)]   # free mode's design: spread out
    narrow = measured + rng.normal(0, 1, (6, 25)) * np.r_[5.0, np.full(24, 0.01)]  # fixed mode's design: narrow
    states = {"fixed": _state(np.vstack([narrow, y_best])), "free": _state(np.vstack([wide, y_best]))}
    entry = {"lvv_model_ml": y_best[0], "strain_residuals": (y_best[1:] - measured[1:]).tolist(), "alpha_endo": -60,
             "alpha_epi": 90, "theta": {"a": 1, "b": 1, "af": 1, "bf": 1}, "evaluations": 7,
             "failed_evaluations": {"count": 0}, "seconds": 1.0}
    own = {m: float(bm.common_objective(y_best, measured, np.std(np.asarray(states[m]["Y"])[:6], axis=0))[0])
           for m in states}
    entries = {m: {**entry, "objective_best": own[m]} for m in states}
    c = bm.compare(entries, states, {"measured": measured.tolist(), "clean": measured.tolist()}, n_initial=6)
    assert own["fixed"] > 5 * own["free"]  # each mode's own scale: the narrow design makes fixed look far worse
    assert c["fixed"]["objective_common_at_best"] == pytest.approx(c["free"]["objective_common_at_best"])
    np.testing.assert_allclose(c["scale"], np.std(np.vstack([narrow, wide]), axis=0))
    assert c["fixed"]["lvv_abs_error_ml"] == pytest.approx(4.0)
    assert c["free"]["strain_rmse"] == pytest.approx(np.sqrt(np.mean((y_best[1:] - measured[1:]) ** 2)))
    assert c["fixed"]["objective_common_min"] <= c["fixed"]["objective_common_at_best"]


def test_verdicts_per_kind():
    def run(kind, vol, fixed, free):
        mk = lambda e: {"lvv_abs_error_ml": e, "strain_rmse": 0.02, "objective_common_at_best": e,  # noqa: E731
                        "lvv_abs_error_vs_noise_free_ml": e}
        return {"volunteer": vol, "kind": kind, "strain_rms_mismatch": 0.02, "lvv_mismatch_ml": -3.0, "fixed": mk(fixed),
                "free": mk(free)}
    runs = [run("angles", v, 10.0 + i, 3.0 + i) for i, v in enumerate(("HV1", "HV2", "HV3"))]
    runs += [run("sheet", v, 5.0, 5.0 + d) for v, d in (("HV1", -1.0), ("HV2", 1.0), ("HV3", 0.5))]
    runs += [run("base", v, 4.0, 6.0 + i) for i, v in enumerate(("HV1", "HV2", "HV3"))]
    s = bm.kind_summary(runs, n_boot=500)
    v = bm.verdicts(s)["F6"]
    assert v["by_kind"]["angles"]["verdict"] == "reproduced" and v["verdict"] == "reproduced"
    assert v["value"] == pytest.approx(7.0)
    assert v["by_kind"]["sheet"]["verdict"] == "not reproduced"
    assert v["by_kind"]["base"]["verdict"] == "refuted"
    assert s["angles"]["free_lvv_error_lower"] == 3 and s["base"]["free_lvv_error_lower"] == 0


def test_small_run_with_the_analytic_stand_in(tmp_path):
    """Pipeline: data, both BO modes per volunteer and kind, state files, common scale, outputs, resume."""
    fac = lambda v, mode, kind: AnalyticForward(input_names=bo_fibres.bo_space(mode).names)  # noqa: E731
    truth = AnalyticForward(input_names=bo_fibres.bo_space("free").names)

    def simulate(case):
        m, f = case["material"], case["fibres"]
        y = np.array(truth({**{n: m[n] for n in ("a", "b", "af", "bf")}, **f}), float)
        if case["boundary"]["base"] == "clamped":
            y[1:] += 0.02
        return y

    kw = dict(out=tmp_path, n_initial=5, n_iterations=1, forward_factory=fac, simulate=simulate, n_boot=100)
    res = bm.run_study(["HV1", "HV2"], ["angles", "base"], **kw)
    data = bm.load(tmp_path)
    assert len(data["runs"]) == 4 and set(data["summary"]) == {"angles", "base"}
    assert data["verdicts"]["F6"]["by_kind"]["base"]["angles_can_absorb"] is False
    assert "REDUCED" in data["meta"]["budget"]["label"]
    for r in data["runs"]:
        for m in ("fixed", "free"):
            assert r[m]["evaluations"] == 6 and r[m]["objective_common_at_best"] >= 0
    assert data["runs"][0]["strain_rms_mismatch"] > 0  # the angles kind moves the strains
    assert len(list((tmp_path / "state").glob("*.json"))) == 8 and (tmp_path / bm.RUNS_FILE).is_file()
    assert {"fig_errors", "fig_common_objective"} <= set(bm.figures(data))
    assert "| angles:" in bm.markdown_table(data)
    again = bm.run_study(["HV1", "HV2"], ["angles", "base"], **{**kw, "simulate": lambda c: pytest.fail("resimulated")})
    key = lambda runs: [(r["volunteer"], r["kind"], r[m]["objective_common_at_best"], r[m]["alpha_endo"])  # noqa: E731
                        for r in runs for m in ("fixed", "free")]
    assert key(again["runs"]) == key(res["runs"])


def test_cli_names_a_bad_volunteer_and_kind(tmp_path, capsys):
    from lvcore.cli import main

    assert main(["study", "bo-mismatch", "--volunteers", "HV99", "--out", str(tmp_path)]) == 2
    assert "--volunteers" in capsys.readouterr().err
    assert main(["study", "bo-mismatch", "--kinds", "nonsense", "--out", str(tmp_path)]) == 2
    assert "--kinds" in capsys.readouterr().err


def test_docs_quote_the_shipped_verdicts():
    path = bundled_studies_dir() / bm.RESULT_FILE
    if not path.is_file():
        pytest.skip("bo_mismatch.json not shipped yet")
    result = bm.load(bundled_studies_dir())
    assert bm.markdown_table(result) in DOCS.read_text()
    assert json.loads(path.read_text())["meta"]["budget"]["n_initial"] >= 30
    assert all(s["n_volunteers"] >= 3 for s in result["summary"].values())


def test_the_real_lv_is_a_volunteer_of_its_own_mesh_with_simulated_data():
    from lvcore.studies.mismatch import REAL_LV, study_volunteers

    real = study_volunteers([REAL_LV])[0]
    case = bm.data_case(real, "angles")
    assert {k: case["geometry"][k] for k in real.geometry} == real.geometry and case["fibres"] == {"alpha_endo": -30.0, "alpha_epi": 80.0}
    fwd = bm.model_forward(real, "free", kind="angles")
    assert fwd.geometry == real.geometry and not any(k.startswith("h") for k in fwd.conditions)
    assert "REAL-LV mesh" in fwd.label
    assert bm.subject_name(real, "angles") == "REAL-LV-angles"  # a patient's geometry: not labelled SYNTHETIC
    assert bm.subject_name(bundled_volunteers(["HV2"])[0], "base") == "SYNTHETIC-HV2-base"


def test_the_regularised_objective_is_named_in_the_result(tmp_path):
    fac = lambda v, mode, kind: AnalyticForward(input_names=bo_fibres.bo_space(mode).names)  # noqa: E731
    truth = AnalyticForward(input_names=bo_fibres.bo_space("free").names)
    sim = lambda case: np.array(truth({**{n: case["material"][n] for n in ("a", "b", "af", "bf")},  # noqa: E731
                                       **case["fibres"]}), float)
    res = bm.run_study(["HV1"], ["angles"], out=tmp_path, n_initial=5, n_iterations=1, forward_factory=fac,
                       simulate=sim, n_boot=50, objective="posterior")
    meta = res["meta"]
    assert meta["objective"]["name"] == "posterior" and "not the chapter's" in meta["objective"]["what"]
    assert "--objective posterior" in meta["command"]
    run = res["runs"][0]
    assert run["free"]["chi2_at_best"] >= 0 and run["fixed"]["chi2_at_best"] >= 0
    with pytest.raises(bm.LVCoreError, match="--objective"):
        bm.run_study(["HV1"], ["angles"], out=tmp_path, forward_factory=fac, simulate=sim, objective="map")


def test_the_regularised_run_is_shipped_on_eight_volunteers_and_the_real_lv_and_quoted_in_the_docs():
    """``bo_mismatch.json``'s ``posterior`` part: F6 with the regularised objective on HV1-HV8 and the real LV;
    docs/studies.md's block is its generated text; the findings table has its own F6 row, which decides only on
    volunteers whose fits are interior."""
    from lvcore.studies import findings as fd
    from lvcore.studies.mismatch import REAL_LV

    shipped = json.loads((bundled_studies_dir() / bm.RESULT_FILE).read_text())
    post = shipped[bm.POSTERIOR_KEY]
    assert post["meta"]["objective"]["name"] == "posterior" and len(post["meta"]["volunteers"]) >= 9
    assert REAL_LV in post["meta"]["volunteers"] and {r["volunteer"] for r in post["runs"]} >= {REAL_LV, "HV8"}
    assert all(r[m]["chi2_at_best"] >= 0 for r in post["runs"] for m in ("fixed", "free"))
    assert bm.posterior_markdown(shipped) in DOCS.read_text()
    assert bm.DOCS_BEGIN + "\n" + bm.posterior_markdown(shipped) + "\n" + bm.DOCS_END in DOCS.read_text()
    on_box = [(r["volunteer"], m) for r in post["runs"] for m in ("fixed", "free")
              if fd.bo_on_bound(r[m]["theta"], r[m]["alpha_endo"], r[m]["alpha_epi"], m == "free")]
    assert not on_box, f"the shipped regularised run has fits on the BO box: {on_box}"
    rows = [r for r in fd.verdicts(fd.load()) if "regularised BO" in r["finding"]]
    assert len(rows) == 1 and "not the chapter's objective" in rows[0]["doses"]
    verdict_kinds = {(r["objective"], r["kind"]) for r in bm.verdict_rows(bm.load(bundled_studies_dir()))}
    assert ("regularised", "angles") in verdict_kinds and ("chapter", "angles") in verdict_kinds
