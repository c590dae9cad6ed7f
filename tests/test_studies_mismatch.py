"""Mismatch study: the mismatched cases, the per-dose summaries and CIs, the appearance rule, CLI errors."""
import json

import numpy as np
import pytest

from lvcore.mechanics.case import Case
from lvcore.studies import mismatch as mm
from repo_scripts import load_script

THETA = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}
H = (0.5, -0.4, 0.3, -0.2, 0.1)


def test_nominal_case_is_the_calibration_models_condition():
    c = Case.from_dict(mm.mismatch_case(THETA, H, None, 0.0))
    assert (c.fibres.alpha_endo_deg, c.fibres.alpha_epi_deg) == mm.MODEL_ANGLES
    assert c.boundary.base == "sliding" and c.boundary.epicardial_spring == 0.0 and c.regional is None
    assert c.material.params["kappa"] == 0.0 and c.geometry.kind == "pca"


@pytest.mark.parametrize("source,dose,check", [
    ("angles", 30.0, lambda c: (c.fibres.alpha_endo_deg, c.fibres.alpha_epi_deg) == (-30.0, 90.0)),
    ("base", 1.0, lambda c: c.boundary.base == "clamped"),
    ("sheet", 4.0, lambda c: np.isclose(c.material.params["as"], 4 * 0.69)
     and np.isclose(c.material.params["afs"], 4 * 0.31) and c.material.params["bs"] == 1.11),
    ("dispersion", 0.2, lambda c: c.material.params["kappa"] == 0.2),
    ("heterogeneity", 0.4, lambda c: not c.regional.is_uniform()
     and np.isclose(np.std(np.log(c.regional.factors["a"])), 0.4, rtol=0.4)),
    ("pericardium", 0.1, lambda c: c.boundary.epicardial_spring == 0.1 and c.boundary.spring_direction == "normal"),
])
def test_each_source_changes_only_its_own_term(source, dose, check):
    nominal = Case.from_dict(mm.mismatch_case(THETA, H, None, 0.0))
    c = Case.from_dict(mm.mismatch_case(THETA, H, source, dose))
    assert check(c) and c != nominal
    assert c.geometry == nominal.geometry and c.load == nominal.load


def test_heterogeneity_field_is_fixed_and_scales_with_the_dose():
    f1 = mm.mismatch_case(THETA, H, "heterogeneity", 0.2)["material"]["regional"]["a"]
    f2 = mm.mismatch_case(THETA, H, "heterogeneity", 0.4)["material"]["regional"]["a"]
    np.testing.assert_allclose(np.log(f2), 2 * np.log(f1))


def _fit(iid_sigma, err, cov=1.0, n=20):
    return {m: {"coverage": [cov] * n, "output_error": [err[m]] * n,
                **({"sigma_s": [iid_sigma if m == "iid" else 0.03] * n} if m != "volume" else {})}
            for m in mm.MODELS}


def test_summary_cis_and_appearance():
    rng = np.random.default_rng(0)
    low = _fit(0.031, {"volume": 0.01, "iid": 0.008, "discrepancy": 0.01})
    high = _fit(0.06, {"volume": 0.01, "iid": 0.03, "discrepancy": 0.012})
    high["iid"]["sigma_s"] = list(0.06 + 0.002 * rng.standard_normal(20))
    rows = mm.summarise({("dispersion", 0.1): {"HV1": low}, ("dispersion", 0.3): {"HV1": high}},
                        {("dispersion", 0.1): {"mean": 0.01}, ("dispersion", 0.3): {"mean": 0.05}})
    r_low, r_high = rows
    assert r_low["iid_sigma_s_inflation"]["value"] == pytest.approx(0.031 / 0.03)
    assert not r_low["f1"] and not r_low["f3"]
    lo, hi = r_high["iid_sigma_s_inflation"]["ci"]
    assert lo < r_high["iid_sigma_s_inflation"]["value"] < hi and lo > 1.8 and r_high["f1"] and r_high["f3"]
    assert r_high["theta_coverage"]["iid"]["value"] == 1.0 and r_high["output_error"]["iid"]["n"] == 20
    app = mm.appearance(rows)
    assert app["dispersion"]["f1"] == {"dose": 0.3, "strain_rms": 0.05}
    rows2 = mm.summarise({("sheet", 2.0): {"HV1": low}}, {("sheet", 2.0): {"mean": 0.004}})
    assert mm.appearance(rows2)["sheet"]["f1"] == "does not appear up to RMS 0.004"


def test_cli_refuses_bad_options(capsys):
    from lvcore.cli import main

    assert main(["study", "mismatch", "--sources", "angles,moon"]) == 2
    assert "moon" in capsys.readouterr().err
    assert main(["study", "mismatch", "--sources", "sheet", "--doses", "sheet=2,x"]) == 2
    assert "numbers" in capsys.readouterr().err
    assert main(["study", "mismatch", "--sources", "sheet", "--volunteers", "HV99"]) == 2
    assert "HV99" in capsys.readouterr().err


@pytest.mark.slow
def test_fit_datasets_sees_a_strain_mismatch_on_the_analytic_stand_in():
    """fit_datasets on the SYNTHETIC closed-form stand-in: without mismatch iid σ_S ≈ 0.03 and θ is mostly
    covered; a strain offset of RMS 0.06 that θ cannot absorb (alternating by sector, orthogonal to the
    stand-in's loadings 1, cos γ, sin γ, cos 2γ) inflates iid σ_S; ESS and R-hat come per data set."""
    import jax

    from lvcore.inference import samplers
    from lvcore.domain.outputs import THETA_NAMES
    from lvcore.testing.analytic import AnalyticForward

    fwd = AnalyticForward()
    z = np.asarray(fwd(THETA), dtype=float)
    bump = 0.06 * (-1.0) ** (np.arange(24) % 6)
    ys = np.concatenate([mm.noisy_copies(z, 3, 1), mm.noisy_copies(z + np.r_[0.0, bump], 3, 2)])
    truths = np.repeat(np.array([[THETA[n] for n in THETA_NAMES]]), 6, axis=0)
    cfg = samplers.SamplerConfig(num_warmup=100, num_samples=100, num_chains=2)
    res = mm.fit_datasets(fwd, ys, None, truths, np.repeat(z[None], 6, axis=0), config=cfg,
                          keys=jax.random.split(jax.random.PRNGKey(0), 6))
    clean_iid, bumped_iid = np.median(res["iid"]["sigma_s"][:3]), np.median(res["iid"]["sigma_s"][3:])
    assert clean_iid == pytest.approx(0.03, abs=0.008) and bumped_iid > 1.5 * clean_iid
    assert np.mean(res["iid"]["coverage"][:3]) >= 0.6
    for m in mm.MODELS:
        assert all(len(res[m][k]) == 6 for k in ("coverage", "output_error", "min_ess", "max_rhat"))
        assert np.all(res[m]["min_ess"] > 0) and np.all(res[m]["max_rhat"] > 0.9)
    assert "sigma_s" not in res["volume"] and np.all(np.asarray(res["discrepancy"]["sigma_s"]) > 0)


def test_unit_seed_depends_only_on_the_key():
    assert mm.unit_seed("HV1__sheet__4", 0) == mm.unit_seed("HV1__sheet__4", 0)
    assert mm.unit_seed("HV1__sheet__4", 0) != mm.unit_seed("HV1__sheet__8", 0)
    assert mm.unit_seed("HV1__sheet__4", 0) != mm.unit_seed("HV1__sheet__4", 1)
    a, b = mm.noisy_copies(np.zeros(25), 4, 7), mm.noisy_copies(np.zeros(25), 4, 7)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (4, 25) and 2 < np.std(a[:, 0]) < 9 and 0.01 < np.std(a[:, 1:]) < 0.05


def test_measured_doses_are_the_strain_rms_over_volunteers():
    vols = [mm.Volunteer("A", H, THETA), mm.Volunteer("B", H, THETA)]
    nom = np.r_[100.0, np.zeros(24)]
    sims = {"A__none__0": {"converged": True, "outputs": nom.tolist()},
            "B__none__0": {"converged": True, "outputs": nom.tolist()},
            "A__sheet__2": {"converged": True, "outputs": (nom + np.r_[5.0, np.full(24, 0.02)]).tolist()},
            "B__sheet__2": {"converged": True, "outputs": (nom + np.r_[0.0, np.full(24, 0.04)]).tolist()},
            "A__sheet__4": {"converged": False, "reason": "diverged"}, "B__sheet__4": {"converged": False}}
    m = mm.measured_doses(sims, vols, {"sheet": (2.0, 4.0)})
    by = m[("sheet", 2.0)].pop("by_volunteer")
    assert m[("sheet", 2.0)] == pytest.approx({"mean": 0.03, "min": 0.02, "max": 0.04, "n": 2, "failed": 0})
    assert by == pytest.approx({"A": 0.02, "B": 0.04})  # each volunteer's own size (the cluster bootstrap's unit)
    assert m[("sheet", 4.0)]["n"] == 0 and m[("sheet", 4.0)]["failed"] == 2 and m[("sheet", 4.0)]["mean"] is None


# ---------------------------------------------------------------------------- results, figures, findings
def test_figures_have_axis_titles_ci_bands_and_no_negative_values(mismatch_result):
    res = mismatch_result()
    figs = mm.figures(res)
    assert set(figs) == set(mm.TITLES) - {"table_mismatch_real_lv"}      # no real-LV rows in this result
    for name in ("fig_mismatch_sigma_s_inflation", "fig_mismatch_discrepancy_sigma_s", "fig_mismatch_output_error"):
        fig = figs[name]
        assert "SYNTHETIC" in fig.layout.title.text
        assert fig.layout.xaxis.title.text and "strain RMS" in fig.layout.xaxis.title.text
        assert fig.layout.yaxis.title.text
        bands = [t for t in fig.data if t.fill == "toself"]
        lines = [t for t in fig.data if t.mode == "lines+markers"]
        assert bands and len(bands) == len(lines)
        for band, line in zip(bands, lines):
            assert band.name == f"{line.name} CI"
            n = len(line.x)
            hi, lo = np.asarray(band.y[:n]), np.asarray(band.y[n:])[::-1]
            assert np.all(lo <= np.asarray(line.y) + 1e-12) and np.all(np.asarray(line.y) <= hi + 1e-12)
            assert np.all(np.asarray(band.y) >= 0) and np.all(np.asarray(line.y) >= 0)
            assert np.all(np.asarray(line.x) >= 0)
    err = figs["fig_mismatch_output_error"]
    assert {t.name for t in err.data if t.mode == "lines+markers"} == set(mm.MODELS)
    tabs = mm.tables(res)
    assert len(tabs["table_mismatch_doses"]) == 3 and (tabs["fig_mismatch_output_error"]["lo"] >= 0).all()
    assert mm.figures({**res, "rows": []}) == {}


def test_inflation_ci_and_f3_gap_from_paired_differences(mismatch_result):
    rows = mismatch_result()["rows"]
    assert [r["f1"] for r in rows] == [False, False, True]
    assert rows[2]["iid_sigma_s_inflation"]["ci"][0] > 2.0
    assert [r["f3"] for r in rows] == [False, True, True]
    assert rows[0]["diagnostics"]["iid"]["share_rhat_over_1_05"] == 0.0
    assert mm.appearance(rows)["dispersion"] == {"f1": {"dose": 3.0, "strain_rms": 0.06},
                                                 "f3": {"dose": 2.0, "strain_rms": 0.03}}


def test_load_refuses_other_json(tmp_path):
    import json

    from lvcore.exceptions import LVCoreError

    (tmp_path / "mismatch.json").write_text(json.dumps({"study": "operators"}))
    with pytest.raises(ValueError, match="not the output of lvcore study mismatch"):
        mm.load(tmp_path)
    with pytest.raises(LVCoreError):
        mm.load(tmp_path / "nowhere")


def test_shipped_results_docs_and_locator():
    """The shipped mismatch.json is found by the results locator, drawn, and docs/studies.md's two generated
    blocks (per-dose table; findings table with verdicts) are exactly what the shipped JSON gives."""
    from pathlib import Path

    from lvcore.studies import findings as fd
    from lvcore.studies import results

    folder = dict(results.result_sources()["mismatch"])["bundled"]
    shipped = mm.load(folder)
    assert shipped["synthetic"] and shipped["shipped"]["script"] == "scripts/ship_mismatch.py"
    assert shipped["seeds_per_dose"] >= 20 and shipped["rows"] and all(r["n_datasets"] >= 20 for r in shipped["rows"])
    planned = {(s, d) for s, ds in shipped["doses"].items() for d in ds}  # fitted + listed as not fitted = planned
    assert {(r["source"], r["dose"]) for r in shipped["rows"]} | {(u["source"], u["dose"]) for u in
                                                                  shipped["not_fitted"]} == planned
    assert shipped["complete"] == (not shipped["not_fitted"] and not shipped["failed"])
    doc = (Path(__file__).resolve().parents[1] / "docs" / "studies.md").read_text()
    for mod, text in ((mm, mm.docs_markdown(shipped)), (fd, fd.docs_markdown(fd.load(folder)))):
        assert doc.count(mod.DOCS_BEGIN) == 1 and doc.count(mod.DOCS_END) == 1
        block = doc.split(mod.DOCS_BEGIN)[1].split(mod.DOCS_END)[0].strip()
        assert block == text.strip(), f"run python scripts/ship_mismatch.py --docs-only ({mod.__name__})"
    rows = fd.verdicts(fd.load(folder))
    assert {r["verdict"] for r in rows} <= set(fd.VERDICTS)
    assert [r["finding"].split(" ")[0] for r in rows][:3] == ["F1", "F2", "F3"]
    # F5 / F6: one row per study (their fits re-judged by the findings' rule: tests/test_studies_findings_stats.py)
    assert any(r["finding"].startswith("F5 (") for r in rows) and any(r["finding"].startswith("F6 (") for r in rows)
    assert set(mm.figures(shipped)) == set(mm.TITLES)


def test_fit_cost_sums_batches_once_and_reports_per_dataset_cost():
    a = {"cpu_s": 120.0, "wall_s": 300.0, "datasets": 40, "units": 2}  # one batch behind two fits
    b = {"cpu_s": 80.0, "wall_s": 200.0, "datasets": 40, "units": 1}  # a padded last batch behind one fit
    c = mm.fit_cost([a, a, b])
    assert c["cpu_s"] == pytest.approx(200.0) and c["batches"] == pytest.approx(2.0) and c["fits_with_cost"] == 3
    assert c["cpu_s_per_dataset_median"] == pytest.approx(3.0) and c["cpu_s_per_dataset_range"] == [2.0, 3.0]
    assert mm.fit_cost([]) is None


def test_verdict_rows_take_the_convergence_check_in_place_of_the_main_rows(mismatch_result):
    res = mismatch_result()
    check_rows = [dict(res["rows"][2], iid_sigma_s_inflation={"value": 1.1, "ci": [1.0, 1.2], "n": 20}, f1=False)]
    res = {**res, "sampler": {"num_chains": 1, "num_warmup": 150, "num_samples": 150},
           "check": {"sampler": {"num_chains": 2, "num_warmup": 300, "num_samples": 300}, "rows": check_rows,
                     "not_fitted": [], "fit_cost": None}}
    rows = mm.verdict_rows(res)
    assert [r["checked"] for r in rows] == [False, False, True]
    assert [r["budget"] for r in rows] == ["1 × (150 + 150)"] * 2 + ["2 × (300 + 300)"]
    assert rows[2]["iid_sigma_s_inflation"]["value"] == 1.1 and not rows[2]["f1"]
    assert rows[0]["iid_sigma_s_inflation"] == res["rows"][0]["iid_sigma_s_inflation"]
    text = mm.docs_markdown(res)
    assert "**Convergence check.**" in text and "2 × (300 + 300)" in text
    # the checked dose appears at both budgets in the check table
    check_table = text.split("**Convergence check.**")[1]
    assert check_table.count("| dispersion | 3 | 1 × (150 + 150) |") == 1
    assert check_table.count("| dispersion | 3 | 2 × (300 + 300) |") == 1
    assert mm.verdict_rows({**res, "check": None}) == [{**r, "budget": "1 × (150 + 150)", "checked": False}
                                                       for r in res["rows"]]


def _ship_script():
    return load_script("scripts/ship_mismatch.py")


def test_carry_over_fills_only_not_fitted_doses_of_the_same_design(mismatch_result, tmp_path):
    import json

    ship = _ship_script()
    full = mismatch_result()
    old = {**full, "shipped": {"date": "2026-11-25", "command": "python scripts/ship_mismatch.py"}}
    old.pop("folder")
    (tmp_path / "old.json").write_text(json.dumps(old))
    res = {**full, "rows": full["rows"][:1], "failed": [],
           "not_fitted": [{"volunteer": "HV1", "source": "dispersion", "dose": d} for d in (2.0, 3.0)]}
    ship.carry_over(res, tmp_path / "old.json")
    assert [r["dose"] for r in res["rows"]] == [1.0, 2.0, 3.0] and res["complete"] and not res["not_fitted"]
    assert [r.get("carried_over") for r in res["rows"]] == [None, "2026-11-25", "2026-11-25"]
    assert res["appearance"] == mm.appearance(full["rows"]) and len(res["carried_over"]["doses"]) == 2
    text = mm.docs_markdown({**res, "seeds_per_dose": 20})
    assert "**Carried over (†):** 2 doses" in text and "| dispersion | 2 † |" in text
    other = {**old, "sampler": {**old["sampler"], "num_chains": 1}}
    (tmp_path / "other.json").write_text(json.dumps(other))
    with pytest.raises(SystemExit, match="another design"):
        ship.carry_over({**full, "not_fitted": []}, tmp_path / "other.json")


def test_carry_over_keeps_the_earlier_checks_rows_of_doses_the_new_check_did_not_refit(mismatch_result, tmp_path):
    """A check that refits some doses anew (e.g. the realistic ones) keeps the earlier check's rows of the others,
    marked carried over; a check at another budget is refused."""
    import json

    ship = _ship_script()
    full = mismatch_result()
    smp = {"num_chains": 2, "num_warmup": 300, "num_samples": 300}
    old = {**full, "shipped": {"date": "2026-11-27", "command": "python scripts/ship_mismatch.py"},
           "check": {"sampler": smp, "rows": full["rows"][1:], "not_fitted": [], "failed": []}}
    old.pop("folder")
    (tmp_path / "old.json").write_text(json.dumps(old))
    check = {"sampler": smp, "rows": full["rows"][:1], "failed": [],
             "not_fitted": [{"volunteer": "HV1", "source": "dispersion", "dose": d} for d in (2.0, 3.0)]}
    ship.carry_over(check, tmp_path / "old.json", part="check")
    assert [r["dose"] for r in check["rows"]] == [1.0, 2.0, 3.0] and not check["not_fitted"]
    assert [r.get("carried_over") for r in check["rows"]] == [None, "2026-11-27", "2026-11-27"]
    assert "complete" not in check
    with pytest.raises(SystemExit, match="another design"):
        ship.carry_over({**check, "sampler": {**smp, "num_chains": 4}}, tmp_path / "old.json", part="check")


def test_an_unfitted_convergence_check_is_said_in_the_docs_block(mismatch_result):
    res = {**mismatch_result(), "check": {"sampler": {"num_chains": 2, "num_warmup": 300, "num_samples": 300},
                                          "rows": [], "not_fitted": [{"volunteer": "HV1", "source": "dispersion",
                                                                      "dose": 3.0}]}}
    text = mm.docs_markdown(res)
    assert "**Convergence check** (2 × (300 + 300) on dispersion 3): not fitted" in text
    assert all(not r["checked"] for r in mm.verdict_rows(res))


def test_the_real_lv_is_shown_beside_the_volunteers_and_kept_out_of_the_verdicts(mismatch_result):
    """The shipped JSON's real_lv rows get a table of their own in the docs block, each dose beside the
    volunteers' row of the same dose (their per-volunteer medians); the findings' dose tests read the volunteers'
    rows only."""
    from lvcore.studies import findings as fd

    res = mismatch_result()
    real = mismatch_result(doses=((0.02, 0.045, 0.01),))["rows"]     # dose 1.0, another mismatch size
    res["real_lv"] = {"rows": real, "sampler": res["sampler"], "seeds_per_dose": 20,
                      "theta": {"a": 0.994, "b": 2.14, "af": 1.05, "bf": 3.9}}
    text = mm.docs_markdown(res)
    assert "**The real LV beside the volunteers.**" in text and "a 0.994, b 2.14" in text
    line = next(x for x in text.splitlines() if x.startswith("| dispersion | 1 | 0.0200 / 0.0100"))
    vol = res["rows"][0]["per_volunteer"]["HV1"]["iid_sigma_s"]
    assert f"{np.median(vol) / 0.03:.2f} [" in line           # the volunteers' per-volunteer median
    assert "real LV" not in mm.docs_markdown(mismatch_result())  # no real_lv, no table
    tab = mm.tables(res)["table_mismatch_real_lv"]
    assert tab.loc[0, "strain RMS real LV"] == pytest.approx(0.02) and "table_mismatch_real_lv" in mm.figures(res)
    assert len(fd.mismatch_dose_tests(res)) == len(res["rows"])


def test_carry_over_replaces_a_dose_fitted_for_some_volunteers_only(mismatch_result, tmp_path):
    import json

    ship = _ship_script()
    full = mismatch_result()
    old = {**full, "shipped": {"date": "2026-11-25"}}
    old.pop("folder")
    (tmp_path / "old.json").write_text(json.dumps(old))
    partial = {**full["rows"][1], "n_datasets": 20}
    res = {**full, "rows": [full["rows"][0], partial], "failed": [],
           "not_fitted": [{"volunteer": "HV2", "source": "dispersion", "dose": 2.0}]}
    ship.carry_over(res, tmp_path / "old.json")
    assert [(r["dose"], r.get("carried_over")) for r in res["rows"]] == [(1.0, None), (2.0, "2026-11-25")]


def test_a_check_of_every_dose_becomes_the_shipped_run_and_the_main_run_is_superseded(mismatch_result):
    """promote_check: with a convergence check that refitted every dose, the check's rows and sampler are the
    run (every shipped fit has its chains) and the main run is only recorded (budget, worst R-hat share); a check
    of some doses leaves the result as it is. The shipped mismatch.json is promoted: no fit with one chain."""
    res = {**mismatch_result(), "sampler": {"num_chains": 1, "num_warmup": 150, "num_samples": 150}}
    smp = {"num_chains": 2, "num_warmup": 300, "num_samples": 300}
    full = {"sampler": smp, "rows": [dict(r, n_datasets=99) for r in res["rows"]], "failed": [], "not_fitted": []}
    out = mm.promote_check({**res, "check": full})
    assert "check" not in out and out["sampler"] == smp and [r["n_datasets"] for r in out["rows"]] == [99] * len(
        res["rows"])
    assert out["superseded"]["sampler"] == res["sampler"] and out["complete"]
    assert all(r["budget"] == "2 × (300 + 300)" for r in mm.verdict_rows(out))
    some = {**full, "rows": full["rows"][1:]}
    assert mm.promote_check({**res, "check": some}) == {**res, "check": some}
    assert mm.promote_check(res) == res
    from lvcore.studies import results

    shipped = mm.load(dict(results.result_sources()["mismatch"])["bundled"])
    assert "check" not in shipped and shipped["sampler"]["num_chains"] >= 2 and shipped["superseded"]
    assert (shipped["real_lv"]["sampler"]["num_chains"]) >= 2


def test_carry_over_from_a_promoted_ship_fills_the_check_and_not_the_main_run(tmp_path, mismatch_result):
    ship = load_script("scripts/ship_mismatch.py")
    smp = {"num_chains": 2, "num_warmup": 300, "num_samples": 300}
    full = mismatch_result()
    promoted = {**full, "sampler": smp, "superseded": {"sampler": {"num_chains": 1}}, "shipped": {"date": "d"}}
    (tmp_path / "old.json").write_text(json.dumps({**promoted, "folder": None}))
    missing = [{"source": r["source"], "dose": r["dose"]} for r in full["rows"][:1]]
    check = {"sampler": smp, "rows": full["rows"][1:], "not_fitted": missing, "failed": []}
    ship.carry_over(check, tmp_path / "old.json", part="check")
    assert [(r["source"], r["dose"]) for r in check["rows"]] == [(r["source"], r["dose"]) for r in full["rows"]]
    main = {**full, "sampler": {"num_chains": 1, "num_warmup": 150, "num_samples": 150}, "not_fitted": missing,
            "rows": full["rows"][1:]}
    ship.carry_over(main, tmp_path / "old.json")          # no main run in a promoted ship: nothing carried
    assert len(main["rows"]) == len(full["rows"]) - 1 and "carried_over" not in main
