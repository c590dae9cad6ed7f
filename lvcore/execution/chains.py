"""Continuation chains: a batch of solves ordered so that each one warm-starts from a neighbour's solution.

A campaign, a Bayesian-optimisation design or a sweep solves hundreds of
nearby points on one geometry. A cold solve climbs the load in steps with a
fresh tangent on most Newton iterations; a solve started at full load from the
converged state of a nearby point (``simulate(initial=...)``, see
:func:`lvcore.mechanics.newton.solve`) needs a few chord iterations. This
module turns a batch into such warm-started work:

* :func:`continuation_order` orders the points (in scaled, unit-cube-like
  coordinates) along a depth-first walk of their Euclidean minimum spanning
  tree, so consecutive points are near neighbours;
* :func:`solve_in_order` runs one task's points in that order, each starting
  from the nearest converged state among the task's earlier points and the
  *seeds* it was given, moved by a linear fit over the nearest ones
  (:func:`predicted_state`; a point whose warm start fails is solved cold by
  the solver itself, so a poor neighbour costs time, never the result);
* :func:`run_chains` splits the order into contiguous chains, at least two per
  worker so no core waits on the driver, and feeds each chain to the executor
  in chunks of ``chunk`` points. The next chunk of a chain is submitted as soon
  as the previous one returns, seeded with the nearest converged states the
  driver holds. When a chain runs dry, the longest remaining one is split in
  two so both cores stay busy until the end.

Results reach the caller chunk by chunk (a campaign records each row as it
arrives), so killing a run loses only the chunks in flight, and a resumed run
chains whatever is still pending.

Forward models opt in by providing ``evaluate_warm(point, initial)``
returning ``(ForwardBatch of one point, state or None, start, why)``: how the
point was solved (``"cold"``, ``"warm"`` or ``"re-solved cold"``) and why it was
solved cold although a start was given (the FE simulator does, with its guard:
:func:`lvcore.mechanics.forward.solve_warm`); others are evaluated point by
point, cold, in the same order.
"""
from __future__ import annotations

import functools
import math
import time
from collections import abc
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Sequence

import numpy as np

#: Points per task: large enough that the driver's round trip is small against the solves, small enough
#: that a killed run loses little and the chains rebalance at the end.
DEFAULT_CHUNK = 12
#: Converged states the driver keeps to seed new chunks (the most recent ones).
DEFAULT_KEPT_STATES = 256
#: Seeds sent with each chunk (nearest to its points): as many as the spline predictor uses.
SEEDS_PER_CHUNK = 60
#: Chains per worker: two, so a worker always has a queued chunk while the driver handles the other's result.
CHAINS_PER_WORKER = 2


class ChainTaskError(RuntimeError):
    """A chunk's task failed in the executor (not a failed solve: those are results)."""


@dataclass(frozen=True)
class Seed:
    """A converged state offered as a warm start: its scaled coordinates, the solver state and (optionally)
    the key of the point it was solved for (reported as :attr:`ChainRow.seed` of the rows it starts)."""

    unit: np.ndarray
    state: Any
    key: int | None = None


@dataclass(frozen=True)
class ChainRow:
    """One solved point of a task: its key (row index), scaled coordinates, result and state (None if failed).

    ``warm``: it was started from a converged state; ``seed``: the key of that state's point (the nearest
    of the predictor's neighbours; None when cold or the seed had no key). ``chain`` and ``position``: the
    chain of :func:`run_chains` that solved it and its place in that chain (-1 outside ``run_chains``).
    """

    key: int
    unit: np.ndarray
    result: Any
    state: Any = None
    warm: bool = False
    seed: int | None = None
    chain: int = -1
    position: int = -1


def continuation_order(U: np.ndarray, k: int = 10) -> np.ndarray:
    """A permutation of the rows of ``U`` (n, d) that walks between near neighbours.

    Depth-first (preorder) walk of the Euclidean minimum spanning tree of a
    ``k``-nearest-neighbour graph, children visited nearest first; components
    of that graph (rare) are walked one after another, each from its point
    nearest the end of the previous walk.

    Parameters
    ----------
    U : (n, d) array
        Points in scaled coordinates (comparable units per column, e.g. the unit cube of a design space).
    k : int
        Neighbours per point in the graph whose spanning tree is walked.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
    from scipy.spatial import cKDTree

    U = np.asarray(U, dtype=float)
    n = U.shape[0]
    if n <= 2:
        return np.arange(n)
    kk = min(k, n - 1)
    tree = cKDTree(U)
    dist, nb = tree.query(U, kk + 1)
    rows = np.repeat(np.arange(n), kk)
    d = dist[:, 1:].ravel()
    # zero distances (duplicate points) would vanish from a sparse graph: keep them as tiny edges
    d = np.where(d > 0, d, 1e-300)
    g = coo_matrix((d, (rows, nb[:, 1:].ravel())), shape=(n, n)).tocsr()
    g = g.maximum(g.T)
    mst = minimum_spanning_tree(g)
    mst = (mst + mst.T).tocsr()
    n_comp, labels = connected_components(mst, directed=False)
    seen = np.zeros(n, bool)
    order: list[int] = []
    start = 0
    for _ in range(n_comp):
        stack = [start]
        while stack:
            v = stack.pop()
            if seen[v]:
                continue
            seen[v] = True
            order.append(v)
            lo, hi = mst.indptr[v], mst.indptr[v + 1]
            nbrs, w = mst.indices[lo:hi], mst.data[lo:hi]
            for j in nbrs[np.argsort(-w)]:  # pushed farthest first: the nearest is walked next
                if not seen[j]:
                    stack.append(int(j))
        rest = np.flatnonzero(~seen)
        if rest.size:
            start = int(rest[np.argmin(np.linalg.norm(U[rest] - U[order[-1]], axis=1))])
    return np.asarray(order, dtype=np.int64)


def _doubled(a: np.ndarray) -> np.ndarray:
    return np.concatenate([a, np.zeros_like(a)])


class SeedPool(abc.Sequence):
    """Seeds (a sequence of :class:`Seed`) with their coordinates, and the solutions of their states, stacked.

    What :func:`predicted_state` reads of a chain's converged states on every warm start: the
    coordinates of all of them (distances) and the solutions ``u``, ``p`` of the nearest ~60
    (the fit). Kept as rows of arrays grown in place (capacity doubled), those are one
    vectorised distance and one row gather instead of a Python loop over the states and an
    array built from ~60 separate ones (default LV, 1,000-point θ design: the predictor's
    2.4 ms per warm start in a chain, half of it that gathering). A state has a solution when
    it is a named tuple with arrays ``u`` and ``p`` (a :class:`~lvcore.mechanics.forward.WarmState`)
    of the same shapes as the first such state's; others are offered as they are.
    """

    def __init__(self, seeds: Sequence[Seed] = ()):
        self._seeds: list[Seed] = []
        self._units = self._u = self._p = self._solved = None
        self._p_shape = None
        for seed in seeds:
            self.append(seed)

    def __len__(self) -> int:
        return len(self._seeds)

    def __getitem__(self, i):
        return self._seeds[i]

    def __setitem__(self, i: int, seed: Seed) -> None:
        """Replace a seed by one of the same point and solution (e.g. its state without the factorised tangent)."""
        self._seeds[i] = seed

    def append(self, seed: Seed) -> None:
        n = len(self._seeds)
        unit = np.asarray(seed.unit, dtype=float).ravel()
        st = seed.state
        solved = hasattr(st, "_replace") and isinstance(getattr(st, "u", None), np.ndarray) \
            and isinstance(getattr(st, "p", None), np.ndarray)
        if self._units is None:
            self._units, self._solved = np.zeros((8, unit.size)), np.zeros(8, bool)
        if solved and self._u is None:
            self._u, self._p = np.zeros((len(self._solved), st.u.size)), np.zeros((len(self._solved), st.p.size))
            self._p_shape = np.shape(st.p)
        solved = solved and st.u.size == self._u.shape[1] and np.shape(st.p) == self._p_shape
        if n == len(self._solved):  # full: every array doubles (new rows zero)
            self._units, self._solved = _doubled(self._units), _doubled(self._solved)
            if self._u is not None:
                self._u, self._p = _doubled(self._u), _doubled(self._p)
        self._units[n], self._solved[n] = unit, solved
        if solved:
            self._u[n], self._p[n] = st.u.ravel(), np.ravel(st.p)
        self._seeds.append(seed)

    @property
    def units(self) -> np.ndarray:
        """(n, d) coordinates of the seeds."""
        return self._units[:len(self._seeds)] if self._seeds else np.zeros((0, 0))

    @property
    def solved(self) -> np.ndarray:
        """(n,) whether each seed's state has a solution ``u``, ``p`` the predictor can use."""
        return self._solved[:len(self._seeds)] if self._seeds else np.zeros(0, bool)

    def combine(self, rows, weights) -> tuple[np.ndarray, np.ndarray]:
        """``Σ_j weights[j] u_{rows[j]}`` and the same of the raveled ``p``, over the given (solved) seeds.

        Where the rows are most of the pool, one product with the whole stack (zero weights
        elsewhere; the rows of seeds without a solution are zeros) reads less memory than
        gathering them first (0.11 against 0.21 ms for 59 of 72 default-LV solutions, caches cold).
        """
        n = len(self._seeds)
        if 2 * len(rows) >= n:
            full = np.zeros(n)
            full[rows] = weights
            return full @ self._u[:n], full @ self._p[:n]
        return weights @ self._u[rows], weights @ self._p[rows]


def nearest_state(unit: np.ndarray, candidates: Sequence[Seed]):
    """The state of the candidate nearest ``unit``, or None when there is none."""
    if not candidates:
        return None
    return candidates[int(_by_distance(unit, np.array([c.unit for c in candidates], dtype=float))[0])].state


def _by_distance(unit: np.ndarray, units: np.ndarray) -> np.ndarray:
    """Indices of the rows of ``units`` (n, d), nearest ``unit`` first (ties in their given order)."""
    return np.argsort(np.sum((units - unit) ** 2, axis=1), kind="stable")


#: Converged neighbours the linear predictor fits (:func:`predicted_state`), at least; it uses
#: ``dimension + 4`` where that is more, and needs ``dimension + 2``.
PREDICTOR_NEIGHBOURS = 8
#: Largest neighbourhood of the spline predictor: it needs twice as many neighbours as a full quadratic in
#: the scaled coordinates has coefficients (30 in 4-D), so it is used up to 4-D when that many states are at
#: hand, through the nearest ``QUADRATIC_MAX_NEIGHBOURS`` of them.
QUADRATIC_MAX_NEIGHBOURS = 60


@functools.lru_cache(maxsize=None)
def _pairs(d: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(d)`` (kept: called for every warm start, ~0.1 ms each)."""
    return np.triu_indices(d)


def _quadratic_features(Z: np.ndarray) -> np.ndarray:
    """Rows ``(1, z_i, z_i z_j (i ≤ j))`` of a full quadratic in the columns of ``Z`` (m, d)."""
    i, j = _pairs(Z.shape[1])
    return np.hstack([np.ones((Z.shape[0], 1)), Z, Z[:, i] * Z[:, j]])


def _spline_weights(Z: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Weights ``w`` (m,) such that ``Σ w_i y_i`` is the polyharmonic spline through ``(Z_i, y_i)`` at ``z``.

    The spline is ``Σ c_i |x − Z_i|⁵`` plus a full quadratic, with the c orthogonal to the
    quadratics (the kernel is conditionally positive definite of order 3, so the system is
    non-singular when the points determine a quadratic); it interpolates every ``y_i`` and
    reproduces quadratics exactly. A point closer than ``1e-3`` (in the units of ``Z``) to an
    earlier one (a repeated design point) gets weight zero: interpolating two states that differ
    only by solver round-off through almost the same point would amplify that round-off.
    """
    m = Z.shape[0]
    # squared distances between the points and to z, one array (the spline's kernel, r⁵, from them)
    Zz = np.vstack([Z, z])
    sq = np.einsum("ij,ij->i", Zz, Zz)
    R2 = np.maximum(sq[:, None] + sq[None, :m] - 2.0 * (Zz @ Z.T), 0.0)  # (m + 1, m): the last row to z
    R2, r2 = R2[:m], R2[m]
    keep = np.ones(m, dtype=bool)
    if np.any(np.triu(R2 < 1e-6, k=1)):
        for j in range(1, m):
            keep[j] = not np.any(R2[j, :j][keep[:j]] < 1e-6)
        Z, R2, r2 = Z[keep], R2[np.ix_(keep, keep)], r2[keep]
        Zz = np.vstack([Z, z])
    n = Z.shape[0]
    P = _quadratic_features(Zz)  # the points' rows, then z's
    M = np.zeros((n + P.shape[1],) * 2)
    M[:n, :n] = R2 * R2 * np.sqrt(R2)
    M[:n, n:], M[n:, :n] = P[:n], P[:n].T
    rhs = np.concatenate([r2 * r2 * np.sqrt(r2), P[n]])
    try:
        sol = np.linalg.solve(M, rhs)
    except np.linalg.LinAlgError:  # too few distinct points for a quadratic: the least-squares solution
        sol = np.linalg.lstsq(M, rhs, rcond=None)[0]
    w = np.zeros(m)
    w[keep] = sol[:n]
    return w


def predicted_state(unit: np.ndarray, candidates: Sequence[Seed], k: int | None = None):
    """The nearest candidate's state with its solution moved by a local fit over the nearest neighbours.

    Each converged neighbour ``i`` gives ``(x_i, u_i)`` (scaled coordinates, solution). With at least
    ``2 × (1 + d + d(d+1)/2)`` neighbours at hand (30 in 4-D), the polyharmonic spline through the
    nearest :data:`QUADRATIC_MAX_NEIGHBOURS` or fewer (``r⁵`` plus a full quadratic, :func:`_spline_weights`)
    predicts the solution at ``unit`` (exact for quadratics, like the least-squares quadratic it replaced,
    but interpolating the nearest states instead of averaging over farther ones); otherwise the
    least-squares plane through the nearest ``x_0`` over the nearest ``max(8, d + 4)`` (second order; the
    nearest state alone: first order). Newton then starts closer and needs fewer chord iterations
    (``default`` mesh, 1,000-point θ design, points 100–400 of one chain predicted from the earlier ones:
    median relative displacement error 5.9e-2 (nearest), 2.8e-3 (least-squares quadratic over 30),
    1.3e-3 / 1.1e-3 / 9.0e-4 (spline over 30 / 40 / 60); ``--chain-profile 300``: 4.59 → 3.73 Newton
    iterations and 4.71 → 3.85 residuals per warm solve, spline over 60 against least-squares quadratic
    over 30). States other than a
    :class:`~lvcore.mechanics.forward.WarmState` (arrays ``u`` and ``p``), fewer than ``d + 2`` of them,
    or a point farther from the nearest than every fitted neighbour is (an extrapolation) give the nearest
    state unchanged. ``k`` fixes the number of neighbours of the plane (and disables the spline).

    The plane and the nearest state carry the newest factorised tangent (chord iterations on it: cheap
    where neighbours are close, as in a sweep). The spline (before it, a quadratic fit), used where a
    design fills the space around the point, carries none: there the neighbours' parameters differ too much for a chord on
    their tangent (1,000-point θ design, ``default`` mesh: it contracted well enough in 6 % of the warm
    starts), and Newton's first iteration takes a fresh tangent at once (``--chain-profile 150``: 4.65
    instead of 5.33 iterations, 5.70 instead of 6.40 residuals, 1.07 instead of 0.99 tangents per
    solve; 5–6 % less time).
    """
    return _predicted(unit, candidates, k)[0]


def _predicted(unit: np.ndarray, candidates: Sequence[Seed], k: int | None = None):
    """:func:`predicted_state` and the index (into ``candidates``) of the nearest candidate, its base (None: none)."""
    if not candidates:
        return None, None
    pool = candidates if isinstance(candidates, SeedPool) else SeedPool(candidates)
    dim = np.size(unit)
    n_quad = 2 * (1 + dim + dim * (dim + 1) // 2)
    quadratic = k is None and n_quad <= min(len(pool), QUADRATIC_MAX_NEIGHBOURS)
    n_near = min(len(pool), QUADRATIC_MAX_NEIGHBOURS) if quadratic else (k or max(PREDICTOR_NEIGHBOURS, dim + 4))
    near = _by_distance(unit, pool.units)[:n_near]
    nearest = int(near[0])
    base = pool[nearest].state
    usable = near[pool.solved[near]]
    if len(usable) < dim + 2 or usable[0] != near[0]:
        return base, nearest
    quadratic = quadratic and len(usable) == len(near)
    X = pool.units[usable[1:]] - pool.units[usable[0]]  # (m, d)
    step = np.asarray(unit, dtype=float) - pool.units[usable[0]]
    radius = np.max(np.linalg.norm(X, axis=1))
    if np.linalg.norm(step) > radius:
        return base, nearest  # beyond the neighbours: an extrapolated fit can be worse than the nearest state
    # the fit evaluated at ``unit`` is a fixed combination of the neighbours' offsets from the nearest
    # state, Σ_j w_j (y_j − y_0): its weights come from the small design matrix (the pseudo-inverse of the
    # plane's, the spline's system), applied to the states without forming the offsets (~1.6 ms less per
    # warm start at the default LV than solving for every coefficient of every degree of freedom)
    if quadratic:  # through the nearest state too (its row: zero offset), coordinates scaled to O(1)
        weights = _spline_weights(np.vstack([np.zeros(dim), X]) / radius, step / radius)[1:]
    else:
        weights = step @ np.linalg.pinv(X, rcond=1e-6)
    du, dp = pool.combine(usable[1:], weights)
    u = base.u + du - weights.sum() * base.u
    p = np.ravel(base.p) + dp - weights.sum() * np.ravel(base.p)
    tangent = None
    if not quadratic:  # a sparse neighbourhood (a sweep): chord iterations on the newest factorised tangent
        tangent = base.tangent or next((c.state.tangent for c in reversed(pool)
                                        if getattr(c.state, "tangent", None)), None)
    return base._replace(u=u, p=p.reshape(np.shape(base.p)), tangent=tangent), nearest


#: A warm-started row's result is trusted (not re-solved cold) only if its one Newton solve converged from
#: the predicted state within this many iterations (``material`` space, ``fast`` mesh, 800-row Sobol design,
#: one chain: median 8, 90th percentile 13, 99th 18; 3.6 % of the rows took more; the row found on another
#: equilibrium with a positive definite tangent took 20).
WARM_TRUSTED_ITERATIONS = 15
#: Why a row was re-solved cold when only its seed row was (it does not pass the suspicion on).
SEED_RESOLVED = "its seed row was re-solved cold"


def warm_path_problem(log) -> str:
    """Why the result of a warm-started row must not be trusted to equal its cold solve ('' if it may be).

    ``log``: the :class:`~lvcore.mechanics.newton.SolveRecord` of every Newton solve of the row
    (:func:`lvcore.mechanics.newton.recorded_solves`), in order. A warm result is trusted when it came
    from one Newton solve at full load from the predicted state (no failed attempt and continuation
    through a midpoint) in at most :data:`WARM_TRUSTED_ITERATIONS` iterations, to a state whose last
    tangent was positive definite (:func:`~lvcore.mechanics.newton.tangent_definite`: a stable
    equilibrium). Damped line-search steps (12 % of the rows of that design) and the distance from the
    predicted state (median 5 %, 90th percentile 25 %) did not tell the rows that found another
    equilibrium from the others.

    Where it is not, the equilibrium may not be unique and the start decides which one Newton finds:
    on the soft corner of the ``material`` space (a, af ≲ 0.15 kPa) the cold load path needs many
    step cuts or stops, tangents turn indefinite, and warm starts from neighbours converged to other
    equilibria, 1–4 % apart in strain (0.01–0.03 mL in LVV), with clean-looking Newton paths
    as well as rescued ones. Rows whose result came from a cold solve (the forward model's own cold
    fallback) and forward models without Newton solves (an empty log) are never suspect. The look of
    a path is not a proof: a clean-looking path reached another equilibrium there too where the
    rounding changed (XLA at -O0), so the simulator solves that corner cold whatever the path
    (:func:`lvcore.mechanics.forward.soft_corner`); elsewhere this judgement costs time, not results.
    Used by the simulator's one guarded warm solve, :func:`lvcore.mechanics.forward.solve_warm`
    (campaign chains, warm-starting :class:`~lvcore.mechanics.forward.SimulatorForward` batches, the
    subject emulators' runs).
    """
    if not log:
        return ""
    last = log[-1]
    if not (last.warm_converged and last.converged):
        return ""  # a cold solve's result (or a failure): what the cold run records
    if len(log) > 1:
        return "the warm start failed and was continued through intermediate parameters"
    if last.definite is not True:
        return "the converged state is not a stable equilibrium (indefinite tangent)" if last.definite is False \
            else "the stability of the converged state cannot be told (no positive definite factorisation)"
    if last.iterations > WARM_TRUSTED_ITERATIONS:
        return f"{last.iterations} Newton iterations from the predicted state (more than {WARM_TRUSTED_ITERATIONS})"
    return ""


def passes_suspicion(why: str) -> bool:
    """Whether a row re-solved cold for ``why`` makes the rows started from its state suspect: re-solved for
    its own Newton path, not only because its seed row was."""
    return why not in ("", SEED_RESOLVED)


def solve_in_order(keys: Sequence[int], units: np.ndarray, seeds: Sequence[Seed],
                   solve: Callable[..., tuple[Any, Any]]) -> list[ChainRow]:
    """Solve ``keys`` in the given order, each warm-started from the nearest converged state so far
    (moved by the linear predictor of :func:`predicted_state` where the states allow it).

    Parameters
    ----------
    keys : sequence of int
        Row keys, in continuation order.
    units : (len(keys), d) array
        Their scaled coordinates.
    seeds : sequence of Seed
        States available before the first point (e.g. the end of the chain's previous chunk).
    solve : callable
        ``solve(key, initial) -> (result, state)``; ``initial`` is None (cold) or a
        state; ``state`` is None when the point did not converge (it is then
        never used as a start).
    """
    pool = SeedPool(seeds)
    out = []
    for key, u in zip(keys, np.asarray(units, dtype=float)):
        initial, nearest = _predicted(u, pool)
        seed = None if initial is None or nearest is None else pool[nearest].key
        result, state = solve(int(key), initial)
        if state is not None:
            if pool:  # only the newest state keeps its factorised tangent (they are large)
                pool[-1] = replace(pool[-1], state=light_state(pool[-1].state))
            pool.append(Seed(u, state, int(key)))
        out.append(ChainRow(int(key), u, result, state, initial is not None, seed))
    # the caller keeps these states: only the last one keeps its tangent
    return [r if i == len(out) - 1 else replace(r, state=light_state(r.state)) for i, r in enumerate(out)]


def light_state(state):
    """A solver state without its factorised tangent (``(u, p, tangent)`` -> ``(u, p)``; a
    :class:`~lvcore.mechanics.forward.WarmState` keeps its parameters); others unchanged."""
    if hasattr(state, "_replace") and hasattr(state, "tangent"):  # a WarmState keeps its parameters
        return state._replace(tangent=None)
    if isinstance(state, tuple) and len(state) > 2:
        return state[:2]
    return state


@dataclass
class _Chain:
    rows: list[int]                 # positions (into the batch) still to submit, in order
    index: int = 0                  # the chain's number in this run (a split-off chain gets the next one)
    taken: int = 0                  # points submitted so far: the place in the chain of the next one

    def take(self, n: int) -> list[int]:
        head, self.rows = self.rows[:n], self.rows[n:]
        self.taken += len(head)
        return head


@dataclass
class ChainStats:
    """What :func:`run_chains` did: chunks, chains (after splits), points solved warm and cold."""

    chunks: int = 0
    chains: int = 0
    splits: int = 0
    warm: int = 0
    cold: int = 0
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)


def plan_chains(U: np.ndarray, workers: int) -> list[list[int]]:
    """Split the continuation order of ``U`` into ``CHAINS_PER_WORKER × workers`` contiguous chains (positions)."""
    order = continuation_order(U)
    n_chains = max(1, min(len(order), CHAINS_PER_WORKER * max(1, int(workers))))
    return [list(map(int, part)) for part in np.array_split(order, n_chains) if part.size]


def run_chains(executor, submit_chunk: Callable[[list[int], list[Seed]], Any], U: np.ndarray, *,
               workers: int, on_rows: Callable[[list[ChainRow]], None], chunk: int = DEFAULT_CHUNK,
               seeds: Sequence[Seed] = (), kept_states: int = DEFAULT_KEPT_STATES) -> ChainStats:
    """Run the points of ``U`` as continuation chains on ``executor``.

    Parameters
    ----------
    executor : object with ``as_completed(futures)`` (see :mod:`lvcore.execution.parallel`)
    submit_chunk : callable
        ``submit_chunk(positions, seeds) -> future`` whose result is a list of
        :class:`ChainRow` keyed by those positions (rows of ``U``); it is
        expected to call :func:`solve_in_order` in a worker.
    U : (n, d) array
        Scaled coordinates of the points.
    workers : int
        Worker processes of the executor (chains are ``2 × workers``).
    on_rows : callable
        Receives every returned chunk's rows, after the chain's next chunk
        has been submitted (so recording never idles a worker).
    chunk : int
        Points per task.
    seeds : sequence of Seed
        States known before the run (e.g. from earlier batches).
    kept_states : int
        Converged states the driver keeps to seed chunks.

    Raises
    ------
    ChainTaskError
        When a task raises (a dead worker): finished chunks were already passed to ``on_rows``.
    """
    t0 = time.perf_counter()
    U = np.asarray(U, dtype=float)
    stats = ChainStats()
    if U.shape[0] == 0:
        return stats
    chains = [_Chain(c, i) for i, c in enumerate(plan_chains(U, workers))]
    stats.chains = len(chains)
    kept: list[Seed] = list(seeds)[-kept_states:]
    chunk = max(1, int(chunk))

    def seeds_for(positions: list[int]) -> list[Seed]:
        if not kept:
            return []
        cu = np.stack([s.unit for s in kept])
        d = np.min(np.linalg.norm(cu[:, None, :] - U[positions][None, :, :], axis=2), axis=1)
        return [kept[i] for i in np.argsort(d)[:SEEDS_PER_CHUNK]]

    inflight: dict[Any, tuple[_Chain, int]] = {}

    def launch(ch: _Chain) -> None:
        first = ch.taken
        positions = ch.take(chunk)
        inflight[submit_chunk(positions, seeds_for(positions))] = (ch, first)
        stats.chunks += 1

    for ch in chains:
        launch(ch)
    while inflight:
        fut = next(iter(executor.as_completed(list(inflight))))
        ch, first = inflight.pop(fut)
        try:
            rows = fut.result()
        except Exception as err:  # a dead worker or a broken pool: the chunks in flight are lost
            raise ChainTaskError(f"{type(err).__name__}: {err}") from err
        rows = [replace(r, chain=ch.index, position=first + j) for j, r in enumerate(rows)]
        for r in rows:
            if r.state is not None:
                kept.append(Seed(U[r.key], r.state, r.key))
            stats.warm += bool(r.warm)
            stats.cold += not r.warm
        del kept[:-kept_states]
        for i in range(max(0, len(kept) - len(rows) - 8), max(0, len(kept) - 8)):  # few tangents kept in memory
            kept[i] = replace(kept[i], state=light_state(kept[i].state))
        if ch.rows:
            launch(ch)
        else:
            # a chain ran dry: split the longest unsubmitted remainder so every worker stays busy
            longest = max(chains, key=lambda c: len(c.rows))
            if len(longest.rows) >= 2 * chunk:
                half = len(longest.rows) // 2
                new = _Chain(longest.rows[half:], len(chains))
                longest.rows = longest.rows[:half]
                chains.append(new)
                stats.splits += 1
                stats.chains += 1
                launch(new)
        on_rows(rows)
    stats.seconds = time.perf_counter() - t0
    return stats


def scaled_coordinates(names: Sequence[str], X: np.ndarray) -> np.ndarray:
    """Scaled coordinates of named physical inputs, comparable across batches (no design space needed).

    Material parameters (``a, b, af, bf``, positive) on a log scale; fibre
    angles in units of 90°; EDP in units of 8 mmHg; PC scores in units of 4
    (their ±2 box); anything else as given.
    """
    from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME, THETA_NAMES, is_pc_name

    X = np.atleast_2d(np.asarray(X, dtype=float))
    cols = []
    for j, n in enumerate(names):
        x = X[:, j]
        if n in THETA_NAMES:
            cols.append(np.log(np.maximum(x, 1e-300)) / math.log(100.0))
        elif n in ANGLE_NAMES:
            cols.append(x / 90.0)
        elif n == EDP_NAME:
            cols.append(x / 8.0)
        elif is_pc_name(n):
            cols.append(x / 4.0)
        else:
            cols.append(x)
    return np.column_stack(cols) if cols else np.zeros((X.shape[0], 0))


__all__ = ["continuation_order", "solve_in_order", "light_state", "run_chains", "plan_chains", "nearest_state",
           "scaled_coordinates", "Seed", "SeedPool", "ChainRow", "ChainStats", "ChainTaskError", "DEFAULT_CHUNK"]
