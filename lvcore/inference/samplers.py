r"""MCMC runners: NUTS for models (i)-(iii) and the chapter's HMC-within-Gibbs (Algorithm 4).

:func:`run_nuts` runs numpyro NUTS on any model of :mod:`lvcore.inference.models`
(for model (iii) this is plain *joint* NUTS over theta, sigma_S^2, the GP
hyperparameters, b_tilde and v); :func:`run_hmc_gibbs` runs the blocked kernel
:class:`lvcore.inference.gibbs.PolarGPGibbs`; :func:`run_model` picks the default
sampler of a model.

The pieces live one concept per module and are re-exported here:

* :mod:`lvcore.inference.sampler_config`: :class:`SamplerConfig`, :data:`INTERACTIVE`, :class:`SamplerRun`;
* :mod:`lvcore.inference.compiled_samplers`: the compiled-program cache, chain methods, the trace lock and the
  run-time conditions of a forward model;
* :mod:`lvcore.inference.gibbs`: the HMC-within-Gibbs kernel.
"""
from __future__ import annotations

import time
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from numpyro.infer import MCMC, NUTS

from lvcore.inference import models
from lvcore.inference.compiled_samplers import (  # noqa: F401  (re-exported: the samplers' public surface)
    ETA_CACHE, MCMC_CACHE_SIZE, TRACE_LOCK, ConditionedForward, _cached_mcmc, _collect, _conditioned_model,
    _config_key, _mcmc, _MCMC_CACHE, _template_key, _trace_guard, _with_dynamic_model_args, clear_sampler_cache,
    compile_only, emulator_fingerprint, pmap_chains, pmap_vmap, resolve_chain_method, runtime_conditions,
    use_host_devices)
from lvcore.inference.gibbs import DISCREPANCY_BLOCKS, GibbsState, PolarGPGibbs, sigma_s2_conditional  # noqa: F401
from lvcore.inference.sampler_config import INTERACTIVE, SamplerConfig, SamplerRun  # noqa: F401
from lvcore.domain.outputs import N_OUTPUTS

_STATS_FIELDS = {"diverging": "diverging", "n_steps": "num_steps"}


def _run_and_collect(mcmc: MCMC, rng_key, run_kwargs: dict) -> tuple[dict, dict]:
    """Run ``mcmc`` (under the trace lock where its chain method traces outside the compiled call) and return
    ``(samples, stats)`` with leading axes (chain, draw); the one run-and-collect step of every runner."""
    with _trace_guard(mcmc):
        mcmc.run(rng_key, extra_fields=("diverging", "num_steps"), **run_kwargs)
    return _collect(mcmc, _STATS_FIELDS)


def _run_kwargs(y, values) -> dict:
    """The compiled sampler's arguments: the data ``y`` and, for an emulator, its run-time conditions."""
    run_kwargs = dict(y=jnp.asarray(y, dtype=jnp.float64))
    if values is not None:
        run_kwargs["conditions"] = values
    return run_kwargs


def sampler_cache_key(method: str, model_name: str, template, config: SamplerConfig, model_kwargs: dict):
    """The key of a compiled sampler in this process's cache (:func:`_cached_mcmc`), or None for a forward model
    whose programs are not kept (``template`` from :func:`runtime_conditions`). It holds everything compiled in:
    the emulator template, the sampler settings but the seed (so the discrepancy model's block 4 and GP kernel,
    ``config.discrepancy_block`` / ``discrepancy_kernel``: a product-kernel run never reuses an additive program)
    and the model's keyword arguments."""
    key = _template_key(template)
    if key is None:
        return None
    if method == "nuts":
        return ("nuts", model_name, key, _config_key(config, model_kwargs))
    return ("hmc_gibbs", key, _config_key(config, model_kwargs))


def run_nuts(model_name: str, y, forward, config: SamplerConfig = SamplerConfig(), **model_kwargs) -> SamplerRun:
    """Run NUTS on model ``model_name`` (``volume``, ``iid`` or ``discrepancy`` = joint NUTS).

    Parameters
    ----------
    model_name : str
        Name in :data:`lvcore.inference.models.MODELS`.
    y : array_like, shape (25,)
        Measured LVV (mL) and 24 strains.
    forward : lvcore.core.Forward
        JAX-traceable (a :class:`lvcore.core.TraceableForward`).
        Forward model (emulator adapter or stand-in).
    config : SamplerConfig
    **model_kwargs
        ``sigma_v``, ``infer_angles`` (and ``nugget`` for the discrepancy model, whose GP kernel is
        ``config.discrepancy_kernel``).
    """
    if model_name == "discrepancy":
        model_kwargs = {**model_kwargs, "kernel": config.discrepancy_kernel}
    # the forward model and settings are bound into the model; the data y and the forward model's conditions
    # (runtime_conditions: PC scores, EDP, angles, scale) are (dynamic) arguments of the compiled sampler
    template, values = runtime_conditions(forward)
    if values is None:
        model = partial(models.get_model(model_name), forward=forward, **model_kwargs)
    else:
        model = _conditioned_model(models.get_model(model_name), template, **model_kwargs)
    key = sampler_cache_key("nuts", model_name, template, config, model_kwargs)
    mcmc = _cached_mcmc(key, lambda: _mcmc(NUTS(model, target_accept_prob=config.target_accept_prob,
                                                max_tree_depth=config.max_tree_depth, dense_mass=config.dense_mass),
                                           config, dynamic_args=True))
    t0 = time.perf_counter()
    run_kwargs = _run_kwargs(y, values)
    samples, stats = _run_and_collect(mcmc, jax.random.PRNGKey(config.seed), run_kwargs)
    return SamplerRun("nuts", model_name, samples, stats, time.perf_counter() - t0, mcmc, run_kwargs)


def run_hmc_gibbs(y, forward, config: SamplerConfig = SamplerConfig(), **model_kwargs) -> SamplerRun:
    """Run :class:`PolarGPGibbs` (model (iii), Algorithm 4) with block 4 ``config.discrepancy_block`` and the GP
    kernel ``config.discrepancy_kernel``; ``model_kwargs`` as for the kernel."""
    template, values = runtime_conditions(forward)
    key = sampler_cache_key("hmc_gibbs", "discrepancy", template, config, model_kwargs)
    # y (and the forward model's conditions, runtime_conditions) are arguments of the compiled sampler, as for NUTS
    mcmc = _cached_mcmc(key, lambda: _mcmc(PolarGPGibbs(forward, y, target_accept_prob=config.target_accept_prob,
                                                        max_tree_depth=config.max_tree_depth,
                                                        block4=config.discrepancy_block,
                                                        kernel=config.discrepancy_kernel, **model_kwargs),
                                           config, dynamic_args=True))
    t0 = time.perf_counter()
    run_kwargs = _run_kwargs(y, values)
    samples, stats = _run_and_collect(mcmc, jax.random.PRNGKey(config.seed), run_kwargs)
    # eta at every draw (the blocked kernel does not record it as it goes).
    samples["eta"] = np.asarray(posterior_eta(forward, samples))
    return SamplerRun("hmc_gibbs", "discrepancy", samples, stats, time.perf_counter() - t0, mcmc, run_kwargs)


def continue_run(run: SamplerRun, forward) -> SamplerRun:
    """Draw ``num_samples`` more per chain from where ``run`` stopped (no new warm-up).

    Used by :func:`lvcore.inference.diagnostics.sample_until_converged` to
    discard non-converged draws as burn-in.
    """
    mcmc = run.mcmc
    mcmc.post_warmup_state = mcmc.last_state
    t0 = time.perf_counter()
    samples, stats = _run_and_collect(mcmc, mcmc.post_warmup_state.rng_key, run.run_kwargs)
    if "eta" not in samples:
        samples["eta"] = np.asarray(posterior_eta(forward, samples))
    return SamplerRun(run.method, run.model, samples, stats, run.wall_s + time.perf_counter() - t0, mcmc,
                      run.run_kwargs)


def posterior_eta(forward, samples: dict):
    """Forward-model outputs at every draw, shape (chain, draw, 25).

    An emulator forward model's conditions are an argument (:func:`runtime_conditions`), so the
    compiled map is kept per emulator and reused for every subject.
    """
    names = forward.input_names
    flat = {n: jnp.reshape(jnp.asarray(samples[n]), (-1,)) for n in names}
    lead = np.shape(samples[names[0]])
    template, values = runtime_conditions(forward)
    key = _template_key(template)
    if key is None:
        eta = jax.jit(jax.vmap(lambda p: forward(p)))(flat)
    else:
        fn = ETA_CACHE.get(key)
        if fn is None:
            fn = ETA_CACHE.setdefault(key, jax.jit(lambda p, v, t=template: jax.vmap(lambda q: t.bind(v)(q))(p)))
        eta = fn(flat, values)
    return jnp.reshape(eta, lead + (N_OUTPUTS,))


def run_model(model_name: str, y, forward, config: SamplerConfig = SamplerConfig(), *,
              sampler: str = "auto", **model_kwargs) -> SamplerRun:
    """Run the default sampler of a model: NUTS for (i), (ii); HMC-within-Gibbs for (iii).

    ``sampler="nuts"`` forces joint NUTS for the discrepancy model. ``forward``
    must be JAX-traceable (:func:`lvcore.inference.models.check_traceable`).
    """
    models.check_traceable(forward, model_kwargs.get("infer_angles", False))
    if model_name == "discrepancy" and sampler in ("auto", "hmc_gibbs"):
        return run_hmc_gibbs(y, forward, config, **model_kwargs)
    if model_name != "discrepancy":
        model_kwargs.pop("nugget", None)
    return run_nuts(model_name, y, forward, config, **model_kwargs)


def precompile(model_name: str, y, forward, config: SamplerConfig = SamplerConfig(), *, sampler: str = "auto",
               **model_kwargs) -> float:
    """Trace and compile (or load from the persistent cache) the sampler :func:`run_model` would run, without
    sampling; later runs with this emulator and these settings in this process start sampling at once.

    Returns
    -------
    float
        Wall time (s).
    """
    t0 = time.perf_counter()
    with compile_only():
        run_model(model_name, y, forward, config, sampler=sampler, **model_kwargs)
    return time.perf_counter() - t0


__all__ = ["SamplerConfig", "SamplerRun", "PolarGPGibbs", "GibbsState", "run_nuts", "run_hmc_gibbs",
           "run_model", "continue_run", "posterior_eta", "sigma_s2_conditional", "resolve_chain_method", "pmap_vmap", "pmap_chains",
           "use_host_devices", "runtime_conditions", "ConditionedForward", "INTERACTIVE", "TRACE_LOCK", "compile_only",
           "precompile", "clear_sampler_cache", "emulator_fingerprint", "MCMC_CACHE_SIZE",
           "DISCREPANCY_BLOCKS", "sampler_cache_key"]
