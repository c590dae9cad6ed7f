"""Compiled samplers kept and reused: numpyro chain methods that compile once per sampler and input shapes,
the lock around model tracing, the per-process cache of compiled samplers keyed on what they compile in, and
the forward model's conditions passed at run time (so one compiled program serves every subject of an
emulator).

The runners that use them are in :mod:`lvcore.inference.samplers`.
"""
from __future__ import annotations

import copy
import hashlib
import threading
from contextlib import contextmanager, nullcontext
from dataclasses import replace
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from numpyro.infer import MCMC

from lvcore.execution.bounded_cache import BoundedCache
from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.inference import kernels
from lvcore.inference.sampler_config import SamplerConfig
from lvcore.domain.outputs import N_OUTPUTS


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

    numpyro's own ``"vectorized"`` chain method (several chains) gets a fresh MCMC every time: its kernel's
    ``init`` replaces the kernel's sample function by a vmapped one in place, so a second run of a shared kernel
    vmapped it twice and failed ("vmap was requested to map its argument along axis 0 ... rank 0"). Nothing
    compiled is lost: that chain method traces outside :func:`_compiled_call` on every run anyway.
    """
    if key is None:
        return factory()

    def made():
        base = factory()
        base.__dict__["_lvcore_compiled"] = {}
        return base

    base = _MCMC_CACHE.get_or_create(key, made)
    if base.chain_method == "vectorized" and base.num_chains > 1:
        return factory()
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
    ETA_CACHE.clear()


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
    """``(samples, stats)`` of a finished run, leading axes (chain, draw); ``stats_fields`` maps output names to
    numpyro's extra fields."""
    samples = {k: np.asarray(v) for k, v in mcmc.get_samples(group_by_chain=True).items()}
    extra = mcmc.get_extra_fields(group_by_chain=True)
    stats = {out: np.asarray(extra[src]) for out, src in stats_fields.items() if src in extra}
    return samples, stats


#: Compiled maps of an emulator's outputs over posterior draws (:func:`lvcore.inference.samplers.posterior_eta`),
#: kept per emulator template like the samplers and cleared with them.
ETA_CACHE: dict = {}


# --------------------------------------------------------------------------- run-time conditions
class ConditionedForward:
    """An emulator forward whose bound conditions are read from run-time values, not compiled in.

    :func:`runtime_conditions` splits a forward model into this template and
    its values (PC scores, EDP, fixed angles, geometry scale). The samplers
    pass the values as an argument of the compiled sampler, next to the data,
    so one compiled program serves every subject of an emulator: a new
    geometry reuses it (in memory, and across processes and app sessions
    through JAX's persistent compilation cache, :mod:`lvcore.execution.jax_cache`)
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


__all__ = ["TRACE_LOCK", "compile_only", "pmap_chains", "pmap_vmap", "use_host_devices", "resolve_chain_method",
           "MCMC_CACHE_SIZE", "emulator_fingerprint", "clear_sampler_cache", "ConditionedForward",
           "runtime_conditions", "ETA_CACHE"]
