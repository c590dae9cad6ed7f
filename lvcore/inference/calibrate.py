"""One calibration: measured data + geometry + forward model -> posterior, diagnostics, files.

This is the layer the CLI (``lvcore calibrate``), the app page, the
benchmarks and the studies share. :func:`calibrate` runs a model with
:func:`lvcore.inference.diagnostics.sample_until_converged` and wraps the
draws in ArviZ InferenceData; :func:`calibrate_subjects` does that for every
(subject, model) pair and writes netCDF plus a summary table per pair.
"""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import arviz as az
import numpy as np
import pandas as pd

from lvcore import limits
from lvcore.core.space import SIGMA_V_ML
from lvcore.exceptions import GeometryError
from lvcore.inference import diagnostics, models, samplers
from lvcore.inference.data import validate_measurements
from lvcore.outputs import is_pc_name

#: Number format of the summary CSV: 6 significant digits, so sigma_s2 ~ 1e-4 is not rounded to 0.0.
SUMMARY_FLOAT_FORMAT = "%.6g"


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
        Write ``<stem>_<model>.nc`` and ``_summary.csv`` there (:func:`write_result`), ``<stem>``
        the subject's :func:`file_stem`; subjects with equal stems are refused (``DataError``).
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
    # safe, unique file names, checked before any sampling (duplicates would overwrite each other's files)
    stems = output_stems([str(s[0]) for s in subjects], source="subjects") if out_dir is not None else None
    pairs = [(s, m) for s in subjects for m in model_names]
    out = []
    for k, ((subject, y, forward), m) in enumerate(pairs):
        def step(msg, frac, k=k, tag=f"[{subject} / {m}]"):
            progress(f"{tag} {msg}", (k + frac) / len(pairs))

        res = calibrate(y, forward, m, config=config, sampler=sampler, sigma_v=sigma_v, infer_angles=infer_angles,
                        progress=None if progress is None else step, attrs={"subject": str(subject), **(attrs or {})})
        files = write_result(res, out_dir, stems[k // len(model_names)]) if out_dir is not None else {}
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
    path = limits.check_regular_file(path, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
    suffix = path.suffix.lower()
    if suffix == ".json":
        obj = limits.read_json_file(path, limits.MAX_SCORES_BYTES, "geometry file", GeometryError)
        if isinstance(obj, dict):
            if "h" in obj:
                h = obj["h"]
            else:
                keys = sorted((k for k in obj if is_pc_name(k)), key=lambda k: int(k[1:]))
                h = [obj[k] for k in keys]
        else:
            h = obj
        h = _score_list(h, path.name)
    elif suffix == ".csv":
        limits.check_regular_file(path, limits.MAX_SCORES_BYTES, "geometry file", GeometryError)
        try:
            df = pd.read_csv(path)
            cols = [c for c in df.columns if is_pc_name(c)]
            if cols:
                cols = sorted(cols, key=lambda c: int(str(c)[1:]))
                h = df.loc[0, cols].to_numpy(dtype=float)
            else:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # "input contained no data": reported below
                    h = np.loadtxt(path, delimiter=",", ndmin=1).reshape(-1)
        except (ValueError, TypeError, KeyError, IndexError, OverflowError, UnicodeDecodeError,
                pd.errors.ParserError, pd.errors.EmptyDataError) as err:
            raise GeometryError(f"{path.name}: cannot read PC scores from this CSV ({type(err).__name__}: "
                                f"{str(err)[:200]}); give columns h1..h5 or one row of numbers") from None
    elif suffix in (".vtu", ".vtk", ".xdmf", ".npy", ".npz"):
        h = _project_mesh(path)
    else:
        raise GeometryError(f"{path.name}: unknown geometry format '{suffix}'; give PC scores as .json/.csv "
                            "or a template mesh (.vtu, .vtk, .xdmf, .npy, .npz)")
    try:
        h = np.asarray(h, dtype=float).reshape(-1)
    except (TypeError, ValueError, OverflowError):
        raise GeometryError(f"{path.name}: PC scores must be numbers") from None
    if h.size < n_pc:
        raise GeometryError(f"{path.name}: need {n_pc} PC scores, found {h.size}")
    if not np.all(np.isfinite(h[:n_pc])):
        raise GeometryError(f"{path.name}: PC scores must be finite numbers")
    return h[:n_pc]


def _score_list(h, name: str) -> list:
    """The scores of a JSON geometry file: a flat list of numbers."""
    if not isinstance(h, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in h):
        raise GeometryError(f"{name}: PC scores must be a list of numbers ({{\"h\": [h1, h2, ...]}}, "
                            f"{{\"h1\": ..., \"h2\": ...}} or [h1, h2, ...])")
    return h


def read_scale(path) -> float:
    """The uniform scale ``s`` stored with PC scores (JSON key or CSV column ``scale``); 1 when absent.

    ``s`` is the factor of :mod:`lvcore.geometry.scaling`: the geometry is
    ``s`` times the shape with the stored scores, and the emulated LVV is
    multiplied by ``s^3``.

    Raises
    ------
    GeometryError
        If the scale is not a number in :data:`lvcore.geometry.scaling.SCALE_BOUNDS`.
    """
    from lvcore.geometry.scaling import SCALE_BOUNDS

    path = Path(path)
    value = None
    if path.suffix.lower() == ".json":
        obj = limits.read_json_file(path, limits.MAX_SCORES_BYTES, "geometry file", GeometryError)
        if isinstance(obj, dict):
            value = obj.get("scale")
    elif path.suffix.lower() == ".csv":
        try:
            df = pd.read_csv(path)
        except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
            return 1.0
        if "scale" in df.columns and len(df):
            value = df.loc[0, "scale"]
    if value is None:
        return 1.0
    try:
        s = float(value)
    except (TypeError, ValueError):
        raise GeometryError(f"{path.name}: 'scale' must be a number, got {str(value)[:40]!r}") from None
    if isinstance(value, bool) or not (np.isfinite(s) and SCALE_BOUNDS[0] <= s <= SCALE_BOUNDS[1]):
        raise GeometryError(f"{path.name}: scale = {value} is outside {SCALE_BOUNDS[0]:g}-{SCALE_BOUNDS[1]:g}; it is "
                            "the uniform size factor of the geometry (1 = the shape with these scores as it is)")
    return s


def _project_mesh(path: Path, n_pc: int | None = None, with_scale: bool = False):
    """Scores of a template mesh file: the plain projection, or with ``with_scale``
    ``(h, scale, projection MSE (cm²), unscaled h)`` of :func:`lvcore.geometry.scaling.size_normalised_scores`."""
    from lvcore.geometry.io import _check_nodes, read_template_mesh
    from lvcore.geometry.template import DEFAULT_TEMPLATE

    if path.suffix.lower() in (".npy", ".npz"):
        try:
            from lvcore import limits
            from lvcore.headers import load_npy, load_npz

            # array headers are checked against the limits before numpy allocates (lvcore.headers)
            if path.suffix.lower() == ".npy":
                nodes = load_npy(path, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
            else:
                arrays = load_npz(path, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
                if not arrays:
                    raise GeometryError(f"{path.name}: the .npz archive holds no arrays; store the template "
                                        "node positions as 'nodes'")
                nodes = arrays["nodes"] if "nodes" in arrays else next(iter(arrays.values()))
            if not (np.issubdtype(nodes.dtype, np.integer) or np.issubdtype(nodes.dtype, np.floating)):
                raise GeometryError(f"{path.name}: node positions must be real numbers, got an array of {nodes.dtype}")
            nodes = np.asarray(nodes, dtype=float)
        except GeometryError:
            raise
        except (ValueError, TypeError, OSError, EOFError, KeyError, OverflowError) as err:
            raise GeometryError(f"{path.name}: cannot read node positions ({type(err).__name__}: {str(err)[:200]}); "
                                "give a numeric (n_nodes, 3) array of the template's nodes in mm") from None
        nodes = _check_nodes(nodes, DEFAULT_TEMPLATE, path.name)
    else:
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
    if with_scale:
        from lvcore.geometry.scaling import size_normalised_scores

        res = size_normalised_scores(np.asarray(nodes, dtype=float), n_pc or 5, model)
        return res.h, res.scale, res.projection_mse_cm2, res.unscaled_h
    return np.asarray(model.project(np.asarray(nodes, dtype=float)), dtype=float)


# --------------------------------------------------------------------------- output files
#: Longest file stem made from a subject name.
MAX_STEM_LENGTH = 64


def file_stem(subject: str) -> str:
    """A safe file-name stem for a subject name: letters, digits, ``.``, ``_`` and ``-`` only.

    Path separators, ``..``, leading dots, control characters and anything
    else become ``_``; the stem is cut to :data:`MAX_STEM_LENGTH` characters
    and is never empty. The subject name itself is kept in the data
    (``attrs["subject"]``, ``summary.json``).
    """
    stem = re.sub(r"[^A-Za-z0-9._-]", "_", str(subject))
    stem = re.sub(r"\.{2,}", "_", stem).lstrip(".-_")[:MAX_STEM_LENGTH].rstrip(".")
    return stem or "subject"


def output_stems(subjects, source: str = "measured data") -> list[str]:
    """:func:`file_stem` of each subject; refuses duplicates (which would overwrite each other's files).

    Raises
    ------
    DataError
        Naming both rows when two subjects are equal or map to the same file stem.
    """
    from lvcore.exceptions import DataError

    seen: dict[str, int] = {}
    stems = []
    for i, subject in enumerate(subjects):
        stem = file_stem(subject)
        key = stem.lower()  # case-insensitive file systems
        if key in seen:
            j = seen[key]
            same = "the same subject ID" if subjects[j] == subject else f"the same file name '{stem}'"
            raise DataError(f"{source}: rows {j + 1} ('{str(subjects[j])[:80]}') and {i + 1} ('{str(subject)[:80]}') "
                            f"have {same}; subject IDs must be unique, or their result files would overwrite "
                            "each other")
        seen[key] = i
        stems.append(stem)
    return stems


def write_result(result: CalibrationResult, out_dir, stem: str) -> dict:
    """Write ``<stem>_<model>.nc`` (InferenceData) and ``<stem>_<model>_summary.csv``; return the paths.

    ``stem`` is made safe with :func:`file_stem`, so nothing is written outside ``out_dir``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = file_stem(stem)
    nc_path, csv = out / f"{stem}_{result.model}.nc", out / f"{stem}_{result.model}_summary.csv"
    for p in (nc_path, csv):
        if p.resolve().parent != out.resolve():  # pragma: no cover - file_stem already prevents it
            raise GeometryError(f"refusing to write '{p}' outside the output folder '{out}'")
    nc = diagnostics.save_netcdf(result.idata, nc_path)
    result.summary.to_csv(csv, float_format=SUMMARY_FLOAT_FORMAT)
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


__all__ = ["CalibrationResult", "SubjectResult", "calibrate", "calibrate_subjects", "read_pc_scores", "read_scale",
           "write_result",
           "result_record", "file_stem", "output_stems"]
