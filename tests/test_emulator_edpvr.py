"""lvcore.emulator.edpvr: the bundled EDPVR emulator (an EDP input, 0-30 mmHg) against the FE simulator, its V₀,
and the choice between it and the FE load path in the derived quantities."""
import numpy as np
import pytest

from lvcore.emulator import edpvr
from lvcore.inference import derived

PRESSURES = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0)


@pytest.fixture(scope="module")
def emu():
    return edpvr.load_edpvr_emulator()


def _draw(a=1.0, b=5.0, af=1.5, bf=6.0, h=(0.4, -0.8, 0.3, 0.6, -0.2), scale=1.0, **extra):
    return {"a": a, "b": b, "af": af, "bf": bf, "h": list(h), "scale": scale, **extra}


def test_bundled_emulator_is_small_and_shipped_apart_from_the_calibration_emulators(emu):
    from lvcore.emulator.io import available_emulators

    folder = edpvr.find_edpvr_emulator()
    assert (folder / "network.npz").stat().st_size < 1_000_000
    assert "edpvr" not in available_emulators()   # not offered as a calibration emulator (no metadata.json)
    assert (emu.base, emu.resolution) == ("sliding", "default")
    assert emu.fixed == {"alpha_endo": -60.0, "alpha_epi": 60.0}
    assert emu.lower[-1] == 0.0 and emu.upper[-1] == 30.0
    t = emu.metadata["test"]
    assert t["n_paths"] >= 32 and max(t["pressures_mmhg"]) == 30.0
    # the stated held-out error is what derive() adds to the band: at most a few per cent of the volume
    assert 0 < max(t["log_volume_ratio_rmse"]) < 0.05


def test_reference_volumes_are_the_simulators(emu):
    """V₀ from the saved endocardium (linear in h) equals the simulator's own reference cavity."""
    from lvcore.inference.loaded_states import reference_volume_ml

    h = np.random.default_rng(3).uniform(-2, 2, (3, 5))
    got = edpvr.reference_volumes_ml(h, emu.geometry)
    for k in range(3):
        want = reference_volume_ml({"kind": "pca", "scores": list(h[k]), "resolution": "default"})
        assert got[k] == pytest.approx(want, rel=1e-9)


def test_emulator_agrees_with_fe_load_paths_on_held_out_draws(emu):
    """Three draws off the training design: the emulated EDPVR is within 4 times the stated held-out error (relative
    volume RMSE at each pressure) of FE load paths, and the mean fibre stretch at the EDP within 4 RMSEs + 0.005."""
    draws = [_draw(), _draw(a=0.4, b=9.0, af=3.0, bf=2.0, h=(-1.0, 0.5, 1.2, -0.4, 0.9), scale=1.1),
             _draw(a=2.5, b=2.0, af=0.8, bf=12.0, h=(1.5, 1.0, -1.3, 0.2, 0.0))]
    fe = derived.fe_load_path(draws, edp_mmhg=11.0, angles=(-60.0, 60.0), base="sliding", resolution="default",
                              pressures_mmhg=PRESSURES)
    assert fe.n_failed == 0
    em = edpvr.emulated_load_path(emu, draws, edp_mmhg=11.0, pressures_mmhg=PRESSURES)
    np.testing.assert_allclose(em.volumes_ml[:, 0], fe.volumes_ml[:, 0], rtol=1e-9)   # V₀ is exact
    sd = emu.volume_log_sd(np.asarray(PRESSURES))
    rel = np.abs(np.log(em.volumes_ml[:, 1:] / fe.volumes_ml[:, 1:]))
    assert np.all(rel <= 4 * sd + 1e-3), (rel, sd)
    assert np.all(np.abs(np.log(em.volume_at_edp_ml / fe.volume_at_edp_ml)) <= 4 * emu.volume_log_sd(11.0) + 1e-3)
    lam_sd = float(emu.stretch_sd(11.0))
    np.testing.assert_allclose(em.fibre_stretch_at_edp, fe.fibre_stretch_at_edp, atol=4 * lam_sd + 0.005)


def test_path_choice(emu):
    """The emulator for the shape model's PC routes (given or inferred scores, any scale) at its conditions; the FE
    load path for a subject emulator's mesh, inferred angles, another base, mesh or angles, draws outside its box, or
    when asked."""
    kw = dict(angles=(-60.0, 60.0), base="sliding", resolution="default", edp_mmhg=8.0, pressures_mmhg=PRESSURES)
    got, why = edpvr.emulator_for([_draw(), _draw(scale=1.3, h=(1.9, -1.9, 0, 0, 0))], geometry=None, **kw)
    assert got is not None and got.name == "edpvr" and why == ""
    mesh = {"kind": "mesh", "path": "subject.json"}
    cases = [(dict(geometry=mesh), [_draw()], "mesh"),
             (dict(), [_draw(alpha_endo=-50.0, alpha_epi=55.0)], "angles"),
             (dict(base="clamped"), [_draw()], "base"),
             (dict(resolution="fast"), [_draw()], "resolution"),
             (dict(angles=(-50.0, 60.0)), [_draw()], "angles"),
             (dict(angles=(None, None)), [_draw()], "angles"),
             (dict(), [_draw(h=(2.5, 0, 0, 0, 0))], "box"),
             (dict(), [_draw(a=20.0)], "box"),
             (dict(edp_mmhg=31.0), [_draw()], "box"),
             (dict(name=None), [_draw()], "FE load path was asked")]
    for change, draws, word in cases:
        args = {"geometry": None, **kw, **change}
        got, why = edpvr.emulator_for(draws, **args)
        assert got is None and word in why, (change, why)


def test_derive_records_the_path_and_widens_the_band_by_the_emulator_error(emu):
    """derive() on a SYNTHETIC posterior with given PC scores takes the emulator path (no FE solve): the record says
    so, and the 99 % predictive band at the EDP is the draws' volumes with the data's sd and the emulator's held-out
    error added in quadrature."""
    import arviz as az

    rng = np.random.default_rng(0)
    n = 200
    post = {"a": np.exp(rng.normal(0.0, 0.1, (2, n))), "b": np.exp(rng.normal(1.6, 0.1, (2, n))),
            "af": np.exp(rng.normal(0.4, 0.1, (2, n))), "bf": np.exp(rng.normal(1.8, 0.1, (2, n)))}
    idata = az.from_dict(posterior=post)
    h = [0.4, -0.8, 0.3, 0.6, -0.2]
    bounds = {"a": (0.05, 10.0), "b": (0.1, 30.0), "af": (0.05, 10.0), "bf": (0.1, 30.0)}
    kw = dict(bounds=bounds, edp_mmhg=8.0, angles=(-60.0, 60.0), base="sliding", resolution="default",
              measured_edv_ml=None, lvv_sd_ml=1e-6, h=h, scale=1.0, n_draws=100)
    rec, dd = derived.derive(idata, **kw)
    assert (rec["path"], rec["emulator"], rec["path_reason"]) == ("emulator", "edpvr", "")
    assert rec["seconds"]["fe"] == 0.0 and rec["edpvr_check"]["n_failed_solves"] == 0
    assert "EDPVR emulator 'edpvr'" in rec["edpvr_check"]["source"]
    v = dd.fe_edv_ml
    med = float(np.median(v))
    rec2, _ = derived.derive(idata, **{**kw, "measured_edv_ml": med})
    lo, hi = rec2["edpvr_check"]["predictive_99"]
    sd = emu.volume_log_sd(8.0) * v
    want = derived.predictive_interval(v, sd, level=0.99)
    assert (lo, hi) == pytest.approx(want, rel=1e-9)
    assert hi - lo > np.quantile(v, 0.995) - np.quantile(v, 0.005)   # wider than the draws' spread alone
    assert rec2["edpvr_check"]["inside"] and derived.check_flags(rec2) == []


def test_load_path_solves_are_the_simulators():
    """A load path (warm continuation from the pressure below) gives the cold solve's LVV, strains and mean fibre
    stretch at each pressure (fast mesh)."""
    from lvcore.campaigns.load_paths import solve_load_path
    from lvcore.domain import units
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.mechanics.fibre_stretch import mean_fibre_stretch
    from lvcore.mechanics.simulate import simulate

    case = build_case({"a": 0.8, "b": 6.0, "af": 1.5, "bf": 8.0, "h1": 0.5, "h2": -0.3}, resolution="fast",
                      base="sliding")
    v0, lvv, strains, lam = solve_load_path(case, (2.0, 8.0))
    c8 = {**case, "load": {"pressure": 8.0, "units": "mmHg"}}
    res = simulate(c8)
    assert v0 == pytest.approx(res.cavity_volume_mm3[0] / units.MM3_PER_ML, rel=1e-9)
    assert lvv[1] == pytest.approx(res.outputs()[0], rel=1e-6) and lvv[0] < lvv[1]
    np.testing.assert_allclose(strains[1], res.outputs()[1:], atol=1e-6)
    assert lam[1] == pytest.approx(mean_fibre_stretch(c8, res), rel=1e-6) and 1.0 < lam[0] < lam[1]


def test_build_script_refuses_load_path_rows_off_its_blocks(tmp_path):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "build_emulators.py"
    spec = importlib.util.spec_from_file_location("build_emulators_edpvr", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    args = mod.parse_args(["--emulators", "edpvr", "--load-path-rows", "100,64,64", "--workdir", str(tmp_path)])
    with pytest.raises(SystemExit, match="multiples of 64"):
        mod.build_load_path_one("edpvr", args)
    assert not any(tmp_path.iterdir())   # refused before any design or run


def test_the_edpvr_quantiles_carry_the_emulators_own_error(emu):
    """One draw repeated: the emulated EDPVR's spread at each pressure is the held-out error drawn in (V₀ exact)."""
    n = 4000
    em = edpvr.emulated_load_path(emu, [_draw()] * n, edp_mmhg=8.0, pressures_mmhg=PRESSURES)
    vols, lam = edpvr.emulator_error_draws(emu, em, 8.0)
    assert np.array_equal(vols[:, 0], em.volumes_ml[:, 0])            # V0 from the geometry: no error
    log_sd = np.log(vols[:, 1:] / em.volumes_ml[:, 1:]).std(axis=0)
    # the sd of 4,000 normal draws is within 5 % of its value with probability > 0.999 (se of an sd: s/sqrt(2n))
    np.testing.assert_allclose(log_sd, emu.volume_log_sd(np.asarray(PRESSURES)), rtol=0.05)
    np.testing.assert_allclose(lam.std(), float(emu.stretch_sd(8.0)), rtol=0.05)
    # one standard normal per draw at every pressure (the error along a curve is smooth): a draw's standardised
    # log errors are equal across pressures, where independent ones made single curves fall with pressure
    z = np.log(vols[:, 1:] / em.volumes_ml[:, 1:]) / emu.volume_log_sd(np.asarray(PRESSURES))[None, :]
    np.testing.assert_allclose(z, np.repeat(z[:, :1], z.shape[1], axis=1), rtol=1e-9, atol=1e-9)
    again, _ = edpvr.emulator_error_draws(emu, em, 8.0)
    assert np.array_equal(again, vols)                                   # seeded: a rerun gives the same band
