"""FE load paths: one row of a design (θ, PC scores) solved at every pressure of an EDPVR grid.

A campaign (:mod:`lvcore.campaigns.runner`) solves one pressure per row; the training data of an emulator with an
EDP input come cheaper from load paths: :func:`solve_load_path` solves one (θ, geometry) row at increasing
pressures, each pressure a warm continuation (:func:`lvcore.mechanics.forward.warm_continuation`) from the
converged state at the pressure below, the first one cold. Each converged pressure gives the 25 outputs (LVV, the 24
strains) and the volume-weighted mean fibre stretch (:func:`lvcore.mechanics.fibre_stretch.mean_fibre_stretch`);
the reference cavity V₀ comes with the first solve.

:func:`run_load_paths` runs the rows of a design in worker processes (niced by the caller) and returns
:class:`LoadPathData` (arrays, saved as one ``.npz``). ``scripts/build_emulators.py --emulators edpvr`` is the
seeded command that builds the bundled ``edpvr`` emulator from it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER

#: Pressures (mmHg) of each training load path: 0 is the reference state (exact: V = V₀, no strain, stretch 1).
LOAD_PATH_PRESSURES_MMHG = (1.0, 2.0, 3.0, 4.0, 5.0, 6.5, 8.0, 10.0, 12.0, 14.0, 17.0, 20.0, 25.0, 30.0)
#: Pressures (mmHg) of the held-out test paths: between the training pressures wherever the grids allow, and the
#: EDPVR's 5-30 mmHg, so the test measures the interpolation in pressure too.
TEST_PRESSURES_MMHG = (0.5, 1.5, 2.5, 3.5, 5.0, 7.0, 9.0, 11.0, 13.0, 15.0, 18.5, 22.5, 27.5, 30.0)
#: Strain outputs recorded per pressure.
N_STRAINS = 24


@dataclass(frozen=True)
class LoadPathData:
    """Load paths of ``n`` design rows at ``P`` pressures.

    Attributes
    ----------
    inputs : ndarray (n, d)
        The rows (physical units, the space's ``names``).
    input_names : tuple of str
    pressures_mmhg : ndarray (P,)
    v0_ml : ndarray (n,)
        Reference cavity volume (mL), NaN where the row failed at its first pressure.
    lvv_ml : ndarray (n, P)
        Cavity volume (mL), NaN where a solve failed (and at every pressure above it).
    strains : ndarray (n, P, 24)
    fibre_stretch : ndarray (n, P)
        Volume-weighted mean fibre stretch of the wall (-).
    seconds : ndarray (n,)
        Wall time of each row's path (s).
    """

    inputs: np.ndarray
    input_names: tuple
    pressures_mmhg: np.ndarray
    v0_ml: np.ndarray
    lvv_ml: np.ndarray
    strains: np.ndarray
    fibre_stretch: np.ndarray
    seconds: np.ndarray

    def save(self, path) -> None:
        np.savez(path, inputs=self.inputs, input_names=np.array(self.input_names), pressures_mmhg=self.pressures_mmhg,
                 v0_ml=self.v0_ml, lvv_ml=self.lvv_ml, strains=self.strains, fibre_stretch=self.fibre_stretch,
                 seconds=self.seconds)

    @classmethod
    def load(cls, path) -> "LoadPathData":
        with np.load(path) as z:
            return cls(z["inputs"], tuple(str(s) for s in z["input_names"]), z["pressures_mmhg"], z["v0_ml"],
                       z["lvv_ml"], z["strains"], z["fibre_stretch"], z["seconds"])

    @classmethod
    def concatenate(cls, parts: Sequence["LoadPathData"]) -> "LoadPathData":
        first = parts[0]
        return cls(*(np.concatenate([getattr(p, k) for p in parts]) if k not in ("input_names", "pressures_mmhg")
                     else getattr(first, k) for k in cls.__dataclass_fields__))


def solve_load_path(case: dict, pressures_mmhg: Sequence[float] = LOAD_PATH_PRESSURES_MMHG) -> tuple:
    """One case's load path: ``(v0_ml, lvv_ml (P,), strains (P, 24), fibre_stretch (P,))``, NaN from the first
    pressure that did not converge on (warm continuation from the pressure below, then a cold solve)."""
    from lvcore.domain import units
    from lvcore.mechanics.fibre_stretch import mean_fibre_stretch
    from lvcore.mechanics.forward import _as_warm, case_values, continue_or_solve

    P = len(pressures_mmhg)
    lvv, lam = np.full(P, np.nan), np.full(P, np.nan)
    strains = np.full((P, N_STRAINS), np.nan)
    v0, warm = float("nan"), None
    for j, p in enumerate(pressures_mmhg):
        c = {**case, "load": {"pressure": float(p), "units": "mmHg"}}
        res = continue_or_solve(c, warm)
        if res is None:
            break
        out = res.outputs()
        v0 = res.cavity_volume_mm3[0] / units.MM3_PER_ML
        lvv[j], strains[j] = out[0], out[1:]
        lam[j] = float(mean_fibre_stretch(c, res))
        warm = _as_warm(res, case_values(c))
    return v0, lvv, strains, lam


def _solve_rows(args) -> list:
    from lvcore.mechanics.case_inputs import space_case

    space, rows, resolution, pressures, geometry, strain_layer = args
    out = []
    for row in rows:
        t0 = time.perf_counter()
        r = solve_load_path(space_case(space, row, resolution, strain_layer, geometry), pressures)
        out.append(r + (time.perf_counter() - t0,))
    return out


def run_load_paths(space, rows: np.ndarray, *, resolution: str = "default", workers: int = 1,
                   pressures_mmhg: Sequence[float] = LOAD_PATH_PRESSURES_MMHG, chunk: int = 10,
                   progress=None, geometry: Mapping | None = None,
                   strain_layer: str = DEFAULT_STRAIN_LAYER) -> LoadPathData:
    """Load paths of every row of ``rows`` (values of ``space.names``) on ``workers`` processes.

    Parameters
    ----------
    space : ParameterSpace
        The rows' space (its fixed inputs and base condition; its ``edp`` is replaced by each pressure).
    rows : ndarray (n, d)
    resolution : str
        Mesh preset.
    workers : int
        Worker processes (1: this process).
    pressures_mmhg : sequence of float
        Increasing pressures (mmHg).
    chunk : int
        Rows per task.
    progress : callable(done, total), optional
    geometry : mapping, optional
        A fixed case ``geometry`` section for every row (a subject emulator's mesh,
        :mod:`lvcore.emulator.subject_edpvr`); default: the rows' PC scores.
    strain_layer : str
        The wall layer of the recorded strains (:data:`lvcore.domain.outputs.STRAIN_LAYERS`).

    Returns
    -------
    LoadPathData
    """
    rows = np.asarray(rows, float)
    p = np.asarray(pressures_mmhg, float)
    geometry = None if geometry is None else dict(geometry)
    tasks = [(space, rows[i:i + chunk], resolution, tuple(p), geometry, strain_layer)
             for i in range(0, len(rows), chunk)]
    results: list = [None] * len(tasks)
    if workers <= 1:
        for k, t in enumerate(tasks):
            results[k] = _solve_rows(t)
            if progress is not None:
                progress(min((k + 1) * chunk, len(rows)), len(rows))
    else:
        from lvcore.execution.parallel import make_executor

        with make_executor(workers) as ex:
            futures = {ex.submit(_solve_rows, t): k for k, t in enumerate(tasks)}
            import concurrent.futures as cf

            done = 0
            for f in cf.as_completed(futures):
                results[futures[f]] = f.result()
                done += len(results[futures[f]])
                if progress is not None:
                    progress(done, len(rows))
    flat = [r for part in results for r in part]
    return LoadPathData(rows, tuple(space.names), p, np.array([r[0] for r in flat]),
                        np.array([r[1] for r in flat]), np.array([r[2] for r in flat]),
                        np.array([r[3] for r in flat]), np.array([r[4] for r in flat]))


__all__ = ["LOAD_PATH_PRESSURES_MMHG", "TEST_PRESSURES_MMHG", "LoadPathData", "solve_load_path", "run_load_paths"]
