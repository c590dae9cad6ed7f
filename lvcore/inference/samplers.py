r"""MCMC samplers: NUTS for models (i)-(iii) and the chapter's HMC-within-Gibbs (Algorithm 4).

:func:`run_nuts` runs numpyro NUTS on any model of :mod:`lvcore.inference.models`
(for model (iii) this is plain *joint* NUTS over theta, sigma_S^2, the GP
hyperparameters, b_tilde and v).

:class:`PolarGPGibbs` is a blocked sampler for model (iii), one sweep being
exactly Algorithm 4 of the chapter:

1. ``sigma_S^2 | rest ~ IG(alpha0 + 12, beta0 + RSS / 2)`` (conjugate, closed form),
   with ``RSS = sum_i (y_i - eta_i - b_i - v)^2`` over the 24 strains;
2. one NUTS transition for the GP hyperparameters ``(lam, sigma1^2, sigma2^2, c, tau)``
   targeting ``MVN(b | 0, K) * prior`` with ``b`` held fixed;
3. Cholesky ``K = L L^T`` of the new Gram matrix, and ``b_tilde = L^{-1} b`` so that
   ``b`` is unchanged by step 2;
4. one NUTS transition for ``(theta, b_tilde, v)`` with ``b = L b_tilde`` (whitened).

Each NUTS block keeps its own step size and diagonal mass-matrix adaptation
(numpyro's functional :func:`numpyro.infer.hmc.hmc` with ``potential_fn_gen``),
and the cached potential energy and gradient are refreshed whenever the
conditioning values change. The kernel plugs into :class:`numpyro.infer.MCMC`,
so chains run sequentially, vectorised or in parallel like any numpyro kernel.
"""
from __future__ import annotations

import copy
import hashlib
import threading
import time
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import numpyro.distributions as dist
from jax.scipy.linalg import solve_triangular
from numpyro.distributions.transforms import biject_to
from numpyro.infer import MCMC, NUTS
from numpyro.infer.hmc import hmc
from numpyro.infer.mcmc import MCMCKernel

from lvcore.bounded_cache import BoundedCache
from lvcore.conditions import SIGMA_V_ML
from lvcore.inference import kernels, models
from lvcore.outputs import N_OUTPUTS


@dataclass(frozen=True)
class SamplerConfig:
    """MCMC settings.

    Attributes
    ----------
    num_warmup, num_samples, num_chains : int
        Warm-up (adaptation) iterations, kept draws and chains.
    chain_method : str
        ``"auto"`` (parallel when there are enough JAX devices, else
        vectorized), or numpyro's ``"parallel"``, ``"vectorized"``, ``"sequential"``.
    seed : int
        PRNG seed.
    target_accept_prob : float
        NUTS dual-averaging target.
    max_tree_depth : int
        NUTS maximum tree depth.
    dense_mass : bool
        Dense mass matrix for plain NUTS (default: diagonal). Neither wins
        everywhere: over 7 SYNTHETIC iid data sets on the ``chapter``
        emulator (4 x (1000 + 1000)) a dense matrix gave the larger minimum
        ESS on 4 but the two poorest runs (ESS 61 with R-hat 1.05, and 571),
        where the diagonal one's poorest was 1441
        (``benchmarks/bench_calibration.py --runs iid [--dense-mass]``).
    progress_bar : bool
        numpyro's text progress bar.
    discrepancy_block : str
        Block 4 of the discrepancy model's HMC-within-Gibbs, one of :data:`DISCREPANCY_BLOCKS`: ``"marginal"``
        (b integrated out of the NUTS block, then drawn exactly) or ``"chapter"`` (Algorithm 4 as written).
    """

    num_warmup: int = 1000
    num_samples: int = 1000
    num_chains: int = 4
    chain_method: str = "auto"
    seed: int = 0
    target_accept_prob: float = 0.8
    max_tree_depth: int = 10
    dense_mass: bool = False
    progress_bar: bool = False
    discrepancy_block: str = "marginal"


#: The app's default run: 4 chains x (250 warm-up + 500 draws). Chosen by measured ESS per CPU second
#: (``benchmarks/bench_calibration.py --sweep``, 2 SYNTHETIC data sets, ``chapter`` emulator, docs/calibration.md):
#: the discrepancy sampler (HMC-within-Gibbs) costs ~5 CPU-ms per chain iteration and gives a bulk ESS of theta
#: of 0.35-0.7 per draw, so 4 x (1000 + 1000) (43 CPU-s, ESS 2,500-3,000) spends most of the click on draws
#: nobody needs; 4 x (250 + 500) costs 18 CPU-s and still gives a worst theta ESS of 1,400 (all parameters,
#: GP hyperparameters included: 395) with R-hat <= 1.01; 250 warm-up iterations gave the same ESS per draw as
#: 500. The iid model (NUTS, ~1.2 CPU-ms per iteration) gets the same setting. Four chains keep R-hat
#: meaningful; on 2 cores they run as 4 XLA host devices. (Those figures are the chapter's block 4; the
#: marginal block, the default since, costs ~2.3-3.1 CPU-ms per chain iteration for a larger minimum ESS.)
INTERACTIVE = SamplerConfig(num_warmup=250, num_samples=500, num_chains=4)


@dataclass
class SamplerRun:
    """Output of one sampler call.

    Attributes
    ----------
    method : str
        ``"nuts"`` or ``"hmc_gibbs"``.
    model : str
        ``"volume"``, ``"iid"`` or ``"discrepancy"``.
    samples : dict of ndarray
        Posterior draws, leading axes (chain, draw).
    sample_stats : dict of ndarray
        Per-draw statistics (``diverging``, ``n_steps``), axes (chain, draw).
    wall_s : float
        Wall time of the call, compilation included (s).
    mcmc : numpyro.infer.MCMC
        The MCMC object (for continuing a chain after non-convergence).
    """

    method: str
    model: str
    samples: dict
    sample_stats: dict
    wall_s: float
    mcmc: Any = field(repr=False, default=None)
    run_kwargs: dict = field(repr=False, default_factory=dict)


def _with_dynamic_model_args(fn):
    """Split numpyro's per-chain function into ``(call(map_args, model_args), model_args)``.

    numpyro hands a callable chain method ``partial(_single_chain_mcmc,
    args=..., kwargs=...)``; mapping the model arguments (the data) as an
    explicit, unmapped argument instead of a closure keeps them out of the
    compiled program as constants. With ``jit_model_args=True`` the compiled
    sampler then depends only on the shapes, so a new data set reuses it
    (in memory, and across processes through the persistent cache).
    """
    if not (isinstance(fn, partial) and {"args", "kwargs"} <= set(fn.keywords)):
        return (lambda map_args, _: fn(map_args)), None  # another numpyro layout: closure as before
    kw = dict(fn.keywords)
    model_args = (kw.pop("args"), kw.pop("kwargs"))

    def call(map_args, model_args):
        args, kwargs = model_args
        return fn.func(map_args, args=args, kwargs=kwargs, **kw)

    return call, model_args


#: Held while a numpyro model is traced. numpyro's effect-handler stack is one global list, so two threads
#: tracing models at once corrupt each other's traces ("all sites must have unique names"); running an
#: already compiled sampler needs no lock, so compiled samplers of several models can run side by side.
TRACE_LOCK = threading.RLock()

_COMPILE_ONLY = threading.local()


@contextmanager
def compile_only():
    """Within this block the chain methods compile (or load from the persistent cache) without sampling.

    ``MCMC.run`` then returns zeros of the right shapes; used by :func:`precompile` to warm an app.
    """
    _COMPILE_ONLY.on = True
    try:
        yield
    finally:
        _COMPILE_ONLY.on = False


def _avals(tree):
    leaves, treedef = jax.tree.flatten(tree)
    return treedef, tuple((tuple(np.shape(x)), str(jnp.result_type(x))) for x in leaves)


def _compiled_call(fn, transform, name: str, pre=lambda a: a, post=lambda out: out):
    """``transform(call)(map_args, model_args)``, compiled once per MCMC object, phase and input shapes.

    The executable is kept on the :class:`numpyro.infer.MCMC` object (``fn`` is a partial of its bound
    ``_single_chain_mcmc``), keyed on what the trace reads besides the inputs (collected fields, the
    collection window) and on the inputs' structure and shapes: a reused MCMC object with new data of
    the same shape runs the compiled program without tracing the model again. Tracing and compiling
    happen under :data:`TRACE_LOCK`. ``pre`` and ``post`` reshape the chain axis around the compiled call.
    """
    call, model_args = _with_dynamic_model_args(fn)
    owner = getattr(getattr(fn, "func", None), "__self__", None)
    params = getattr(owner, "_collection_params", None)

    def run(map_args):
        map_args = pre(map_args)
        if owner is None or params is None:
            with TRACE_LOCK:
                return post(transform(call)(map_args, model_args))
        key = (name, getattr(fn.func, "__name__", ""), fn.keywords.get("collect_fields"),
               fn.keywords.get("remove_sites"), tuple(sorted(params.items())), _avals((map_args, model_args)))
        cache = owner.__dict__.setdefault("_lvcore_compiled", {})
        compiled = cache.get(key)
        if compiled is None:
            with TRACE_LOCK:
                compiled = cache.get(key)  # compiled meanwhile by another thread (the app's warm-up)?
                if compiled is None:
                    compiled = cache[key] = transform(call).lower(map_args, model_args).compile()
        if getattr(_COMPILE_ONLY, "on", False):
            return post(jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), compiled.out_info))
        return post(compiled(map_args, model_args))
    return run


def pmap_chains(fn):
    """numpyro chain method: one chain per JAX device (pmap), the data passed as an argument; compiled once
    per MCMC object and input shapes (:func:`_compiled_call`)."""
    return _compiled_call(fn, lambda call: jax.pmap(call, in_axes=(0, None)), "parallel")


pmap_chains.__name__ = "parallel"


def pmap_vmap(n_devices: int):
    """numpyro chain method: chains split over ``n_devices`` JAX devices (pmap), vectorised within each (vmap).

    With 2 CPU cores, ``numpyro.set_host_device_count(2)`` and 4 chains this
    runs two vectorised pairs of chains side by side.
    """
    def pre(args):
        return jax.tree.map(lambda x: x.reshape((n_devices, x.shape[0] // n_devices) + x.shape[1:]), args)

    def post(out):
        return jax.tree.map(lambda x: x.reshape((x.shape[0] * x.shape[1],) + x.shape[2:]), out)

    def wrap(fn):
        return _compiled_call(fn, lambda call: jax.pmap(jax.vmap(call, in_axes=(0, None)), in_axes=(0, None)),
                              f"pmap{n_devices}_vmap", pre, post)
    wrap.__name__ = f"pmap{n_devices}_vmap"
    return wrap


def use_host_devices(num_chains: int = 4) -> None:
    """Give every chain its own XLA host device, so ``auto`` runs the chains with numpyro's ``parallel``.

    Call it at an entry point before JAX's first computation (``lvcore
    calibrate``, ``lvcore study``, the app, the benchmark scripts); importing
    lvcore never does, and once JAX's backend is up the call has no effect.
    Host devices are threads, so this pays off with more chains than cores:
    on the 2-core machine, 4 chains of the iid model on 4 host devices took
    12.8-15.8 s against 22.5-23.0 s on 2 devices (vmapped pairs), compilation
    included, with the same ESS (``benchmarks/bench_calibration.py``).
    """
    import numpyro

    if int(num_chains) > 1:
        numpyro.set_host_device_count(int(num_chains))


def resolve_chain_method(config: SamplerConfig):
    """Resolve ``"auto"``: ``parallel`` if there are as many JAX devices as chains; :func:`pmap_vmap`
    if several devices divide the chains; else ``vectorized``. Entry points create host devices with
    :func:`use_host_devices`; importing lvcore never does."""
    if config.chain_method != "auto":
        return config.chain_method
    n_dev = jax.local_device_count()
    if config.num_chains > 1 and n_dev >= config.num_chains:
        return pmap_chains
    if config.num_chains > 1 and n_dev > 1 and config.num_chains % n_dev == 0:
        return pmap_vmap(n_dev)
    return "vectorized"


def _mcmc(kernel, config: SamplerConfig, dynamic_args: bool = False) -> MCMC:
    """numpyro MCMC; ``dynamic_args``: the model's arguments (arrays only) are inputs of the
    compiled sampler (``jit_model_args``), not constants, so new data of the same shape reuse it."""
    return MCMC(
        kernel,
        num_warmup=config.num_warmup,
        num_samples=config.num_samples,
        num_chains=config.num_chains,
        chain_method=resolve_chain_method(config),
        progress_bar=config.progress_bar,
        jit_model_args=dynamic_args,
    )


#: Compiled samplers kept in this process (least recently used first out): an app that calibrates
#: several subjects with one emulator traces and compiles each sampler once, not once per click.
MCMC_CACHE_SIZE = 8
_MCMC_CACHE: BoundedCache = BoundedCache(MCMC_CACHE_SIZE)


def emulator_fingerprint(emulator) -> str:
    """A digest of an emulator's arrays and settings: two loads of one emulator share compiled samplers."""
    fp = getattr(emulator, "_lvcore_fingerprint", None)
    if fp is not None:
        return fp
    h = hashlib.sha1(type(emulator).__name__.encode())
    for name, value in sorted(vars(emulator).items()):
        if name.startswith("_lvcore") or name == "metadata":
            continue
        h.update(name.encode())
        for leaf in jax.tree.leaves(value):
            if hasattr(leaf, "shape") and hasattr(leaf, "dtype"):
                arr = np.asarray(leaf)
                h.update(f"{arr.shape}{arr.dtype}".encode())
                h.update(np.ascontiguousarray(arr).tobytes())
            else:
                h.update(type(leaf).__name__.encode() + repr(leaf).encode() if isinstance(
                    leaf, (str, int, float, bool, type(None))) else type(leaf).__name__.encode())
    fp = h.hexdigest()
    try:
        object.__setattr__(emulator, "_lvcore_fingerprint", fp)
    except (AttributeError, TypeError):  # pragma: no cover - slots: recomputed next time
        pass
    return fp


def _template_key(template):
    """What a :class:`ConditionedForward` compiles in (the emulator, which inputs are read, which are
    run-time conditions, whether there is a scale; not its label, which names the scale), or None for any
    other forward model (those are not cached)."""
    if not isinstance(template, ConditionedForward):
        return None
    return (emulator_fingerprint(template._inner.emulator), template.input_names, template._keys, template._scaled,
            _representation_key(template.representation))


def _representation_key(rep):
    """What a mesh's representation-error floor compiles into the likelihood (None without one): a floored
    and an unfloored model of the same emulator must not share a compiled program. A mesh's own factor
    (``strain_scale``) is not in it: that is a run-time value (:func:`runtime_conditions`)."""
    if rep is None:
        return None
    import hashlib

    cov = np.ascontiguousarray(np.asarray(rep.strain_cov, dtype=np.float64))
    return (int(rep.n_pc), float(rep.lvv_rel_sd), hashlib.sha256(cov.tobytes()).hexdigest())


def _cached_mcmc(key, factory) -> MCMC:
    """A numpyro MCMC for one run: a shallow copy of the cached one for ``key`` (sharing its compiled
    programs, :func:`_compiled_call`) or, with ``key`` None, ``factory()``.

    The copy has its own run state (last state, draws, collection window), so concurrent runs of one
    cached sampler (two app sessions) do not disturb each other.
    """
    if key is None:
        return factory()
    def made():
        base = factory()
        base.__dict__["_lvcore_compiled"] = {}
        return base

    base = _MCMC_CACHE.get_or_create(key, made)
    mcmc = copy.copy(base)
    mcmc._collection_params = dict(base._collection_params)
    mcmc._warmup_state = None
    mcmc._last_state = None
    mcmc._states = mcmc._states_flat = None
    return mcmc


def _trace_guard(mcmc: MCMC):
    """:data:`TRACE_LOCK` around a whole run whose chain method traces outside :func:`_compiled_call`
    (numpyro's own ``vectorized`` / ``sequential``, or one chain); nothing for the compiled chain methods."""
    if callable(mcmc.chain_method) and mcmc.num_chains > 1:
        return nullcontext()
    return TRACE_LOCK


def clear_sampler_cache() -> None:
    """Forget the compiled samplers kept in this process (:data:`MCMC_CACHE_SIZE`)."""
    _MCMC_CACHE.clear()
    _ETA_CACHE.clear()


#: The models' keyword arguments at their defaults: a sampler compiled without them (the app's warm-up) is the
#: one a run that passes them explicitly (``calibrate``) needs.
_MODEL_KWARG_DEFAULTS = {"sigma_v": SIGMA_V_ML, "infer_angles": False, "nugget": kernels.DEFAULT_NUGGET}


def _config_key(config: SamplerConfig, model_kwargs: dict):
    """The settings compiled into a sampler: everything but the seed (the PRNG key is an argument), and the
    model's keyword arguments with their defaults filled in and numbers as Python numbers (``5.0`` and
    ``np.float64(5.0)``, given or defaulted, compile the same model)."""
    def canonical(v):
        return repr(v.item() if isinstance(v, np.generic) else v)

    kwargs = {**_MODEL_KWARG_DEFAULTS, **model_kwargs}
    return (replace(config, seed=0), tuple(sorted((k, canonical(v)) for k, v in kwargs.items())))


def _collect(mcmc: MCMC, stats_fields: dict) -> tuple[dict, dict]:
    samples = {k: np.asarray(v) for k, v in mcmc.get_samples(group_by_chain=True).items()}
    extra = mcmc.get_extra_fields(group_by_chain=True)
    stats = {out: np.asarray(extra[src]) for out, src in stats_fields.items() if src in extra}
    return samples, stats


# --------------------------------------------------------------------------- run-time conditions
class ConditionedForward:
    """An emulator forward whose bound conditions are read from run-time values, not compiled in.

    :func:`runtime_conditions` splits a forward model into this template and
    its values (PC scores, EDP, fixed angles, geometry scale). The samplers
    pass the values as an argument of the compiled sampler, next to the data,
    so one compiled program serves every subject of an emulator: a new
    geometry reuses it (in memory, and across processes and app sessions
    through JAX's persistent compilation cache, :mod:`lvcore.jax_cache`)
    instead of compiling the sampler again (10-25 CPU-s per model).

    Call :meth:`bind` with the (traced) values to get the forward model.
    """

    def __init__(self, forward, inner, keys: tuple[str, ...], scaled: bool):
        self.forward, self._inner, self._keys, self._scaled = forward, inner, tuple(keys), bool(scaled)
        # the shape model's representation error a mesh's forward model carries (its covariance a constant of
        # the model, its per-mesh factor a run-time value: lvcore.inference.representation_error.FlooredForward)
        self.representation = getattr(forward, "representation", None)
        self.input_names = tuple(forward.input_names)
        self.label = getattr(forward, "label", type(forward).__name__)
        self.traceable = True

    @property
    def input_bounds(self):
        return self.forward.input_bounds

    def bind(self, values):
        """The forward model at ``values`` (:func:`runtime_conditions`' second output, possibly traced)."""
        return _BoundConditions(self, values)


class _BoundConditions:
    """:class:`ConditionedForward` with its values: a traceable forward model (``__call__(params)``)."""

    def __init__(self, template: ConditionedForward, values):
        self._t, self._v = template, values
        self.input_names, self.label, self.traceable = template.input_names, template.label, True
        rep = template.representation
        if rep is not None and "floor_scale" in values:  # the mesh's own floor factor, a run-time value
            from dataclasses import replace

            rep = replace(rep, strain_scale=values["floor_scale"])
        self.representation = rep

    @property
    def input_bounds(self):
        return self._t.input_bounds

    def __call__(self, params):
        t, v = self._t, self._v
        emu = t._inner.emulator
        cond = {k: v["conditions"][i] for i, k in enumerate(t._keys)}
        x = jnp.stack([jnp.asarray(params[n] if n in t._inner.input_names else cond[n], dtype=jnp.float64)
                       for n in emu.input_names], axis=-1)
        out = jnp.reshape(emu.apply(x), (N_OUTPUTS,))
        if t._scaled:
            from lvcore.geometry.scaling import scale_outputs

            out = scale_outputs(out, v["scale"])
        return out


def runtime_conditions(forward):
    """``(template, values)`` for passing ``forward``'s conditions at run time, or ``(forward, None)``.

    Recognised: :class:`lvcore.emulator.forward.EmulatorForward` and a
    :class:`lvcore.geometry.scaling.ScaledForward` around one (the scale
    becomes a value too), either possibly inside a
    :class:`lvcore.inference.representation_error.FlooredForward` (a mesh's
    representation-error floor, carried by the template; its per-mesh factor
    ``strain_scale`` becomes a value). Any other forward
    model is returned unchanged, its constants compiled in as before.
    """
    from lvcore.emulator.forward import EmulatorForward
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference.representation_error import FlooredForward

    inner, scale, floor_scale = forward, None, None
    if type(inner) is FlooredForward:
        inner, floor_scale = inner.forward, inner.representation.strain_scale
    if type(inner) is ScaledForward:
        inner, scale = inner.forward, float(inner.scale)
    if type(inner) is not EmulatorForward:
        return forward, None
    keys = tuple(sorted(inner.conditions))
    values = {"conditions": jnp.asarray([inner.conditions[k] for k in keys], dtype=jnp.float64).reshape(len(keys))}
    if scale is not None:
        values["scale"] = jnp.asarray(scale, dtype=jnp.float64)
    if floor_scale is not None:  # the mesh's representation-error factor (for_projection): one program for all
        values["floor_scale"] = jnp.asarray(floor_scale, dtype=jnp.float64)
    return ConditionedForward(forward, inner, keys, scale is not None), values


def _conditioned_model(model_fn, template, **model_kwargs):
    """``model_fn`` with its forward model bound from a ``conditions`` argument (see :class:`ConditionedForward`)."""
    def model(y=None, conditions=None):
        return model_fn(y, forward=template.bind(conditions), **model_kwargs)

    return model


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
        ``sigma_v``, ``infer_angles`` (and ``nugget`` for the discrepancy model).
    """
    # the forward model and settings are bound into the model; the data y and the forward model's conditions
    # (runtime_conditions: PC scores, EDP, angles, scale) are (dynamic) arguments of the compiled sampler
    template, values = runtime_conditions(forward)
    if values is None:
        model = partial(models.get_model(model_name), forward=forward, **model_kwargs)
    else:
        model = _conditioned_model(models.get_model(model_name), template, **model_kwargs)
    key = _template_key(template)
    key = None if key is None else ("nuts", model_name, key, _config_key(config, model_kwargs))
    mcmc = _cached_mcmc(key, lambda: _mcmc(NUTS(model, target_accept_prob=config.target_accept_prob,
                                                max_tree_depth=config.max_tree_depth, dense_mass=config.dense_mass),
                                           config, dynamic_args=True))
    t0 = time.perf_counter()
    run_kwargs = dict(y=jnp.asarray(y, dtype=jnp.float64))
    if values is not None:
        run_kwargs["conditions"] = values
    with _trace_guard(mcmc):
        mcmc.run(jax.random.PRNGKey(config.seed), extra_fields=("diverging", "num_steps"), **run_kwargs)
    samples, stats = _collect(mcmc, {"diverging": "diverging", "n_steps": "num_steps"})
    return SamplerRun("nuts", model_name, samples, stats, time.perf_counter() - t0, mcmc, run_kwargs)


# --------------------------------------------------------------------------- blocked sampler
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

    Parameters
    ----------
    forward : lvcore.core.Forward
        JAX-traceable (a :class:`lvcore.core.TraceableForward`).
        Forward model returning the 25 outputs.
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

    Sites in ``state.z``: theta (and angles), ``sigma_s2``, ``lam``, ``sigma1_sq``,
    ``sigma2_sq``, ``c``, ``tau``, ``disc_tilde`` (24, whitened), ``disc`` (24, the discrepancy b), ``v``.
    """

    sample_field = "z"

    def __init__(self, forward, y=None, *, sigma_v: float = SIGMA_V_ML, infer_angles: bool = False,
                 nugget: float = kernels.DEFAULT_NUGGET, target_accept_prob: float = 0.8, max_tree_depth: int = 10,
                 block4: str = "marginal"):
        if block4 not in DISCREPANCY_BLOCKS:
            raise ValueError(f"block4 must be one of {DISCREPANCY_BLOCKS}, got {block4!r}")
        self.block4 = block4
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
        self.hyper_priors = models.hyper_priors()
        self.v_prior = models.v_prior()
        self._hyper_init, self._hyper_sample = hmc(potential_fn_gen=self._hyper_potential_gen, algo="NUTS")
        self._main_gen = self._marginal_potential_gen if block4 == "marginal" else self._main_potential_gen
        self._main_init, self._main_sample = hmc(potential_fn_gen=self._main_gen, algo="NUTS")

    # --- conditionals -------------------------------------------------------
    def _hyper_potential_gen(self, b, y=None):
        """Potential of block 2: ``-log MVN(b | 0, K(hyper)) - log prior`` (unconstrained)."""
        def potential(u):
            hyper, logp = _constrain(self.hyper_priors, u)
            chol = kernels.gram_cholesky(hyper, nugget=self.nugget)
            alpha = solve_triangular(chol, b, lower=True)
            loglik = -0.5 * alpha @ alpha - jnp.sum(jnp.log(jnp.diag(chol)))
            return -(loglik + logp)
        return potential

    def _forward_at(self, cond):
        """The forward model with run-time conditions ``cond`` (None: the forward as given)."""
        return self.forward if cond is None else self._template.bind(cond)

    def _main_potential_gen(self, sigma_s2, chol, y, cond=None):
        """Potential of block 4 over (theta, b_tilde, v) given sigma_S^2 and L."""
        forward = self._forward_at(cond)

        def potential(u):
            params, logp = _constrain(self.theta_priors, u)
            eta = forward(params)
            b = chol @ u["disc_tilde"]
            logl = dist.Normal(eta[0], self.sigma_v).log_prob(y[0])
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
            logl = dist.Normal(eta[0], self.sigma_v).log_prob(y[0])
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
        ``chol_k``, ``chol_t``: Cholesky factors of K and of K + σ² I."""
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
            b_tilde = 0.5 * jax.random.normal(k_bt, (24,))
            v = 0.01 * jax.random.normal(k_v, ())
        else:
            u_theta = _unconstrain(self.theta_priors, init_params)
            u_hyper = _unconstrain(self.hyper_priors, init_params)
            b_tilde = jnp.asarray(init_params.get("disc_tilde", jnp.zeros(24)), dtype=jnp.float64)
            v = jnp.asarray(init_params.get("v", 0.0), dtype=jnp.float64)
        hyper, _ = _constrain(self.hyper_priors, u_hyper)
        chol = kernels.gram_cholesky(hyper, nugget=self.nugget)
        b = chol @ b_tilde
        params, _ = _constrain(self.theta_priors, u_theta)
        sigma_s2 = self._sigma_s2_draw(k_s, params, b, v, y, cond)
        common = dict(num_warmup=num_warmup, target_accept_prob=self.target_accept_prob,
                      max_tree_depth=self.max_tree_depth)
        hyper_state = self._hyper_init(u_hyper, model_args=(b,), rng_key=k_h, **common)
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
        # 1. sigma_S^2 from its conjugate inverse gamma.
        sigma_s2 = self._sigma_s2_draw(k_s, params, b, z["v"], y, cond)
        # 2. NUTS on the GP hyperparameters given b.
        hyper_state = self._refresh(state.hyper_state, self._hyper_potential_gen(b))
        hyper_state = self._hyper_sample(hyper_state, model_args=(b,))
        hyper, _ = _constrain(self.hyper_priors, hyper_state.z)
        # 3. Cholesky of the new K.
        chol = kernels.gram_cholesky(hyper, nugget=self.nugget)
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


def run_hmc_gibbs(y, forward, config: SamplerConfig = SamplerConfig(), **model_kwargs) -> SamplerRun:
    """Run :class:`PolarGPGibbs` (model (iii), Algorithm 4); ``model_kwargs`` as for the kernel."""
    template, values = runtime_conditions(forward)
    key = _template_key(template)
    key = None if key is None else ("hmc_gibbs", key, _config_key(config, model_kwargs))
    # y (and the forward model's conditions, runtime_conditions) are arguments of the compiled sampler, as for NUTS
    mcmc = _cached_mcmc(key, lambda: _mcmc(PolarGPGibbs(forward, y, target_accept_prob=config.target_accept_prob,
                                                        max_tree_depth=config.max_tree_depth,
                                                        block4=config.discrepancy_block, **model_kwargs),
                                           config, dynamic_args=True))
    t0 = time.perf_counter()
    run_kwargs = dict(y=jnp.asarray(y, dtype=jnp.float64))
    if values is not None:
        run_kwargs["conditions"] = values
    with _trace_guard(mcmc):
        mcmc.run(jax.random.PRNGKey(config.seed), extra_fields=("diverging", "num_steps"), **run_kwargs)
    samples, stats = _collect(mcmc, {"diverging": "diverging", "n_steps": "num_steps"})
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
    with _trace_guard(mcmc):
        mcmc.run(mcmc.post_warmup_state.rng_key, extra_fields=("diverging", "num_steps"), **run.run_kwargs)
    samples, stats = _collect(mcmc, {"diverging": "diverging", "n_steps": "num_steps"})
    if "eta" not in samples:
        samples["eta"] = np.asarray(posterior_eta(forward, samples))
    return SamplerRun(run.method, run.model, samples, stats, run.wall_s + time.perf_counter() - t0, mcmc,
                      run.run_kwargs)


_ETA_CACHE: dict = {}


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
        fn = _ETA_CACHE.get(key)
        if fn is None:
            fn = _ETA_CACHE.setdefault(key, jax.jit(lambda p, v, t=template: jax.vmap(lambda q: t.bind(v)(q))(p)))
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
           "DISCREPANCY_BLOCKS"]
