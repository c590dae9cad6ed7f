"""The simulator adapter: the FE simulator as a forward model of :mod:`lvcore.core.forward`.

:class:`SimulatorForward` runs :func:`lvcore.mechanics.simulate.simulate` on
the case :func:`lvcore.mechanics.case_inputs.build_case` writes for each point (outputs
only, a :class:`~lvcore.core.forward.Forward`); batches run in this process or
on the process pools of :mod:`lvcore.execution.parallel`. :class:`AdjointSimulatorForward`
reads material parameters only and adds their Jacobian from the adjoint
sensitivities (:mod:`lvcore.mechanics.sensitivities`): a
:class:`~lvcore.core.forward.JacobianForward`.

Importing this module registers the default campaign forward model
``"simulator"`` (:mod:`lvcore.core.registry`).
"""
from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, NamedTuple

import numpy as np

from lvcore.core.forward import ForwardBatch, as_columns, failure_reason, is_traced
from lvcore.core.registry import DEFAULT_FORWARD_NAME, register_forward
from lvcore.mechanics.case_inputs import build_case
from lvcore.exceptions import ForwardError
from lvcore.mechanics.simulate import simulate
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, N_OUTPUTS, THETA_NAMES
from lvcore.domain.outputs import strain_layer as canonical_strain_layer


class WarmState(NamedTuple):
    """A converged solve as a warm start: ``simulate(..., initial=)`` reads ``(u, p, tangent)``.

    ``values`` (:func:`case_values`) are the material parameters, fibre angles
    and pressure it was solved at, so that a failed warm start can continue
    through intermediate parameters (:func:`warm_continuation`). ``suspect``: the
    state is the cold solution of a point whose own warm Newton path was suspect
    (:func:`solve_warm`); a point started from it is solved cold too. A predicted
    start (:func:`lvcore.execution.chains.predicted_state`) keeps the nearest state's
    ``values`` and ``suspect``.
    """

    u: np.ndarray
    p: np.ndarray
    tangent: Any = None
    values: tuple | None = None
    suspect: bool = False


#: Material parameters interpolated geometrically by the continuation (positive), then the linear ones.
_LOG_FIELDS = (("material", "a"), ("material", "b"), ("material", "af"), ("material", "bf"))
_LIN_FIELDS = (("fibres", "alpha_endo"), ("fibres", "alpha_epi"), ("load", "pressure"))
#: Halvings of the parameter step a failed warm start may try before the cold solve (1: via the midpoint;
#: 2, with at most 8 iterations per warm attempt, lost more warm starts than it saved on a 200-point design).
CONTINUATION_DEPTH = 1
#: Newton iterations of each warm attempt (chord iterations included): the solver's default, so every warm
#: start that converged before still does.
WARM_MAX_ITERATIONS = 25
#: Newton settings of the warm attempts: no restart from zero load (the continuation or the cold solve follows).
_WARM_ONLY = None


def _warm_only_options():
    global _WARM_ONLY
    if _WARM_ONLY is None:
        from lvcore.mechanics.newton import NewtonOptions

        _WARM_ONLY = NewtonOptions(cold_fallback=False, max_iterations=WARM_MAX_ITERATIONS)
    return _WARM_ONLY


def case_values(case: Mapping) -> tuple | None:
    """``(a, b, af, bf, alpha_endo, alpha_epi, pressure)`` of a case dict (kPa, -, kPa, -, deg, deg, the case's
    pressure units), or None when it lacks one of them (another law, a box case)."""
    try:
        vals = tuple(float(case[s][k]) for s, k in _LOG_FIELDS + _LIN_FIELDS)
    except (KeyError, TypeError, ValueError):
        return None
    return vals if all(v > 0 for v in vals[:len(_LOG_FIELDS)]) else None


def _with_values(case: Mapping, values: tuple) -> dict:
    out = copy.deepcopy(dict(case))
    for (sec, key), v in zip(_LOG_FIELDS + _LIN_FIELDS, values):
        out[sec][key] = float(v)
    return out


def _midpoint(v0: tuple, v1: tuple) -> tuple:
    n = len(_LOG_FIELDS)
    return tuple(math.sqrt(x * y) if i < n else 0.5 * (x + y) for i, (x, y) in enumerate(zip(v0, v1)))


def _as_warm(result, values, suspect: bool = False) -> WarmState:
    u, p, tangent = result.warm_state
    return WarmState(u, p, tangent, values, suspect)


def warm_continuation(case: Mapping, initial, *, with_sensitivities: bool = False,
                      depth: int | None = None):
    """Solve ``case`` from a converged neighbour ``initial`` by a continuation in its parameters.

    A Newton warm start at full load from ``initial`` (a :class:`WarmState`);
    if it does not converge and ``initial`` knows its parameters, the
    midpoint between the two parameter sets (geometric for a, b, af, bf;
    arithmetic for the angles and the pressure) is solved warm first, and the
    case from there, halving again up to ``depth`` times. Each step is a
    warm start at full load (at most :data:`WARM_MAX_ITERATIONS` Newton
    iterations; default ``depth`` :data:`CONTINUATION_DEPTH`), so the path costs a few Newton iterations where
    a cold solve from zero load costs a dozen load steps on soft materials.

    Returns the :class:`~lvcore.mechanics.simulate.SimulationResult` of the
    case, ``converged`` False when no path converged (the caller then solves
    cold, see :func:`_simulate_point`); the converged solution satisfies the
    same tolerances as a cold solve.
    """
    depth = CONTINUATION_DEPTH if depth is None else int(depth)
    opts = _warm_only_options()
    r = simulate(case, with_sensitivities=with_sensitivities, options=opts, initial=initial)
    start, target = getattr(initial, "values", None), case_values(case)
    if r.converged or depth <= 0 or start is None or target is None:
        return r
    mid_values = _midpoint(start, target)
    mid = warm_continuation(_with_values(case, mid_values), initial, depth=depth - 1)
    if not mid.converged:
        return r
    return warm_continuation(case, _as_warm(mid, mid_values), with_sensitivities=with_sensitivities,
                             depth=depth - 1)


def continue_or_solve(case: Mapping, initial=None):
    """``case`` solved by :func:`warm_continuation` from ``initial`` (a :class:`WarmState`) where given, else, or
    when that does not converge, cold; the converged :class:`~lvcore.mechanics.simulate.SimulationResult`, or None
    when neither converged or the case was refused (:class:`~lvcore.exceptions.LVCoreError`).

    The step of a load path (:mod:`lvcore.campaigns.load_paths`, :func:`lvcore.inference.derived.fe_load_path`),
    without :func:`solve_warm`'s guard of warm results.
    """
    from lvcore.exceptions import LVCoreError

    try:
        res = None if initial is None else warm_continuation(case, initial)
        if res is None or not res.converged:
            res = simulate(case)
    except LVCoreError:
        return None
    return res if res.converged else None


def _simulate_point(case: dict, input_names: tuple[str, ...], jacobian: bool, warm: dict | None = None):
    """One simulator run -> ``(outputs (25,), converged, message, jacobian (25, p) or None, seconds)``.

    Runs in worker processes; never raises for a failing simulation. ``warm``
    (in-process only): a dict whose ``"state"`` warm-starts the solve
    (:func:`warm_continuation`, then a cold solve if that fails) and is
    replaced by this solve's :class:`WarmState` when it converges.
    """
    t0 = time.perf_counter()
    nan_jac = np.full((N_OUTPUTS, len(input_names)), np.nan) if jacobian else None
    try:
        initial = None if warm is None else warm.get("state")
        r = None
        if initial is not None:
            r = warm_continuation(case, initial, with_sensitivities=jacobian)
        if r is None or not r.converged:
            r = simulate(case, with_sensitivities=jacobian)
        if warm is not None and r.converged:
            warm["state"] = _as_warm(r, case_values(case))
        seconds = time.perf_counter() - t0
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


#: How :func:`solve_warm` solved a point: from zero load (no start given, or one in :func:`soft_corner`), warm
#: from the given start, or warm and then again cold (:attr:`WarmSolve.why`).
COLD, WARM, RESOLVED = "cold", "warm", "re-solved cold"
#: Why a point given a start was solved cold when its warm start failed (the solver's own cold fallback).
WARM_FAILED = "the warm start failed and the point was solved cold"


class WarmSolve(NamedTuple):
    """One point solved from a converged neighbour's state (:meth:`SimulatorForward.evaluate_warm`).

    ``batch``: its outputs (a :class:`~lvcore.core.forward.ForwardBatch` of one point); ``state``: its
    :class:`WarmState` (None unless converged); ``start``: :data:`COLD`, :data:`WARM` or :data:`RESOLVED`;
    ``why``: why a point given a start was solved cold ('' when its result is the warm start's or no start
    was given).
    """

    batch: ForwardBatch
    state: WarmState | None
    start: str = COLD
    why: str = ""


#: The soft corner of the θ box (kPa, at 8 mmHg), where the equilibrium is not unique: a point with ``a``
#: and ``af`` both below these is solved cold even when a start is given (:func:`soft_corner`). Measured
#: (``material`` space, default LV, ``fast`` mesh; each row warm-started six ways: from its three nearest
#: rows' cold states, their spline prediction and two noisy predictions): rows with a second equilibrium had
#: a <= 0.126 and af <= 0.102 kPa, cold tangents were indefinite up to a 0.143, af 0.111 kPa; none of 210 rows
#: with a or af above 0.2 kPa (the other down to 0.05) had one: 1,027 converged warm starts, all within 4.7e-9
#: relative of the cold solve (docs/reliability.md, "Reproducible campaigns").
SOFT_CORNER_KPA = {"a": 0.2, "af": 0.2}
#: The pressure the soft corner was measured at (mmHg); at higher pressures its bounds grow in proportion.
SOFT_CORNER_PRESSURE_MMHG = 8.0


def soft_corner(case: Mapping) -> str:
    """Why ``case`` is solved cold whatever start it is given ('' where a warm start may be used).

    There the equilibrium is not unique and which one Newton finds depends on where it starts:
    ``a`` and ``af`` both below :data:`SOFT_CORNER_KPA` at 8 mmHg, bounds scaled by ``max(1, pressure /
    8 mmHg)`` (the isotropic and fibre terms of the Holzapfel-Ogden law are linear in ``a`` and ``af``:
    the same strains under ``a, af, p`` as under ``ka, kaf, kp`` but for the fixed sheet terms). Cases
    without the four material parameters (:func:`case_values`) are never in it. Measured on the default
    LV with the chapter's fibre angles and a clamped base; other shapes, angles and bases are given the
    same bounds.
    """
    from lvcore.domain.units import mmhg_to_kpa
    from lvcore.mechanics.case import PRESSURE_UNITS

    vals = case_values(case)
    if vals is None:
        return ""
    try:
        p_kpa = float(case["load"]["pressure"]) * PRESSURE_UNITS[str(case["load"]["units"]).lower()]
    except (KeyError, TypeError, ValueError):
        return ""
    grow = max(1.0, p_kpa / mmhg_to_kpa(SOFT_CORNER_PRESSURE_MMHG))
    if vals[0] < SOFT_CORNER_KPA["a"] * grow and vals[2] < SOFT_CORNER_KPA["af"] * grow:
        return (f"in the soft corner (a, af < {SOFT_CORNER_KPA['a'] * grow:.3g}, "
                f"{SOFT_CORNER_KPA['af'] * grow:.3g} kPa), where the equilibrium is not unique")
    return ""


def solve_warm(case: dict, input_names: tuple[str, ...], jacobian: bool = False, initial=None):
    """One point from ``initial`` (a :class:`WarmState`, or None: cold), with the guard of warm results.

    Returns ``(result, state, start, why)``: ``result`` as :func:`_simulate_point` (``seconds``: all
    its solves), ``state`` its :class:`WarmState` (None unless converged), ``start`` :data:`COLD`,
    :data:`WARM` or :data:`RESOLVED`, ``why`` why a point given a start was solved cold.

    A warm result is kept only where it equals the cold solve, whatever the start and the rounding:

    * a point in :func:`soft_corner` (the equilibrium is not unique there) is solved cold at once;
    * a warm result whose Newton path is suspect (:func:`lvcore.execution.chains.warm_path_problem`)
      is solved again cold, and so is one started from a ``suspect`` state; the cold state of a point
      re-solved for its own path is marked ``suspect`` (:func:`lvcore.execution.chains.passes_suspicion`);
    * a warm start that failed is solved cold by :func:`_simulate_point` (:data:`WARM_FAILED`).

    Used by :meth:`SimulatorForward.evaluate_warm` (campaign chains, the subject emulators' runs) and
    by a warm-starting :class:`SimulatorForward`'s batches.
    """
    from lvcore.execution import chains
    from lvcore.mechanics.newton import recorded_solves

    t0 = time.perf_counter()
    why = "" if initial is None else soft_corner(case)
    if initial is None or why:
        warm = {"state": None}
        res = _simulate_point(case, input_names, jacobian, warm)
        return res, warm["state"] if res[1] else None, COLD, why
    warm = {"state": initial}
    with recorded_solves() as log:
        res = _simulate_point(case, input_names, jacobian, warm)
    if not res[1]:
        return res, None, WARM, ""
    if log and not log[-1].warm_converged:
        why = WARM_FAILED
    else:
        why = chains.warm_path_problem(log) or (chains.SEED_RESOLVED if getattr(initial, "suspect", False) else "")
        if why:
            warm = {"state": None}
            res = _simulate_point(case, input_names, jacobian, warm)
    res = (*res[:4], time.perf_counter() - t0)
    state = warm["state"] if res[1] else None
    if state is not None and chains.passes_suspicion(why):
        state = state._replace(suspect=True)
    return res, state, RESOLVED if why else WARM, why


def _simulate_chunk(input_names, cases, keys, units, seeds, jacobian):
    """Worker task: ``cases`` in order, each warm-started from the nearest converged state (a chain chunk).

    Returns :class:`lvcore.execution.chains.ChainRow` objects whose results are :func:`_simulate_point`
    tuples with two more items, the ``start`` and ``why`` of :func:`solve_warm` (which guards each point).
    """
    from lvcore.execution.chains import solve_in_order

    by_key = dict(zip(keys, cases))

    def solve(key, initial):
        res, state, start, why = solve_warm(by_key[key], input_names, jacobian, initial)
        return (*res, start, why), state

    return solve_in_order(keys, units, seeds, solve)


#: Converged states a warm-starting SimulatorForward keeps between batches.
WARM_KEPT_STATES = 64


@dataclass(frozen=True, eq=False)
class SimulatorForward:
    """The FE simulator (:func:`lvcore.simulate`) as a :class:`~lvcore.core.forward.Forward` (outputs only).

    Each point's named inputs, merged with ``conditions``, go through
    :func:`lvcore.mechanics.case_inputs.build_case` on ``geometry`` at ``resolution``.

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
    strain_layer : str
        The wall layer of the strains (:data:`lvcore.domain.outputs.STRAIN_LAYERS`; default the inner half).
    workers : int, optional
        Batches of more than one point run on a local process pool of this
        many workers (:class:`lvcore.execution.parallel.LocalExecutor`;
        ``None``: one per core). ``1`` (default) runs them in this process.
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a Dask scheduler for batches (overrides ``workers``).
    label : str
    warm_start : bool
        Every point starts Newton at full load from the nearest converged
        state (:func:`lvcore.mechanics.newton.solve`), which saves most of the
        load stepping: a batch is ordered into continuation chains
        (:mod:`lvcore.execution.chains`), in this process or split across the executor's
        workers, and the forward keeps its last converged states to start
        later batches (a sequence of nearby points: an SQP, a line search, BO
        iterations). A failed warm start falls back to a cold solve, and the
        result satisfies the same tolerances. Without it every point is solved
        cold.

    Notes
    -----
    The simulator is not JAX-traceable. Its Jacobian (adjoint sensitivities,
    material parameters only) is :class:`AdjointSimulatorForward`'s.
    """

    input_names: tuple[str, ...] = THETA_NAMES
    conditions: Mapping[str, float] = field(default_factory=dict)
    geometry: Mapping | None = None
    resolution: str = "default"
    base: str = "clamped"
    strain_layer: str = DEFAULT_STRAIN_LAYER
    workers: int | None = 1
    scheduler: str | None = None
    label: str = "FE simulator"
    warm_start: bool = False
    _warm: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "input_names", tuple(str(n) for n in self.input_names))
        object.__setattr__(self, "conditions", {str(k): float(v) for k, v in dict(self.conditions).items()})
        try:
            object.__setattr__(self, "strain_layer", canonical_strain_layer(self.strain_layer))
        except ValueError as err:
            raise ForwardError(f"simulator forward: {err}") from None
        both = sorted(set(self.input_names) & set(self.conditions))
        if both:
            raise ForwardError(f"simulator forward: {both} are both inputs and fixed conditions")
        # fail now, not per point, on names the case builder does not know
        probe = {**{n: 1.0 for n in THETA_NAMES}, **self.conditions, **{n: 0.0 for n in self.input_names}}
        probe.update({n: 1.0 for n in THETA_NAMES if n in self.input_names})
        build_case(probe, geometry=self.geometry, resolution=self.resolution, base=self.base,
                   strain_layer=self.strain_layer)

    def __getstate__(self):
        # the kept warm-start states stay in this process (a pickled copy, e.g. sent to a worker, starts empty)
        return {k: v for k, v in self.__dict__.items() if k != "_warm"}

    def __setstate__(self, state):
        self.__dict__.update(state)
        object.__setattr__(self, "_warm", {})

    @property
    def input_bounds(self) -> dict:
        return {}

    def case(self, point: Mapping[str, float]) -> dict:
        """The simulator case of one point (``input_names`` -> values)."""
        return build_case({**self.conditions, **{n: float(point[n]) for n in self.input_names}},
                          geometry=self.geometry, resolution=self.resolution, base=self.base,
                          strain_layer=self.strain_layer)

    def evaluate(self, inputs: Mapping[str, Any], *, executor=None) -> ForwardBatch:
        """Simulate every point (see :class:`~lvcore.core.forward.Forward`); ``executor`` reuses a running pool.

        ``executor`` is any object of :mod:`lvcore.execution.parallel`
        (``submit``/``as_completed``); it is not closed.
        """
        return self._batch(inputs, False, executor)

    def _batch(self, inputs: Mapping[str, Any], jacobian: bool, executor) -> ForwardBatch:
        cols, n = as_columns(inputs, self.input_names, self.label)
        cases = [self.case({k: cols[k][i] for k in self.input_names}) for i in range(n)]
        X = np.column_stack([cols[k] for k in self.input_names]) if self.input_names else np.zeros((n, 0))
        if executor is None and n > 1 and (self.scheduler or self.workers != 1):
            from lvcore.execution.parallel import make_executor

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
        """Warm-started continuation chains over the batch (see ``warm_start``); each point is guarded by
        :func:`solve_warm`, and points re-solved cold are counted in :attr:`resolved_cold`."""
        from lvcore.execution import chains

        U = chains.scaled_coordinates(self.input_names, X)
        seeds = self._warm.setdefault("seeds", [])
        resolved = self._warm.setdefault("resolved", [])
        results: list = [None] * len(cases)

        def collect(rows):
            for r in rows:
                *result, start, why = r.result
                results[r.key] = tuple(result)
                if start == RESOLVED:
                    resolved.append(why)
                if r.state is not None and not r.state.suspect:  # later batches never start there
                    seeds.append(chains.Seed(r.unit, r.state))

        if executor is None:
            order = chains.continuation_order(U)
            collect(_simulate_chunk(self.input_names, [cases[i] for i in order], list(map(int, order)), U[order],
                                    list(seeds[-chains.SEEDS_PER_CHUNK * 4:]), jacobian))
        else:
            def submit(positions, chunk_seeds):
                return executor.submit(_simulate_chunk, self.input_names, [cases[i] for i in positions], positions,
                                       U[positions], chunk_seeds, jacobian)

            try:
                chains.run_chains(executor, submit, U, workers=getattr(executor, "workers", 1), on_rows=collect,
                                  seeds=seeds[-chains.DEFAULT_KEPT_STATES:])
            except chains.ChainTaskError as err:
                raise err.__cause__ or err from None
        del seeds[:-WARM_KEPT_STATES]
        for i in range(max(0, len(seeds) - 1)):  # keep one factorised tangent in memory
            seeds[i] = chains.Seed(seeds[i].unit, chains.light_state(seeds[i].state))
        return results

    @property
    def resolved_cold(self) -> tuple[str, ...]:
        """Why each warm-started point so far was re-solved cold (its warm result was suspect or its warm start
        failed), in order; points solved cold at once (:func:`soft_corner`) are not listed."""
        return tuple(self._warm.get("resolved", ()))

    def evaluate_warm(self, point: Mapping[str, float], initial=None) -> WarmSolve:
        """One point started from ``initial`` (a converged state of this forward, or None: cold).

        Returns a :class:`WarmSolve` (the outputs, the state, how the point was solved and why it was
        solved cold if given a start): :func:`solve_warm`, which keeps a warm result only where it equals
        the cold solve. Used by campaign chains (:mod:`lvcore.execution.chains`) and the subject
        emulators' FE runs.
        """
        cols, n = as_columns({k: point[k] for k in self.input_names}, self.input_names, self.label)
        if n != 1:
            raise ForwardError("evaluate_warm takes one point")
        (y, ok, msg, _, sec), state, start, why = solve_warm(self.case({k: cols[k][0] for k in self.input_names}),
                                                             self.input_names, False, initial)
        return WarmSolve(ForwardBatch(y[None], np.array([ok]), (msg,), None, np.array([sec])), state, start, why)

    def __call__(self, params: Mapping[str, Any]) -> np.ndarray:
        """Outputs ``(25,)`` of one point; raises :class:`SolverError` if it fails. Not JAX-traceable."""
        if is_traced(params):
            raise ForwardError("the FE simulator is not JAX-traceable (its sparse solves run on the host): "
                               "use an EmulatorForward for jax.grad/NUTS, or SimulatorForward.evaluate "
                               "(AdjointSimulatorForward.jacobian for the adjoint gradient)")
        batch = self.evaluate({n: params[n] for n in self.input_names}).raise_on_failure()
        return batch.outputs[0]


@dataclass(frozen=True, eq=False)
class AdjointSimulatorForward(SimulatorForward):
    """The FE simulator with its adjoint Jacobian: a :class:`~lvcore.core.forward.JacobianForward`.

    As :class:`SimulatorForward`, but every input must be a material parameter (``a, b, af, bf``): the adjoint
    sensitivities (:mod:`lvcore.mechanics.sensitivities`) exist for those only.
    """

    label: str = "FE simulator (adjoint Jacobian)"

    def __post_init__(self):
        super().__post_init__()
        if not self.input_names or not set(self.input_names) <= set(THETA_NAMES):
            raise ForwardError(f"the simulator's adjoint Jacobian covers {list(THETA_NAMES)} only; "
                               f"this forward reads {list(self.input_names)} (use SimulatorForward)")

    def jacobian(self, inputs: Mapping[str, Any], *, executor=None) -> ForwardBatch:
        """Outputs and ``d outputs / d inputs`` (adjoint) of every point; ``executor`` as in :meth:`evaluate`."""
        return self._batch(inputs, True, executor)


def simulator_factory(space, resolution: str) -> SimulatorForward:
    """The default campaign forward model: the simulator over ``space`` at ``resolution`` (fixed inputs bound in)."""
    return SimulatorForward(input_names=space.names, conditions=space.fixed_dict(), resolution=resolution,
                            base=space.base)


register_forward(DEFAULT_FORWARD_NAME, simulator_factory)

__all__ = ["SimulatorForward", "AdjointSimulatorForward", "simulator_factory", "WarmSolve", "solve_warm", "soft_corner",
           "continue_or_solve"]
