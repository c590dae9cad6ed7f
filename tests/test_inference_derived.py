"""lvcore.inference.derived: what one calibration identifies (contraction, the ridge, the FE EDPVR, stress)."""
import json

import numpy as np
import pytest

from lvcore.inference import derived


def test_log_uniform_moments_match_monte_carlo():
    rng = np.random.default_rng(0)
    for lo, hi in ((0.05, 10.0), (0.1, 30.0), (1.0, 2.0)):
        x = np.log(rng.uniform(lo, hi, 2_000_000))
        m, v = derived.log_uniform_moments(lo, hi)
        assert m == pytest.approx(x.mean(), abs=2e-3)
        assert v == pytest.approx(x.var(), rel=3e-3)
    with pytest.raises(ValueError):
        derived.log_uniform_moments(0.0, 1.0)


def test_contraction_is_zero_for_the_prior_and_near_one_when_pinned():
    rng = np.random.default_rng(1)
    bounds = {"a": (0.05, 10.0), "b": (0.1, 30.0), "af": (0.05, 10.0), "bf": (0.1, 30.0)}
    prior = {n: rng.uniform(*bounds[n], 20000) for n in bounds}
    pinned = {n: rng.lognormal(0.0, 0.05, 20000) for n in bounds}
    c0 = derived.contraction(prior, bounds)
    c1 = derived.contraction(pinned, bounds)
    assert all(abs(v) < 0.03 for v in c0.values()), c0
    assert all(v > 0.99 for v in c1.values()), c1


def test_ridge_finds_the_combination_the_draws_pin():
    """log a + 0.8 log b is pinned (sd 0.02), the orthogonal direction free: the best-determined combination is
    that one (coefficients a 1, b 0.8), the least-determined one is across it."""
    rng = np.random.default_rng(2)
    n = 20000
    t = rng.normal(0, 1.0, n)            # along the ridge
    s = rng.normal(0, 0.02, n)           # across it
    d = np.array([1.0, 0.8]) / np.hypot(1.0, 0.8)
    e = np.array([-0.8, 1.0]) / np.hypot(1.0, 0.8)
    la, lb = (t[:, None] * e + s[:, None] * d).T
    samples = {"a": np.exp(la), "b": np.exp(lb), "af": rng.lognormal(0, 0.3, n), "bf": rng.lognormal(1, 0.3, n)}
    r = derived.ridge(samples)
    ab = r["a_b"]["coefficients"]
    assert ab["log_a"] == pytest.approx(1.0) and ab["log_b"] == pytest.approx(0.8, abs=0.01)
    best = r["best"]["coefficients"]
    assert abs(best["log_af"]) < 0.05 and abs(best["log_bf"]) < 0.05
    assert best["log_b"] / best["log_a"] == pytest.approx(0.8, abs=0.01)
    # the 90 % width of log a + 0.8 log b: 2 * 1.645 * 0.02 * |(1, 0.8)|
    assert r["a_b"]["width90_log"] == pytest.approx(2 * 1.645 * 0.02 * np.hypot(1.0, 0.8), rel=0.05)
    assert r["correlation_log_a_log_b"] < -0.9
    least = r["least"]["coefficients"]
    assert least["log_b"] / least["log_a"] == pytest.approx(-1.25, rel=0.05)


def test_fe_load_path_matches_direct_solves_and_the_scale_identity():
    """The chained load path gives what separate cold solves give, and a geometry scaled by s has every volume
    times s^3 (lvcore.geometry.scaling): checked on the fast mesh with three draws."""
    from lvcore.domain import units
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.mechanics.simulate import simulate

    h = [0.3, -0.5, 0.2, 0.0, 0.1]
    draws = [{"a": a, "b": b, "af": 1.2, "bf": 4.0, "h": h, "scale": 1.0} for a, b in ((0.5, 3.0), (0.6, 2.5),
                                                                                        (0.4, 4.0))]
    path = derived.fe_load_path(draws, edp_mmhg=8.0, angles=(-60.0, 60.0), base="sliding", resolution="fast",
                                pressures_mmhg=(5.0, 15.0, 30.0))
    assert path.n_failed == 0
    assert list(path.pressures_mmhg) == [0.0, 5.0, 15.0, 30.0]
    assert np.all(np.diff(path.volumes_ml, axis=1) > 0)
    for k in (0, 2):
        for j, p in ((2, 15.0), (None, 8.0)):
            case = build_case({**{n: draws[k][n] for n in ("a", "b", "af", "bf")}, "edp": p,
                               **{f"h{i + 1}": v for i, v in enumerate(h)}}, resolution="fast", base="sliding")
            res = simulate(case)
            v = res.cavity_volume_mm3[1] / units.MM3_PER_ML
            got = path.volumes_ml[k, j] if j is not None else path.volume_at_edp_ml[k]
            assert got == pytest.approx(v, rel=1e-6)
        assert path.volumes_ml[k, 0] == pytest.approx(res.cavity_volume_mm3[0] / units.MM3_PER_ML, rel=1e-9)
    assert np.all((path.fibre_stretch_at_edp > 1.0) & (path.fibre_stretch_at_edp < 1.4))
    scaled = derived.fe_load_path([{**draws[0], "scale": 1.3}], edp_mmhg=8.0, angles=(-60.0, 60.0),
                                  base="sliding", resolution="fast", pressures_mmhg=(5.0, 15.0, 30.0))
    np.testing.assert_allclose(scaled.volumes_ml[0], 1.3 ** 3 * path.volumes_ml[0], rtol=1e-6)
    assert scaled.fibre_stretch_at_edp[0] == pytest.approx(path.fibre_stretch_at_edp[0], rel=1e-6)
    with pytest.raises(ValueError):
        derived.fe_load_path(draws, edp_mmhg=8.0, angles=(-60.0, 60.0), base="sliding", pressures_mmhg=(10.0, 5.0))


def test_check_flags_only_when_the_measured_point_is_outside():
    rec = {"edpvr_check": {"inside": True}}
    assert derived.check_flags(rec) == []
    rec = {"edpvr_check": {"inside": False, "predictive_99": [100.0, 120.0], "measured_edv_ml": 150.0,
                           "edp_mmhg": 8.0, "emulator_to_fe_offset_ml": {"median": 0.3}}}
    (flag,) = derived.check_flags(rec)
    assert "misses the measured point" in flag and "150.0" in flag
    lo, hi = derived.predictive_interval(np.full(400, 100.0), 5.0, level=0.99)
    assert lo == pytest.approx(100 - 2.576 * 5, abs=0.6) and hi == pytest.approx(100 + 2.576 * 5, abs=0.6)


def test_calibrate_reports_derived_quantities_and_exits_0_on_weak_identification(tmp_path):
    """A bundled volunteer through the CLI: summary.json has the derived EDPVR (0-30 mmHg) with the measured
    point inside its predictive band, stress, the ridge and contraction; weak identification is a note, not a
    flag, so the run exits 0; the per-draw values are saved."""
    from lvcore.cli import main

    out = tmp_path / "o"
    rc = main(["calibrate", "--volunteer", "SYNTHETIC_HV2", "--model", "iid", "--chains", "2", "--warmup", "300",
               "--samples", "300", "--derived-draws", "12", "--out", str(out), "--json"])
    (rec,) = json.loads((out / "summary.json").read_text())
    d = rec["derived"]
    # a given mesh's PC scores and scale with the chapter emulator: the EDPVR emulator, not FE load paths
    assert (d["path"], d["emulator"], d["seconds"]["fe"]) == ("emulator", "edpvr", 0.0)
    assert [r["pressure_mmhg"] for r in d["edpvr"]] == [0, 5, 10, 15, 20, 25, 30]
    med = [r["median"] for r in d["edpvr"]]
    assert all(np.diff(med) > 0)
    assert all(r["q05"] <= r["median"] <= r["q95"] for r in d["edpvr"])
    check = d["edpvr_check"]
    assert check["inside"]
    assert check["predictive_99"][0] <= check["measured_edv_ml"] <= check["predictive_99"][1]
    assert abs(check["emulator_to_fe_offset_ml"]["median"]) < 5.0   # the emulator reproduces the FE here
    assert set(d["contraction"]) == {"a", "b", "af", "bf"}
    assert d["ridge"]["a_b"]["coefficients"]["log_a"] == 1.0
    assert d["stress"]["fixed_stretch"]["fibre_kpa"]["median"] > 0
    assert 1.0 < d["stress"]["end_diastolic"]["stretch"]["median"] < 1.4
    assert not any(f.startswith(("IDENTIFIABILITY", "BOUND")) for f in rec["flags"]), rec["flags"]
    assert rc == (4 if rec["flags"] else 0)
    npz = np.load(out / "SYNTHETIC-HV2_iid_derived.npz")
    assert npz["edpvr_ml"].shape == (12, 7) and npz["theta_a"].shape == (12,)


@pytest.mark.parametrize("value", ["30,20", "0,10", "10,40", "ten"])
def test_derived_pressures_option_is_checked(tmp_path, value):
    from lvcore.cli import main

    assert main(["calibrate", "--volunteer", "SYNTHETIC_HV2", "--derived-pressures", value,
                 "--out", str(tmp_path / "o")]) == 2


def test_the_cli_table_and_the_app_panel_word_the_stress_alike():
    """One wording of the stresses (derived.stress_phrases) in the CLI's table and the app's panel; a record
    without the end-diastolic stretch gives the fixed-stretch phrase only."""
    from lvcore.app.physiology_panel import summary_lines

    def q(m):
        return {"median": m, "q05": 0.9 * m, "q95": 1.1 * m}

    combo = {"text": "log_a + log_b", "median": 0.1, "width90_factor": 1.5, "width90_log": 0.4}
    record = {"stress": {"fixed_stretch": {"stretch": 1.1, "fibre_kpa": q(2.0), "cross_fibre_kpa": q(0.5)},
                         "end_diastolic": {"stretch": q(1.08), "fibre_kpa": q(1.2), "cross_fibre_kpa": q(0.3)}},
              "ridge": {"a_b": combo, "best": combo, "least": combo, "correlation_log_a_log_b": -0.5},
              "edpvr": [{"pressure_mmhg": 0, "median": 50.0, "q05": 48.0, "q95": 52.0}],
              "edpvr_check": {"edp_mmhg": 8.0, "emulator_to_fe_offset_ml": q(0.2), "source": "FE"},
              "contraction": {"a": 0.5}, "weakly_identified": []}
    phrases = derived.stress_phrases(record["stress"])
    assert phrases == ["Cauchy stress at fibre stretch 1.10: fibre 2.00 kPa [1.80, 2.20]; cross-fibre 0.50 kPa "
                       "[0.45, 0.55]", "At the mean end-diastolic fibre stretch 1.080 [0.972, 1.188]: fibre 1.20 kPa "
                       "[1.08, 1.32]; cross-fibre 0.30 kPa [0.27, 0.33]"]
    table = derived.text_table(record).splitlines()
    assert [f"  {p}" for p in phrases] == [line for line in table if "fibre stretch" in line]
    panel = [line for line in summary_lines(record) if "fibre stretch" in line]
    assert [p.replace("**", "") for p in panel] == [f"{p}." for p in phrases]
    assert panel[0].startswith("**Cauchy stress at fibre stretch 1.10**:")
    del record["stress"]["end_diastolic"]
    assert derived.stress_phrases(record["stress"]) == phrases[:1]
