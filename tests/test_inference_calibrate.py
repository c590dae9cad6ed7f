"""calibrate(), the emulator adapter and the `lvcore calibrate` command."""
import json

import jax
import numpy as np
import pytest

from lvcore.emulator.forward import emulator_forward
from lvcore.exceptions import EmulatorError
from lvcore.inference import calibrate as cal
from lvcore.inference import coverage, models, samplers
from lvcore.domain.outputs import THETA_NAMES, pc_names
from lvcore.testing.analytic import AnalyticForward


def _random_emulator(name="chapter", angles=False):
    """An UNTRAINED emulator object of the real class (random weights) to test the plumbing only."""
    from lvcore.emulator.model import Emulator
    from lvcore.emulator.network import MLP

    names = THETA_NAMES + (("alpha_endo", "alpha_epi", "edp") if angles else ()) + pc_names(5)
    d = len(names)
    b_lo = 0.5 if angles else 0.1  # the 'angles' space trains on b, bf >= 0.5
    lower = np.array([0.05, b_lo, 0.05, b_lo] + ([-90.0, 0.0, 6.0] if angles else []) + [-2.0] * 5)
    upper = np.array([10.0, 30.0, 10.0, 30.0] + ([0.0, 90.0, 14.0] if angles else []) + [2.0] * 5)
    log = tuple(n in THETA_NAMES for n in names)
    return Emulator(name=name, input_names=names, lower=lower, upper=upper, log_inputs=log,
                    x_mean=np.zeros(d), x_sd=np.ones(d), y_mean=np.r_[140.0, np.full(24, -0.15)],
                    y_sd=np.r_[20.0, np.full(24, 0.03)], network=MLP(d, 25, (20, 20), seed=1),
                    fixed={} if angles else {"alpha_endo": -60.0, "alpha_epi": 60.0, "edp": 8.0})


def test_emulator_adapter_matches_direct_call_and_is_differentiable():
    emu = _random_emulator()
    h = np.array([0.3, -0.2, 0.1, 0.0, 0.5])
    fwd = emulator_forward(emu, h)
    theta = {"a": 0.7, "b": 3.0, "af": 1.2, "bf": 4.0}
    direct = np.asarray(emu.apply(np.r_[0.7, 3.0, 1.2, 4.0, h]))
    np.testing.assert_allclose(np.asarray(fwd(theta)), direct, rtol=1e-12)
    g = jax.grad(lambda a: fwd({**theta, "a": a})[0])(0.7)
    eps = 1e-6
    fd = (fwd({**theta, "a": 0.7 + eps})[0] - fwd({**theta, "a": 0.7 - eps})[0]) / (2 * eps)
    assert float(g) == pytest.approx(float(fd), rel=1e-5)
    with pytest.raises(EmulatorError, match="fixed fibre angles"):
        emulator_forward(emu, h, infer_angles=True)
    emu_a = _random_emulator("angles", angles=True)
    fa = emulator_forward(emu_a, h, infer_angles=True)
    assert fa.input_names[-2:] == ("alpha_endo", "alpha_epi")
    y1 = fa({**theta, "alpha_endo": -30.0, "alpha_epi": 60.0})
    y2 = emulator_forward(emu_a, h, alpha_endo=-30.0, alpha_epi=60.0)(theta)
    np.testing.assert_allclose(np.asarray(y1), np.asarray(y2), rtol=1e-12)


def test_priors_are_cut_to_the_emulator_training_box():
    """NUTS must never push an emulator outside its training box: the priors are intersected with it."""
    emu = _random_emulator("angles", angles=True)
    fwd = emulator_forward(emu, np.zeros(5), infer_angles=True)
    assert fwd.input_bounds["b"] == (0.5, 30.0) and fwd.input_bounds["alpha_epi"] == (0.0, 90.0)
    bounds = models.prior_bounds(True, fwd)
    assert bounds["b"] == bounds["bf"] == (0.5, 30.0)  # emulator box is narrower than Table 9.1
    assert bounds["a"] == (0.05, 10.0) and bounds["alpha_endo"] == (-90.0, 0.0)
    assert models.prior_bounds(False, AnalyticForward())["b"] == (0.1, 30.0)  # no box: Table 9.1
    assert set(models.theta_priors(False, emulator_forward(_random_emulator(), np.zeros(5)))) == set(THETA_NAMES)
    emu.upper[1] = 0.09  # a box that misses the prior entirely
    with pytest.raises(ValueError, match="'b'.*do not overlap"):
        models.prior_bounds(False, emulator_forward(emu, np.zeros(5)))


def test_calibrate_writes_inference_data(tmp_path):
    import arviz as az

    f = AnalyticForward()
    y = coverage.simulate_data(f, {"a": 0.8, "b": 4.0, "af": 2.0, "bf": 3.0}, np.random.default_rng(0))
    cfg = samplers.SamplerConfig(num_warmup=200, num_samples=200, num_chains=2)
    res = cal.calibrate(y, f, "volume", config=cfg)
    assert res.sampler == "nuts" and res.summary.shape[0] == 4
    paths = cal.write_result(res, tmp_path, "S1")
    idata = az.from_netcdf(paths["netcdf"])
    assert set(idata.groups()) >= {"posterior", "posterior_predictive", "observed_data", "sample_stats"}
    assert idata.posterior["eta"].shape == (2, 200, 25)
    assert "convergence_converged" in idata.attrs
    rec = cal.result_record(res)
    json.dumps(rec)
    assert rec["a"]["q05"] <= rec["a"]["median"] <= rec["a"]["q95"]


def test_read_pc_scores(tmp_path):
    (tmp_path / "h.json").write_text(json.dumps({"h": [1, 2, 3, 4, 5, 6]}))
    np.testing.assert_allclose(cal.read_pc_scores(tmp_path / "h.json"), [1, 2, 3, 4, 5])
    (tmp_path / "h.csv").write_text("h1,h2,h3,h4,h5\n0.1,0.2,0.3,0.4,0.5\n")
    np.testing.assert_allclose(cal.read_pc_scores(tmp_path / "h.csv"), [0.1, 0.2, 0.3, 0.4, 0.5])
    (tmp_path / "short.json").write_text("[1, 2]")
    from lvcore.exceptions import GeometryError
    with pytest.raises(GeometryError, match="need 5 PC scores"):
        cal.read_pc_scores(tmp_path / "short.json")


def test_cli_missing_emulator_is_clear(tmp_path, monkeypatch, capsys):
    from lvcore.cli import main

    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path / "none"))
    (tmp_path / "h.json").write_text("[0, 0, 0, 0, 0]")
    data = tmp_path / "m.csv"
    from lvcore.inference.data import MeasuredData, write_measured_csv
    write_measured_csv(data, [MeasuredData(np.r_[130.0, np.full(24, -0.12)], "S1")])
    import lvcore.emulator.io as eio
    monkeypatch.setattr(eio, "ASSETS_DIR", tmp_path / "assets_emulators")
    rc = main(["calibrate", "--data", str(data), "--geometry", str(tmp_path / "h.json"), "--out", str(tmp_path / "o")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "emulator 'chapter' not found" in err and "build_emulators.py" in err


def test_cli_end_to_end_with_saved_emulator(tmp_path, monkeypatch):
    from lvcore.cli import main
    from lvcore.emulator.io import save_emulator

    save_emulator(_random_emulator(), tmp_path / "emus" / "chapter")
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path / "emus"))
    (tmp_path / "h.json").write_text(json.dumps({"h1": 0.1, "h2": 0, "h3": 0, "h4": 0, "h5": 0}))
    from lvcore.inference.data import MeasuredData, write_measured_csv
    data = write_measured_csv(tmp_path / "m.csv", [MeasuredData(np.r_[135.0, np.full(24, -0.15)], "S1")])
    rc = main(["calibrate", "--data", str(data), "--geometry", str(tmp_path / "h.json"), "--model", "volume",
               "--chains", "2", "--warmup", "100", "--samples", "100", "--out", str(tmp_path / "o"), "--json"])
    assert rc in (0, 1, 4)  # 1 = ran but not converged (reported, not hidden); 4 = ran, results flagged
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary[0]["model"] == "volume" and (tmp_path / "o" / "S1_volume.nc").is_file()


def test_cli_joint_angle_inference_with_an_angles_emulator(tmp_path, monkeypatch):
    """`lvcore calibrate --angles infer` picks the 'angles' emulator and reports the angles with theta."""
    import arviz as az

    from lvcore.cli import main
    from lvcore.emulator.io import save_emulator
    from lvcore.inference.data import MeasuredData, write_measured_csv

    save_emulator(_random_emulator("angles", angles=True), tmp_path / "emus" / "angles")  # UNTRAINED test double
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path / "emus"))
    (tmp_path / "h.json").write_text(json.dumps({"h1": 0.1, "h2": 0, "h3": 0, "h4": 0, "h5": 0}))
    data = write_measured_csv(tmp_path / "m.csv", [MeasuredData(np.r_[135.0, np.full(24, -0.15)], "S1")])
    rc = main(["calibrate", "--data", str(data), "--geometry", str(tmp_path / "h.json"), "--model", "iid",
               "--angles", "infer", "--chains", "2", "--warmup", "100", "--samples", "100",
               "--out", str(tmp_path / "o"), "--json"])
    assert rc in (0, 1, 4)  # 1 = ran but not converged (reported, not hidden); 4 = ran, results flagged
    idata = az.from_netcdf(tmp_path / "o" / "S1_iid.nc")
    for name in ("alpha_endo", "alpha_epi"):
        draws = np.asarray(idata.posterior[name])
        assert draws.shape == (2, 100)
        lo, hi = (-90.0, 0.0) if name == "alpha_endo" else (0.0, 90.0)
        assert np.all((draws >= lo) & (draws <= hi))
    for name in ("b", "bf"):  # the prior is cut to the emulator's box (b, bf >= 0.5), not Table 9.1's 0.1
        assert np.all(np.asarray(idata.posterior[name]) >= 0.5)
    # an emulator trained at fixed angles cannot infer them: a clear error, exit code 2
    save_emulator(_random_emulator(), tmp_path / "emus" / "chapter")
    rc = main(["calibrate", "--data", str(data), "--geometry", str(tmp_path / "h.json"), "--angles", "infer",
               "--emulator", "chapter", "--out", str(tmp_path / "o2")])
    assert rc == 2


def test_cli_volunteer_option_finds_the_bundled_files_and_refuses_mixtures(tmp_path, capsys):
    from lvcore.cli import main

    out = str(tmp_path / "o")
    assert main(["calibrate", "--volunteer", "HV99", "--out", out]) == 2
    assert "SYNTHETIC_HV1" in capsys.readouterr().err  # the message lists the bundled volunteers
    assert main(["calibrate", "--volunteer", "SYNTHETIC_HV1", "--data", "m.csv", "--out", out]) == 2
    assert "--volunteer replaces --data and --geometry" in capsys.readouterr().err
    assert main(["calibrate", "--data", "m.csv", "--out", out]) == 2
    assert "--volunteer NAME" in capsys.readouterr().err


def test_summary_keeps_small_variances(tmp_path):
    """sigma_s2 of order 1e-4 survives the summary table and its CSV (ArviZ rounds to 2 decimals by default)."""
    import pandas as pd

    from lvcore.inference import diagnostics

    rng = np.random.default_rng(0)
    samples = {"a": rng.normal(1.0, 0.1, (2, 50)), "sigma_s2": rng.normal(1.234e-4, 1e-6, (2, 50))}
    table = diagnostics.summary_table(samples)
    assert table.loc["sigma_s2", "mean"] == pytest.approx(1.234e-4, rel=1e-2)
    p = tmp_path / "s.csv"
    table.to_csv(p, float_format=cal.SUMMARY_FLOAT_FORMAT)
    back = pd.read_csv(p, index_col=0)
    assert back.loc["sigma_s2", "mean"] == pytest.approx(table.loc["sigma_s2", "mean"], rel=1e-5)
