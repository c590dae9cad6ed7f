"""Fibre-angle Bayesian optimisation on the SYNTHETIC volunteers (chapter §9.3.1, Tables 9.2 and 9.3).

For each volunteer (measured LVV + 24 strains, early-diastolic geometry) the
material parameters θ = (a, b, af, bf) are fitted by the chapter's Bayesian
optimisation (:func:`lvcore.optimise.bayesopt.bayesian_optimise`: a 300-point
exp-warped Latin hypercube, then 300 GP-LCB iterations) in two modes:

``fixed`` (4-D)
    θ only, fibre helix angles fixed at (α_endo, α_epi) = (−60°, 90°);
``free`` (6-D)
    θ plus α_endo ∈ [−90°, 0°] and α_epi ∈ [0°, 90°].

The objective is evaluated by the FE simulator on the volunteer's own
geometry (:class:`lvcore.mechanics.SimulatorForward`), never an emulator: the
point of the study is the mismatch between the model with fixed angles and
the data. Batches run on the campaign executors (a local process pool or a
Dask cluster). Every evaluation is written to a state file
``DIR/state/<subject>_<mode>.json`` (atomically) as soon as its batch
returns, so a killed run resumes without repeating evaluations: on resume the
optimiser replays the recorded evaluations (same seed, same points, same
outputs) and continues where it stopped.

The volunteers' hidden truth (``volunteers/truth/``) is read only by
:func:`findings`, to report whether the angles found are near the hidden
ones; it is never used by the fit.

Outputs of :func:`write_outputs`: the result file :data:`RESULT_FILE` (a list, one entry per
subject and mode), ``bo_fibres_meta.json`` (budget, settings, findings),
``tables.csv`` (Tables 9.2/9.3 side by side) and figures (strain residuals
before/after optimising the angles, convergence curves).
"""
from __future__ import annotations

import collections
import json
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from lvcore import cli_args
from lvcore.core.forward import ForwardBatch, as_columns
from lvcore.mechanics.forward import SimulatorForward
from lvcore.domain.conditions import SIMULATOR_DEFAULT_ANGLES
from lvcore.core.space import ANGLE_BOUNDS, Parameter, ParameterSpace
from lvcore.exceptions import LVCoreError
from lvcore.domain.outputs import ANGLE_NAMES, N_OUTPUTS, THETA_NAMES
from lvcore.resources import asset_path
from lvcore.studies import registry
from lvcore.studies._common import (add_simulator_options, clean, comma_list, print_result, progress_bar,
                                    save_figure, study_executor, write_json_atomic)

#: Fibre angles (deg) of the fixed-angle mode (the chapter's Table 9.2): the simulator's default rule-based angles.
FIXED_ANGLES = SIMULATOR_DEFAULT_ANGLES
MODES = ("fixed", "free")
#: GP hyperparameters are re-estimated every this many BO iterations (warm started).
REFIT_EVERY = 20

#: The chapter's budget: 300-point exp design then 300 LCB iterations.
CHAPTER_INITIAL, CHAPTER_ITERATIONS = 300, 300
#: Chapter §9.3.1 (real volunteers, Tables 9.2 vs 9.3): optimising the angles lowered the LVV error for 8/8.
CHAPTER_FINDING = {"free_lvv_error_lower": "8/8",
                   "median_lvv_abs_error_ml": {"fixed": 18.89, "free": 5.92},
                   "median_median_abs_strain_error": {"fixed": 0.0409, "free": 0.0381}}
STATE_VERSION = 1
#: The BO objectives: the chapter's standardised RSS, or the regularised one (:func:`posterior_objective`).
OBJECTIVES = ("chapter", "posterior")
#: The regularised objective's prior on each stiffness (kPa): log-normal with median 1, the geometric centre of
#: the BO box [0.1, 10], and log-SD ln(10)/2, so the box's edges sit 2 SD out. Weakly informative and set by the
#: box alone, never by the volunteers' hidden θ.
THETA_PRIOR = (1.0, float(np.log(10.0) / 2.0))
#: Its prior on each free fibre angle (deg): normal about the middle of the angle's box, SD a quarter of the box's
#: width (the edges 2 SD out), by the same rule as the stiffnesses'. Not about the fixed pair: its α_epi (90°) is
#: the box's edge, where a prior would park every fit the data do not move.
ANGLE_PRIOR = {n: ((lo + hi) / 2.0, (hi - lo) / 4.0) for n, (lo, hi) in ANGLE_BOUNDS.items()}


class StudyStateError(LVCoreError):
    """A state file that does not belong to the run being resumed."""


# ----------------------------------------------------------------------------- subjects
@dataclass(frozen=True)
class Subject:
    """One bundled SYNTHETIC volunteer: ``name`` like ``SYNTHETIC-HV1``."""

    name: str
    measured: np.ndarray  # (25,) LVV (mL), 24 strains
    geometry: Path        # early-diastolic template mesh (.vtu)

    @property
    def stem(self) -> str:
        return self.name.replace("-", "_")


def available_subjects() -> list[str]:
    """Names of the bundled volunteers (``SYNTHETIC-HV1`` ...)."""
    d = asset_path("volunteers")
    stems = sorted(p.name[: -len("_measured.csv")] for p in d.glob("*_measured.csv"))
    return [s.replace("_", "-", 1) for s in sorted(stems, key=lambda s: (len(s), s))]


def load_subject(name: str) -> Subject:
    """The measured data and geometry of bundled volunteer ``name`` (``SYNTHETIC-HV3`` or ``SYNTHETIC_HV3``)."""
    from lvcore.inference.data import read_measured_csv

    stem = name.replace("-", "_")
    d = asset_path("volunteers")
    csv, vtu = d / f"{stem}_measured.csv", d / f"{stem}_geometry.vtu"
    if not (csv.is_file() and vtu.is_file()):
        raise LVCoreError(f"--subjects: volunteer '{name}' is not bundled (bundled: {', '.join(available_subjects())})")
    row = read_measured_csv(csv)[0]
    return Subject(row.subject, np.asarray(row.y, dtype=float), vtu)


def hidden_truth() -> dict:
    """The volunteers' hidden generating parameters (for the findings only, never the fit)."""
    path = asset_path("volunteers", "truth", "SYNTHETIC_volunteers_truth.json")
    return {v["subject"]: v for v in json.loads(path.read_text())["volunteers"]}


def posterior_objective(measured, mode: str):
    """The regularised BO objective of one run (:class:`lvcore.optimise.bayesopt.PosteriorObjective`): the
    calibration's noise model (σ_V, σ_S) plus :data:`THETA_PRIOR` on a, b, af, bf and, in ``free`` mode,
    :data:`ANGLE_PRIOR` on the angles."""
    from lvcore.domain.conditions import SIGMA_S, SIGMA_V_ML
    from lvcore.optimise.bayesopt import PosteriorObjective

    if mode not in MODES:
        raise LVCoreError(f"mode must be one of {MODES}, got {mode!r}")
    angles = {n: ANGLE_PRIOR[n] for n in ANGLE_NAMES} if mode == "free" else {}
    return PosteriorObjective(np.asarray(measured, dtype=float), SIGMA_V_ML, SIGMA_S,
                              {n: THETA_PRIOR for n in THETA_NAMES}, angles)


# ----------------------------------------------------------------------------- spaces and forwards
def bo_space(mode: str) -> ParameterSpace:
    """The optimisation box: a, b, af, bf in [0.1, 10] (the chapter's exp design), plus the angles when free."""
    if mode not in MODES:
        raise LVCoreError(f"mode must be one of {MODES}, got {mode!r}")
    params = tuple(Parameter(n, 0.1, 10.0) for n in THETA_NAMES)
    if mode == "free":
        params += tuple(Parameter(n, *ANGLE_BOUNDS[n]) for n in ANGLE_NAMES)
        return ParameterSpace("bo-fibres-free", params)
    return ParameterSpace("bo-fibres-fixed", params, tuple(zip(ANGLE_NAMES, FIXED_ANGLES)))


def simulator_forward(subject: Subject, mode: str, resolution: str = "default") -> SimulatorForward:
    """The FE simulator on the subject's geometry, reading the mode's inputs."""
    space = bo_space(mode)
    return SimulatorForward(input_names=space.names, conditions=space.fixed_dict(),
                            geometry={"kind": "mesh", "path": str(subject.geometry)}, resolution=resolution,
                            label=f"FE simulator on {subject.name} ({resolution})",
                            warm_start=True)  # warm-started chains (issue 25): same results within tolerance


# ----------------------------------------------------------------------------- state + recording forward
class EvaluationLog:
    """Every forward evaluation of one BO run, in order, saved to a JSON state file.

    The file holds the run's settings (checked on resume), the points, outputs,
    convergence flags and messages, and the wall time spent so far.
    """

    def __init__(self, path: Path | None, settings: dict):
        self.path = None if path is None else Path(path)
        self.settings = dict(settings)
        self.X: list[list[float]] = []
        self.Y: list[list[float]] = []
        self.converged: list[bool] = []
        self.messages: list[str] = []
        self.prior_seconds = 0.0  # wall time of earlier (interrupted) sessions
        self.session_start = time.perf_counter()
        self.iterations_done = 0
        if self.path is not None and self.path.is_file():
            self._load()

    def _load(self) -> None:
        try:
            d = json.loads(self.path.read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise StudyStateError(f"state file '{self.path}' is unreadable ({err}); delete it to start afresh") from None
        if d.get("version") != STATE_VERSION or d.get("settings") != self.settings:
            raise StudyStateError(
                f"state file '{self.path}' was written by a run with other settings "
                f"({d.get('settings')} vs {self.settings}); use another --out or delete the file")
        self.X, self.Y = d["X"], d["Y"]
        self.converged, self.messages = d["converged"], d["messages"]
        self.prior_seconds = float(d.get("seconds", 0.0))
        self.iterations_done = int(d.get("iterations_done", 0))

    @property
    def seconds(self) -> float:
        """Wall time of this run over every session (s)."""
        return self.prior_seconds + time.perf_counter() - self.session_start

    def __len__(self) -> int:
        return len(self.X)

    def save(self) -> None:
        if self.path is not None:
            write_json_atomic(self.path, {
                "version": STATE_VERSION, "settings": self.settings, "seconds": self.seconds,
                "iterations_done": self.iterations_done, "X": self.X, "Y": self.Y,
                "converged": self.converged, "messages": self.messages})

    def failures(self) -> dict:
        reasons = collections.Counter(m for m, ok in zip(self.messages, self.converged) if not ok)
        return {"count": int(sum(not ok for ok in self.converged)), "reasons": dict(reasons)}


class RecordingForward:
    """A :class:`~lvcore.core.Forward` that records every evaluation in an :class:`EvaluationLog`.

    The first ``len(log)`` evaluations asked for are answered from the log
    (their points must match the recorded ones exactly: the optimiser is
    deterministic for a given seed); later ones run on ``inner`` in chunks of
    ``chunk`` points, the log being saved after each chunk.
    """

    def __init__(self, inner, log: EvaluationLog, *, executor=None, chunk: int = 1, bar=None,
                 on_evaluation: Callable[[int], None] | None = None):
        self.inner, self.log, self.executor, self.chunk, self.bar = inner, log, executor, max(1, int(chunk)), bar
        self.input_names = tuple(inner.input_names)
        self.label = f"recorded {inner.label}"
        self.cursor = 0
        self.fresh = 0
        self.on_evaluation = on_evaluation

    @property
    def input_bounds(self):
        return self.inner.input_bounds

    def _inner_batch(self, cols: dict) -> ForwardBatch:
        if self.executor is not None and isinstance(self.inner, SimulatorForward):
            return self.inner.evaluate(cols, executor=self.executor)
        return self.inner.evaluate(cols)

    def evaluate(self, inputs) -> ForwardBatch:
        cols, n = as_columns(inputs, self.input_names, self.label)
        X = np.column_stack([cols[k] for k in self.input_names])
        rows: list[tuple] = []
        i = 0
        while i < n and self.cursor < len(self.log):
            if not np.array_equal(np.asarray(self.log.X[self.cursor]), X[i]):
                raise StudyStateError(
                    f"state file '{self.log.path}': evaluation {self.cursor} was recorded at "
                    f"{self.log.X[self.cursor]}, the optimiser now asks for {X[i].tolist()} (different code or "
                    "settings); use another --out or delete the file")
            rows.append((self.log.Y[self.cursor], self.log.converged[self.cursor], self.log.messages[self.cursor]))
            self.cursor += 1
            i += 1
            if self.bar is not None:
                self.bar.update(1)
        while i < n:
            j = min(n, i + self.chunk)
            b = self._inner_batch({k: X[i:j, c] for c, k in enumerate(self.input_names)})
            for r in range(b.n):
                rows.append((b.outputs[r].tolist(), bool(b.converged[r]), b.messages[r]))
                self.log.X.append(X[i + r].tolist())
                self.log.Y.append(b.outputs[r].tolist())
                self.log.converged.append(bool(b.converged[r]))
                self.log.messages.append(b.messages[r] or "")
            self.log.save()
            self.cursor += b.n
            self.fresh += b.n
            if self.bar is not None:
                self.bar.update(b.n)
            if self.on_evaluation is not None:
                self.on_evaluation(self.fresh)
            i = j
        y = np.array([r[0] for r in rows], dtype=float).reshape(n, N_OUTPUTS)
        return ForwardBatch(y, np.array([r[1] for r in rows], dtype=bool), tuple(r[2] for r in rows))

    def __call__(self, params):
        return self.evaluate({k: params[k] for k in self.input_names}).raise_on_failure().outputs[0]


# ----------------------------------------------------------------------------- one run
def run_one(subject: Subject, mode: str, *, n_initial: int = CHAPTER_INITIAL, n_iterations: int = CHAPTER_ITERATIONS,
            seed: int = 0, resolution: str = "default", state_dir=None, executor=None, workers: int = 1,
            forward=None, progress: bool = False, on_evaluation=None, refit_every: int = REFIT_EVERY,
            objective: str = "chapter") -> dict:
    """BO of one subject in one mode; returns its entry of the result file (:data:`RESULT_FILE`).

    Parameters
    ----------
    subject : Subject
    mode : {"fixed", "free"}
    n_initial, n_iterations : int
        Budget (chapter: 300 and 300).
    seed : int
    resolution : str
        Simulator mesh preset.
    state_dir : path, optional
        Folder of the state files (resume); None keeps no state.
    executor : campaign executor, optional
        Runs the simulator batches (local pool or Dask); None: in this process.
    workers : int
        Points per chunk of the initial design (state saved after each chunk).
    forward : Forward, optional
        Replaces the simulator (tests: :class:`lvcore.testing.AnalyticForward`).
    progress : bool
        Show a tqdm bar on stderr.
    on_evaluation : callable, optional
        ``on_evaluation(n_fresh)`` after each fresh chunk (tests interrupt runs with it).
    refit_every : int
        GP hyperparameters re-estimated every this many iterations (see
        :func:`lvcore.optimise.bayesopt.bayesian_optimise`); recorded in the
        state, since the points chosen depend on it.
    objective : {"chapter", "posterior"}
        The chapter's standardised RSS, or the regularised :func:`posterior_objective`; recorded in the state
        (a state of the other objective is refused on resume) and in the entry.
    """
    from sklearn.exceptions import ConvergenceWarning

    from lvcore.optimise.bayesopt import bayesian_optimise

    if objective not in OBJECTIVES:
        raise LVCoreError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    space = bo_space(mode)
    inner = forward if forward is not None else simulator_forward(subject, mode, resolution)
    settings = {"subject": subject.name, "mode": mode, "n_initial": int(n_initial), "seed": int(seed),
                "resolution": resolution if forward is None else inner.label, "refit_every": int(refit_every),
                "measured": [float(v) for v in subject.measured]}
    posterior = None
    if objective != "chapter":  # older states have no key: they are the chapter's
        settings["objective"] = objective
        posterior = posterior_objective(subject.measured, mode)
        settings["prior"] = {n: list(v) for n, v in {**posterior.log_prior, **posterior.normal_prior}.items()}
    path = None if state_dir is None else Path(state_dir) / f"{subject.stem}_{mode}.json"
    log = EvaluationLog(path, settings)
    total = n_initial + n_iterations
    with progress_bar(total, f"{subject.name} {mode}", progress) as bar:
        rec = RecordingForward(inner, log, executor=executor, chunk=max(1, 2 * int(workers)), bar=bar,
                               on_evaluation=on_evaluation)

        def callback(it, best):
            log.iterations_done = max(log.iterations_done, it + 1)
            bar.set_postfix(best=f"{best:.3g}")

        with warnings.catch_warnings():  # sklearn's GP hyperparameter bound warnings, hundreds per run
            warnings.simplefilter("ignore", ConvergenceWarning)
            res = bayesian_optimise(rec, subject.measured, space, n_initial=n_initial, n_iterations=n_iterations,
                                    seed=seed, refit_every=refit_every, callback=callback, objective=posterior)
    log.save()
    x = dict(zip(space.names, res.x_best.tolist()))
    angles = {n: x.get(n, space.fixed_dict().get(n)) for n in ANGLE_NAMES}
    residual = res.y_best - subject.measured
    return {
        "subject": subject.name,
        "mode": mode,
        "theta": {n: float(x[n]) for n in THETA_NAMES},
        "alpha_endo": float(angles["alpha_endo"]),
        "alpha_epi": float(angles["alpha_epi"]),
        "lvv_abs_error_ml": float(abs(residual[0])),
        "median_abs_strain_error": float(np.median(np.abs(residual[1:]))),
        "evaluations": len(log),
        "failed_evaluations": log.failures(),
        "seconds": round(log.seconds, 2),
        # beyond the format of issue 13 (kept for figures and the report)
        "objective": objective,
        "objective_best": float(res.f_best),
        "lvv_model_ml": float(res.y_best[0]),
        "lvv_measured_ml": float(subject.measured[0]),
        "strain_residuals": [float(v) for v in residual[1:]],
        "convergence": [float(v) for v in res.best_so_far()],
        "n_initial": int(n_initial),
        "n_iterations": int(n_iterations),
        "seed": int(seed),
        "refit_every": int(refit_every),
        "resolution": settings["resolution"],
        "fresh_evaluations": rec.fresh,
        **({"chi2_best": float(posterior.misfit(res.y_best)[0]),
            "prior_penalty_best": float(posterior.penalty(space.names, res.x_best)[0])} if posterior else {}),
    }


# ----------------------------------------------------------------------------- the study
def run_study(subjects: Sequence[str] | None = None, *, modes: Sequence[str] = MODES, out=None,
              n_initial: int = CHAPTER_INITIAL, n_iterations: int = CHAPTER_ITERATIONS, workers: int = 1,
              scheduler: str | None = None, seed: int = 0, resolution: str = "default", progress: bool = False,
              forward_factory: Callable | None = None, log: Callable[[str], None] | None = None,
              refit_every: int = REFIT_EVERY) -> list[dict]:
    """Run the BO of every subject and mode; write the result file (:data:`RESULT_FILE`) etc. under ``out`` when
    ``out`` is given.

    ``forward_factory(subject, mode)`` replaces the simulator (tests). With
    ``workers > 1`` or a ``scheduler``, simulator batches run on one executor
    shared by every run.
    """
    names = list(subjects) if subjects else available_subjects()
    subs = [load_subject(n) for n in names]
    for m in modes:
        bo_space(m)
    state_dir = None if out is None else Path(out) / "state"
    entries = []
    with study_executor(workers, scheduler, local=forward_factory is not None) as executor:
        for s in subs:
            for m in modes:
                fwd = forward_factory(s, m) if forward_factory is not None else None
                e = run_one(s, m, n_initial=n_initial, n_iterations=n_iterations, seed=seed, resolution=resolution,
                            state_dir=state_dir, executor=executor, workers=workers, forward=fwd, progress=progress,
                            refit_every=refit_every)
                entries.append(e)
                if log is not None:
                    log(f"{s.name} {m:5s}: LVV error {e['lvv_abs_error_ml']:.2f} mL, median |strain error| "
                        f"{e['median_abs_strain_error']:.4f}, angles ({e['alpha_endo']:.0f}, {e['alpha_epi']:.0f}), "
                        f"{e['evaluations']} evaluations ({e['failed_evaluations']['count']} failed), "
                        f"{e['seconds']:.0f} s")
                if out is not None:  # partial results after every run
                    write_json_atomic(Path(out) / RESULT_FILE, clean(entries))
    if out is not None:
        write_outputs(entries, out, settings={"n_initial": n_initial, "n_iterations": n_iterations, "seed": seed,
                                              "refit_every": refit_every,
                                              "resolution": resolution, "workers": workers,
                                              "executor": "dask" if scheduler else "local"})
    return entries


# ----------------------------------------------------------------------------- findings, tables, figures
def budget_label(n_initial: int, n_iterations: int) -> str:
    full = (n_initial, n_iterations) == (CHAPTER_INITIAL, CHAPTER_ITERATIONS)
    return (f"{n_initial} + {n_iterations} evaluations" + (" (the chapter's full budget)" if full
            else f" (REDUCED budget; the chapter used {CHAPTER_INITIAL} + {CHAPTER_ITERATIONS})"))


def findings(entries: Sequence[dict], truth: dict | None = None) -> dict:
    """How often free angles beat fixed ones on LVV error, and how near the found angles are to the hidden ones."""
    by = {(e["subject"], e["mode"]): e for e in entries}
    subjects = sorted({e["subject"] for e in entries}, key=lambda s: (len(s), s))
    pairs = [(by[(s, "fixed")], by[(s, "free")]) for s in subjects if (s, "fixed") in by and (s, "free") in by]
    out = {"n_subjects_both_modes": len(pairs), "chapter": CHAPTER_FINDING}
    if pairs:
        lvv_better = [fr["lvv_abs_error_ml"] < fx["lvv_abs_error_ml"] for fx, fr in pairs]
        strain_better = [fr["median_abs_strain_error"] < fx["median_abs_strain_error"] for fx, fr in pairs]
        out.update({
            "free_lvv_error_lower": int(sum(lvv_better)),
            "free_lvv_error_lower_share": float(np.mean(lvv_better)),
            "free_strain_error_lower": int(sum(strain_better)),
            "median_lvv_abs_error_ml": {m: float(np.median([p[i]["lvv_abs_error_ml"] for p in pairs]))
                                        for i, m in enumerate(MODES)},
            "median_median_abs_strain_error": {m: float(np.median([p[i]["median_abs_strain_error"] for p in pairs]))
                                               for i, m in enumerate(MODES)},
        })
    truth = hidden_truth() if truth is None else truth
    rows = []
    for e in entries:
        if e["mode"] != "free" or e["subject"] not in truth:
            continue
        t = truth[e["subject"]]["fibres_deg"]
        rows.append({"subject": e["subject"], "alpha_endo": e["alpha_endo"], "alpha_epi": e["alpha_epi"],
                     "hidden_alpha_endo": t["alpha_endo"], "hidden_alpha_epi": t["alpha_epi"],
                     "error_endo_deg": e["alpha_endo"] - t["alpha_endo"], "error_epi_deg": e["alpha_epi"] - t["alpha_epi"]})
    if rows:
        out["angles_vs_hidden"] = rows
        out["median_abs_angle_error_deg"] = {
            "alpha_endo": float(np.median([abs(r["error_endo_deg"]) for r in rows])),
            "alpha_epi": float(np.median([abs(r["error_epi_deg"]) for r in rows]))}
        out["within_15deg_both"] = int(sum(abs(r["error_endo_deg"]) <= 15 and abs(r["error_epi_deg"]) <= 15 for r in rows))
    return out


#: Result file of :func:`write_outputs`, read by :func:`load`.
RESULT_FILE = registry.result_file("bo-fibres")
#: The command that makes the results.
COMMAND = "lvcore study bo-fibres --out RESULTS"
#: Figures and tables :func:`figures` draws, with their titles.
TITLES = {"table9_2_bo_fixed_angles": "Table 9.2: BO of θ with the angles fixed at (−60°, 90°)",
          "table9_3_bo_free_angles": "Table 9.3: BO of θ and the fibre angles",
          "fig_bo_lvv_error": "Tables 9.2/9.3: LVV and strain errors, fixed vs free angles",
          "fig_strain_residuals": "Strain residuals at the BO optimum, fixed vs free angles",
          "fig_convergence": "BO convergence per volunteer and mode"}
#: Columns of the tables (one row per subject and mode) and their headers in the drawn tables.
COLUMNS = {"subject": "subject", "a": "a (kPa)", "b": "b", "af": "af (kPa)", "bf": "bf",
           "alpha_endo": "α_endo (°)", "alpha_epi": "α_epi (°)", "lvv_abs_error_ml": "LVV |error| (mL)",
           "median_abs_strain_error": "median |strain error|", "evaluations": "evaluations", "failed": "failed"}
_MODE_TABLES = {"fixed": ("table9_2_bo_fixed_angles", "Table 9.2 — angles fixed at (−60°, 90°)"),
                "free": ("table9_3_bo_free_angles", "Table 9.3 — θ and the fibre angles optimised")}


def _failed_count(v) -> int | None:
    """``failed_evaluations`` as a count (the study writes ``{"count", "reasons"}``; older files an int)."""
    if isinstance(v, dict):
        return int(v.get("count", 0))
    return None if v is None else int(v)


def load(folder) -> dict:
    """The results of a bo-fibres ``--out`` folder (or the bundled one).

    Returns
    -------
    dict
        ``entries`` (the result file's list), ``meta`` (``bo_fibres_meta.json``,
        or just the findings when that file is missing) and ``folder``.

    Examples
    --------
    The bundled (SYNTHETIC) result:

    >>> from lvcore.studies import bo_fibres
    >>> from lvcore.studies.results import bundled_studies_dir
    >>> result = bo_fibres.load(bundled_studies_dir())
    >>> sorted({e["mode"] for e in result["entries"]})   # fibre angles fixed at the rule's values, or optimised
    ['fixed', 'free']
    """
    from lvcore.studies.results import read_json

    folder = Path(folder)
    entries = read_json(folder / RESULT_FILE)
    if isinstance(entries, dict):  # {"results": [...]} wrapping
        entries = entries.get("results", [])
    meta_path = folder / "bo_fibres_meta.json"
    meta = read_json(meta_path) if meta_path.is_file() else {}
    if not meta:
        meta = {"findings": findings(entries)}
    return {"entries": entries, "meta": meta, "folder": str(folder)}


def source_line(result: dict) -> str:
    """Where the numbers come from, as one readable line."""
    from lvcore.studies.results import source_label

    budget = result["meta"].get("budget", {}).get("label")
    return f"{RESULT_FILE} ({source_label(result['folder'])})" + (f"; budget {budget}" if budget else "")


def table_rows(entries: Sequence[dict]):
    """One row per subject and mode (``mode`` and :data:`COLUMNS`), in file order."""
    import pandas as pd

    rows = []
    for e in entries:
        th = e.get("theta", {})
        th = th if isinstance(th, dict) else dict(zip(THETA_NAMES, th))
        rows.append({"subject": e["subject"], "mode": e["mode"], **{n: float(th[n]) for n in THETA_NAMES if n in th},
                     "alpha_endo": e.get("alpha_endo"), "alpha_epi": e.get("alpha_epi"),
                     "lvv_abs_error_ml": e.get("lvv_abs_error_ml"),
                     "median_abs_strain_error": e.get("median_abs_strain_error"),
                     "evaluations": e.get("evaluations"), "failed": _failed_count(e.get("failed_evaluations"))})
    return pd.DataFrame(rows, columns=["subject", "mode", *list(COLUMNS)[1:]])


def side_by_side(entries: Sequence[dict]):
    """Tables 9.2 (fixed angles) and 9.3 (free angles) side by side, one row per subject (``<mode>_<column>``)."""
    import pandas as pd

    long = table_rows(entries)
    rows = {}
    for _, r in long.iterrows():
        row = rows.setdefault(r["subject"], {"subject": r["subject"]})
        row.update({f"{r['mode']}_{c}": r[c] for c in list(COLUMNS)[1:]})
    df = pd.DataFrame(list(rows.values()))
    return df.sort_values("subject", key=lambda c: c.str.len() * 1000 + c.str[-1].map(ord)).reset_index(drop=True)


def tables(result: dict) -> dict:
    """The study's tables (DataFrames) by name: Tables 9.2 and 9.3, both side by side, all rows, the found angles."""
    import pandas as pd

    entries = result["entries"]
    long = table_rows(entries)
    out = {}
    for mode, (name, _) in _MODE_TABLES.items():
        sub = long[long["mode"] == mode].drop(columns=["mode"]).reset_index(drop=True)
        if not sub.empty:
            out[name] = sub
    out["tables_9_2_9_3"] = side_by_side(entries)
    out["fig_bo_lvv_error"] = long
    hidden = result["meta"].get("findings", {}).get("angles_vs_hidden")
    if hidden:
        out["angles_vs_hidden"] = pd.DataFrame(hidden)
    return out


def figures(result: dict) -> dict:
    """The study's figures by name (see :data:`TITLES`); figures whose data the results lack are left out."""
    from lvcore.viz import study_figures
    from lvcore.viz.report_figures import table_figure

    entries = result["entries"]
    tabs = tables(result)
    out = {}
    for mode, (name, label) in _MODE_TABLES.items():
        if name in tabs:
            out[name] = table_figure(tabs[name].rename(columns=COLUMNS),
                                     title=f"{label} (SYNTHETIC volunteers, Bayesian optimisation)")
    if entries:
        out["fig_bo_lvv_error"] = study_figures.bo_error_bars(tabs["fig_bo_lvv_error"])
    if any(e.get("strain_residuals") for e in entries):
        out["fig_strain_residuals"] = study_figures.residual_figure(entries)
    if any(e.get("convergence") for e in entries):
        out["fig_convergence"] = study_figures.convergence_figure(entries)
    return out


def write_outputs(entries: Sequence[dict], out, settings: dict | None = None) -> dict:
    """Write the result file (:data:`RESULT_FILE`), ``bo_fibres_meta.json``, ``tables.csv`` and the figures under
    ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    settings = dict(settings or {})
    n0 = settings.get("n_initial", entries[0]["n_initial"] if entries else 0)
    n1 = settings.get("n_iterations", entries[0]["n_iterations"] if entries else 0)
    paths = {"json": str(write_json_atomic(out / RESULT_FILE, clean(list(entries))))}
    meta = {"study": "bo-fibres", "label": "SYNTHETIC volunteers (generated data, not real subjects)",
            "budget": {"n_initial": n0, "n_iterations": n1, "label": budget_label(n0, n1),
                       "chapter_budget": n0 >= CHAPTER_INITIAL and n1 >= CHAPTER_ITERATIONS},
            "subjects": sorted({e["subject"] for e in entries}, key=lambda s: (len(s), s)),
            "runs": [f"{e['subject']} {e['mode']}" for e in entries],
            "complete_study": len({(e["subject"], e["mode"]) for e in entries}) == 2 * len(available_subjects()),
            "objective": "FE simulator on each volunteer's geometry", "settings": settings,
            "findings": findings(entries)}
    paths["meta"] = str(write_json_atomic(out / "bo_fibres_meta.json", clean(meta)))
    side_by_side(entries).to_csv(out / "tables.csv", index=False)
    paths["tables"] = str(out / "tables.csv")
    figs = figures({"entries": list(entries), "meta": meta, "folder": str(out)})
    paths["fig_residuals"] = save_figure(figs["fig_strain_residuals"], out / "fig_strain_residuals")
    paths["fig_convergence"] = save_figure(figs["fig_convergence"], out / "fig_convergence")
    return paths


def format_findings(meta_findings: dict) -> str:
    f = meta_findings
    lines = []
    if f.get("n_subjects_both_modes"):
        n = f["n_subjects_both_modes"]
        ch = f["chapter"] if isinstance(f.get("chapter"), dict) else CHAPTER_FINDING
        lines.append(f"free angles lowered the LVV error for {f['free_lvv_error_lower']}/{n} volunteers "
                     f"(chapter: {ch['free_lvv_error_lower']}); median LVV error fixed "
                     f"{f['median_lvv_abs_error_ml']['fixed']:.2f} mL, free {f['median_lvv_abs_error_ml']['free']:.2f} mL "
                     f"(chapter {ch['median_lvv_abs_error_ml']['fixed']} and {ch['median_lvv_abs_error_ml']['free']} mL)")
        lines.append(f"median |strain error| fixed {f['median_median_abs_strain_error']['fixed']:.4f}, "
                     f"free {f['median_median_abs_strain_error']['free']:.4f} "
                     f"(free lower for {f['free_strain_error_lower']}/{n})")
    if "angles_vs_hidden" in f:
        lines.append(f"found angles vs hidden: median |error| alpha_endo {f['median_abs_angle_error_deg']['alpha_endo']:.1f} deg, "
                     f"alpha_epi {f['median_abs_angle_error_deg']['alpha_epi']:.1f} deg; both within 15 deg for "
                     f"{f['within_15deg_both']}/{len(f['angles_vs_hidden'])}")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- CLI
def add_budget_options(parser, n_initial: int, n_iterations: int, *, per_run: bool = False, note: str = "") -> None:
    """``--initial`` (size of the exp design, at least 2) and ``--iterations`` (LCB iterations) of a BO study, with
    their defaults; ``per_run``: the study runs several BOs, each with this budget; ``note`` follows the defaults."""
    each = " of each run" if per_run else ""
    parser.add_argument("--initial", type=cli_args.int_in(2, 100_000), default=n_initial,
                        help=f"size of the exp design{each}, 2 to 100,000 (default {n_initial}{note})")
    parser.add_argument("--iterations", type=cli_args.int_in(0, 100_000), default=n_iterations,
                        help=f"LCB iterations{each}, 0 to 100,000 (default {n_iterations}{note})")


def add_study_parser(study_subparsers) -> None:
    """``lvcore study bo-fibres``."""
    p = study_subparsers.add_parser("bo-fibres", help="§9.3.1: BO of theta with fixed vs free fibre angles "
                                                      "(FE simulator, SYNTHETIC volunteers; Tables 9.2/9.3)")
    p.add_argument("--subjects", default=None, help="comma-separated, e.g. SYNTHETIC-HV1,SYNTHETIC-HV2 (default: all 8)")
    p.add_argument("--modes", default="fixed,free", help="fixed, free or both (default)")
    add_budget_options(p, CHAPTER_INITIAL, CHAPTER_ITERATIONS, note=", the chapter's")
    add_simulator_options(p)
    p.add_argument("--seed", type=cli_args.seed, default=0, help="random seed, 0 to 2^32 - 1 (default 0)")
    p.add_argument("--refit-every", type=int, default=REFIT_EVERY,
                   help=f"re-estimate the GP hyperparameters every N iterations (default {REFIT_EVERY})")
    p.add_argument("--json", action="store_true", help="print the entries and findings as JSON")
    p.add_argument("--out", type=cli_args.output_dir, required=True, help="output folder (state files for resuming go to OUT/state)")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    subjects = comma_list(args.subjects) if args.subjects else None
    modes = comma_list(args.modes)
    if args.refit_every < 1:
        raise LVCoreError("--refit-every must be >= 1")
    entries = run_study(subjects, modes=modes, out=args.out, n_initial=args.initial, n_iterations=args.iterations,
                        workers=args.workers, scheduler=args.scheduler, seed=args.seed, resolution=args.resolution,
                        progress=not args.json, log=None if args.json else print, refit_every=args.refit_every)
    meta = json.loads((Path(args.out) / "bo_fibres_meta.json").read_text())
    return print_result(args.json, {"entries": clean(entries), "meta": meta},
                        lambda: f"{format_findings(meta['findings'])}\nbudget: {meta['budget']['label']}; wrote "
                                f"{args.out}/{RESULT_FILE}, tables.csv and figures")
