"""The FE runs of a subject emulator's design: warm-started continuation chains, saved as they return.

:func:`simulate_rows` solves every design row on one geometry (in this process or on a pool of workers, with no
barrier) and saves the rows done to a checkpoint file (:data:`RUNS_FILE`) after every chunk, so a stopped or failed
build resumes from them. Used by :mod:`lvcore.emulator.subject` (which re-exports these names).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore.core.space import ParameterSpace
from lvcore.exceptions import EmulatorError
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, N_OUTPUTS

#: FE runs per batch of a build on one worker (in this process): progress is reported, and the runs done are saved
#: to :data:`RUNS_FILE`, after each. With a pool every chain chunk (:data:`lvcore.execution.chains.DEFAULT_CHUNK` runs) is.
CHECKPOINT_ROWS = 100
#: The FE runs of a build so far, in the emulator directory; kept when a build fails or is stopped (a new build of
#: the same design, geometry and mesh resumes from it), removed when the emulator is saved.
RUNS_FILE = "fe_runs.npz"


@dataclass(frozen=True)
class SimulatedRows:
    """FE outputs of design rows (input order kept).

    Attributes
    ----------
    outputs : (n, 25) ndarray
        NaN rows where a solve failed.
    converged : (n,) bool ndarray
    messages : tuple of str
    seconds : (n,) ndarray
        Solver time per row (s).
    wall_s : float
        Wall time of all rows (s).
    workers : int
        Worker processes used (1: this process).
    """

    outputs: np.ndarray
    converged: np.ndarray
    messages: tuple[str, ...]
    seconds: np.ndarray
    wall_s: float
    workers: int


def simulate_rows(space: ParameterSpace, x: np.ndarray, geometry: Mapping, *, resolution: str = "default",
                  workers: int = 2, checkpoint=None, chunk: int | None = None,
                  progress: Callable[[int, int], None] | None = None, stop: Callable[[], bool] | None = None,
                  executor=None, strain_layer: str = DEFAULT_STRAIN_LAYER) -> SimulatedRows:
    """Simulate every row of ``x`` (physical units, columns ``space.names``) on ``geometry``.

    The FE simulator with warm starts (:meth:`~lvcore.mechanics.forward.SimulatorForward.evaluate_warm`):
    the rows are ordered along one continuation walk over the whole design
    (:func:`lvcore.execution.chains.continuation_order`), each solve starting Newton from
    a neighbour's converged solution and falling back to a cold solve when that
    fails or when the warm result could differ from the cold solve
    (:func:`lvcore.mechanics.forward.solve_warm`), so the results equal the cold solves within
    the solver tolerance. Failures are data (NaN rows, ``converged`` False); results come back in the input order.

    With ``workers > 1`` the walk is split into continuation chains fed to a
    process pool chunk by chunk (:func:`lvcore.execution.chains.run_chains`: the next
    chunk of a chain is submitted as soon as the previous one returns, and a
    chain that runs dry splits the longest remaining one), with no barrier
    anywhere: both cores are busy until the last chunk. With ``workers=1`` the
    walk is solved in this process, ``chunk`` rows at a time.

    Parameters
    ----------
    checkpoint : path, optional
        An ``.npz`` file where the rows done so far are saved as every chunk
        returns. Rows already saved there for the same inputs, geometry, mesh
        and base are taken from it, not simulated again (a stopped or failed
        build resumes; the rest is walked again from cold starts).
    chunk : int, optional
        Rows per task (default :data:`lvcore.execution.chains.DEFAULT_CHUNK` with a pool,
        :data:`CHECKPOINT_ROWS` in this process).
    progress : callable, optional
        ``progress(done, total)`` (rows) as every chunk returns.
    stop : callable, optional
        Asked as every chunk returns (and before the first); when it returns
        True the simulation stops with an :class:`~lvcore.exceptions.EmulatorError`
        (the rows done are in ``checkpoint``; chunks in flight are finished
        and kept too).
    executor : optional
        A running pool of :mod:`lvcore.execution.parallel` to use (not closed), e.g.
        shared by the stages of a build; default one of ``workers`` processes
        is started for the call.
    strain_layer : str
        Wall layer of the strains (:data:`lvcore.domain.outputs.STRAIN_LAYERS`), in the checkpoint's identity.
    """
    import contextlib

    from lvcore.execution.chains import DEFAULT_CHUNK, ChainTaskError, continuation_order, run_chains, scaled_coordinates
    from lvcore.mechanics.forward import SimulatorForward

    x_given = np.atleast_2d(np.asarray(x, dtype=float))
    n = x_given.shape[0]
    order = continuation_order(scaled_coordinates(space.names, x_given)) if n > 2 else np.arange(n)
    x = x_given[order]  # walk order: a chain is a stretch of it
    units = scaled_coordinates(space.names, x)
    pooled = int(workers) > 1
    chunk = max(1, int(chunk or (DEFAULT_CHUNK if pooled else CHECKPOINT_ROWS)))
    outputs = np.full((n, N_OUTPUTS), np.nan)
    converged = np.zeros(n, dtype=bool)
    messages, seconds = [""] * n, np.zeros(n)
    signature = _runs_signature(space, geometry, resolution, strain_layer)
    done = _resume_rows(checkpoint, signature, x, outputs, converged, messages, seconds)
    if progress is not None and done.any():
        progress(int(done.sum()), n)
    fwd = SimulatorForward(input_names=space.names, conditions=space.fixed_dict(), geometry=dict(geometry),
                           resolution=resolution, base=space.base, workers=1, warm_start=True, strain_layer=strain_layer)

    def record(rows) -> None:
        for r in rows:
            outputs[r.key], converged[r.key], messages[r.key], seconds[r.key] = r.result
            done[r.key] = True
        if checkpoint is not None:
            _save_rows(checkpoint, signature, x, done, outputs, converged, messages, seconds)
        if progress is not None:
            progress(int(done.sum()), n)
        check_stop()

    def check_stop() -> None:
        if stop is not None and not done.all() and stop():
            where = f"; they are kept in {checkpoint} and a new build of the same design resumes from them" \
                if checkpoint is not None else ""
            raise EmulatorError(f"stopped after {int(done.sum())} of {n} FE runs{where}")

    t0 = time.perf_counter()
    check_stop()
    todo = np.flatnonzero(~done)
    if todo.size and pooled and todo.size > 1:
        from lvcore.execution.parallel import make_executor

        with contextlib.ExitStack() as stack:
            if executor is None:
                executor = stack.enter_context(make_executor(workers=int(workers)))

            def submit(positions, seeds):  # rows keyed by position in todo (run_chains' bookkeeping)
                walk = todo[positions]
                return executor.submit(_fe_chunk, fwd, x[walk], positions, units[walk], seeds)

            def on_rows(rows):
                record([r.__class__(int(todo[r.key]), r.unit, r.result) for r in rows])

            try:
                run_chains(executor, submit, units[todo], workers=int(workers), on_rows=on_rows, chunk=chunk)
            except ChainTaskError as err:
                raise err.__cause__ or err from None
    else:
        state = None
        for start in range(0, todo.size, chunk):
            keys = [int(k) for k in todo[start:start + chunk]]
            seeds = [] if state is None else [state]
            rows = _fe_chunk(fwd, x[keys], keys, units[keys], seeds)
            last = [r for r in rows if r.state is not None]
            if last:
                from lvcore.execution.chains import Seed

                state = Seed(last[-1].unit, last[-1].state)
            record(rows)
    back = np.empty(n, dtype=int)
    back[order] = np.arange(n)  # row i of the design was solved at position back[i]
    return SimulatedRows(outputs[back], converged[back], tuple(messages[j] for j in back), seconds[back],
                         time.perf_counter() - t0, int(workers))


def _fe_chunk(forward, points: np.ndarray, keys: Sequence[int], units: np.ndarray, seeds) -> list:
    """Worker task: FE runs of one chain chunk, in order, each warm-started from the nearest converged state.

    Returns :class:`lvcore.execution.chains.ChainRow` objects keyed by ``keys`` whose results are
    ``(outputs (25,), converged, message, seconds)``.
    """
    from lvcore.execution.chains import solve_in_order

    by_key = {int(k): p for k, p in zip(keys, np.atleast_2d(points))}

    def solve(key, initial):
        batch, state, _, _ = forward.evaluate_warm(dict(zip(forward.input_names, by_key[key])), initial)
        result = (np.asarray(batch.outputs[0], dtype=float), bool(batch.converged[0]), str(batch.messages[0] or ""),
                  float(batch.seconds[0]))
        return result, state

    return solve_in_order(keys, units, seeds, solve)


def _runs_signature(space: ParameterSpace, geometry: Mapping, resolution: str,
                    strain_layer: str = DEFAULT_STRAIN_LAYER) -> str:
    import json

    key = {"space": space.to_dict(), "geometry": dict(geometry), "resolution": str(resolution)}
    if strain_layer != DEFAULT_STRAIN_LAYER:  # the default is left out: checkpoints written before still resume
        key["strain_layer"] = strain_layer
    return json.dumps(key, sort_keys=True, default=str)


def _save_rows(path, signature: str, x, done, outputs, converged, messages, seconds) -> None:
    """Write the rows done so far (atomically: a killed build leaves the previous file whole)."""
    path = Path(path)
    tmp = path.with_name(path.stem + ".partial.npz")
    np.savez(tmp, signature=np.array(signature), inputs=x[done], outputs=outputs[done], converged=converged[done],
             messages=np.array([m for m, d in zip(messages, done) if d], dtype=str), seconds=seconds[done])
    tmp.replace(path)


def _resume_rows(path, signature: str, x, outputs, converged, messages, seconds) -> np.ndarray:
    """Fill the rows of ``x`` already saved in ``path`` (same signature, identical inputs); the mask of rows done.

    The saved rows may be any subset of ``x`` (chains return out of order); a saved row that is not a row of
    ``x`` means another design, and nothing is taken.
    """
    done = np.zeros(x.shape[0], dtype=bool)
    if path is None or not Path(path).is_file():
        return done
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["signature"]) != signature:
                return done
            saved = np.asarray(z["inputs"], dtype=float)
            where = {row.tobytes(): i for i, row in enumerate(x)}
            idx = [where.get(row.tobytes(), -1) for row in saved]
            if saved.ndim != 2 or saved.shape[1] != x.shape[1] or min(idx, default=0) < 0 \
                    or len(set(idx)) != len(idx):
                return done
            idx = np.asarray(idx, dtype=int)
            outputs[idx], converged[idx], seconds[idx] = z["outputs"], z["converged"], z["seconds"]
            for i, m in zip(idx, z["messages"]):
                messages[i] = str(m)
            done[idx] = True
    except (OSError, KeyError, ValueError):  # a damaged file: simulate again
        done[:] = False
    return done



__all__ = ["SimulatedRows", "CHECKPOINT_ROWS", "RUNS_FILE", "simulate_rows"]
