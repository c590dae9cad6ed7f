"""--prior klotz: the Klotz et al. (2006) EDPVR as a likelihood term on the model's V20 and V30.

The single-beat prediction is :mod:`lvcore.domain.physiology`'s Klotz curve (checked against it, not a copy); the
Bn scatter's linearisation against a finite difference; the refusals (no EDP input, an EDP box short of
30 mmHg) exit 2; on SYNTHETIC cases whose truth follows Klotz's curve the prior keeps the true V20 inside
its 90 % interval and narrows that interval, and summary.json records the prior.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from loaded_states_double import at

from lvcore.domain import physiology
from lvcore.exceptions import DataError
from lvcore.inference import loaded_states as ls


def _prior(edp=8.0, v0=80.0, pressures=ls.KLOTZ_PRESSURES_MMHG):
    return ls.KlotzPrior(tuple(at(p, v0) for p in pressures), edp, v0_ml=v0)


@pytest.mark.parametrize("edp,edv,v0", [(8.0, 150.0, 80.0), (12.0, 210.0, 120.0), (4.0, 95.0, 70.0)])
def test_the_single_beat_prediction_is_the_physiology_modules_klotz_curve(edp, edv, v0):
    v30 = physiology.klotz_v30(edv, edp, v0)   # the normalising volume (EDVn = 1, i.e. An = 27.78 mmHg on the fit)
    expect = [physiology.klotz_volume(20.0, v0, v30), physiology.klotz_volume(30.0, v0, v30)]
    assert np.allclose(np.asarray(_prior(edp, v0).target(edv, v0)), expect, rtol=1e-12)
    # through the measured point: EDP = An EDVn^Bn at the measured EDV
    assert physiology.klotz_edp((edv - v0) / (v30 - v0)) == pytest.approx(edp, rel=1e-9)


def test_the_bn_scatter_is_the_derivative_of_the_single_beat_volumes():
    """C = sd^2 g g^T + diag(residual^2): g against a central difference of V_p(Bn) = V0 + (EDV - V0)(p/EDP)^(1/Bn)."""
    edp, edv, v0, bn, h = 8.0, 150.0, 80.0, physiology.KLOTZ_BN, 1e-5
    pr = _prior(edp, v0)

    def vp(b):
        return np.array([v0 + (edv - v0) * (p / edp) ** (1.0 / b) for p in pr.pressures_mmhg])

    g = (vp(bn + h) - vp(bn - h)) / (2 * h)
    rise = vp(bn) - v0
    expect = pr.bn_sd ** 2 * np.outer(g, g) + np.diag((pr.residual_rel_sd * rise) ** 2)
    cov = np.asarray(pr.covariance(edv, v0))
    assert np.allclose(cov, expect, rtol=1e-6, atol=1e-5)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_emulators_without_20_to_30_mmhg_are_refused(tmp_path, capsys):
    from lvcore.cli import main
    from lvcore.emulator import load_emulator

    with pytest.raises(DataError, match=r"covers EDP 6-14 mmHg \(20, 30 outside"):
        ls.check_klotz_pressures(load_emulator("angles"), "angles")
    with pytest.raises(DataError, match="needs an emulator with an EDP input; 'chapter' was trained at a fixed EDP"):
        ls.check_klotz_pressures(load_emulator("chapter"), "chapter")
    p = tmp_path / "m.csv"
    p.write_text("lvv_ml," + ",".join(f"strain_{k:02d}" for k in range(1, 25)) + "\n150," + ",".join(["-0.15"] * 24)
                 + "\n")
    code = main(["calibrate", "--data", str(p), "--geometry", "mean", "--prior", "klotz", "--emulator", "angles",
                 "--out", str(tmp_path / "o")])
    assert code == 2 and "--prior klotz puts its term on the model's volumes at 20, 30 mmHg" in capsys.readouterr().err


def test_v0_may_be_a_function_of_the_parameters():
    pr = ls.KlotzPrior(tuple(at(p) for p in ls.KLOTZ_PRESSURES_MMHG), 8.0, v0_fn=lambda q: 70.0 + q["a"])
    assert float(pr.v0({"a": 10.0})) == 80.0
    with pytest.raises(ValueError, match="not both"):
        ls.KlotzPrior(pr.forward_by_pressure, 8.0, v0_ml=80.0, v0_fn=pr.v0_fn)


def _v20(samples, v0):
    fw = at(20.0, v0)
    flat = {n: jnp.asarray(np.asarray(samples[n]).reshape(-1)) for n in ("a", "b", "af", "bf")}
    return np.asarray(jax.vmap(lambda q: fw(q)[0])(flat))


@pytest.mark.slow
def test_the_prior_keeps_the_true_v20_inside_and_narrows_its_interval(tmp_path):
    """Three SYNTHETIC cases on the stand-in (tests/loaded_states_double.py), each with a truth on Klotz's curve
    (b = 5; a, V0 and the EDP vary), one noisy volume (sigma_V 5 mL), volume-only model, 2 chains: with the prior
    the true V20 stays inside the 90 % interval and the interval is narrower than without it."""
    from lvcore.inference.calibrate import calibrate
    from lvcore.inference.cli import _states_records
    from lvcore.inference.data import MeasuredData
    from lvcore.inference.samplers import SamplerConfig

    cfg = SamplerConfig(num_warmup=200, num_samples=300, num_chains=2, chain_method="sequential", seed=4)
    rng = np.random.default_rng(7)
    for a, v0, edp in ((0.6, 80.0, 8.0), (0.3, 100.0, 10.0), (2.0, 70.0, 12.0)):
        theta = {"a": a, "b": 5.0, "af": 1.5, "bf": 5.0}
        fw = at(edp, v0)
        truth = float(at(20.0, v0)(theta)[0])
        edv = float(fw(theta)[0])
        assert truth == pytest.approx(physiology.klotz_volume(20.0, v0, physiology.klotz_v30(edv, edp, v0)), rel=1e-9)
        y = np.asarray(fw(theta)) + np.r_[5.0 * rng.standard_normal(), np.zeros(24)]
        width = {}
        for key, forward in (("none", fw), ("klotz", ls.LoadedStatesForward(fw, (), _prior(edp, v0)))):
            res = calibrate(y, forward, "volume", config=cfg, max_rounds=1)
            v20 = _v20({n: res.idata.posterior[n] for n in ("a", "b", "af", "bf")}, v0)
            q05, q95 = np.quantile(v20, [0.05, 0.95])
            width[key] = q95 - q05
            if key == "klotz":
                assert q05 < truth < q95, (a, v0, edp, q05, truth, q95)
                assert np.allclose(np.asarray(res.idata.posterior["klotz_volumes"])[..., 0].reshape(-1), v20)
                rec = _states_records(MeasuredData(y=y, extras={"edp_mmhg": edp}), forward, res)["prior"]
                assert rec["name"] == "klotz" and "Klotz et al. (2006)" in rec["reference"]
                assert rec["v0_ml"] == v0 and rec["posterior_ml"]["V20"]["q05"] == pytest.approx(q05)
        assert width["klotz"] < width["none"], (a, v0, edp, width)
