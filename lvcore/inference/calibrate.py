"""One calibration: measured data + geometry + forward model -> posterior, diagnostics, files.

This is the layer the CLI (``lvcore calibrate``), the app page, the
benchmarks and the studies share. :func:`calibrate` runs a model with
:func:`lvcore.inference.diagnostics.sample_until_converged` and wraps the
draws in ArviZ InferenceData; :func:`calibrate_subjects` does that for every
(subject, model) pair and writes netCDF plus a summary table per pair.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import arviz as az
import numpy as np
import pandas as pd

from lvcore.core.space import SIGMA_V_ML
from lvcore.exceptions import GeometryError
from lvcore.inference import diagnostics, models, samplers
from lvcore.inference.data import validate_measurements
from lvcore.outputs import is_pc_name


@dataclass(frozen=True)
class CalibrationResult:
    """Posterior of one model for one data set.

    Attributes
    ----------
    model : str
        ``volume``, ``iid`` or ``discrepancy``.
    sampler : str
        ``nuts`` or ``hmc_gibbs``.
    idata : arviz.InferenceData
        Posterior (theta, sigma_s2, GP hyperparameters, ``disc`` = b, ``eta``),
        posterior predictive ``y_rep``, observed ``y``, sample stats.
    convergence : Convergence
    summary : pandas.DataFrame
        ArviZ summary of the scalar parameters.
    wall_s : float
        Sampling wall time including compilation (s).
    ess_per_s : dict
        Bulk ESS per second for theta (and the minimum).
    """

    model: str
    sampler: str
    idata: az.InferenceData = field(repr=False)
    convergence: diagnostics.Convergence
    summary: pd.DataFrame = field(repr=False)
    wall_s: float
    ess_per_s: dict


def calibrate(y, forward, model: str = "iid", *, config: samplers.SamplerConfig = samplers.SamplerConfig(),
              sampler: str = "auto", sigma_v: float = SIGMA_V_ML, infer_angles: bool = False,
              rhat_max: float = diagnostics.DEFAULT_RHAT_MAX, ess_min: float = diagnostics.DEFAULT_ESS_MIN,
              max_rounds: int = 3, progress=None, attrs: dict | None = None) -> CalibrationResult:
    """Calibrate theta (and optionally the fibre angles) from one subject's data.

    Parameters
    ----------
    y : array_like, shape (25,)
        ``[LVV (mL), 24 strains]``; validated with :func:`lvcore.inference.data.validate_measurements`.
    forward : lvcore.core.Forward
        JAX-traceable, e.g. :func:`lvcore.core.load_emulator_forward` (``h`` bound in).
    model : str
        ``volume``, ``iid`` or ``discrepancy``.
    sampler : str
        ``auto`` (NUTS for volume/iid, HMC-within-Gibbs for discrepancy),
        ``nuts`` (joint NUTS for discrepancy too) or ``hmc_gibbs``.
    infer_angles : bool
        Sample alpha_endo, alpha_epi too (forward model must take them).
    progress : callable, optional
        ``progress(message, fraction)``.
    """
    y = validate_measurements(y)
    if model not in models.MODEL_NAMES:
        raise ValueError(f"unknown model '{model}'; choose one of {models.MODEL_NAMES}")
    kwargs = {"sigma_v": sigma_v, "infer_angles": infer_angles}
    run, conv = diagnostics.sample_until_converged(model, y, forward, config, sampler=sampler, rhat_max=rhat_max,
                                                   ess_min=ess_min, max_rounds=max_rounds, progress=progress,
                                                   **kwargs)
    label = getattr(forward, "label", type(forward).__name__)
    idata = diagnostics.to_inference_data(run, y, convergence=conv, sigma_v=sigma_v, forward_label=label,
                                          extra_attrs=attrs)
    return CalibrationResult(model, run.method, idata, conv, diagnostics.summary_table(run.samples), run.wall_s,
                             diagnostics.ess_per_second(run))


@dataclass(frozen=True)
class SubjectResult:
    """One (subject, model) calibration of :func:`calibrate_subjects`.

    Attributes
    ----------
    subject : str
    model : str
    result : CalibrationResult
    files : dict
        Paths written by :func:`write_result` (empty without ``out_dir``).
    """

    subject: str
    model: str
    result: CalibrationResult = field(repr=False)
    files: dict = field(default_factory=dict)

    def record(self) -> dict:
        """Plain-data summary: subject, :func:`result_record` and the file paths."""
        return {"subject": self.subject, **result_record(self.result), **self.files}


def calibrate_subjects(subjects: Sequence[tuple], model_names: Sequence[str], *,
                       config: samplers.SamplerConfig = samplers.SamplerConfig(), sampler: str = "auto",
                       sigma_v: float = SIGMA_V_ML, infer_angles: bool = False, out_dir=None,
                       attrs: dict | None = None, progress: Callable[[str, float], None] | None = None,
                       on_result: Callable[[SubjectResult], None] | None = None) -> list[SubjectResult]:
    """Calibrate every model for every subject, in order (subject-major).

    Parameters
    ----------
    subjects : sequence of (subject id, y, forward)
        ``y`` the 25 measured values, ``forward`` a JAX-traceable
        :class:`lvcore.core.Forward` with that subject's geometry bound in.
    model_names : sequence of str
        ``volume``, ``iid``, ``discrepancy``.
    config, sampler, sigma_v, infer_angles
        As in :func:`calibrate`.
    out_dir : path, optional
        Write ``<subject>_<model>.nc`` and ``_summary.csv`` there (:func:`write_result`).
    attrs : dict, optional
        Extra InferenceData attributes (``subject`` is added).
    progress : callable, optional
        ``progress(message, fraction of all pairs)``; messages start ``[subject / model]``.
    on_result : callable, optional
        Called with each :class:`SubjectResult` as soon as it is done.

    Returns
    -------
    list of SubjectResult
    """
    bad = [m for m in model_names if m not in models.MODEL_NAMES]
    if bad or not model_names:
        raise ValueError(f"unknown or no model(s) {bad}; choose from {', '.join(models.MODEL_NAMES)}")
    pairs = [(s, m) for s in subjects for m in model_names]
    out = []
    for k, ((subject, y, forward), m) in enumerate(pairs):
        def step(msg, frac, k=k, tag=f"[{subject} / {m}]"):
            progress(f"{tag} {msg}", (k + frac) / len(pairs))

        res = calibrate(y, forward, m, config=config, sampler=sampler, sigma_v=sigma_v, infer_angles=infer_angles,
                        progress=None if progress is None else step, attrs={"subject": str(subject), **(attrs or {})})
        files = write_result(res, out_dir, str(subject)) if out_dir is not None else {}
        item = SubjectResult(str(subject), m, res, files)
        out.append(item)
        if on_result is not None:
            on_result(item)
    return out


# --------------------------------------------------------------------------- geometry input
def read_pc_scores(path, n_pc: int = 5) -> np.ndarray:
    """PC scores of a geometry from JSON, CSV or a template mesh file.

    * JSON: ``{"h": [h1, h2, ...]}`` or ``{"h1": ..., "h2": ...}`` or a plain list;
    * CSV: columns ``h1..hk`` (first row used) or one row/column of numbers;
    * mesh (``.vtu``, ``.vtk``, ``.xdmf``, ``.npy``, ``.npz``): node positions on
      the template, projected with ``lvcore.geometry.shape_model.load_shape_model().project(nodes)``.

    Returns the first ``n_pc`` scores.
    """
    path = Path(path)
    if not path.is_file():
        raise GeometryError(f"geometry file {path} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".json":
        obj = json.loads(path.read_text())
        if isinstance(obj, dict):
            if "h" in obj:
                h = obj["h"]
            else:
                keys = sorted((k for k in obj if is_pc_name(k)), key=lambda k: int(k[1:]))
                h = [obj[k] for k in keys]
        else:
            h = obj
    elif suffix == ".csv":
        df = pd.read_csv(path)
        cols = [c for c in df.columns if is_pc_name(c)]
        if cols:
            cols = sorted(cols, key=lambda c: int(str(c)[1:]))
            h = df.loc[0, cols].to_numpy(dtype=float)
        else:
            h = np.loadtxt(path, delimiter=",").reshape(-1)
    elif suffix in (".vtu", ".vtk", ".xdmf", ".npy", ".npz"):
        h = _project_mesh(path)
    else:
        raise GeometryError(f"{path.name}: unknown geometry format '{suffix}'; give PC scores as .json/.csv "
                            "or a template mesh (.vtu, .vtk, .xdmf, .npy, .npz)")
    h = np.asarray(h, dtype=float).reshape(-1)
    if h.size < n_pc:
        raise GeometryError(f"{path.name}: need {n_pc} PC scores, found {h.size}")
    if not np.all(np.isfinite(h[:n_pc])):
        raise GeometryError(f"{path.name}: PC scores must be finite numbers")
    return h[:n_pc]


def _project_mesh(path: Path) -> np.ndarray:
    if path.suffix.lower() == ".npy":
        nodes = np.load(path)
    elif path.suffix.lower() == ".npz":
        with np.load(path) as z:
            key = "nodes" if "nodes" in z else list(z.keys())[0]
            nodes = z[key]
    else:
        from lvcore.geometry.io import read_template_mesh

        nodes = read_template_mesh(path)
    try:
        from lvcore.geometry.shape_model import load_shape_model
    except ImportError as err:
        raise GeometryError(f"cannot project {path.name}: the PCA shape model (lvcore.geometry.shape_model) "
                            f"is not available ({err}); give PC scores as .json/.csv instead") from err
    try:
        model = load_shape_model()
    except (FileNotFoundError, OSError) as err:
        raise GeometryError(f"cannot project {path.name}: no shape model found ({err}); build it with the "
                            "geometry commands or give PC scores as .json/.csv") from err
    return np.asarray(model.project(np.asarray(nodes, dtype=float)), dtype=float)


# --------------------------------------------------------------------------- output files
def write_result(result: CalibrationResult, out_dir, stem: str) -> dict:
    """Write ``<stem>_<model>.nc`` (InferenceData) and ``<stem>_<model>_summary.csv``; return the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    nc = diagnostics.save_netcdf(result.idata, out / f"{stem}_{result.model}.nc")
    csv = out / f"{stem}_{result.model}_summary.csv"
    result.summary.to_csv(csv)
    return {"netcdf": str(nc), "summary_csv": str(csv)}


def result_record(result: CalibrationResult) -> dict:
    """Plain-data summary (JSON-serialisable) of one result."""
    post = result.idata.posterior
    rec = {
        "model": result.model,
        "sampler": result.sampler,
        "wall_s": round(result.wall_s, 2),
        "converged": result.convergence.converged,
        "convergence": result.convergence.message(),
        "ess_per_s_min": round(result.ess_per_s["min"], 2),
    }
    for n in list(result.summary.index):
        vals = np.asarray(post[n]).reshape(-1)
        rec[n] = {"median": float(np.median(vals)), "q05": float(np.quantile(vals, 0.05)),
                  "q95": float(np.quantile(vals, 0.95))}
    return rec


__all__ = ["CalibrationResult", "SubjectResult", "calibrate", "calibrate_subjects", "read_pc_scores", "write_result",
           "result_record"]
