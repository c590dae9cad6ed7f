r"""The chapter's HMC-within-Gibbs sampler for the discrepancy model (iii): :class:`PolarGPGibbs`.

One sweep is exactly Algorithm 4 of the chapter:

1. ``sigma_S^2 | rest ~ IG(alpha0 + 12, beta0 + RSS / 2)`` (conjugate, closed form),
   with ``RSS = sum_i (y_i - eta_i - b_i - v)^2`` over the 24 strains;
2. one NUTS transition for the GP hyperparameters ``(lam, sigma1^2, sigma2^2, c, tau)``
   targeting ``MVN(b | 0, K) * prior`` with ``b`` held fixed;
3. Cholesky ``K = L L^T`` of the new Gram matrix, and ``b_tilde = L^{-1} b`` so that
   ``b`` is unchanged by step 2;
4. one NUTS transition for ``(theta, b_tilde, v)`` with ``b = L b_tilde`` (whitened), or (block
   ``"marginal"``) for ``(theta, v)`` with ``b`` integrated out, then ``b`` from its Gaussian full
   conditional.

With a forward model that carries the shape model's representation error (a mesh's floor,
:class:`lvcore.inference.representation_error.FlooredForward`), ``K`` above is ``K_GP + Sigma_rep``
(:func:`lvcore.inference.models.discrepancy_cholesky`: ``Sigma_rep`` a known part of the discrepancy, its
per-mesh factor a run-time value) and the LVV sd is :func:`lvcore.inference.models.lvv_sd`, as in
:func:`lvcore.inference.models.discrepancy_model`; ``sigma_S^2`` stays conjugate. Without one every step is
the GP's alone, draw for draw as before.

``kernel="product"`` uses the product (sector × level) polar kernel for ``K`` in steps 2-4
(:func:`lvcore.inference.models.discrepancy_cholesky`); its GP has no ``sigma2^2``, so block 2 samples
``(lam, sigma1^2, c, tau)`` (:func:`lvcore.inference.models.hyper_priors`). The default, the chapter's additive
kernel, draws exactly what it drew before the option existed.

Each NUTS block keeps its own step size and diagonal mass-matrix adaptation
(numpyro's functional :func:`numpyro.infer.hmc.hmc` with ``potential_fn_gen``),
and the cached potential energy and gradient are refreshed whenever the
conditioning values change. The kernel plugs into :class:`numpyro.infer.MCMC`,
so chains run sequentially, vectorised or in parallel like any numpyro kernel;
:func:`lvcore.inference.samplers.run_hmc_gibbs` runs it.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpyro.distributions as dist
from jax.scipy.linalg import solve_triangular
from numpyro.distributions.transforms import biject_to
from numpyro.infer.hmc import hmc
from numpyro.infer.mcmc import MCMCKernel

from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.inference import kernels, models
from lvcore.inference.compiled_samplers import runtime_conditions
from lvcore.domain.outputs import N_OUTPUTS


def _constrain(priors: dict, u: dict):
    """Constrained values and ``log prior + log|Jacobian|`` for unconstrained ``u``."""
    out, logp = {}, 0.0
    for name, d in priors.items():
        t = biject_to(d.support)
        x = t(u[name])
        out[name] = x
        logp = logp + jnp.sum(d.log_prob(x)) + jnp.sum(t.log_abs_det_jacobian(u[name], x))
    return out, logp


def _unconstrain(priors: dict, x: dict) -> dict:
    return {n: biject_to(d.support).inv(jnp.asarray(x[n], dtype=jnp.float64)) for n, d in priors.items()}


class GibbsState(NamedTuple):
    """State of :class:`PolarGPGibbs`; ``z`` holds constrained values of every site."""

    z: dict
    hyper_state: Any
    main_state: Any
    diverging: Any
    num_steps: Any
    rng_key: Any


#: Block 4 of the discrepancy sampler: ``"marginal"`` integrates the discrepancy b out of the NUTS block and
#: then draws it from its Gaussian full conditional; ``"chapter"`` is Algorithm 4 as written (NUTS over θ, the
#: whitened b̃ and v). Both leave the same posterior invariant (``tests/test_inference_samplers.py`` compares
#: them). At the app's 4 × (250 + 500), ``chapter`` emulator, compiled, one core: SYNTHETIC_HV2 marginal
#: 9.3 CPU-s, 26 NUTS steps per block-4 transition, 4 divergent, minimum bulk ESS 596; chapter 16.0 CPU-s,
#: 59 steps, 44 divergent, 544. SYNTHETIC_HV1: 7.0 against 17.0 CPU-s, 2 against 20 divergent, ESS 695
#: against 568 (docs/calibration.md, *Block 4, marginalised*). A dense mass matrix halved the steps on HV2
#: but left HV1 at ESS 113 with 35 divergent transitions, so block 4's is diagonal.
DISCREPANCY_BLOCKS = ("marginal", "chapter")


class PolarGPGibbs(MCMCKernel):
    """HMC-within-Gibbs for the discrepancy model (iii), Algorithm 4 of the chapter.

    Each sweep: (1) σ_S² from its conjugate inverse gamma given b; (2) NUTS on the GP hyperparameters given
    b; (3) the Cholesky factor L of the new Gram matrix K; (4) with ``block4="marginal"`` (default) NUTS on
    (θ, v) with b integrated out, ``y_S ~ N(η_S(θ) + v, K + σ_S² I)``, then b from its Gaussian full
    conditional by Matheron's rule; with ``block4="chapter"``
    NUTS on (θ, b̃, v), ``b = L b̃``, as the chapter writes it. Steps (4) of either kind draw (θ, v, b) from
    their joint conditional given σ_S² and the hyperparameters, so both samplers have the same posterior.

    A forward model that carries the representation error (a mesh's floor) makes K the GP's Gram matrix plus
    the known Σ_rep in every step, and widens the LVV sd (:func:`lvcore.inference.models.lvv_sd`): the model
    of :func:`lvcore.inference.models.discrepancy_model`.

    Parameters
    ----------
    forward : lvcore.core.Forward
        JAX-traceable (a :class:`lvcore.core.TraceableForward`).
        Forward model returning the 25 outputs; its ``representation`` (if any) is used.
    y : array_like, shape (25,)
        Measured data [LVV (mL), 24 strains].
    sigma_v : float
        Fixed LVV noise sd (mL).
    infer_angles : bool
        Also sample the fibre angles (uniform priors) in block 4.
    nugget : float
        Diagonal jitter of the Gram matrix (strain²).
    target_accept_prob, max_tree_depth : float, int
        NUTS settings of both blocks.
    block4 : str
        One of :data:`DISCREPANCY_BLOCKS` (above).
    kernel : {"additive", "product"}
        The GP's kernel: the chapter's additive one (default) or the product (sector × level) one
        (:data:`lvcore.inference.models.KERNEL_KINDS`).

    Sites in ``state.z``: theta (and angles), ``sigma_s2``, ``lam``, ``sigma1_sq``,
    ``sigma2_sq`` (additive kernel only), ``c``, ``tau``, ``disc_tilde`` (24, whitened), ``disc`` (24, the
    discrepancy b), ``v``.
    """

    sample_field = "z"

    def __init__(self, forward, y=None, *, sigma_v: float = SIGMA_V_ML, infer_angles: bool = False,
                 nugget: float = kernels.DEFAULT_NUGGET, target_accept_prob: float = 0.8, max_tree_depth: int = 10,
                 block4: str = "marginal", kernel: str = models.DEFAULT_KERNEL):
        if block4 not in DISCREPANCY_BLOCKS:
            raise ValueError(f"block4 must be one of {DISCREPANCY_BLOCKS}, got {block4!r}")
        self.block4 = block4
        self.kernel = models.check_kernel(kernel)
        self.forward = forward
        # the forward model's conditions are run-time values (runtime_conditions), not compiled in
        self._template, self.conditions = runtime_conditions(forward)
        self.y = None if y is None else jnp.asarray(y, dtype=jnp.float64)
        if self.y is not None and self.y.shape != (N_OUTPUTS,):
            raise ValueError(f"y must have shape ({N_OUTPUTS},), got {self.y.shape}")
        self.sigma_v = float(sigma_v)
        self.nugget = float(nugget)
        self.target_accept_prob = target_accept_prob
        self.max_tree_depth = max_tree_depth
        self.theta_priors = models.theta_priors(infer_angles, forward)
        self.hyper_priors = models.hyper_priors(kernel)
        self.v_prior = models.v_prior()
        self._hyper_init, self._hyper_sample = hmc(potential_fn_gen=self._hyper_potential_gen, algo="NUTS")
        self._main_gen = self._marginal_potential_gen if block4 == "marginal" else self._main_potential_gen
        self._main_init, self._main_sample = hmc(potential_fn_gen=self._main_gen, algo="NUTS")

    # --- conditionals -------------------------------------------------------
    def _hyper_potential_gen(self, b, rep_cov=None):
        """Potential of block 2: ``-log MVN(b | 0, K(hyper) [+ Sigma_rep]) - log prior`` (unconstrained)."""
        def potential(u):
            hyper, logp = _constrain(self.hyper_priors, u)
            chol = models.discrepancy_cholesky(hyper, self.nugget, rep_cov, self.kernel)
            alpha = solve_triangular(chol, b, lower=True)
            loglik = -0.5 * alpha @ alpha - jnp.sum(jnp.log(jnp.diag(chol)))
            return -(loglik + logp)
        return potential

    def _forward_at(self, cond):
        """The forward model with run-time conditions ``cond`` (None: the forward as given)."""
        return self.forward if cond is None else self._template.bind(cond)

    def _rep_cov(self, cond):
        """``Sigma_rep`` of the forward model at run-time conditions ``cond`` (its floor factor one of them), or
        None without a floor."""
        return models.strain_rep_covariance(self._forward_at(cond))

    @staticmethod
    def _hyper_args(b, rep_cov):
        return (b,) if rep_cov is None else (b, rep_cov)

    def _main_potential_gen(self, sigma_s2, chol, y, cond=None):
        """Potential of block 4 over (theta, b_tilde, v) given sigma_S^2 and L."""
        forward = self._forward_at(cond)

        def potential(u):
            params, logp = _constrain(self.theta_priors, u)
            eta = forward(params)
            b = chol @ u["disc_tilde"]
            logl = dist.Normal(eta[0], models.lvv_sd(eta[0], self.sigma_v, forward)).log_prob(y[0])
            logl += jnp.sum(dist.Normal(eta[1:] + b + u["v"], jnp.sqrt(sigma_s2)).log_prob(y[1:]))
            logp += -0.5 * u["disc_tilde"] @ u["disc_tilde"] + self.v_prior.log_prob(u["v"])
            return -(logl + logp)
        return potential

    def _marginal_potential_gen(self, sigma_s2, chol, y, cond=None):
        """Potential of the marginal block 4 over (theta, v) given sigma_S^2 and ``chol``, the Cholesky
        factor of ``K + sigma_S^2 I`` (b integrated out; constants dropped)."""
        forward = self._forward_at(cond)

        def potential(u):
            params, logp = _constrain(self.theta_priors, u)
            eta = forward(params)
            logl = dist.Normal(eta[0], models.lvv_sd(eta[0], self.sigma_v, forward)).log_prob(y[0])
            alpha = solve_triangular(chol, y[1:] - eta[1:] - u["v"], lower=True)
            logp += self.v_prior.log_prob(u["v"])
            return -(logl - 0.5 * alpha @ alpha + logp)
        return potential

    def _block4_args(self, sigma_s2, chol_k, y, cond):
        """The model arguments of block 4: ``chol_k`` (of K) for ``chapter``, that of ``K + σ_S² I`` for ``marginal``."""
        if self.block4 == "chapter":
            return (sigma_s2, chol_k, y, cond)
        return (sigma_s2, jnp.linalg.cholesky(chol_k @ chol_k.T + sigma_s2 * jnp.eye(chol_k.shape[0])), y, cond)

    def _discrepancy_draw(self, key, params, v, sigma_s2, chol_k, chol_t, y, cond=None):
        """b from its full conditional ``N(K (K + σ²I)⁻¹ r, K - K (K + σ²I)⁻¹ K)``, r = y_S - η_S - v, by
        Matheron's rule: ``b = b₀ + K (K + σ²I)⁻¹ (r - b₀ - e₀)``, b₀ ~ N(0, K), e₀ ~ N(0, σ²I).
        ``chol_k``, ``chol_t``: Cholesky factors of K (the GP's, plus Σ_rep with a floor) and of K + σ² I."""
        k_b, k_e = jax.random.split(key)
        n = chol_k.shape[0]
        r = y[1:] - self._forward_at(cond)(params)[1:] - v
        b0 = chol_k @ jax.random.normal(k_b, (n,))
        e0 = jnp.sqrt(sigma_s2) * jax.random.normal(k_e, (n,))
        w = solve_triangular(chol_t.T, solve_triangular(chol_t, r - b0 - e0, lower=True), lower=False)
        return b0 + chol_k @ (chol_k.T @ w)

    def _sigma_s2_draw(self, key, params, b, v, y, cond=None):
        """Step 1: conjugate inverse-gamma draw of sigma_S^2."""
        return sigma_s2_conditional(y[1:], self._forward_at(cond)(params)[1:] + b + v).sample(key)

    @staticmethod
    def _refresh(state, potential):
        pe, grad = jax.value_and_grad(potential)(state.z)
        return state._replace(potential_energy=pe, z_grad=grad)

    # --- MCMCKernel API -------------------------------------------------------
    def init(self, rng_key, num_warmup, init_params, model_args, model_kwargs):
        y, cond = self._data(model_args, model_kwargs), self._conditions(model_kwargs)
        if jnp.ndim(rng_key) > 1 or (jnp.ndim(rng_key) == 1 and rng_key.shape[0] != 2):
            # vectorized chains: one key per chain
            if init_params is None:
                return jax.vmap(lambda k: self._init_one(k, num_warmup, None, y, cond))(rng_key)
            return jax.vmap(lambda k, p: self._init_one(k, num_warmup, p, y, cond))(rng_key, init_params)
        return self._init_one(rng_key, num_warmup, init_params, y, cond)

    def _init_one(self, rng_key, num_warmup, init_params, y=None, cond=None):
        k_theta, k_hyp, k_bt, k_v, k_s, k_h, k_m, rng_key = jax.random.split(rng_key, 8)
        if init_params is None:
            u_theta = {n: jax.random.uniform(k, (), minval=-2.0, maxval=2.0)
                       for n, k in zip(self.theta_priors, jax.random.split(k_theta, len(self.theta_priors)))}
            kh = jax.random.split(k_hyp, 5)
            u_hyper = {
                "lam": jax.random.uniform(kh[0], (), minval=-1.0, maxval=1.0),
                "sigma1_sq": jax.random.uniform(kh[1], (), minval=jnp.log(1e-4), maxval=jnp.log(1e-2)),
                "sigma2_sq": jax.random.uniform(kh[2], (), minval=jnp.log(1e-4), maxval=jnp.log(1e-2)),
                "c": jax.random.uniform(kh[3], (), minval=-2.0, maxval=2.0),
                "tau": jax.random.uniform(kh[4], (), minval=-2.0, maxval=2.0),
            }
            u_hyper = {n: u_hyper[n] for n in self.hyper_priors}  # the product kernel has no sigma2_sq
            b_tilde = 0.5 * jax.random.normal(k_bt, (24,))
            v = 0.01 * jax.random.normal(k_v, ())
        else:
            u_theta = _unconstrain(self.theta_priors, init_params)
            u_hyper = _unconstrain(self.hyper_priors, init_params)
            b_tilde = jnp.asarray(init_params.get("disc_tilde", jnp.zeros(24)), dtype=jnp.float64)
            v = jnp.asarray(init_params.get("v", 0.0), dtype=jnp.float64)
        hyper, _ = _constrain(self.hyper_priors, u_hyper)
        rep_cov = self._rep_cov(cond)
        chol = models.discrepancy_cholesky(hyper, self.nugget, rep_cov, self.kernel)
        b = chol @ b_tilde
        params, _ = _constrain(self.theta_priors, u_theta)
        sigma_s2 = self._sigma_s2_draw(k_s, params, b, v, y, cond)
        common = dict(num_warmup=num_warmup, target_accept_prob=self.target_accept_prob,
                      max_tree_depth=self.max_tree_depth)
        hyper_state = self._hyper_init(u_hyper, model_args=self._hyper_args(b, rep_cov), rng_key=k_h, **common)
        if self.block4 == "chapter":
            main_state = self._main_init({**u_theta, "disc_tilde": b_tilde, "v": v},
                                         model_args=(sigma_s2, chol, y, cond), rng_key=k_m, **common)
        else:
            main_state = self._main_init({**u_theta, "v": v}, model_args=self._block4_args(sigma_s2, chol, y, cond),
                                         rng_key=k_m, **common)
        z = {**params, **hyper, "sigma_s2": sigma_s2, "disc_tilde": b_tilde, "disc": b, "v": v}
        return GibbsState(z, hyper_state, main_state, jnp.array(False), jnp.array(0), rng_key)

    def _data(self, model_args, model_kwargs=None):
        """Data from ``MCMC.run(key, y)`` or ``MCMC.run(key, y=y)`` if given (one compilation serves
        many data sets), else ``self.y``."""
        if model_args:
            return jnp.asarray(model_args[0], dtype=jnp.float64)
        if model_kwargs and model_kwargs.get("y") is not None:
            return jnp.asarray(model_kwargs["y"], dtype=jnp.float64)
        return self.y

    def _conditions(self, model_kwargs=None):
        """Run-time conditions from ``MCMC.run(key, y=y, conditions=...)``, else the forward model's own."""
        if model_kwargs and model_kwargs.get("conditions") is not None:
            return model_kwargs["conditions"]
        return self.conditions

    def sample(self, state, model_args, model_kwargs):
        y, cond = self._data(model_args, model_kwargs), self._conditions(model_kwargs)
        if jnp.ndim(state.rng_key) > 1:  # vectorized chains
            return jax.vmap(lambda s: self._sample_one(s, y, cond))(state)
        return self._sample_one(state, y, cond)

    def _sample_one(self, state, y, cond=None):
        if self.block4 == "chapter":  # the chapter's key stream, unchanged
            rng_key, k_s = jax.random.split(state.rng_key)
            k_b = None
        else:
            rng_key, k_s, k_b = jax.random.split(state.rng_key, 3)
        z = state.z
        params = {n: z[n] for n in self.theta_priors}
        b = z["disc"]
        rep_cov = self._rep_cov(cond)
        # 1. sigma_S^2 from its conjugate inverse gamma.
        sigma_s2 = self._sigma_s2_draw(k_s, params, b, z["v"], y, cond)
        # 2. NUTS on the GP hyperparameters given b (b ~ N(0, K + Sigma_rep) with a floor).
        hyper_args = self._hyper_args(b, rep_cov)
        hyper_state = self._refresh(state.hyper_state, self._hyper_potential_gen(*hyper_args))
        hyper_state = self._hyper_sample(hyper_state, model_args=hyper_args)
        hyper, _ = _constrain(self.hyper_priors, hyper_state.z)
        # 3. Cholesky of the new K (+ Sigma_rep).
        chol = models.discrepancy_cholesky(hyper, self.nugget, rep_cov, self.kernel)
        args = self._block4_args(sigma_s2, chol, y, cond)
        main_state = state.main_state
        if self.block4 == "chapter":  # re-whiten so that b is unchanged
            main_state = main_state._replace(z={**main_state.z, "disc_tilde": solve_triangular(chol, b, lower=True)})
        main_state = self._refresh(main_state, self._main_gen(*args))
        # 4. NUTS on (theta, b_tilde, v) given sigma_S^2 and L, or on (theta, v) with b integrated out and
        #    then b from its Gaussian full conditional.
        main_state = self._main_sample(main_state, model_args=args)
        params, _ = _constrain(self.theta_priors, main_state.z)
        v = main_state.z["v"]
        if self.block4 == "chapter":
            b_tilde = main_state.z["disc_tilde"]
            b = chol @ b_tilde
        else:
            b = self._discrepancy_draw(k_b, params, v, sigma_s2, chol, args[1], y, cond)
            b_tilde = solve_triangular(chol, b, lower=True)
        z = {**params, **hyper, "sigma_s2": sigma_s2, "disc_tilde": b_tilde, "disc": b, "v": v}
        diverging = jnp.logical_or(hyper_state.diverging, main_state.diverging)
        num_steps = hyper_state.num_steps + main_state.num_steps
        return GibbsState(z, hyper_state, main_state, diverging, num_steps, rng_key)

    def get_diagnostics_str(self, state):
        return ""


def sigma_s2_conditional(y_strain, mean_strain):
    """Conjugate full conditional of ``sigma_S^2`` under the IG(0.001, 0.001) prior.

    ``IG(alpha0 + n/2, beta0 + sum((y - mean)^2)/2)`` with n = number of strains.
    """
    resid = jnp.asarray(y_strain) - jnp.asarray(mean_strain)
    n = resid.shape[-1]
    return dist.InverseGamma(models.IG_SHAPE + 0.5 * n, models.IG_SCALE + 0.5 * jnp.sum(resid**2, axis=-1))


__all__ = ["PolarGPGibbs", "GibbsState", "DISCREPANCY_BLOCKS", "sigma_s2_conditional"]
