"""The forward-model interface: named physical inputs -> the 25 outputs.

A *forward model* is anything that satisfies the :class:`Forward` protocol.
It maps named physical inputs (``a, af`` in kPa, ``b, bf`` dimensionless,
``alpha_endo, alpha_epi`` in degrees, ``edp`` in mmHg, PC scores ``h1..hk``)
to the 25 outputs ``[LVV (mL), 24 circumferential strains]`` in the order of
:mod:`lvcore.outputs`. Inputs that are not varied (a geometry, fixed angles,
the EDP) are bound into the forward model when it is built, so its users
(campaigns, optimisers, samplers, studies, the app) see only the inputs in
:attr:`Forward.input_names`.

Two ways to call a forward model:

``forward.evaluate(inputs, jacobian=False) -> ForwardBatch``
    batched and numeric: ``inputs`` maps every name of ``input_names`` to an
    array of shape ``(n,)`` (scalars broadcast). Failures are data: a point
    that does not converge is a NaN row with ``converged`` False and a
    message; ``evaluate`` raises only for malformed inputs. With
    ``jacobian=True`` (needs ``provides_jacobian``) the batch carries
    ``d outputs / d inputs`` of shape ``(n, 25, len(input_names))``.
``forward(params) -> (25,)``
    one point; for JAX-traceable forwards (``traceable`` True: the emulator,
    the analytic stand-in) this is a pure JAX function that ``jax.grad``,
    ``jax.vmap`` and numpyro can trace. The simulator solves sparse systems
    on the host and is *not* traceable: calling it with traced values raises
    :class:`~lvcore.exceptions.ForwardError` saying so.

Implementations: :class:`SimulatorForward` (the FE simulator, adjoint
Jacobian, batches over a process pool or Dask), :class:`EmulatorForward`
(a trained emulator with conditions bound in) and :class:`AnalyticForward`
(a SYNTHETIC closed-form stand-in for tests and benchmarks only).
"""
from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Mapping, Protocol, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np

from lvcore.core.space import CHAPTER_ANGLES, CHAPTER_EDP, build_case
from lvcore.exceptions import EmulatorError, ForwardError, SolverError
from lvcore.outputs import ANGLE_NAMES, EDP_NAME, N_OUTPUTS, THETA_NAMES, is_pc_name, pc_names
from lvcore.units import DEFAULT_ALPHA_ENDO_DEG, DEFAULT_ALPHA_EPI_DEG, DEFAULT_EDP_MMHG


# --------------------------------------------------------------------------- the interface
@dataclass(frozen=True, eq=False)
class ForwardBatch:
    """Outputs of one :meth:`Forward.evaluate` call.

    Attributes
    ----------
    outputs : (n, 25) float array
        ``[LVV (mL), 24 strains]`` per point; NaN rows where a point failed.
    converged : (n,) bool array
    messages : tuple of str
        Per point: the solver's message, the failure reason where it failed.
    jacobian : (n, 25, p) float array or None
        ``d outputs / d inputs`` over the forward model's ``input_names``
        (NaN rows where a point failed); only when asked for.
    seconds : (n,) float array or None
        Wall time per point (s), where the forward model measures it.
    """

    outputs: np.ndarray
    converged: np.ndarray
    messages: tuple[str, ...]
    jacobian: np.ndarray | None = None
    seconds: np.ndarray | None = None

    def __post_init__(self):
        y = np.asarray(self.outputs, dtype=float)
        if y.ndim != 2 or y.shape[1] != N_OUTPUTS:
            raise ForwardError(f"forward outputs must have shape (n, {N_OUTPUTS}), got {y.shape}")
        n = y.shape[0]
        conv = np.asarray(self.converged, dtype=bool).reshape(-1)
        if conv.shape != (n,) or len(self.messages) != n:
            raise ForwardError(f"a batch of {n} points needs {n} convergence flags and messages, "
                               f"got {conv.shape[0]} and {len(self.messages)}")
        object.__setattr__(self, "outputs", y)
        object.__setattr__(self, "converged", conv)
        object.__setattr__(self, "messages", tuple(str(m) for m in self.messages))
        if self.jacobian is not None:
            jac = np.asarray(self.jacobian, dtype=float)
            if jac.ndim != 3 or jac.shape[:2] != (n, N_OUTPUTS):
                raise ForwardError(f"a Jacobian must have shape ({n}, {N_OUTPUTS}, p), got {jac.shape}")
            object.__setattr__(self, "jacobian", jac)
        if self.seconds is not None:
            object.__setattr__(self, "seconds", np.asarray(self.seconds, dtype=float).reshape(n))

    @property
    def n(self) -> int:
        """Number of points."""
        return self.outputs.shape[0]

    def raise_on_failure(self) -> "ForwardBatch":
        """Return ``self`` if every point converged, else raise :class:`SolverError` naming the first failure."""
        bad = np.flatnonzero(~self.converged)
        if bad.size:
            raise SolverError(f"{bad.size} of {self.n} forward evaluation(s) failed; point {bad[0]}: "
                              f"{self.messages[bad[0]]}")
        return self


@runtime_checkable
class Forward(Protocol):
    """A forward model: named physical inputs -> the 25 outputs (see the module docstring).

    Attributes
    ----------
    input_names : tuple of str
        Inputs read at call time, in Jacobian-column order.
    label : str
        Human-readable description (summaries, stores); says SYNTHETIC for stand-ins.
    provides_jacobian : bool
        ``evaluate(..., jacobian=True)`` is available.
    traceable : bool
        ``__call__`` is a pure JAX function (usable inside ``jax.grad`` and numpyro).
    input_bounds : mapping
        Box in which the forward model is valid (an emulator's training box),
        name -> (lower, upper); empty where unrestricted.
    """

    input_names: tuple[str, ...]
    label: str
    provides_jacobian: bool
    traceable: bool

    @property
    def input_bounds(self) -> Mapping[str, tuple[float, float]]:  # pragma: no cover - protocol
        ...

    def evaluate(self, inputs: Mapping[str, Any], *, jacobian: bool = False) -> ForwardBatch:  # pragma: no cover
        ...

    def __call__(self, params: Mapping[str, Any]) -> Any:  # pragma: no cover - protocol
        ...


def as_columns(inputs: Mapping[str, Any], names: tuple[str, ...], who: str = "forward model") -> tuple[dict, int]:
    """Check ``inputs`` against ``names`` and broadcast them to float columns of one length.

    Returns ``(columns, n)``; raises :class:`ForwardError` for missing or
    unknown names, mismatched lengths, more than one dimension or non-finite values.
    """
    if not isinstance(inputs, Mapping):
        raise ForwardError(f"{who}: inputs must be a mapping name -> values, got {type(inputs).__name__}")
    missing = [n for n in names if n not in inputs]
    unknown = [k for k in inputs if k not in names]
    if missing or unknown:
        raise ForwardError(f"{who} reads inputs {list(names)}; "
                           + (f"missing {missing}" if missing else "") + ("; " if missing and unknown else "")
                           + (f"unexpected {unknown}" if unknown else ""))
    try:
        cols = [np.asarray(inputs[n], dtype=float) for n in names]
    except (TypeError, ValueError) as err:
        raise ForwardError(f"{who}: inputs must be numbers ({err})") from None
    if any(c.ndim > 1 for c in cols):
        raise ForwardError(f"{who}: each input must be a number or a 1-d array of points")
    try:
        cols = np.broadcast_arrays(*[np.atleast_1d(c) for c in cols]) if cols else []
    except ValueError:
        raise ForwardError(f"{who}: inputs have different numbers of points "
                           f"{ {n: np.size(inputs[n]) for n in names} }") from None
    n = cols[0].shape[0] if cols else 1
    out = {name: np.array(c, dtype=float) for name, c in zip(names, cols)}
    bad = [name for name, c in out.items() if not np.all(np.isfinite(c))]
    if bad:
        raise ForwardError(f"{who}: input(s) {bad} contain NaN or inf")
    return out, n


def _is_traced(params: Mapping[str, Any]) -> bool:
    return any(isinstance(v, jax.core.Tracer) for v in params.values())


def failure_reason(err: BaseException) -> str:
    """``"Type: message (file.py:line)"`` for a recorded failure."""
    if isinstance(err, SolverError):
        return f"SolverError: {err}"
    last = traceback.extract_tb(err.__traceback__)[-1] if err.__traceback__ else None
    where = f" ({Path(last.filename).name}:{last.lineno})" if last else ""
    return f"{type(err).__name__}: {err}{where}"


class _JaxForward:
    """Shared ``evaluate`` for forward models whose ``__call__`` is a pure JAX function of one point."""

    traceable: ClassVar[bool] = True
    provides_jacobian: ClassVar[bool] = True

    def _point(self, x):
        return self(dict(zip(self.input_names, x)))

    def evaluate(self, inputs: Mapping[str, Any], *, jacobian: bool = False) -> ForwardBatch:
        cols, n = as_columns(inputs, self.input_names, self.label)
        x = jnp.stack([jnp.asarray(cols[k]) for k in self.input_names], axis=-1) if self.input_names \
            else jnp.zeros((n, 0))
        self._check_box(np.asarray(x))
        y = np.array(jax.vmap(self._point)(x), dtype=float)
        ok = np.all(np.isfinite(y), axis=1)
        jac = np.array(jax.vmap(jax.jacfwd(self._point))(x), dtype=float) if jacobian else None
        if jac is not None:
            jac[~ok] = np.nan
        y[~ok] = np.nan
        msgs = tuple("" if o else "non-finite outputs" for o in ok)
        return ForwardBatch(y, ok, msgs, jac)

    def _check_box(self, x: np.ndarray) -> None:
        """Hook: warn or raise for points outside the valid box (the emulator does)."""


# --------------------------------------------------------------------------- the simulator
def _simulate_point(case: dict, input_names: tuple[str, ...], jacobian: bool, warm: dict | None = None):
    """One simulator run -> ``(outputs (25,), converged, message, jacobian (25, p) or None, seconds)``.

    Runs in worker processes; never raises for a failing simulation. ``warm``
    (in-process only): a dict whose ``"state"`` warm-starts the solve and is
    replaced by this solve's state when it converges.
    """
    t0 = time.perf_counter()
    nan_jac = np.full((N_OUTPUTS, len(input_names)), np.nan) if jacobian else None
    try:
        from lvcore import simulate

        r = simulate(case, with_sensitivities=jacobian, initial=None if warm is None else warm.get("state"))
        if warm is not None and r.converged:
            warm["state"] = r.warm_state
        seconds = float(getattr(r, "seconds", time.perf_counter() - t0))
        if not r.converged:
            return np.full(N_OUTPUTS, np.nan), False, str(r.message or "did not converge"), nan_jac, seconds
        y = np.asarray(r.outputs(), dtype=float)
        jac = None
        if jacobian:
            sens = r.sensitivities or {}
            jac = np.column_stack([np.asarray(sens[n], dtype=float) for n in input_names])
        return y, True, str(r.message or ""), jac, seconds
    except Exception as err:  # noqa: BLE001 - recorded as a failed point, never swallowed silently
        return np.full(N_OUTPUTS, np.nan), False, failure_reason(err), nan_jac, time.perf_counter() - t0


def _simulate_chunk(input_names, cases, keys, units, seeds, jacobian):
    """Worker task: ``cases`` in order, each warm-started from the nearest converged state (a chain chunk).

    Returns :class:`lvcore.campaigns.chains.ChainRow` objects whose results are
    :func:`_simulate_point` tuples.
    """
    from lvcore.campaigns.chains import solve_in_order

    by_key = dict(zip(keys, cases))

    def solve(key, initial):
        warm = {"state": initial}
        res = _simulate_point(by_key[key], input_names, jacobian, warm)
        return res, (warm["state"] if res[1] else None)

    return solve_in_order(keys, units, seeds, solve)


#: Converged states a warm-starting SimulatorForward keeps between batches.
WARM_KEPT_STATES = 64


@dataclass(frozen=True, eq=False)
class SimulatorForward:
    """The FE simulator (:func:`lvcore.simulate`) as a :class:`Forward`.

    Each point's named inputs, merged with ``conditions``, go through
    :func:`lvcore.core.space.build_case` on ``geometry`` at ``resolution``.

    Parameters
    ----------
    input_names : tuple of str
        Inputs read at call time (default ``a, b, af, bf``).
    conditions : mapping
        Fixed inputs by name (fibre angles in deg, ``edp`` in mmHg, PC scores
        ``h1..hk`` of a ``pca`` geometry). Unset angles and EDP are the
        chapter's (-60°, 60°) and 8 mmHg (:func:`build_case`).
    geometry : mapping, optional
        The case's geometry section (default: the PC scores among the inputs,
        else the default LV).
    resolution : str
        Mesh preset (``"fast"``, ``"coarse"``, ``"default"``, ``"accurate"``).
    base : {"clamped", "sliding"}
    workers : int, optional
        Batches of more than one point run on a local process pool of this
        many workers (:class:`lvcore.campaigns.executors.LocalExecutor`;
        ``None``: one per core). ``1`` (default) runs them in this process.
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a Dask scheduler for batches (overrides ``workers``).
    label : str
    warm_start : bool
        Every point starts Newton at full load from the nearest converged
        state (:func:`lvcore.mechanics.newton.solve`), which saves most of the
        load stepping: a batch is ordered into continuation chains
        (:mod:`lvcore.campaigns.chains`), in this process or split across the
        executor's workers, and the forward keeps its last converged states to
        start later batches (a sequence of nearby points: an SQP, a line
        search, BO iterations). A failed warm start falls back to a cold solve,
        and the result satisfies the same tolerances. Without it every point
        is solved cold.

    Notes
    -----
    The Jacobian comes from the simulator's adjoint sensitivities
    (:mod:`lvcore.mechanics.sensitivities`), which exist for the material
    parameters only: ``provides_jacobian`` is True when every input is one
    of ``a, b, af, bf``. The simulator is not JAX-traceable.
    """

    input_names: tuple[str, ...] = THETA_NAMES
    conditions: Mapping[str, float] = field(default_factory=dict)
    geometry: Mapping | None = None
    resolution: str = "default"
    base: str = "clamped"
    workers: int | None = 1
    scheduler: str | None = None
    label: str = "FE simulator"
    warm_start: bool = False
    _warm: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    traceable: ClassVar[bool] = False

    def __post_init__(self):
        object.__setattr__(self, "input_names", tuple(str(n) for n in self.input_names))
        object.__setattr__(self, "conditions", {str(k): float(v) for k, v in dict(self.conditions).items()})
        both = sorted(set(self.input_names) & set(self.conditions))
        if both:
            raise ForwardError(f"simulator forward: {both} are both inputs and fixed conditions")
        # fail now, not per point, on names the case builder does not know
        probe = {**{n: 1.0 for n in THETA_NAMES}, **self.conditions, **{n: 0.0 for n in self.input_names}}
        probe.update({n: 1.0 for n in THETA_NAMES if n in self.input_names})
        build_case(probe, geometry=self.geometry, resolution=self.resolution, base=self.base)

    def __getstate__(self):
        # the kept warm-start states stay in this process (a pickled copy, e.g. sent to a worker, starts empty)
        return {k: v for k, v in self.__dict__.items() if k != "_warm"}

    def __setstate__(self, state):
        self.__dict__.update(state)
        object.__setattr__(self, "_warm", {})

    @property
    def provides_jacobian(self) -> bool:
        return bool(self.input_names) and set(self.input_names) <= set(THETA_NAMES)

    @property
    def input_bounds(self) -> dict:
        return {}

    def case(self, point: Mapping[str, float]) -> dict:
        """The simulator case of one point (``input_names`` -> values)."""
        return build_case({**self.conditions, **{n: float(point[n]) for n in self.input_names}},
                          geometry=self.geometry, resolution=self.resolution, base=self.base)

    def evaluate(self, inputs: Mapping[str, Any], *, jacobian: bool = False, executor=None) -> ForwardBatch:
        """Simulate every point (see :class:`Forward`); ``executor`` reuses a running pool.

        ``executor`` is any object of :mod:`lvcore.campaigns.executors`
        (``submit``/``as_completed``); it is not closed.
        """
        if jacobian and not self.provides_jacobian:
            raise ForwardError(f"the simulator's adjoint Jacobian covers {list(THETA_NAMES)} only; "
                               f"this forward reads {list(self.input_names)}")
        cols, n = as_columns(inputs, self.input_names, self.label)
        cases = [self.case({k: cols[k][i] for k in self.input_names}) for i in range(n)]
        X = np.column_stack([cols[k] for k in self.input_names]) if self.input_names else np.zeros((n, 0))
        if executor is None and n > 1 and (self.scheduler or self.workers != 1):
            from lvcore.campaigns.executors import make_executor

            with make_executor(workers=self.workers, scheduler=self.scheduler) as ex:
                results = self._run(cases, jacobian, ex, X)
        else:
            results = self._run(cases, jacobian, executor, X)
        y, conv, msgs, jacs, secs = zip(*results)
        return ForwardBatch(np.stack(y), np.array(conv), tuple(msgs), np.stack(jacs) if jacobian else None,
                            np.array(secs))

    def _run(self, cases, jacobian, executor, X=None):
        if self.warm_start:
            return self._run_chained(cases, jacobian, executor, X)
        if executor is None:
            return [_simulate_point(c, self.input_names, jacobian) for c in cases]
        futures = [executor.submit(_simulate_point, c, self.input_names, jacobian) for c in cases]
        return [f.result() for f in futures]

    def _run_chained(self, cases, jacobian, executor, X):
        """Warm-started continuation chains over the batch (see ``warm_start``)."""
        from lvcore.campaigns import chains

        U = chains.scaled_coordinates(self.input_names, X)
        seeds = self._warm.setdefault("seeds", [])
        results: list = [None] * len(cases)

        def collect(rows):
            for r in rows:
                results[r.key] = r.result
                if r.state is not None:
                    seeds.append(chains.Seed(r.unit, r.state))

        if executor is None:
            order = chains.continuation_order(U)
            collect(_simulate_chunk(self.input_names, [cases[i] for i in order], list(map(int, order)), U[order],
                                    list(seeds[-chains.SEEDS_PER_CHUNK * 4:]), jacobian))
        else:
            def submit(positions, chunk_seeds):
                return executor.submit(_simulate_chunk, self.input_names, [cases[i] for i in positions], positions,
                                       U[positions], chunk_seeds, jacobian)

            chains.run_chains(executor, submit, U, workers=getattr(executor, "workers", 1), on_rows=collect,
                              seeds=seeds[-chains.DEFAULT_KEPT_STATES:])
        del seeds[:-WARM_KEPT_STATES]
        for i in range(max(0, len(seeds) - 1)):  # keep one factorised tangent in memory
            seeds[i] = chains.Seed(seeds[i].unit, chains.light_state(seeds[i].state))
        return results

    def evaluate_warm(self, point: Mapping[str, float], initial=None, *, jacobian: bool = False):
        """One point started from ``initial`` (a converged state of this forward, or None: cold).

        Returns ``(ForwardBatch of one point, state)``; ``state`` is None when the
        point did not converge. Used by campaign chains (:mod:`lvcore.campaigns.chains`).
        """
        cols, n = as_columns({k: point[k] for k in self.input_names}, self.input_names, self.label)
        if n != 1:
            raise ForwardError("evaluate_warm takes one point")
        warm = {"state": initial}
        y, ok, msg, jac, sec = _simulate_point(self.case({k: cols[k][0] for k in self.input_names}),
                                               self.input_names, jacobian, warm)
        batch = ForwardBatch(y[None], np.array([ok]), (msg,), None if jac is None else jac[None], np.array([sec]))
        return batch, (warm["state"] if ok else None)

    def __call__(self, params: Mapping[str, Any]) -> np.ndarray:
        """Outputs ``(25,)`` of one point; raises :class:`SolverError` if it fails. Not JAX-traceable."""
        if _is_traced(params):
            raise ForwardError("the FE simulator is not JAX-traceable (its sparse solves run on the host): "
                               "use an EmulatorForward for jax.grad/NUTS, or SimulatorForward.evaluate "
                               "(with jacobian=True for the adjoint gradient)")
        batch = self.evaluate({n: params[n] for n in self.input_names}).raise_on_failure()
        return batch.outputs[0]


# --------------------------------------------------------------------------- the emulator
@dataclass(frozen=True, eq=False)
class EmulatorForward(_JaxForward):
    """A trained emulator with fixed conditions bound in, as a :class:`Forward`.

    Parameters
    ----------
    emulator : lvcore.emulator.model.Emulator
        From :func:`lvcore.emulator.load_emulator`. Its one calling convention
        is used: ``emulator.apply(x)`` with ``x`` of shape ``(..., d)`` in the
        order of ``emulator.input_names`` (physical units), a pure, jittable
        JAX function returning ``(..., 25)``.
    conditions : mapping
        Fixed inputs by name (``h1..hk``; ``edp`` in mmHg and fibre angles in
        degrees for emulators that take them).
    input_names : tuple of str
        Inputs read at call time.
    label : str
    """

    emulator: Any
    conditions: Mapping[str, float]
    input_names: tuple[str, ...] = THETA_NAMES
    label: str = "emulator"

    def __post_init__(self):
        names = tuple(getattr(self.emulator, "input_names", ()) or ())
        if not names or not callable(getattr(self.emulator, "apply", None)):
            raise EmulatorError(f"{type(self.emulator).__name__} is not an emulator (needs input_names and apply); "
                                "load one with lvcore.emulator.load_emulator(name)")
        object.__setattr__(self, "input_names", tuple(self.input_names))
        object.__setattr__(self, "conditions", {str(k): float(v) for k, v in dict(self.conditions).items()})
        missing = [n for n in names if n not in self.input_names and n not in self.conditions]
        if missing:
            raise EmulatorError(f"emulator '{self.label}' needs inputs {missing} that are neither read nor fixed")
        extra = [n for n in self.input_names if n not in names]
        if extra:
            raise EmulatorError(f"emulator '{self.label}' has no input(s) {extra}; its inputs: {list(names)}")

    @property
    def base(self) -> str:
        """Basal boundary condition of the simulations the emulator was trained on."""
        return str(getattr(self.emulator, "base", "clamped"))

    @property
    def input_bounds(self) -> dict[str, tuple[float, float]]:
        """The emulator's training box over ``input_names`` (physical units).

        Calibration narrows its uniform priors to this box
        (:func:`lvcore.inference.models.prior_bounds`), so NUTS never asks
        the emulator to extrapolate.
        """
        names = tuple(self.emulator.input_names)
        return {n: (float(self.emulator.lower[names.index(n)]), float(self.emulator.upper[names.index(n)]))
                for n in self.input_names}

    def _vector(self, params):
        return jnp.stack([jnp.asarray(params[n] if n in self.input_names else self.conditions[n], dtype=jnp.float64)
                          for n in self.emulator.input_names], axis=-1)

    def __call__(self, params):
        return jnp.reshape(self.emulator.apply(self._vector(params)), (N_OUTPUTS,))

    def _check_box(self, x: np.ndarray) -> None:
        full = np.stack([x[:, self.input_names.index(n)] if n in self.input_names
                         else np.full(x.shape[0], self.conditions[n]) for n in self.emulator.input_names], axis=-1)
        check = getattr(self.emulator, "check_inputs", None)
        if check is not None:
            check(full)


def emulator_forward(
    emulator,
    h,
    *,
    infer_angles: bool = False,
    alpha_endo: float = DEFAULT_ALPHA_ENDO_DEG,
    alpha_epi: float = DEFAULT_ALPHA_EPI_DEG,
    edp_mmhg: float = DEFAULT_EDP_MMHG,
    name: str | None = None,
) -> EmulatorForward:
    """Bind a geometry (PC scores) and conditions into an emulator for calibration.

    Parameters
    ----------
    emulator : lvcore.emulator.model.Emulator
    h : array_like
        PC scores of the geometry; at least as many as the emulator uses.
    infer_angles : bool
        If True the fibre angles are inputs (read at call time); the emulator
        must take ``alpha_endo`` and ``alpha_epi``.
    alpha_endo, alpha_epi : float
        Fixed fibre angles (deg), used when the emulator takes them and
        ``infer_angles`` is False. Ignored by emulators trained at fixed angles.
    edp_mmhg : float
        End-diastolic pressure (mmHg), used when the emulator takes ``edp``.

    Raises
    ------
    EmulatorError
        If angles are to be inferred but the emulator was trained at fixed
        angles, if ``h`` is too short, or if the emulator lacks an input.
    """
    names = tuple(getattr(emulator, "input_names", ()))
    if not names:
        raise EmulatorError("emulator has no input_names; cannot bind conditions")
    label = name or getattr(emulator, "name", "emulator")
    if infer_angles and not set(ANGLE_NAMES) <= set(names):
        raise EmulatorError(
            f"emulator '{label}' was trained at fixed fibre angles (inputs {names}); "
            "use --angles fixed or an emulator with alpha_endo/alpha_epi inputs (e.g. 'angles')"
        )
    h = np.atleast_1d(np.asarray(h, dtype=float))
    n_pc = sum(1 for n in names if is_pc_name(n))
    if h.size < n_pc:
        raise EmulatorError(f"emulator '{label}' needs {n_pc} PC scores, got {h.size}")
    cond = {n: float(v) for n, v in zip(pc_names(n_pc), h[:n_pc])}
    cond.update({ANGLE_NAMES[0]: float(alpha_endo), ANGLE_NAMES[1]: float(alpha_epi), EDP_NAME: float(edp_mmhg)})
    input_names = THETA_NAMES + (ANGLE_NAMES if infer_angles else ())
    missing = [n for n in names if n not in input_names and n not in cond]
    if missing:
        raise EmulatorError(f"emulator '{label}' needs inputs {missing} that calibration cannot supply")
    cond = {k: v for k, v in cond.items() if k in names and k not in input_names}
    return EmulatorForward(emulator, cond, input_names, label)


def load_emulator_forward(name: str, h, **kwargs) -> EmulatorForward:
    """Load emulator ``name`` (:func:`lvcore.emulator.load_emulator`) and bind ``h`` and conditions.

    Never substitutes a stand-in: a missing emulator is an :class:`EmulatorError`
    telling how to build it. ``kwargs`` go to :func:`emulator_forward`.
    """
    from lvcore.emulator import load_emulator

    try:
        emulator = load_emulator(name)
    except EmulatorError:
        raise
    except (FileNotFoundError, OSError, KeyError) as err:
        raise EmulatorError(
            f"emulator '{name}' not found; build it with python scripts/build_emulators.py ({err})"
        ) from err
    return emulator_forward(emulator, h, name=name, **kwargs)


# --------------------------------------------------------------------------- closed-form stand-in
def _analytic_matrix() -> np.ndarray:
    """Fixed smooth loading of the 4 log-parameters onto the 24 regions (deterministic)."""
    r = np.arange(24)
    gamma = (r % 6) * np.pi / 3
    z = (r // 6) / 3.0
    return np.stack([
        1.0 + 0.3 * z,
        0.6 + 0.4 * np.cos(gamma),
        0.8 * np.sin(gamma + 0.5) + 0.3 * z,
        0.5 - 0.6 * z + 0.3 * np.cos(2 * gamma),
    ], axis=1)


@dataclass(frozen=True)
class AnalyticForward(_JaxForward):
    """SYNTHETIC closed-form stand-in forward model, for tests and benchmarks only.

    Smooth, differentiable and identifiable from 25 noisy outputs; it is not a
    model of the heart. With ``u = log(theta / theta_ref)``:
    ``LVV = 140 - 25 tanh(0.5 u_a + 0.3 u_b + 0.3 u_af + 0.2 u_bf)`` (mL) and
    ``strain_r = -0.15 + 0.04 sum_j M_rj u_j + 0.004 |u|^2`` with ``M`` a fixed
    smooth map over (sector, level). If ``alpha_endo``/``alpha_epi`` are in
    ``input_names`` they shift the strains linearly, by 0.02 per 30 degrees
    times fixed sector (alpha_endo) and level (alpha_epi) patterns that no
    change of theta can mimic.
    """

    theta_ref: tuple[float, float, float, float] = (0.6, 5.0, 1.5, 5.0)
    input_names: tuple[str, ...] = THETA_NAMES
    label: str = "analytic stand-in (SYNTHETIC, tests only)"

    @property
    def input_bounds(self) -> dict:
        return {}

    def __call__(self, params):
        u = jnp.stack([jnp.log(jnp.asarray(params[n]) / r) for n, r in zip(THETA_NAMES, self.theta_ref)])
        lvv = 140.0 - 25.0 * jnp.tanh(0.5 * u[0] + 0.3 * u[1] + 0.3 * u[2] + 0.2 * u[3])
        m = jnp.asarray(_analytic_matrix())
        strains = -0.15 + 0.04 * (m @ u) + 0.004 * jnp.sum(u**2)
        if ANGLE_NAMES[0] in self.input_names:
            r = jnp.arange(24)
            zz = (r // 6) / 3.0
            gg = (r % 6) * jnp.pi / 3
            # patterns orthogonal to every column of M and to a constant, so the angles are identifiable
            endo_pattern = jnp.sin(2.0 * gg)                 # sectors
            epi_pattern = 9.0 * (zz - 0.5) ** 2 - 1.25       # levels: +1, -1, -1, +1
            strains = strains + 0.02 * (params["alpha_endo"] + 60.0) / 30.0 * endo_pattern \
                + 0.02 * (params["alpha_epi"] - 60.0) / 30.0 * epi_pattern
        return jnp.concatenate([lvv[None], strains])


__all__ = [
    "Forward", "ForwardBatch", "SimulatorForward", "EmulatorForward", "AnalyticForward", "emulator_forward",
    "load_emulator_forward", "as_columns", "failure_reason", "CHAPTER_ANGLES", "CHAPTER_EDP",
]
