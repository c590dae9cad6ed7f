"""Mismatch study: the mismatched cases, the per-dose summaries and CIs, the appearance rule, CLI errors."""
import numpy as np
import pytest

from lvcore.mechanics.case import Case
from lvcore.studies import mismatch as mm

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
def test_fit_doses_sees_a_strain_mismatch_on_the_analytic_stand_in():
    """fit_doses on the SYNTHETIC closed-form stand-in: without mismatch iid σ_S ≈ 0.03 and θ is mostly
    covered; a strain offset of RMS 0.06 that θ cannot absorb (alternating by sector, orthogonal to the
    stand-in's loadings 1, cos γ, sin γ, cos 2γ) inflates iid σ_S."""
    from lvcore.testing.analytic import AnalyticForward
    from lvcore.inference import samplers

    fwd = AnalyticForward()
    vol = mm.Volunteer("T", H, THETA)
    z = np.asarray(fwd(THETA), dtype=float)
    bump = 0.06 * (-1.0) ** (np.arange(24) % 6)
    zs = {("none", 0.0): z, ("bump", 1.0): z + np.r_[0.0, bump]}
    cfg = samplers.SamplerConfig(num_warmup=150, num_samples=150, num_chains=1)
    res = mm.fit_doses(vol, zs, fwd, seeds=3, config=cfg, seed=0,
                       noise_seeds={("none", 0.0): 1, ("bump", 1.0): 2})
    clean_iid = np.median(res[("none", 0.0)]["iid"]["sigma_s"])
    bumped_iid = np.median(res[("bump", 1.0)]["iid"]["sigma_s"])
    assert clean_iid == pytest.approx(0.03, abs=0.008) and bumped_iid > 1.5 * clean_iid
    assert np.mean(res[("none", 0.0)]["iid"]["coverage"]) >= 0.6
    for k in zs:
        assert all(len(res[k][m]["output_error"]) == 3 and len(res[k][m]["coverage"]) == 3 for m in mm.MODELS)
        assert "sigma_s" not in res[k]["volume"] and np.all(np.asarray(res[k]["discrepancy"]["sigma_s"]) > 0)
