"""One calibration: measured data + geometry + forward model -> posterior, diagnostics, files.

This is the layer the CLI (``lvcore calibrate``), the app page, the
benchmarks and the studies share. :func:`calibrate` runs a model with
:func:`lvcore.inference.diagnostics.sample_until_converged` and wraps the
draws in ArviZ InferenceData; :func:`calibrate_subjects` does that for every
(subject, model) pair and writes netCDF plus a summary table per pair.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import arviz as az
import numpy as np
import pandas as pd

from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.exceptions import GeometryError
from lvcore.geometry.scores import read_pc_scores, read_scale  # noqa: F401 - the calibration's geometry inputs
from lvcore.inference import diagnostics, models, samplers
from lvcore.inference.data import validate_measurements
from lvcore.inference.loaded_states import has_extra_terms

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
        JAX-traceable, e.g. :func:`lvcore.emulator.load_emulator_forward` (``h`` bound in).
    model : str
        ``volume``, ``iid`` or ``discrepancy``.
    sampler : str
        ``auto`` (NUTS for volume/iid, HMC-within-Gibbs for discrepancy),
        ``nuts`` (joint NUTS for discrepancy too) or ``hmc_gibbs``.
    infer_angles : bool
        Sample alpha_endo, alpha_epi too (forward model must take them).
    progress : callable, optional
        ``progress(message, fraction)``.

    Examples
    --------
    Noise-free SYNTHETIC data of the analytic stand-in forward model (tests only), two short chains:

    >>> from lvcore.inference.calibrate import calibrate
    >>> from lvcore.inference.samplers import SamplerConfig
    >>> from lvcore.testing.analytic import AnalyticForward
    >>> forward = AnalyticForward()
    >>> y = forward({"a": 0.6, "b": 5.0, "af": 1.5, "bf": 5.0})      # [LVV (mL), 24 strains]
    >>> result = calibrate(y, forward, "iid", max_rounds=1,
    ...                    config=SamplerConfig(num_warmup=200, num_samples=200, num_chains=2))
    >>> result.model, result.sampler
    ('iid', 'nuts')
    >>> list(result.summary.columns[:5])          # q05-q95: the equal-tailed 90 % interval
    ['mean', 'sd', 'median', 'q05', 'q95']
    >>> bool(result.summary.loc["a", "q05"] < 0.6 < result.summary.loc["a", "q95"])
    True
    """
    y = validate_measurements(y)
    if model not in models.MODEL_NAMES:
        raise ValueError(f"unknown model '{model}'; choose one of {models.MODEL_NAMES}")
    if getattr(forward, "sample_latents", None) is not None and model == "discrepancy":
        # the blocked sampler's conditionals cover theta, the GP and b only; the sampled geometry needs joint NUTS
        if sampler == "hmc_gibbs":
            raise ValueError("--sampler hmc_gibbs cannot sample an inferred geometry (--geometry infer); "
                             "use --sampler auto or nuts (joint NUTS)")
        sampler = "nuts"
    if has_extra_terms(forward) and model == "discrepancy":
        # likewise for further loaded states and the Klotz prior (lvcore.inference.loaded_states)
        if sampler == "hmc_gibbs":
            raise ValueError("--sampler hmc_gibbs cannot use several loaded states or --prior klotz; "
                             "use --sampler auto or nuts (joint NUTS)")
        sampler = "nuts"
    kwargs = {"sigma_v": sigma_v, "infer_angles": infer_angles}
    run, conv = diagnostics.sample_until_converged(model, y, forward, config, sampler=sampler, rhat_max=rhat_max,
                                                   ess_min=ess_min, max_rounds=max_rounds, progress=progress,
                                                   **kwargs)
    label = getattr(forward, "label", type(forward).__name__)
    if model == "discrepancy":  # the GP's kernel (config.discrepancy_kernel), whichever sampler ran
        attrs = {"discrepancy_kernel": config.discrepancy_kernel, **(attrs or {})}
    idata = diagnostics.to_inference_data(run, y, convergence=conv, sigma_v=sigma_v, forward_label=label,
                                          extra_attrs=attrs, forward=forward)
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
    """Plain-data summary (JSON-serialisable) of one result; a discrepancy run's holds its GP kernel
    (``discrepancy_kernel``: ``"additive"``, the chapter's, or ``"product"``)."""
    post = result.idata.posterior
    rec = {
        "model": result.model,
        "sampler": result.sampler,
        "wall_s": round(result.wall_s, 2),
        "converged": result.convergence.converged,
        "convergence": result.convergence.message(),
        "ess_per_s_min": round(result.ess_per_s["min"], 2),
    }
    if result.model == "discrepancy":
        rec["discrepancy_kernel"] = str(result.idata.attrs.get("discrepancy_kernel", "additive"))
    for n in list(result.summary.index):
        vals = np.asarray(post[n]).reshape(-1)
        rec[n] = {"median": float(np.median(vals)), "q05": float(np.quantile(vals, 0.05)),
                  "q95": float(np.quantile(vals, 0.95))}
    return rec


def release_compiled_programs() -> None:
    """Let go of the programs the last calibration compiled (each subject's geometry is bound into its forward
    model, so every subject compiles its own): a process keeps a few memory mappings per program and the kernel caps
    them (``vm.max_map_count``; :mod:`lvcore.execution.restart`). Call it between subjects of a long run."""
    import gc

    import jax

    from lvcore.inference import verdict

    samplers.clear_sampler_cache()
    verdict.clear_best_fit_programs()
    jax.clear_caches()
    gc.collect()


__all__ = ["CalibrationResult", "SubjectResult", "calibrate", "calibrate_subjects", "read_pc_scores", "read_scale",
           "write_result",
           "result_record", "file_stem", "output_stems", "release_compiled_programs"]
