"""Run, resume and inspect simulation campaigns.

A campaign runs every row of a design through a forward model (the
:class:`~lvcore.core.forward.Forward` interface) and records each outcome in
a :class:`~lvcore.campaigns.store.CampaignStore` as soon as it arrives. The
forward model is named, never imported from a string: the store records the
name (default ``"simulator"``, the FE simulator on the design's space at the
store's resolution) and :func:`resume_campaign` looks it up in the
allow-list of :mod:`lvcore.core.registry`; other forward models are
registered in code with :func:`lvcore.core.register_forward`.

Failures are data: a :class:`~lvcore.exceptions.SolverError` (or any other
exception raised by the forward model) or a point that did not converge is
recorded as a failed row with its reason; rows are never dropped or filled in.

Rows run as warm-started continuation chains by default
(:mod:`lvcore.execution.chains`): nearby rows in the design's unit cube are
solved one after another, each starting Newton from a neighbour's solution,
in chunks of :data:`~lvcore.execution.chains.DEFAULT_CHUNK` rows, with at
least two chains per worker; ``chained=False`` (``--cold``) runs one cold
task per row.

Killing a campaign (even with SIGKILL) loses only the rows in flight (the
chunks being solved); :func:`resume_campaign` runs exactly the rows not yet
committed, chaining them afresh.
"""
from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import lvcore
from lvcore.campaigns.designs import Design, load_design
from lvcore.campaigns.store import START_COLD, START_RESOLVED, START_WARM, CampaignStore, RowResult, StoreSummary, \
    recorded_strain_layer, worker_tag
from lvcore.execution.chains import DEFAULT_CHUNK, ChainTaskError, run_chains, solve_in_order
from lvcore.core.forward import failure_reason
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER
from lvcore.domain.outputs import strain_layer as canonical_strain_layer
from lvcore.core.registry import DEFAULT_FORWARD_NAME, make_forward, registered_name
from lvcore.exceptions import CampaignError
from lvcore.mechanics import forward as _simulator_forward  # noqa: F401 - registers the default forward "simulator"
from lvcore.mechanics.resolution import RESOLUTION_PRESET_NAMES, recorded_resolution
from lvcore.execution.parallel import InProcessExecutor, make_executor

#: The real simulator.
DEFAULT_FORWARD = DEFAULT_FORWARD_NAME
RESOLUTIONS = RESOLUTION_PRESET_NAMES

#: A campaign with at most this many rows to run, and neither ``workers`` nor a scheduler given, runs in this
#: process (:class:`~lvcore.execution.parallel.InProcessExecutor`): each spawned worker first imports the simulator and
#: loads its compiled kernels (≈ 2.2 CPU-s, measured), more than it saves on so few rows (a cold ``default`` row
#: ≈ 0.3 CPU-s); on a loaded machine, where CPU time is wall time, the workers' start-up is all loss.
#: BENCHMARKS.md row 61 has both measured. ``--workers N`` given explicitly always starts N workers.
IN_PROCESS_MAX_ROWS = 16
#: ``chained=None`` (the CLI's default): continuation chains for at least this many rows to run, else one cold
#: solve per row. Fewer rows lie too far apart in the design's cube for a neighbour's state to be a good start:
#: most warm starts are then re-solved cold, and chains cost more than cold solves. Measured in one process
#: (Sobol over ``material``, ``default`` mesh, CPU-s in all, imports included): 16 rows 7.8 cold vs 12.2 chained,
#: 32 rows 12.0 vs 23.9, 64 rows 20.1 vs 41.8, 128 rows 45.7 vs 47.2 (BENCHMARKS.md row 61).
CHAIN_MIN_ROWS = 128

_VERSION: list[str] = []


def simulator_version() -> str:
    """``lvcore.__version__`` plus a hash of the simulator's source files.

    ``"0.1.0+src.1a2b3c4d5e"``: the hash covers ``lvcore/mechanics``,
    ``lvcore/geometry`` and ``lvcore/domain`` (``*.py``; the last holds the
    fixed Holzapfel-Ogden terms and units the simulator reads), so rows
    computed by different code are told apart even when the package version
    did not change.
    """
    if not _VERSION:
        import hashlib

        root = Path(lvcore.__file__).resolve().parent
        h = hashlib.sha256()
        for sub in ("mechanics", "geometry", "domain"):
            for f in sorted((root / sub).glob("*.py")):
                h.update(f.name.encode())
                h.update(f.read_bytes())
        _VERSION.append(f"{lvcore.__version__}+src.{h.hexdigest()[:10]}")
    return _VERSION[0]


def execute_row(forward, index: int, inputs: dict) -> RowResult:
    """Run one row in a worker and turn every outcome into a :class:`RowResult`.

    Parameters
    ----------
    forward : Forward
        Pickled to the worker; ``inputs`` maps its ``input_names`` to this row's values.

    Never raises for a failing simulation: solver errors, non-convergence and
    any other exception of the forward model become failed rows with a reason.
    """
    t0 = time.perf_counter()
    tag = worker_tag()
    try:
        batch = forward.evaluate({n: [float(v)] for n, v in inputs.items()})
        seconds = float(batch.seconds[0]) if batch.seconds is not None else time.perf_counter() - t0
        if not bool(batch.converged[0]):
            reason = batch.messages[0] or "did not converge"
            return RowResult(index, np.full(25, np.nan), False, reason, seconds, simulator_version(), tag)
        return RowResult(index, batch.outputs[0], True, "", seconds, simulator_version(), tag)
    except Exception as err:  # noqa: BLE001 - recorded, never swallowed silently
        reason = failure_reason(err)
    return RowResult(index, np.full(25, np.nan), False, reason, time.perf_counter() - t0, simulator_version(), tag)


#: The store's ``start`` of each way a forward model's ``evaluate_warm`` reports (:class:`~lvcore.mechanics.forward.WarmSolve`).
_STARTS = {"cold": START_COLD, "warm": START_WARM, "re-solved cold": START_RESOLVED}


def execute_warm_row(forward, index: int, inputs: dict, initial) -> tuple[RowResult, object]:
    """:func:`execute_row` started from ``initial`` (a converged state, or None) with ``forward.evaluate_warm``.

    Returns ``(RowResult, state)``; ``state`` is None unless the row converged. The forward model decides
    how the row is solved and says so (the simulator: :func:`lvcore.mechanics.forward.solve_warm`, which
    keeps a warm result only where it equals the cold solve); the row records it as its ``start``
    (:data:`~lvcore.campaigns.store.START_COLD`, ``START_WARM`` or ``START_RESOLVED``) and ``resolve_reason``.
    """
    t0 = time.perf_counter()
    tag = worker_tag()
    start = START_COLD if initial is None else START_WARM
    point = {n: float(v) for n, v in inputs.items()}
    try:
        batch, state, how, why = forward.evaluate_warm(point, initial)
        start = _STARTS[how]
        seconds = time.perf_counter() - t0 if batch.seconds is None else float(batch.seconds[0])
        if not bool(batch.converged[0]):
            reason = batch.messages[0] or "did not converge"
            return RowResult(index, np.full(25, np.nan), False, reason, seconds, simulator_version(), tag,
                             start=start, resolve_reason=why), None
        return (RowResult(index, batch.outputs[0], True, "", seconds, simulator_version(), tag, start=start,
                          resolve_reason=why), state)
    except Exception as err:  # noqa: BLE001 - recorded, never swallowed silently
        reason = failure_reason(err)
    return (RowResult(index, np.full(25, np.nan), False, reason, time.perf_counter() - t0, simulator_version(), tag,
                      start=start), None)


def execute_chunk(forward, positions: list[int], indices: list[int], inputs: list[dict], units, seeds) -> list:
    """Run one chunk of a continuation chain in a worker (see :mod:`lvcore.execution.chains`).

    Rows are solved in the given order, each warm-started from the nearest
    converged state among ``seeds`` and the chunk's earlier rows, when the
    forward model can (``evaluate_warm``); otherwise cold, as :func:`execute_row`.
    Returns :class:`~lvcore.execution.chains.ChainRow` objects keyed by ``positions``
    whose results are :class:`RowResult` for store rows ``indices``.
    """
    by_pos = {p: (i, x) for p, i, x in zip(positions, indices, inputs)}
    warm = callable(getattr(forward, "evaluate_warm", None))

    def solve(pos, initial):
        i, x = by_pos[pos]
        if not warm:
            return execute_row(forward, i, x), None
        return execute_warm_row(forward, i, x, initial)

    return solve_in_order(positions, units, seeds, solve)


def row_inputs(design: Design, i: int) -> dict:
    """The named inputs of design row ``i`` (the space's varied inputs; the fixed ones are bound into the forward)."""
    return {n: float(v) for n, v in zip(design.space.names, design.points[i])}


def _drive(store: CampaignStore, rows: np.ndarray, executor, *, forward, progress: bool,
           allow_rerecord: bool = False, chained: bool = True, chunk: int = DEFAULT_CHUNK):
    """Submit ``rows`` to ``forward`` (a Forward) and record their results as they complete.

    ``chained``: the rows run as warm-started continuation chains split across
    the executor's workers (:func:`lvcore.execution.chains.run_chains`), in
    chunks of ``chunk`` rows; otherwise one cold task per row. Returns the
    :class:`~lvcore.execution.chains.ChainStats` of a chained run, else None.
    """
    if rows.size == 0:
        return None
    from tqdm import tqdm

    design = store.design()
    bar = tqdm(total=rows.size, disable=not progress, file=sys.stderr, unit="run", desc="campaign")
    failed = 0

    def record(*results: RowResult) -> None:
        nonlocal failed
        store.record_many(results, allow_rerecord=allow_rerecord)
        failed += sum(not r.converged for r in results)
        bar.update(len(results))
        bar.set_postfix(failed=failed)

    def died(err):  # infrastructure failure: the rows in flight stay pending
        return CampaignError(f"a worker died or could not run a row ({type(err).__name__}: {err}); "
                             f"finished rows are safe, run `lvcore campaign resume {store.path}`")

    try:
        if chained:
            U = design.space.to_unit(design.points[rows])

            def submit(positions, seeds):
                idx = [int(rows[p]) for p in positions]
                return executor.submit(execute_chunk, forward, positions, idx, [row_inputs(design, i) for i in idx],
                                       U[positions], seeds)

            def provenance(r):  # the chain, the place in it and the seed's store row of a chained row
                seed = -1 if r.seed is None or r.result.start == START_COLD else int(rows[r.seed])
                return replace(r.result, chain=r.chain, chain_position=r.position, seed_row=seed)

            try:
                return run_chains(executor, submit, U, workers=getattr(executor, "workers", 1), chunk=chunk,
                                  on_rows=lambda out: record(*(provenance(r) for r in out)))
            except ChainTaskError as err:
                raise died(err.__cause__ or err) from err
        futures = [executor.submit(execute_row, forward, int(i), row_inputs(design, int(i))) for i in rows]
        for fut in executor.as_completed(futures):
            try:
                result = fut.result()
            except Exception as err:
                raise died(err) from err
            record(result)
    finally:
        bar.close()
    return None


def run_campaign(design: Design | str | Path, out: str | Path, *, workers: int | None = None,
                 scheduler: str | None = None, resolution: str = "default", forward: str = DEFAULT_FORWARD,
                 progress: bool = True, executor=None, overwrite: bool = False,
                 chained: bool | None = True, strain_layer: str = DEFAULT_STRAIN_LAYER) -> StoreSummary:
    """Run every row of ``design`` and record the results in a new store ``out``.

    Parameters
    ----------
    design : Design or path
        The design, or a design CSV (:func:`~lvcore.campaigns.designs.load_design`).
    out : path
        The HDF5 store to create (refuses to overwrite unless ``overwrite``).
    workers : int, optional
        Local worker processes (default: none for at most :data:`IN_PROCESS_MAX_ROWS` rows, which run in this
        process, else one per core; see :func:`choose_executor`).
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a Dask scheduler; overrides ``workers``.
    resolution : a preset name of :data:`lvcore.mechanics.resolution.RESOLUTION_PRESET_NAMES`
        Simulator mesh resolution preset.
    forward : str
        Name of a registered forward model (default ``"simulator"``, the FE
        simulator; see :func:`lvcore.core.register_forward`). The store records the name.
    executor : optional
        An executor object (see :mod:`lvcore.execution.parallel`) to use
        instead of creating one; it is not closed.
    chained : bool or None
        Run the rows as warm-started continuation chains of nearby rows split
        across the workers (:mod:`lvcore.execution.chains`; the default), or
        each row cold in its own task; None: chains for at least
        :data:`CHAIN_MIN_ROWS` rows to run, else cold (the CLI's default). Both give the same results within the
        solver tolerance.
    strain_layer : str
        The wall layer of the strains (:data:`lvcore.domain.outputs.STRAIN_LAYERS`; default the inner half), set on
        the forward model (:func:`with_strain_layer`) and recorded as the store attribute ``strain_layer``.

    Returns
    -------
    StoreSummary
        Counts of converged, failed and pending rows, the failure reasons and the mean seconds per row.

    Raises
    ------
    CampaignError
        An unknown resolution or forward model, a design file that cannot be read, a store that exists, or a
        worker that died (the finished rows are kept: ``lvcore campaign resume``).

    Examples
    --------
    A 4-row campaign in seconds: the SYNTHETIC analytic stand-in (tests only, not a model of the heart) registered
    as a forward model, on an executor that runs each task in this process (any object with ``submit`` and
    ``as_completed``, as the executors of :mod:`lvcore.execution.parallel`; without one, ``workers`` processes start):

    >>> import tempfile
    >>> from concurrent.futures import Future
    >>> from pathlib import Path
    >>> from lvcore.campaigns import get_space, make_design, read_store, run_campaign
    >>> from lvcore.core import register_forward
    >>> from lvcore.testing.analytic import AnalyticForward
    >>> register_forward("analytic-example", lambda space, resolution: AnalyticForward(input_names=space.names),
    ...                  overwrite=True)
    >>> class InProcess:
    ...     workers = 1
    ...     def submit(self, fn, *args):
    ...         done = Future()
    ...         done.set_result(fn(*args))
    ...         return done
    ...     def as_completed(self, futures):
    ...         return iter(futures)
    >>> design = make_design(get_space("material"), "sobol", 4, seed=0)
    >>> store = Path(tempfile.mkdtemp()) / "campaign.h5"
    >>> summary = run_campaign(design, store, forward="analytic-example", executor=InProcess(), progress=False)
    >>> summary.converged, summary.failed, summary.pending
    (4, 0, 0)

    Each row's 25 outputs (LVV in mL, then the 24 regional strains) are stored as the forward model gave them:

    >>> rows = read_store(store)
    >>> direct = AnalyticForward().evaluate(dict(zip(design.space.names, design.points.T))).outputs
    >>> rows.outputs.shape, bool(abs(rows.outputs - direct).max() < 1e-9)
    ((4, 25), True)
    """
    if resolution not in RESOLUTIONS:
        raise CampaignError(f"--resolution must be one of {RESOLUTIONS}, got {resolution!r}")
    if not isinstance(design, Design):
        design = load_design(design)
    name = registered_name(forward)  # fail early on an unknown forward model
    fwd = with_strain_layer(make_forward(name, design.space, resolution), strain_layer, name)
    with CampaignStore.create(out, design, forward=name, resolution=resolution, overwrite=overwrite,
                              strain_layer=strain_layer) as store:
        _run_with(store, store.pending_rows(), executor, workers, scheduler, fwd, progress, chained=chained)
        return store.summary()


def resume_campaign(store_path: str | Path, *, workers: int | None = None, scheduler: str | None = None,
                    retry_failed: bool = False, progress: bool = True, executor=None,
                    chained: bool | None = True) -> StoreSummary:
    """Run the rows of an existing store that are not committed yet.

    With ``retry_failed`` the failed rows are run again too (their previous
    reason is overwritten). The store's forward model is looked up by name in
    :mod:`lvcore.core.registry`; an unknown name (e.g. a ``"module:function"``
    string) is a :class:`CampaignError` and nothing runs.
    """
    with CampaignStore.open(store_path, "r+") as store:
        attrs = store.attrs
        before = store.summary()  # the store check: inconsistent rows are reported and never run or counted
        if before.inconsistent and progress:
            print("\n".join(before.format().splitlines()[2:]), file=sys.stderr)
        resolution = recorded_resolution(str(attrs["resolution"]), before.versions)
        fwd = with_strain_layer(make_forward(str(attrs["forward"]), store.design().space, resolution),
                                recorded_strain_layer(attrs), str(attrs["forward"]))
        rows = store.pending_rows(retry_failed=retry_failed)
        _run_with(store, rows, executor, workers, scheduler, fwd, progress, allow_rerecord=retry_failed,
                  chained=chained)
        return store.summary()


def with_strain_layer(fwd, layer: str, name: str = "the forward model"):
    """``fwd`` writing strains of ``layer`` (:data:`lvcore.domain.outputs.STRAIN_LAYERS`): a forward model with a
    ``strain_layer`` field (the simulator) is copied with it set; one without (an analytic stand-in) takes the
    default layer only.

    Raises
    ------
    CampaignError
        An unknown layer, or a layer the forward model cannot write.
    """
    try:
        layer = canonical_strain_layer(layer, "--strain-layer")
    except ValueError as err:
        raise CampaignError(str(err)) from None
    have = getattr(fwd, "strain_layer", None)
    if have is None:
        if layer != DEFAULT_STRAIN_LAYER:
            raise CampaignError(f"forward model '{name}' has no strain layer to set; only the default "
                                f"({DEFAULT_STRAIN_LAYER}) is possible with it")
        return fwd
    return fwd if have == layer else replace(fwd, strain_layer=layer)


def choose_executor(n_rows: int, workers: int | None = None, scheduler: str | None = None):
    """The executor of a campaign with ``n_rows`` rows to run: this process when the campaign is small and the
    user chose neither workers nor a scheduler (:data:`IN_PROCESS_MAX_ROWS`), else
    :func:`lvcore.execution.parallel.make_executor` (``workers`` local processes, default one per core, or Dask)."""
    if workers is None and not scheduler and n_rows <= IN_PROCESS_MAX_ROWS:
        return InProcessExecutor()
    return make_executor(workers=workers, scheduler=scheduler)


def _run_with(store, rows, executor, workers, scheduler, forward, progress, allow_rerecord=False, chained=True):
    if rows.size == 0:
        return
    if chained is None:
        chained = rows.size >= CHAIN_MIN_ROWS
    if executor is not None:
        _drive(store, rows, executor, forward=forward, progress=progress, allow_rerecord=allow_rerecord,
               chained=chained)
        return
    with choose_executor(rows.size, workers, scheduler) as ex:
        if progress:
            how = "warm-started continuation chains" if chained else "cold, one task per row"
            print(f"lvcore campaign: {rows.size} row(s) on {ex.describe()}, {how}", file=sys.stderr)
        _drive(store, rows, ex, forward=forward, progress=progress, allow_rerecord=allow_rerecord, chained=chained)


def campaign_status(store_path: str | Path) -> StoreSummary:
    """Counts of converged / failed / pending rows and the failure reasons."""
    with CampaignStore.open(store_path, "r") as store:
        return store.summary()
