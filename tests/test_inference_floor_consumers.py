"""The representation floor (a mesh's, ``--geometry infer``'s) wherever a calibration's likelihood is used again:
the posterior predictive of each likelihood (:func:`lvcore.inference.diagnostics.posterior_predictive`, through
:func:`lvcore.inference.calibrate.calibrate` into the InferenceData the CLI, summary and app read), the plausibility
check, and the batched posteriors of data sets with their own conditions (:mod:`lvcore.inference.coverage`).
Closed-form stand-in forward model and the bundled chapter emulator (SYNTHETIC)."""
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpyro.distributions.transforms import biject_to
from numpyro.infer.util import potential_energy

from lvcore.inference import coverage, diagnostics, models, plausibility, samplers
from lvcore.inference.representation_error import FlooredForward, RepresentationError
from lvcore.testing.analytic import AnalyticForward

FWD = AnalyticForward()
THETA = {"a": 0.8, "b": 4.0, "af": 2.0, "bf": 3.0}
S2 = 0.02 ** 2
#: Draws of the statistical checks of the replicates: the whitened replicates' sample covariance has entries of
#: sd 1/sqrt(N) (off the diagonal) and sqrt(2/N) (on it), 0.016 at most; WHITE_TOL is 5.5 of those (0.087), while
#: leaving the floor out moves the entries by 0.3 or more (the floors below).
N_REP = 8_000
WHITE_TOL = 5.5 * np.sqrt(2.0 / N_REP)


def _floor(scale=1.0, lvv=0.04, seed=1):
    """A full-rank floor whose strain variance is about 2.5 sigma_S^2 (so leaving it out is far outside WHITE_TOL)."""
    a = np.random.default_rng(seed).normal(size=(24, 24)) * 0.03 / np.sqrt(24)
    return RepresentationError(5, a @ a.T + 1e-4 * np.eye(24), lvv, strain_scale=scale)


def _whitened_cov(resid, cov):
    """Sample covariance (about zero) of ``resid`` (N, 24) whitened by the Cholesky factor of ``cov``."""
    w = np.linalg.solve(np.linalg.cholesky(cov), resid.T).T
    return w.T @ w / w.shape[0]


def _draws(model, n=N_REP, seed=0):
    """One posterior state repeated ``n`` times (eta, sigma_S^2, and for the discrepancy model b and v)."""
    rng = np.random.default_rng(seed)
    eta = np.tile(np.asarray(FWD(THETA), float), (n, 1))
    d = {"eta": eta}
    if model != "volume":
        d["sigma_s2"] = np.full(n, S2)
    if model == "discrepancy":
        d["disc"] = np.tile(0.02 * rng.standard_normal(24), (n, 1))
        d["v"] = np.full(n, 0.004)
    return d


@pytest.mark.parametrize("model", models.MODEL_NAMES)
def test_posterior_predictive_uses_each_likelihoods_noise_with_the_floor(model):
    """Replicates of a floored run: LVV ~ N(eta0, sigma_V^2 + (r_V eta0)^2) in every likelihood; strains
    ~ MVN(eta, sigma_S^2 I + Sigma_rep) (iid), ~ N(eta + b + v, sigma_S^2 I) (discrepancy: Sigma_rep is inside the
    drawn b, not added again), eta without noise (volume). The whitened replicates have unit covariance; the old
    replicates (sigma_V and sigma_S^2 alone) had 1/(1 + r_V^2 eta0^2/sigma_V^2) and about 0.3 in the iid strains."""
    rep = _floor(scale=1.3)
    fw = FlooredForward(FWD, rep)
    d = _draws(model)
    y_rep = diagnostics.posterior_predictive(d, 5.0, np.random.default_rng(7), fw, model)
    assert y_rep.shape == d["eta"].shape
    eta0 = d["eta"][0, 0]
    lvv_var = np.mean((y_rep[:, 0] - eta0) ** 2) / (5.0 ** 2 + (rep.lvv_rel_sd * eta0) ** 2)
    assert lvv_var == pytest.approx(1.0, abs=WHITE_TOL)
    assert (rep.lvv_rel_sd * eta0 / 5.0) ** 2 > 1.0          # the floor more than doubles the LVV variance
    if model == "volume":
        np.testing.assert_array_equal(y_rep[:, 1:], d["eta"][:, 1:])
        return
    mean = d["eta"][:, 1:] + (d["disc"] + d["v"][:, None] if model == "discrepancy" else 0.0)
    cov = S2 * np.eye(24) + (1.3 * rep.strain_cov if model == "iid" else 0.0)
    white = _whitened_cov(y_rep[:, 1:] - mean, cov)
    assert np.max(np.abs(white - np.eye(24))) < WHITE_TOL
    if model == "iid":   # the replicates without the floor are far narrower than the likelihood's
        assert np.trace(cov) > 2.0 * 24 * S2
    # the inferred model (no model given) reads the likelihood from the draws' sites
    np.testing.assert_array_equal(diagnostics.posterior_predictive(d, 5.0, np.random.default_rng(7), fw), y_rep)


def test_without_a_floor_the_replicates_are_unchanged_bit_for_bit():
    """No floor: the replicates are the old formula's, draw for draw (eta_0 + sigma_V z, mean + sqrt(sigma_S^2) z)."""
    for model in models.MODEL_NAMES:
        d = _draws(model, n=500)
        new = diagnostics.posterior_predictive(d, 5.0, np.random.default_rng(3))
        rng = np.random.default_rng(3)
        old = d["eta"].copy()
        old[:, 0] += 5.0 * rng.standard_normal(500)
        if model != "volume":
            mean = d["eta"][:, 1:]
            if model == "discrepancy":   # the old code's order of the sums
                mean = mean + d["disc"] + d["v"][:, None]
            old[:, 1:] = mean + np.sqrt(d["sigma_s2"])[:, None] * rng.standard_normal(mean.shape)
        np.testing.assert_array_equal(new, old)


def test_calibrate_writes_the_floored_predictive_into_its_inference_data(monkeypatch):
    """calibrate() hands its forward model to the InferenceData's y_rep (what summary.json, summary.html and the
    app's predictive figure read): a floored forward model's replicates have the iid likelihood's covariance.
    The sampler is replaced by fixed draws (the plumbing is checked here, the sampler elsewhere)."""
    from lvcore.inference import calibrate as cal

    rep = _floor(scale=0.8)
    fw = FlooredForward(FWD, rep)
    n_chain, n_draw = 4, N_REP // 4
    d = {k: np.reshape(v, (n_chain, n_draw) + np.shape(v)[1:]) for k, v in _draws("iid").items()}
    d.update({k: np.full((n_chain, n_draw), v) for k, v in THETA.items()})
    run = samplers.SamplerRun("nuts", "iid", d, {"diverging": np.zeros((n_chain, n_draw), bool)}, 1.0)
    conv = diagnostics.Convergence(True, 1.0, 1e4, 1e4, 0, ())
    monkeypatch.setattr(cal.diagnostics, "sample_until_converged", lambda *a, **k: (run, conv))
    y = np.asarray(FWD(THETA), float)
    res = cal.calibrate(y, fw, "iid", max_rounds=1)
    y_rep = np.asarray(res.idata.posterior_predictive["y_rep"]).reshape(-1, 25)
    resid = y_rep[:, 1:] - y[1:]
    white = _whitened_cov(resid, S2 * np.eye(24) + 0.8 * rep.strain_cov)
    assert np.max(np.abs(white - np.eye(24))) < WHITE_TOL
    plain = np.asarray(cal.calibrate(y, FWD, "iid", max_rounds=1).idata.posterior_predictive["y_rep"])
    assert np.mean(plain.reshape(-1, 25)[:, 1:].std(axis=0)) < 0.7 * np.mean(resid.std(axis=0))


def test_the_plausibility_check_reads_the_floor():
    """The posterior-predictive plausibility check (summary.json's posterior_predictive, the _ppc.csv) uses the
    iid likelihood's noise with the floor, as the verdict's fit check (verdict.output_sds) does: data 2 floored
    sds from the model pass with the floor and are flagged against sigma_ref alone."""
    from lvcore.inference import verdict

    rep = _floor(scale=3.0, lvv=0.05)   # sds about 1.8 sigma_ref, sigma_V: 2 floored sds are 3.6 plain ones
    fw = FlooredForward(FWD, rep)
    eta = np.asarray(FWD(THETA), float)
    sigma_ref = plausibility.DEFAULT_SIGMA_REF
    sds = verdict.output_sds(eta, 5.0, sigma_ref, fw)
    np.testing.assert_allclose(sds, np.r_[np.hypot(5.0, 0.05 * eta[0]), np.sqrt(sigma_ref ** 2 + 3.0 * np.diag(rep.strain_cov))],
                               rtol=1e-12)
    y = eta + 2.0 * sds
    draws = np.tile(eta, (4000, 1))
    floored = plausibility.posterior_predictive_check(y, draws, 5.0, sigma_ref, forward=fw)
    plain = plausibility.posterior_predictive_check(y, draws, 5.0, sigma_ref)
    assert floored.plausible and np.all(floored.p_values > 0.02), floored.flags
    assert not plain.plausible and np.all(plain.p_values < 0.01)
    # check_result passes the forward model on
    class _Res:
        class idata:   # noqa: N801 - stands in for InferenceData
            posterior = {"eta": draws[None]}

    assert plausibility.check_result(_Res, y, 5.0, sigma_ref, forward=fw).plausible


def test_one_function_composes_the_strain_noise():
    """models.strain_noise_covariance is sigma_S^2 I plus Sigma_rep in the iid likelihood only, batched over draws;
    the iid likelihood, the verdict's whitening and the predictive read it."""
    rep = _floor(scale=2.0)
    fw = FlooredForward(FWD, rep)
    s2 = np.array([1e-4, 4e-4])
    cov = np.asarray(models.strain_noise_covariance(s2, fw))
    assert cov.shape == (2, 24, 24)
    np.testing.assert_allclose(cov[1], 4e-4 * np.eye(24) + 2.0 * rep.strain_cov, rtol=1e-14)
    np.testing.assert_array_equal(np.asarray(models.strain_noise_covariance(s2, fw, "discrepancy")),
                                  np.asarray(models.strain_noise_covariance(s2, FWD)))
    assert models.strain_floor(fw, "volume") is None and models.strain_floor(FWD) is None
    with pytest.raises(ValueError, match="unknown model"):
        models.strain_floor(fw, "gp")
    like = models.strain_likelihood(jnp.zeros(24), 4e-4, fw)
    np.testing.assert_allclose(np.asarray(like.covariance_matrix), cov[1], rtol=1e-14)


# --------------------------------------------------------------------------- batched posteriors
def _meshes():
    """Two 'meshes' of the chapter emulator (PC scores, no size scale) with their own floor factors."""
    from lvcore.emulator import load_emulator
    from lvcore.emulator.forward import emulator_forward
    from lvcore.inference.representation_error import load_representation_error

    emu = load_emulator("chapter")
    rep = load_representation_error(5)
    return [FlooredForward(emulator_forward(emu, np.asarray(h)), replace(rep, strain_scale=k))
            for h, k in (([0.5, -0.4, 0.3, -0.2, 0.1], 0.4), ([-1.0, 0.2, 0.0, 0.6, -0.3], 3.0))]


def _unconstrained(priors, draws, i, j):
    return {n: biject_to(d.support).inv(jnp.asarray(draws[n][i, j])) for n, d in priors.items()}


#: The potential the batched sampler computed at its own draw against the single path's model at that draw: the
#: same float64 terms evaluated jitted and vmapped there, eagerly here, so they differ by rounding only (measured
#: 2026-12-02: iid <= 3.1e-16 relative, discrepancy <= 2.6e-11, its Cholesky factors of K + Sigma_rep + sigma_S^2 I
#: rounding differently); 1e-8 leaves a 380x margin. The other mesh's floor factor moves the potential far more
#: (measured per data set at most 3.1e-4 to 3.6e-2 relative over its draws), asserted > 100 x the tolerance.
POTENTIAL_RTOL = 1e-8


@pytest.mark.parametrize("model_name", ["iid", pytest.param("discrepancy", marks=pytest.mark.slow)])
def test_batched_posteriors_give_each_data_set_its_own_floor(model_name):
    """Two data sets of two meshes with different floor factors in one batched run (batch_conditions): at every
    kept draw the potential energy the batched sampler used equals that of the single-data-set model of the data
    set's own floored forward model (iid: NUTS's -log p(z | y); discrepancy: the blocked sampler's block-4
    potential). Before, the batch passed only the PC scores and every data set got the first mesh's floor; a
    plain array of conditions for a floored forward model is now refused."""
    fws = _meshes()
    ys = np.stack([np.asarray(f(THETA)) + np.r_[3.0, np.full(24, 0.01)] for f in fws])
    conds = coverage.batch_conditions(fws)
    assert conds["floor_scale"].tolist() == [0.4, 3.0]
    cfg = samplers.SamplerConfig(num_warmup=4, num_samples=2, num_chains=1)
    extra = ("sigma_s2",) + ((models.HYPER_NAMES + ("v",)) if model_name == "discrepancy" else ())
    sites = tuple(THETA) + extra + (coverage.POTENTIAL_SITE,)
    d = coverage.batched_posteriors(fws[0], model_name, ys, jax.random.split(jax.random.PRNGKey(2), 2), cfg,
                                    sites=sites, conditions=conds)
    for i, fw in enumerate(fws):
        other_floor = FlooredForward(fw.forward, fws[1 - i].representation)   # this mesh, the other's floor factor
        moved = 0.0
        for j in range(cfg.num_samples):
            got = float(d[coverage.POTENTIAL_SITE][i, j])
            want, other = (_single_potential(model_name, f, ys[i], d, i, j) for f in (fw, other_floor))
            assert got == pytest.approx(want, rel=POTENTIAL_RTOL), (i, j)
            moved = max(moved, abs(other - want) / abs(want))
        assert moved > 100 * POTENTIAL_RTOL, i   # the other factor: far outside the tolerance
    with pytest.raises(ValueError, match="floor factor"):
        coverage.batched_posteriors(fws[0], model_name, ys, jax.random.split(jax.random.PRNGKey(2), 2), cfg,
                                    sites=sites, conditions=np.asarray(conds["conditions"]))


def _single_potential(model_name, fw, y, d, i, j):
    """The single-data-set path's potential at the batched draw ``(i, j)``: the numpyro model with ``fw`` (iid), or
    block 4 of a :class:`PolarGPGibbs` of ``fw`` given the draw's sigma_S^2 and GP hyperparameters."""
    y = jnp.asarray(y)
    if model_name == "iid":
        priors = {**models.theta_priors(), "sigma_s2": models.sigma_s2_prior()}
        return float(potential_energy(models.iid_model, (y,), {"forward": fw}, _unconstrained(priors, d, i, j)))
    kern = samplers.PolarGPGibbs(fw, y)
    hyper = {n: jnp.asarray(d[n][i, j]) for n in models.HYPER_NAMES}
    chol = models.discrepancy_cholesky(hyper, kern.nugget, kern._rep_cov(None))
    args = kern._block4_args(jnp.asarray(d["sigma_s2"][i, j]), chol, y, None)
    u = {**_unconstrained(kern.theta_priors, d, i, j), "v": jnp.asarray(d["v"][i, j])}
    return float(kern._marginal_potential_gen(*args)(u))
