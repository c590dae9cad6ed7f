"""Frequentist check of Bayesian credible intervals (simulation-based calibration).

Draw theta from its prior, simulate data ``y = forward(theta) + noise``
(sigma_V = 5 mL, sigma_S = 0.03, no discrepancy), calibrate, and count how
often the central ``level`` credible interval of each parameter contains the
truth. With truths drawn from the prior a correct sampler covers the truth
``level`` of the time up to binomial noise, so this catches biased
likelihoods, wrong Jacobians and broken Gibbs steps.

All data sets and chains run in one jitted, vmapped computation, so the
cost per data set is just the sampling.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from numpyro.infer.hmc import hmc
from numpyro.infer.util import initialize_model

from lvcore.domain.conditions import SIGMA_S, SIGMA_V_ML
from lvcore.inference import models, samplers
from lvcore.domain.outputs import THETA_NAMES


@dataclass(frozen=True)
class CoverageResult:
    """Outcome of :func:`coverage_study`.

    Attributes
    ----------
    model : str
    n_datasets : int
    level : float
        Nominal credible level (e.g. 0.9).
    per_param : dict
        Fraction of data sets whose interval covers the truth, per parameter.
    overall : float
        Fraction over all parameters and data sets.
    wall_s : float
        Total wall time (s), compilation included.
    hits : ndarray, shape (n_datasets, n_params)
    """

    model: str
    n_datasets: int
    level: float
    per_param: dict
    overall: float
    wall_s: float
    hits: np.ndarray = field(repr=False)

    def binomial_sd(self) -> float:
        """Standard error of ``overall`` if intervals were independent."""
        n = self.hits.size
        return float(np.sqrt(self.level * (1 - self.level) / n))


def simulate_data(forward, theta: dict, rng: np.random.Generator, sigma_v: float = SIGMA_V_ML,
                  sigma_s: float = SIGMA_S, discrepancy=None) -> np.ndarray:
    """SYNTHETIC data: ``forward(theta)`` plus Gaussian noise (and an optional strain discrepancy)."""
    y = np.asarray(forward(theta), dtype=float).copy()
    if discrepancy is not None:
        y[1:] += np.asarray(discrepancy)
    y[0] += sigma_v * rng.standard_normal()
    y[1:] += sigma_s * rng.standard_normal(24)
    return y


def prior_draw(rng: np.random.Generator) -> dict:
    """theta from the uniform priors of Table 9.1."""
    return {n: float(rng.uniform(*models.THETA_BOUNDS[n])) for n in THETA_NAMES}


def _nuts_fns(model_name: str, forward, sigma_v: float, config: samplers.SamplerConfig, y0, template=None,
              c0=None):
    """Pure (jittable, vmappable) init/sample/constrain functions of NUTS on a named model.

    With ``template`` (:func:`lvcore.inference.samplers.runtime_conditions`) the
    functions take the forward model's conditions ``c`` (``{"conditions": (k,)}``)
    next to the data; otherwise ``c`` is ignored.
    """
    kw = {"kernel": config.discrepancy_kernel} if model_name == "discrepancy" else {}
    if template is None:
        model = partial(models.get_model(model_name), forward=forward, sigma_v=sigma_v, **kw)
        args = lambda y, c: (y,)  # noqa: E731
    else:
        model = samplers._conditioned_model(models.get_model(model_name), template, sigma_v=sigma_v, **kw)
        args = lambda y, c: (y, c)  # noqa: E731
    info = initialize_model(jax.random.PRNGKey(0), model, model_args=args(jnp.asarray(y0), c0), dynamic_args=True)
    init_kernel, sample_kernel = hmc(potential_fn_gen=info.potential_fn, algo="NUTS")
    z_proto = info.param_info.z

    def init(key, y, c=None):
        k_z, k_h = jax.random.split(key)
        keys = jax.random.split(k_z, len(z_proto))
        z = {n: jax.random.uniform(k, jnp.shape(v), minval=-2.0, maxval=2.0)
             for k, (n, v) in zip(keys, z_proto.items())}
        return init_kernel(z, config.num_warmup, model_args=args(y, c), rng_key=k_h,
                           target_accept_prob=config.target_accept_prob, max_tree_depth=config.max_tree_depth,
                           dense_mass=config.dense_mass)

    def sample(state, y, c=None):
        return sample_kernel(state, model_args=args(y, c))

    def constrain(z, y, c=None):
        return info.postprocess_fn(*args(y, c))(z)

    return init, sample, constrain, lambda state: state.potential_energy


def _gibbs_fns(forward, sigma_v: float, config: samplers.SamplerConfig):
    kernel = samplers.PolarGPGibbs(forward, None, sigma_v=sigma_v, target_accept_prob=config.target_accept_prob,
                                   max_tree_depth=config.max_tree_depth, block4=config.discrepancy_block,
                                   kernel=config.discrepancy_kernel)
    kw = lambda c: None if c is None else {"conditions": c}  # noqa: E731
    return (lambda key, y, c=None: kernel.init(key, config.num_warmup, None, (y,), kw(c)),
            lambda state, y, c=None: kernel.sample(state, (y,), kw(c)),
            lambda z, y, c=None: z,
            lambda state: state.main_state.potential_energy)


#: The site of :func:`batched_posteriors` that records the sampler's potential energy at each kept draw: NUTS's
#: ``-log p(z | y)`` at the unconstrained draw (volume, iid), block 4's conditional potential for the blocked
#: discrepancy sampler (:class:`lvcore.inference.gibbs.PolarGPGibbs`). It shows which likelihood the sampler used.
POTENTIAL_SITE = "potential_energy"


def batch_conditions(forwards) -> dict:
    """The run-time values (:func:`lvcore.inference.samplers.runtime_conditions`) of one forward model per data
    set, stacked along a leading data-set axis: the ``conditions`` of :func:`batched_posteriors` that give each
    data set exactly the likelihood of its own forward model (its PC scores and, for a mesh, its
    representation-floor factor ``floor_scale``).

    Raises
    ------
    ValueError
        If a forward model's conditions cannot be passed at run time, or the forward models do not share one
        compiled program (another emulator, another floor covariance, a floor on some but not all).
    """
    from lvcore.inference.compiled_samplers import _template_key

    values, keys = [], set()
    for f in forwards:
        template, v = samplers.runtime_conditions(f)
        if v is None:
            raise ValueError(f"batch_conditions: forward model '{getattr(f, 'label', f)}' has no run-time conditions "
                             "(an emulator forward model is needed)")
        keys.add(_template_key(template))
        values.append(v)
    if len(keys) != 1:
        raise ValueError("batch_conditions: the forward models differ in more than their run-time conditions "
                         "(emulator, inputs or representation floor)")
    return {k: jnp.stack([jnp.asarray(v[k], dtype=jnp.float64) for v in values]) for k in values[0]}


def _stacked_conditions(forward, conditions, n: int) -> dict:
    """``conditions`` of :func:`batched_posteriors` as run-time values with a leading data-set axis, checked
    against ``forward``'s own (:func:`lvcore.inference.samplers.runtime_conditions`)."""
    template, values = samplers.runtime_conditions(forward)
    if values is None or "scale" in values:
        raise ValueError("per-data-set conditions need an emulator forward model without a geometry scale")
    if not isinstance(conditions, dict):
        if "floor_scale" in values:
            raise ValueError("per-data-set conditions of a forward model with a representation floor must give each "
                             "data set's floor factor too: pass coverage.batch_conditions(forwards), or a dict with "
                             "'conditions' (n, k) and 'floor_scale' (n,)")
        conditions = {"conditions": conditions}
    if set(conditions) != set(values):
        raise ValueError(f"conditions must hold {sorted(values)} (the forward model's run-time values), got "
                         f"{sorted(conditions)}")
    out = {}
    for k, ref in values.items():
        a, want = jnp.asarray(conditions[k], dtype=jnp.float64), (n,) + tuple(jnp.shape(ref))
        if a.size != int(np.prod(want)):
            floor = f" and floor_scale ({n},)" if "floor_scale" in values else ""
            raise ValueError(f"conditions must have shape ({n}, {values['conditions'].shape[0]}) "
                             f"({', '.join(template._keys)}){floor}, got {k} of shape {a.shape}")
        out[k] = a.reshape(want)
    return out


def batched_posteriors(forward, model_name: str, ys, keys, config: samplers.SamplerConfig,
                       sigma_v: float = SIGMA_V_ML, sites=THETA_NAMES, group_by_chain: bool = False,
                       conditions=None) -> dict:
    """Posterior draws for many data sets at once: one jit, vmapped over (data set x chain).

    Parameters
    ----------
    sites : sequence of str
        Sites to keep (constrained values; ``eta`` is available for NUTS models).
    group_by_chain : bool
        Return arrays of shape (n_datasets, num_chains, num_samples, ...) instead
        of (n_datasets, num_chains * num_samples, ...).
    conditions : array_like, shape (n_datasets, k), or dict, optional
        Per data set, the forward model's run-time conditions (the values of
        :func:`lvcore.inference.samplers.runtime_conditions`, e.g. each data
        set's PC scores): data sets of several geometries then share one
        compiled program. ``forward`` must be an emulator forward model
        (without a geometry scale); its own conditions are replaced. A forward
        model with a mesh's representation floor needs each data set's floor
        factor as well: a dict of all run-time values with a leading data-set axis,
        ``{"conditions": (n, k), "floor_scale": (n,)}``, as :func:`batch_conditions`
        makes from one forward model per data set (each data set then gets the
        posterior its own forward model gives in :func:`lvcore.inference.samplers.run_model`).
    """
    models.check_traceable(forward)
    ys = jnp.asarray(ys, dtype=jnp.float64)
    n = ys.shape[0]
    # every run-time value (PC scores and a mesh's floor factor) per data set, so each data set's likelihood is
    # that of its own forward model
    conds = _stacked_conditions(forward, conditions, n) if conditions is not None else {"none": jnp.zeros((n, 0))}
    key = (id(forward), model_name, config, float(sigma_v), tuple(sites), conditions is not None)
    hit = _COMPILED.get(key)
    if hit is not None and hit[0] is forward:  # the same sampler again (another batch): no new trace/compile
        run = hit[1]
    else:
        run = _batched_sampler(forward, model_name, ys[0], config, sigma_v, sites, conditions is not None)
        if len(_COMPILED) >= 8:
            _COMPILED.pop(next(iter(_COMPILED)))
        _COMPILED[key] = (forward, run)
    chain_keys = jax.vmap(lambda k: jax.random.split(k, config.num_chains))(keys)
    flat_keys = chain_keys.reshape((n * config.num_chains,) + chain_keys.shape[2:])
    flat_y = jnp.repeat(ys, config.num_chains, axis=0)
    flat_c = {k: jnp.repeat(v, config.num_chains, axis=0) for k, v in conds.items()}
    draws = run(flat_keys, flat_y, flat_c)
    shape = (n, config.num_chains, config.num_samples) if group_by_chain else (n, -1)
    return {k: np.asarray(v).reshape(shape + np.shape(v)[2:]) for k, v in draws.items()}


#: Jitted batched samplers by (forward model, likelihood, settings): a second batch reuses the first one's
#: trace and compilation (a new closure per call would be traced and compiled again).
_COMPILED: dict = {}


def _batched_sampler(forward, model_name, y0, config, sigma_v, sites, with_conditions: bool):
    """The jitted ``(keys, ys, conditions) -> draws`` of :func:`batched_posteriors`, vmapped over chains."""
    template = None
    if with_conditions:   # all run-time values (scores, floor factor) per data set, checked by _stacked_conditions
        template, values = samplers.runtime_conditions(forward)
        cond_of = lambda c: c  # noqa: E731
        c0 = values
    else:
        cond_of = lambda c: None  # noqa: E731
        c0 = None
    if model_name == "discrepancy":
        init, sample, constrain, energy = _gibbs_fns(forward, sigma_v, config)
    else:
        init, sample, constrain, energy = _nuts_fns(model_name, forward, sigma_v, config, y0, template, cond_of(c0))
    total = config.num_warmup + config.num_samples

    def one_chain(key, y, cv):
        c = cond_of(cv)
        state = init(key, y, c)

        def body(st, _):
            st = sample(st, y, c)
            zc = constrain(st.z, y, c)
            return st, {k: energy(st) if k == POTENTIAL_SITE else zc[k] for k in sites}

        _, draws = jax.lax.scan(body, state, None, length=total)
        return {k: v[config.num_warmup:] for k, v in draws.items()}

    return jax.jit(jax.vmap(one_chain))


def coverage_study(forward, model_name: str = "iid", n_datasets: int = 50, *, level: float = 0.9,
                   config: samplers.SamplerConfig = samplers.SamplerConfig(num_warmup=500, num_samples=500,
                                                                           num_chains=2),
                   seed: int = 0, sigma_v: float = SIGMA_V_ML, sigma_s: float = SIGMA_S) -> CoverageResult:
    """Coverage of central ``level`` credible intervals over ``n_datasets`` prior-drawn truths."""
    rng = np.random.default_rng(seed)
    truths = [prior_draw(rng) for _ in range(n_datasets)]
    ys = np.stack([simulate_data(forward, th, rng, sigma_v, sigma_s) for th in truths])
    keys = jax.random.split(jax.random.PRNGKey(seed), n_datasets)
    t0 = time.perf_counter()
    draws = batched_posteriors(forward, model_name, ys, keys, config, sigma_v)
    wall = time.perf_counter() - t0
    lo, hi = (1 - level) / 2, 1 - (1 - level) / 2
    hits = np.zeros((n_datasets, len(THETA_NAMES)), dtype=bool)
    for j, n in enumerate(THETA_NAMES):
        q = np.quantile(draws[n], [lo, hi], axis=1)
        tv = np.array([th[n] for th in truths])
        hits[:, j] = (q[0] <= tv) & (tv <= q[1])
    per = {n: float(hits[:, j].mean()) for j, n in enumerate(THETA_NAMES)}
    return CoverageResult(model_name, n_datasets, level, per, float(hits.mean()), wall, hits)


__all__ = ["CoverageResult", "coverage_study", "batched_posteriors", "batch_conditions", "POTENTIAL_SITE",
           "simulate_data", "prior_draw"]
