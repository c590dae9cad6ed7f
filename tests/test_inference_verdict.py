"""One verdict per subject (lvcore.inference.verdict): consistency from the best fit, identifiability, sampler."""
from __future__ import annotations

import numpy as np
import pytest

from lvcore.testing.analytic import AnalyticForward
from lvcore.inference import verdict

THETA = {"a": 0.6, "b": 5.0, "af": 1.5, "bf": 5.0}


def _y(theta=THETA, strains_from=None):
    f = AnalyticForward()
    y = np.array(f(theta), dtype=float)
    if strains_from is not None:
        y[1:] = np.asarray(f(strains_from), float)[1:]
    return y


def test_consistent_data_are_plausible():
    c = verdict.consistency_check(_y(), AnalyticForward(), sigma_v=5.0)
    assert c.plausible, c.flags
    assert np.all(c.p_values > 0.5)


def test_volume_and_strains_of_different_stiffness_are_flagged():
    """LVV of a soft heart, strains of a stiff one: no theta reaches both."""
    y = _y(THETA)
    y[0] = 175.0   # beyond what the stand-in's LVV reaches (115-165 mL)
    c = verdict.consistency_check(y, AnalyticForward(), sigma_v=5.0)
    assert not c.plausible
    assert "volume is not reached" in " ".join(c.flags)


def test_identifiability_flags():
    rng = np.random.default_rng(0)
    bounds = {"a": (0.05, 10.0), "b": (0.1, 30.0), "af": (0.05, 10.0), "bf": (0.1, 30.0)}
    samples = {"a": 0.05 + 0.002 * rng.random(4000),            # piled on the lower bound
               "b": rng.uniform(0.1, 30.0, 4000),                # the prior: nothing learned
               "af": rng.lognormal(np.log(1.5), 0.1, 4000),      # well identified
               "bf": rng.lognormal(np.log(5.0), 0.2, 4000)}
    flags, table, notes = verdict.identifiability_flags(samples, bounds)
    assert len(flags) == 1 and flags[0].startswith("a: posterior piled on the prior's lower bound"), flags
    assert table["a"]["push_ratio_lower"] > verdict.PUSH_RATIO
    # b follows its (uniform) prior to the upper bound: weak identification, a note and no flag
    assert any(n.startswith("b: the 90 % interval") and "do not identify" in n for n in notes)
    assert any(n.startswith("b: the posterior follows its prior to the upper bound") for n in notes)
    assert 0.5 < table["b"]["push_ratio_upper"] < 1.5
    assert not any(f.startswith(("af:", "bf:")) for f in flags + notes)
    assert table["af"]["width_vs_prior"] < 0.1
    # a spread over more than a factor 20 (here 0.1 to 5 kPa) is weak identification: neither a flag nor a note
    # on its own (the derived quantities report it, lvcore.inference.derived)
    flags, _, notes = verdict.identifiability_flags({"a": np.exp(rng.uniform(np.log(0.1), np.log(5.0), 4000))},
                                                    {"a": (0.05, 10.0)})
    assert flags == [] and notes == []
    # the rule is symmetric: the same pile mirrored onto the upper bound is flagged the same way
    flags, table, _ = verdict.identifiability_flags({"b": 30.0 - 0.06 * rng.random(4000)}, {"b": (0.1, 30.0)})
    assert len(flags) == 1 and "upper bound 30" in flags[0]


def test_divergence_threshold():
    from lvcore.inference.diagnostics import Convergence

    ok = Convergence(True, 1.0, 1000.0, 1000.0, 20, ())
    bad = Convergence(True, 1.0, 1000.0, 1000.0, 21, ())
    assert verdict.sampler_flags(ok, 4000) == []
    assert "21 divergent transitions" in verdict.sampler_flags(bad, 4000)[0]
    assert "not converged" in verdict.sampler_flags(Convergence(False, 1.2, 50.0, 50.0, 0, ("a",)), 4000)[0]


@pytest.mark.slow
def test_plausible_is_the_same_whichever_model_ran():
    """Data the model cannot fit: volume, iid and discrepancy runs all say plausible = False and are flagged.

    The verdict's plausibility is the model-independent consistency check, so the claim is about what
    run_verdict makes of each model's result, not about its draws: 2 chains x (30 + 30) are enough."""
    from lvcore.inference.calibrate import calibrate
    from lvcore.inference.samplers import SamplerConfig

    y = _y(THETA)
    y[0] = 175.0
    f = AnalyticForward()
    c = verdict.consistency_check(y, f, sigma_v=5.0)
    config = SamplerConfig(num_warmup=30, num_samples=30, num_chains=2)
    seen = {}
    for model in ("volume", "iid", "discrepancy"):
        res = calibrate(y, f, model, config=config, max_rounds=1)
        v = verdict.run_verdict(res, c, verdict.checked_bounds(f))
        seen[model] = (v.plausible, v.flagged)
    assert {p for p, _ in seen.values()} == {False}, seen
    assert all(flagged for _, flagged in seen.values())


def _level_pattern():
    """A smooth misfit: the apical level 0.025 less negative, the next 0.01 (the benchmark ellipsoid's pattern
    against its 5-mode reconstruction, benchmarks/real_data.py --steps projection)."""
    return np.repeat([-0.003, -0.001, 0.009, 0.026], 6) + 0.001 * np.random.default_rng(5).standard_normal(24)


def test_residual_structure_tells_a_pattern_from_noise():
    i, p = verdict.residual_structure(_level_pattern())
    assert i > 0.5 and p < 0.01
    rng = np.random.default_rng(0)
    ps = [verdict.residual_structure(0.03 * rng.standard_normal(24), n_permutations=500, seed=k)[1] for k in range(200)]
    assert np.mean(np.asarray(ps) < 0.01) <= 0.04     # about 1 % false alarms for independent residuals
    assert 0.3 < np.median(ps) < 0.7


def _result(y, eta_strains, sigma_s2, model="iid"):
    """A stand-in CalibrationResult: posterior eta (200 draws around ``eta_strains``), sigma_s2, observed y."""
    from types import SimpleNamespace

    import arviz as az

    rng = np.random.default_rng(2)
    eta = np.tile(np.r_[y[0], eta_strains], (1, 200, 1)) + 1e-4 * rng.standard_normal((1, 200, 25))
    idata = az.from_dict(posterior={"eta": eta, "sigma_s2": np.full((1, 200), sigma_s2)}, observed_data={"y": y})
    return SimpleNamespace(model=model, idata=idata)


def test_posterior_misfit_flags_structured_residuals_the_likelihood_calls_independent():
    from lvcore.inference.representation_error import RepresentationError

    eta = np.full(24, -0.15)
    y = np.r_[120.0, eta + _level_pattern()]                     # a smooth misfit, no noise
    structure, flags = verdict.posterior_misfit(_result(y, eta, 0.011 ** 2))
    assert flags and "spatially structured" in flags[0] and structure["p_value"] < 0.01
    noisy = np.r_[120.0, eta + 0.03 * np.random.default_rng(1).standard_normal(24)]
    assert verdict.posterior_misfit(_result(noisy, eta, 0.03 ** 2))[1] == []      # independent noise: no flag
    assert verdict.posterior_misfit(_result(y, eta, 0.011 ** 2, model="volume")) == ({}, [])  # strains not modelled

    class Fw:   # a representation error along this pattern: whitened, what is left is the independent noise
        representation = RepresentationError(5, np.outer(_level_pattern(), _level_pattern()), 0.0)

    y = np.r_[120.0, eta + _level_pattern() + 0.001 * np.random.default_rng(4).standard_normal(24)]
    assert verdict.posterior_misfit(_result(y, eta, 0.001 ** 2))[1]          # without the floor: flagged
    structure, flags = verdict.posterior_misfit(_result(y, eta, 0.001 ** 2), Fw())
    assert flags == [] and structure["whitened_by"].endswith("representation error")
    # the discrepancy model's b holds the floor already (models.discrepancy_model): its residual y - η - b - v is
    # the noise, whitened by σ_S² I alone
    disc = _result(y, eta, 0.001 ** 2, model="discrepancy")
    disc.idata.posterior["disc"] = (("chain", "draw", "region"), np.zeros((1, 200, 24)))
    disc.idata.posterior["v"] = (("chain", "draw"), np.zeros((1, 200)))
    structure, flags = verdict.posterior_misfit(disc, Fw())
    assert flags and structure["whitened_by"] == "sigma_S^2 I"
    v = verdict.Verdict(verdict.Consistency({}, np.zeros(25), np.ones(25)), misfit=("x",))
    assert v.plausible and v.flagged and v.flags == ["MISFIT: x"]


def test_weak_identification_is_a_note_for_every_model_not_a_flag():
    """Weak identification ("not informative enough": a's 90 % interval spanning a factor 25, or b following its
    prior to a bound) is information, not a defect: run_verdict gives no flag and the same notes for the same
    draws of a volume, iid or discrepancy run; a posterior pushed onto a bound is flagged (BOUND) for each."""
    from types import SimpleNamespace

    import arviz as az

    from lvcore.inference.diagnostics import Convergence

    bounds = {"a": (0.05, 10.0), "b": (0.1, 30.0), "af": (0.05, 10.0), "bf": (0.1, 30.0)}

    def run(model, pushed):
        rng = np.random.default_rng(7)   # the same draws for every model
        u = rng.uniform(size=(2, 2000))
        la, lb = np.log(0.1), np.log(2.5)
        a = np.exp(la + (lb - la) * (u - 0.05) / 0.9)
        b = 30.0 - 0.05 * rng.random((2, 2000)) if pushed else rng.uniform(0.1, 30.0, (2, 2000))
        post = {"a": a, "b": b, "af": rng.lognormal(np.log(1.5), 0.1, (2, 2000)),
                "bf": rng.lognormal(np.log(5.0), 0.1, (2, 2000))}
        res = SimpleNamespace(model=model, idata=az.from_dict(posterior=post),
                              convergence=Convergence(True, 1.0, 1000.0, 1000.0, 0, ()))
        return verdict.run_verdict(res, verdict.Consistency({}, np.zeros(25), np.ones(25)), bounds)

    for pushed in (False, True):
        seen = {m: run(m, pushed) for m in ("volume", "iid", "discrepancy")}
        assert len({tuple(v.flags) for v in seen.values()}) == 1
        assert len({tuple(v.notes) for v in seen.values()}) == 1
        v = seen["iid"]
        if pushed:
            assert v.flagged and v.flags[0].startswith("BOUND: b: posterior piled on the prior's upper bound")
        else:
            assert not v.flagged, v.flags
            assert any(n.startswith("b:") for n in v.notes) and v.record()["notes"] == list(v.notes)
