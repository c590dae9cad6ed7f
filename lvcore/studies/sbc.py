r"""Simulation-based calibration (Talts et al. 2018) of the whole calibration pipeline: ``lvcore study sbc``.

If data are simulated from parameters drawn from the prior, and the posterior
is computed correctly, the rank of the true value among L posterior draws is
uniform on ``{0, ..., L}``. This study checks that for the pipeline a user
runs, end to end, on SYNTHETIC subjects:

* **Subjects** (SYNTHETIC, from ``--seed``): θ = (a, b, af, bf) from the
  calibration prior (uniform on :data:`lvcore.core.space.THETA_BOUNDS`); the
  geometry from the bundled shape model, PC scores ``h ~ N(0, 1)`` truncated
  to ±2 (5 scores, the ``chapter`` emulator's box) and a scale ``s`` such that
  the reference cavity ``V_ref = s³ V_cav(h)`` is log-uniform in 40–200 mL;
  the ``chapter`` emulator's training conditions (EDP 8 mmHg, fibre angles
  −60°/60°, sliding base, ``default`` mesh). The EDP is fixed at 8 mmHg: the
  ``chapter`` emulator is trained at 8 mmHg only, so an EDP range of 4–20
  mmHg could not be drawn.
* **Truth by the FE simulator** (not the emulator): the data (LVV × s³ and the
  24 strains at 8 mmHg) by :func:`lvcore.mechanics.simulate.simulate`, the
  EDPVR (V0, V20, V30) by :func:`lvcore.inference.derived.fe_load_path`, the
  fibre stress at the fixed stretch 1.10 by
  :func:`lvcore.mechanics.stress.ho_fibre_stress`. A prior draw whose FE solve
  fails is redrawn (counted). Noise: σ_V = 5 mL on the LVV, σ_S = 0.03 on each
  strain, iid Gaussian.
* **Two routes through** ``lvcore calibrate`` (model iid, 2 chains,
  ``--derived-draws D``), in-process: ``mesh`` gives the subject's template
  mesh (the shape at scale s, a ``.vtu``; the command size-normalises and
  projects it), ``infer`` gives ``--geometry infer --reference-volume V`` with
  ``V = V_ref + N(0, 5 mL)``. The study layer may not import ``lvcore.cli``
  (the layers contract), so the sub-command runs through its own parser and
  handler (:mod:`lvcore.inference.cli`) with ``lvcore.cli.main``'s mapping of
  exceptions to exit codes (:func:`calibrate_in_process`; a test checks both
  agree).
* **Statistics** per route and quantity: the rank of the truth among the draws
  (draws below the truth; ties broken at random): a, b, af, bf and the fibre
  stress among L = 100 evenly thinned posterior draws (the stress is the HO
  law's closed form of each θ draw), V0, V20, V30 among the D derived FE
  draws (``*_derived.npz``, ``--derived-pressures 20,30``: the FE solves the
  ranks need; failed solves left out). A 10-bin rank histogram
  with the χ² test of uniformity (expected counts exact for each subject's
  L; no p-value below 5 expected per bin, i.e. under 50 subjects); the
  empirical coverage of the central 50 % and 90 % intervals from the ranks
  (inside when ``(rank + 0.5)/(L + 1)`` lies in ``[(1 − level)/2,
  1 − (1 − level)/2]``) with a Wilson 95 % CI, and beside it the coverage a
  perfectly calibrated posterior gets with the same L (``nominal_*_at_L``: for
  L = 20 it is 90.5 % and 52.4 %, not 90 % and 50 %); for V20 and V30 the
  median over subjects of ``(q95 − q05)/truth``; for V0, V20, V30 the median
  over subjects of ``|median − truth|/truth``. Runs exiting 0 (fine) or 4
  (ran, results flagged) enter the statistics (``all_runs``: every run that
  left a posterior, exit 1 included); the share exiting 4 and the flag kinds
  are reported, other exit codes are counted with their reason.

**Resumable, in pieces.** ``lvcore study sbc --piece K/N`` (or ``--start``/
``--stop``) writes one JSON line per finished subject to
``WORKDIR/subjects_<start>-<stop>.jsonl``; a rerun skips finished subjects (a
killed run loses the subject in flight; a half-written last line is cut off).
Two pieces run at the same time in two processes. Subject ``i``'s draws depend
only on ``(seed, i)``. ``lvcore study sbc --summarise --workdir W --out
sbc.json`` builds the result from whatever is finished
(:func:`summarise`), with the per-subject records in the JSON and in
``sbc_subjects.csv`` beside it.

Caveats the numbers carry: the geometry of the draws is not the ``infer``
route's prior (its scale is log-uniform on 0.5–1.8, here V_ref is
log-uniform on 40–200 mL), the shape-model subjects get the default
representation-error floor (extra variance for a shape the model
represents exactly), and the emulator differs from the FE truth; SBC
measures the pipeline with all of these, as a user runs it. In the ``mesh``
route V0 is fixed by the given mesh (no posterior spread), so its rank is 0
or D and its coverage is near 0 however small the error; the median relative
error of V0, V20 and V30 (``median_abs_rel_error``) says how far off they are.
"""
from __future__ import annotations

import json
import os
import platform
import shutil
import sys
import time
from pathlib import Path
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from lvcore import cli_args
from lvcore.conditions import CHAPTER_ANGLES, CHAPTER_EDP, SIGMA_S, SIGMA_V_ML
from lvcore.exceptions import LVCoreError
from lvcore.outputs import THETA_NAMES
from lvcore.studies._common import clean, round_floats, write_json_atomic

#: Result file of :func:`summarise` (the shipped run: ``assets/studies/sbc.json``), read by :func:`load`.
RESULT_FILE = "sbc.json"
#: Per-subject records beside it.
SUBJECTS_FILE = "sbc_subjects.csv"
#: The commands that make the results (two pieces on two cores, then the summary).
COMMAND = ("lvcore study sbc --n-subjects 200 --seed 0 --piece 1/2 & lvcore study sbc --n-subjects 200 --seed 0 "
           "--piece 2/2; lvcore study sbc --summarise --out DIR/sbc.json")
#: Version of the subject and route records; a work folder from another version is refused.
RECORD_VERSION = 1

ROUTES = ("mesh", "infer")
DERIVED_QUANTITIES = ("V0", "V20", "V30")
#: Every ranked quantity: θ, the derived FE volumes (mL) and the fibre Cauchy stress (kPa) at the fixed stretch.
QUANTITIES = tuple(THETA_NAMES) + DERIVED_QUANTITIES + ("fibre_stress",)
#: Quantities with the relative 90 % width.
WIDTH_QUANTITIES = ("V20", "V30")
#: Pressures (mmHg) of the derived volumes.
DERIVED_PRESSURES_MMHG = {"V0": 0.0, "V20": 20.0, "V30": 30.0}
#: ``--derived-pressures`` of the calibrations (V0 comes with every solve): only the pressures ranked here.
CLI_DERIVED_PRESSURES_MMHG = (20.0, 30.0)
UNITS = {"a": "kPa", "b": "-", "af": "kPa", "bf": "-", "V0": "mL", "V20": "mL", "V30": "mL", "fibre_stress": "kPa"}
LABELS = {"a": "a", "b": "b", "af": "a_f", "bf": "b_f", "V0": "V0", "V20": "V20", "V30": "V30",
          "fibre_stress": "σ_ff(λ=1.10)"}

#: Central interval levels whose coverage is reported.
LEVELS = (0.5, 0.9)
#: Bins of the rank histogram.
N_BINS = 10
#: Smallest expected count per bin for which the χ² p-value is given (the approximation's usual rule).
MIN_EXPECTED_PER_BIN = 5.0
#: Confidence of the coverage CIs (Wilson) and of the uniform band of the histograms (binomial).
CI_LEVEL = 0.95
BAND_LEVEL = 0.99

# ---- the design (docs: the chapter emulator's training conditions)
DEFAULT_N_SUBJECTS = 200
DEFAULT_WARMUP = 500
DEFAULT_SAMPLES = 500
DEFAULT_CHAINS = 2
DEFAULT_DERIVED_DRAWS = 20
DEFAULT_THIN = 100
DEFAULT_WORKDIR = "build/sbc"
MODEL = "iid"
EMULATOR = "chapter"
N_PC = 5
#: Truncation of the PC scores (the ``chapter`` emulator's box).
H_TRUNCATION = 2.0
#: Range of the log-uniform reference cavity volume (mL).
V_REF_RANGE_ML = (40.0, 200.0)
EDP_MMHG = float(CHAPTER_EDP)
ANGLES = tuple(float(a) for a in CHAPTER_ANGLES)
BASE = "sliding"
RESOLUTION = "default"
#: Noise of the ``--reference-volume`` given to the infer route (mL; the command's default sd).
REFERENCE_VOLUME_SD_ML = 5.0
#: Fibre stretch of the stress quantity.
STRESS_STRETCH = 1.10
#: Prior redraws allowed per subject before the study stops (a failed FE solve is redrawn).
MAX_REDRAWS = 20
EDP_NOTE = ("EDP fixed at 8 mmHg: the default `chapter` emulator is trained at 8 mmHg only, so the EDP range "
            "4-20 mmHg of the design could not be drawn")
SYNTHETIC_LABEL = "SYNTHETIC subjects (prior draws simulated by the FE model)"


# ============================================================================ rank statistics (pure)
def rank_of_truth(draws, truth: float, rng) -> tuple[int, int] | None:
    """Rank of ``truth`` among the finite ``draws``: the count of draws below it, ties broken at random.

    Returns
    -------
    (rank, L) with ``0 <= rank <= L`` (L the number of finite draws), or None without a finite draw or truth.
    """
    x = np.asarray(draws, float).reshape(-1)
    x = x[np.isfinite(x)]
    t = float(truth)
    if x.size == 0 or not np.isfinite(t):
        return None
    below = int(np.sum(x < t))
    ties = int(np.sum(x == t))
    extra = int(np.random.default_rng(rng).integers(0, ties + 1)) if ties else 0
    return below + extra, int(x.size)


def pit(ranks, Ls) -> np.ndarray:
    """``(rank + 0.5)/(L + 1)``: where the truth sits in the posterior, in (0, 1)."""
    return (np.asarray(ranks, float) + 0.5) / (np.asarray(Ls, float) + 1.0)


def inside_central(ranks, Ls, level: float) -> np.ndarray:
    """Whether the truth lies in the central ``level`` interval, judged from its rank (module docstring)."""
    u = pit(ranks, Ls)
    lo = (1.0 - level) / 2.0
    return (u >= lo - 1e-12) & (u <= 1.0 - lo + 1e-12)


def nominal_coverage(Ls, level: float) -> float:
    """Expected coverage of :func:`inside_central` when the ranks are uniform (a calibrated posterior), mean over
    subjects with L draws each: ``level`` up to the discreteness of L + 1 possible ranks."""
    Ls = np.atleast_1d(np.asarray(Ls, int))
    if Ls.size == 0:
        return float("nan")
    vals = {int(L): float(np.mean(inside_central(np.arange(L + 1), np.full(L + 1, L), level)))
            for L in set(Ls.tolist())}
    return float(np.mean([vals[int(L)] for L in Ls]))


def wilson_interval(k: int, n: int, level: float = CI_LEVEL) -> tuple[float, float] | None:
    """Wilson score interval of a binomial share ``k/n`` (None for n = 0)."""
    from scipy.stats import norm

    if n <= 0:
        return None
    z = float(norm.ppf(0.5 + level / 2.0))
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


def _bin_of(u: np.ndarray, n_bins: int) -> np.ndarray:
    return np.minimum((np.asarray(u, float) * n_bins).astype(int), n_bins - 1)


def rank_histogram(ranks, Ls, n_bins: int = N_BINS) -> tuple[np.ndarray, np.ndarray]:
    """Observed and expected counts of the ranks in ``n_bins`` equal bins of ``(rank + 0.5)/(L + 1)``.

    The expected count of a bin is the sum over subjects of the share of the L + 1 equally likely ranks that fall
    in it, so the test is exact for any L (L + 1 need not be a multiple of ``n_bins``) and for L varying between
    subjects.
    """
    ranks, Ls = np.asarray(ranks, int), np.asarray(Ls, int)
    observed = np.bincount(_bin_of(pit(ranks, Ls), n_bins), minlength=n_bins).astype(float)
    expected = np.zeros(n_bins)
    for L, count in zip(*np.unique(Ls, return_counts=True)):
        share = np.bincount(_bin_of(pit(np.arange(L + 1), np.full(L + 1, L)), n_bins), minlength=n_bins) / (L + 1)
        expected += count * share
    return observed, expected


def rank_chi2(ranks, Ls, n_bins: int = N_BINS) -> tuple[float, float]:
    """χ² statistic and p-value of the rank histogram against uniform ranks (:func:`scipy.stats.chisquare`)."""
    from scipy.stats import chisquare

    obs, exp = rank_histogram(ranks, Ls, n_bins)
    keep = exp > 0
    if obs.sum() == 0 or keep.sum() < 2:
        return float("nan"), float("nan")
    res = chisquare(obs[keep], exp[keep])
    return float(res.statistic), float(res.pvalue)


def uniform_band(expected, n: int, level: float = BAND_LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Per bin, the central ``level`` binomial range of the count under uniform ranks (the histogram's band)."""
    from scipy.stats import binom

    exp = np.asarray(expected, float)
    if n <= 0:
        return np.zeros_like(exp), np.zeros_like(exp)
    p = exp / n
    a = (1.0 - level) / 2.0
    return binom.ppf(a, n, p), binom.ppf(1.0 - a, n, p)


def quantity_summary(ranks, Ls, widths=None, n_bins: int = N_BINS) -> dict:
    """Coverage (50 %, 90 %) with Wilson CIs, the rank histogram with its χ² p-value, ``n``; and the median
    relative width when ``widths`` are given."""
    ranks, Ls = np.asarray(ranks, int).reshape(-1), np.asarray(Ls, int).reshape(-1)
    n = int(ranks.size)
    out: dict = {"n": n}
    for level in LEVELS:
        tag = f"{round(level * 100):d}"
        k = int(np.sum(inside_central(ranks, Ls, level))) if n else 0
        out[f"coverage_{tag}"] = k / n if n else None
        out[f"coverage_{tag}_ci"] = list(wilson_interval(k, n)) if n else None
        out[f"nominal_{tag}_at_L"] = nominal_coverage(Ls, level) if n else None
    obs, exp = rank_histogram(ranks, Ls, n_bins) if n else (np.zeros(n_bins), np.zeros(n_bins))
    lo, hi = uniform_band(exp, n)
    out["rank_histogram"] = [int(v) for v in obs]
    out["rank_histogram_expected"] = [float(v) for v in exp]
    out["rank_band"] = {"level": BAND_LEVEL, "lo": [float(v) for v in lo], "hi": [float(v) for v in hi]}
    out["rank_chi2"], out["rank_chi2_p"] = rank_chi2(ranks, Ls, n_bins) if n else (None, None)
    if n and float(np.min(exp)) < MIN_EXPECTED_PER_BIN:
        out["rank_chi2"] = out["rank_chi2_p"] = None
        out["rank_chi2_note"] = (f"not computed: {n} subject(s), fewer than {MIN_EXPECTED_PER_BIN:g} expected per bin "
                                 "(the χ² approximation does not hold)")
    out["L"] = {"min": int(Ls.min()), "max": int(Ls.max())} if n else None
    if widths is not None:
        w = np.asarray([v for v in widths if v is not None and np.isfinite(v)], float)
        out["median_width_rel"] = float(np.median(w)) if w.size else None
    return out


def flag_kind(flag: str) -> str:
    """The kind of a summary.json flag: its upper-case prefix (``CONSISTENCY``, ``MISFIT``, ``SAMPLER``,
    ``EXTRAPOLATION``, ...), ``IDENTIFIABILITY`` flags about a prior bound as ``BOUND``."""
    text = str(flag).strip()
    head = text.split(":", 1)[0].strip() if ":" in text else text.split(" ", 1)[0]
    kind = head if head.replace("_", "").replace("-", "").isalpha() and head.isupper() else "OTHER"
    if kind in ("IDENTIFIABILITY", "OTHER") and "bound" in text.lower():
        return "BOUND"
    return kind


# ============================================================================ subjects (SYNTHETIC)
def prior_draw(seed: int, index: int, attempt: int = 0) -> dict:
    """Subject ``index``'s prior draw number ``attempt``: θ (uniform on the prior box), PC scores (N(0, 1)
    truncated to ±2) and the target reference cavity volume (log-uniform in 40-200 mL). Depends only on
    ``(seed, index, attempt)``."""
    from lvcore.core.space import THETA_BOUNDS

    rng = np.random.default_rng([int(seed), int(index), int(attempt), 1])
    theta = {n: float(rng.uniform(*THETA_BOUNDS[n])) for n in THETA_NAMES}
    h = rng.standard_normal(N_PC)
    while np.any(np.abs(h) > H_TRUNCATION):   # rejection: the truncated normal, per score
        bad = np.abs(h) > H_TRUNCATION
        h[bad] = rng.standard_normal(int(bad.sum()))
    v_ref = float(np.exp(rng.uniform(*np.log(V_REF_RANGE_ML))))
    return {"theta": theta, "h": [float(v) for v in h], "v_ref_ml": v_ref}


def noise_draw(seed: int, index: int) -> dict:
    """Subject ``index``'s measurement noise: 25 outputs (σ_V, σ_S) and the reference-volume measurement."""
    rng = np.random.default_rng([int(seed), int(index), 2])
    return {"y": (np.r_[SIGMA_V_ML, np.full(24, SIGMA_S)] * rng.standard_normal(25)).tolist(),
            "reference_volume_ml": float(REFERENCE_VOLUME_SD_ML * rng.standard_normal())}


def calibration_seed(seed: int, index: int, route: str) -> int:
    """The sampler seed (``--seed``) of one subject and route."""
    return int(np.random.default_rng([int(seed), int(index), 3, ROUTES.index(route)]).integers(0, 2 ** 31 - 1))


def fibre_stress(theta: Mapping[str, object], stretch: float = STRESS_STRETCH) -> np.ndarray:
    """The HO fibre Cauchy stress σ_ff (kPa) at a fixed fibre stretch, for θ values or arrays of draws."""
    from lvcore.mechanics.stress import ho_fibre_stress

    ff, _ = ho_fibre_stress({n: np.asarray(theta[n], float) for n in THETA_NAMES}, stretch)
    return np.asarray(ff, float)


class TruthFailure(LVCoreError):
    """A prior draw whose FE truth could not be computed (it is redrawn)."""


def simulate_truth(draw: Mapping) -> dict:
    """FE truth of one prior draw: the scale, the 25 noise-free outputs, V0/V20/V30, the stress.

    Raises
    ------
    TruthFailure
        When a solve fails (the draw is redrawn).
    """
    from lvcore.core.space import build_case
    from lvcore.inference.derived import fe_load_path
    from lvcore.mechanics.edpvr import pca_reference_volume_ml
    from lvcore.mechanics.simulate import simulate

    t0 = time.perf_counter()
    theta, h = dict(draw["theta"]), list(draw["h"])
    try:
        v_cav = pca_reference_volume_ml(h, RESOLUTION)
        scale = float(np.cbrt(draw["v_ref_ml"] / v_cav))
        case = build_case({**theta, **{f"h{k + 1}": v for k, v in enumerate(h)}, "alpha_endo": ANGLES[0],
                           "alpha_epi": ANGLES[1], "edp": EDP_MMHG}, resolution=RESOLUTION, base=BASE)
        res = simulate(case)
        if not res.converged:
            raise TruthFailure(f"the data solve did not converge: {res.message}")
        y = np.asarray(res.outputs(), float)
        y[0] *= scale ** 3      # strains are scale-free, volumes scale by s^3 (lvcore.geometry.scaling)
        path = fe_load_path([{**theta, "h": h, "scale": scale}], edp_mmhg=EDP_MMHG, angles=ANGLES, base=BASE,
                            resolution=RESOLUTION, pressures_mmhg=CLI_DERIVED_PRESSURES_MMHG)
    except TruthFailure:
        raise
    except LVCoreError as err:
        raise TruthFailure(f"{type(err).__name__}: {str(err)[:300]}") from None
    vols = np.asarray(path.volumes_ml, float)[0]
    if path.n_failed or not np.all(np.isfinite(vols)):
        raise TruthFailure(f"{path.n_failed} EDPVR solve(s) failed")
    p = [float(v) for v in path.pressures_mmhg]
    truth = {n: float(theta[n]) for n in THETA_NAMES}
    truth.update({q: float(vols[p.index(DERIVED_PRESSURES_MMHG[q])]) for q in DERIVED_QUANTITIES})
    truth["fibre_stress"] = float(fibre_stress(theta))
    return {"h": h, "scale": scale, "v_cav_ml": float(v_cav), "v_ref_ml": float(v_cav * scale ** 3),
            "y_clean": [float(v) for v in y], "edv_fe_ml": float(np.asarray(path.volume_at_edp_ml)[0]),
            "fibre_stretch_ed": float(np.asarray(path.fibre_stretch_at_edp)[0]), "truth": truth,
            "seconds": time.perf_counter() - t0}


def make_subject(seed: int, index: int, *, truth_fn: Callable[[Mapping], dict] = simulate_truth,
                 max_redraws: int = MAX_REDRAWS) -> dict:
    """Subject ``index``: the first prior draw whose FE truth succeeds, with the noisy data.

    Returns
    -------
    dict
        ``index``, ``subject``, ``draw`` (the prior draw), the :func:`simulate_truth` fields, ``y`` (the noisy
        25 outputs), ``reference_volume_ml`` (V_ref + noise), ``redraws`` and ``redraw_reasons``.
    """
    reasons = []
    for attempt in range(max_redraws + 1):
        draw = prior_draw(seed, index, attempt)
        try:
            sim = truth_fn(draw)
        except TruthFailure as err:
            reasons.append(str(err)[:200])
            continue
        noise = noise_draw(seed, index)
        y = np.asarray(sim["y_clean"], float) + np.asarray(noise["y"], float)
        return {"index": int(index), "subject": subject_name(index), "draw": draw, **sim,
                "y": [float(v) for v in y],
                "reference_volume_ml": float(sim["v_ref_ml"] + noise["reference_volume_ml"]),
                "redraws": attempt, "redraw_reasons": reasons}
    raise LVCoreError(f"subject {index}: {max_redraws + 1} prior draws in a row failed in the FE simulator "
                      f"(last: {reasons[-1] if reasons else '?'})")


def subject_name(index: int) -> str:
    return f"SYNTHETIC-SBC-{int(index):05d}"


def write_subject_files(subject: Mapping, folder) -> dict:
    """The files a user would bring: ``data.csv`` (subject, lvv_ml, strain_01..24) and ``geometry.vtu`` (the
    template mesh of the shape at scale s)."""
    from lvcore.geometry.io import write_template_mesh
    from lvcore.geometry.scaling import scale_nodes
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.inference.data import MeasuredData, write_measured_csv

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    csv = write_measured_csv(folder / "data.csv", [MeasuredData(np.asarray(subject["y"], float), subject["subject"],
                                                                synthetic=True)])
    nodes = scale_nodes(load_shape_model().reconstruct(np.asarray(subject["h"], float)), subject["scale"])
    label = (f"SYNTHETIC {subject['subject']} (lvcore study sbc): PC scores "
             f"{[round(v, 4) for v in subject['h']]} at scale {subject['scale']:.4f}")
    vtu = write_template_mesh(folder / "geometry.vtu", nodes, metadata={"label": label})
    return {"data": str(csv), "mesh": str(vtu)}


# ============================================================================ one route through `lvcore calibrate`
def calibrate_argv(route: str, files: Mapping, subject: Mapping, settings: Mapping, out) -> list[str]:
    """The ``lvcore calibrate`` command line of one subject and route."""
    argv = ["calibrate", "--data", str(files["data"]), "--model", MODEL, "--chains", str(settings["chains"]),
            "--warmup", str(settings["warmup"]), "--samples", str(settings["samples"]),
            "--seed", str(calibration_seed(settings["seed"], subject["index"], route)),
            "--derived-draws", str(settings["derived_draws"]),
            "--derived-pressures", ",".join(f"{p:g}" for p in settings["derived_pressures"]),
            "--out", str(out), "--json"]
    if route == "mesh":
        argv[3:3] = ["--geometry", str(files["mesh"])]
    elif route == "infer":
        argv[3:3] = ["--geometry", "infer", "--reference-volume", f"{subject['reference_volume_ml']:.6f}"]
    else:
        raise LVCoreError(f"unknown route '{route}'; choose from {', '.join(ROUTES)}")
    if settings.get("allow_extrapolation"):
        argv.append("--allow-extrapolation")
    return argv


def calibrate_in_process(argv: Sequence[str], log_path=None) -> tuple[int, str]:
    """Run ``lvcore calibrate ...`` (``argv`` starts with ``calibrate``) in this process.

    The sub-command's own parser and handler (:mod:`lvcore.inference.cli`), with the exit codes of
    ``lvcore.cli.main``: 0 fine, 1 did not converge, 2 bad input, 3 internal error, 4 ran but flagged.
    Its printed output goes to ``log_path``.

    Returns
    -------
    (exit code, the last error line printed, or "")
    """
    import argparse
    import contextlib
    import io

    from lvcore.exceptions import SolverError
    from lvcore.inference import cli as calibrate_cli

    buf = io.StringIO()
    code = 0
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            parser = argparse.ArgumentParser(prog="lvcore")
            calibrate_cli.register(parser.add_subparsers(dest="command", required=True))
            args = parser.parse_args(list(argv))
            args.extra = []
            code = int(args.func(args) or 0)
        except SystemExit as err:          # argparse: exit 2 with its message
            code = int(err.code) if isinstance(err.code, int) else 2
        except SolverError as err:
            print(f"lvcore: did not converge: {err}", file=sys.stderr)
            code = 1
        except LVCoreError as err:
            print(f"lvcore: error: {str(err)[:4000]}", file=sys.stderr)
            code = 2
        except OSError as err:
            print(f"lvcore: error: {type(err).__name__}: {err}", file=sys.stderr)
            code = 2 if err.filename is not None else 3
        except KeyboardInterrupt:
            raise
        except Exception as err:  # noqa: BLE001 - as lvcore.cli.main: one line, exit 3
            print(f"lvcore: internal error: {type(err).__name__}: {' '.join(str(err).split())[:2000]}",
                  file=sys.stderr)
            code = 3
    text = buf.getvalue()
    if log_path is not None:
        Path(log_path).write_text(text)
    errors = [ln for ln in text.splitlines()
              if ln.startswith(("lvcore: error", "lvcore: internal error", "lvcore: did not converge"))
              or ": error: " in ln]   # argparse: "lvcore calibrate: error: ..."
    return code, (errors[-1][:400] if errors and code not in (0, 4) else "")


def _thin(n_total: int, n: int) -> np.ndarray:
    return np.unique(np.linspace(0, n_total - 1, min(int(n), int(n_total))).round().astype(int))


def read_route_outputs(out, subject_name_: str) -> dict:
    """What one ``lvcore calibrate`` run left in ``out``: its summary record, the flattened posterior θ draws
    (``<stem>_iid.nc``) and the derived draws (``<stem>_iid_derived.npz``), each None when missing."""
    from lvcore.inference.calibrate import file_stem

    out = Path(out)
    stem = file_stem(subject_name_)
    rec = None
    if (out / "summary.json").is_file():
        records = json.loads((out / "summary.json").read_text())
        rec = next((r for r in records if r.get("model") == MODEL), None)
    theta = None
    nc = out / f"{stem}_{MODEL}.nc"
    if nc.is_file():
        import arviz as az

        idata = az.from_netcdf(str(nc))
        try:
            theta = {n: np.asarray(idata.posterior[n].values, float).reshape(-1) for n in THETA_NAMES}
        finally:
            close = getattr(idata, "close", None)
            if close is not None:
                close()
    derived = None
    npz = out / f"{stem}_{MODEL}_derived.npz"
    if npz.is_file():
        with np.load(npz) as z:
            derived = {k: np.asarray(z[k]) for k in z.files}
    return {"record": rec, "theta": theta, "derived": derived}


def route_ranks(truth: Mapping[str, float], theta_draws: Mapping | None, derived: Mapping | None, *, thin: int,
                rng) -> tuple[dict, dict, int, dict]:
    """Ranks ``{quantity: [rank, L]}``, relative 90 % widths ``{V20, V30}``, the derived draws with a failed
    solve and the relative error of the posterior median ``{V0, V20, V30}`` (``(median − truth)/truth``), from
    one run's posterior (:func:`read_route_outputs`)."""
    rng = np.random.default_rng(rng)
    ranks, widths, n_failed, rel_error = {}, {}, 0, {}
    if theta_draws is not None:
        n_total = len(theta_draws[THETA_NAMES[0]])
        idx = _thin(n_total, thin)
        thinned = {n: np.asarray(theta_draws[n], float)[idx] for n in THETA_NAMES}
        for n in THETA_NAMES:
            r = rank_of_truth(thinned[n], truth[n], rng)
            ranks[n] = None if r is None else list(r)
        r = rank_of_truth(fibre_stress(thinned), truth["fibre_stress"], rng)
        ranks["fibre_stress"] = None if r is None else list(r)
    if derived is not None and "edpvr_ml" in derived:
        p = [float(v) for v in np.asarray(derived["edpvr_pressures_mmhg"], float)]
        vols = np.asarray(derived["edpvr_ml"], float).reshape(-1, len(p))
        n_failed = int(np.sum(~np.all(np.isfinite(vols), axis=1)))
        for q in DERIVED_QUANTITIES:
            pq = DERIVED_PRESSURES_MMHG[q]
            if pq not in p:
                ranks[q] = None
                continue
            col = vols[:, p.index(pq)]
            r = rank_of_truth(col, truth[q], rng)
            ranks[q] = None if r is None else list(r)
            ok = col[np.isfinite(col)]
            rel_error[q] = float((np.median(ok) - truth[q]) / truth[q]) if ok.size else None
            if q in WIDTH_QUANTITIES:
                widths[q] = (float((np.quantile(ok, 0.95) - np.quantile(ok, 0.05)) / truth[q])
                             if ok.size >= 2 else None)
    return ranks, widths, n_failed, rel_error


def run_route(route: str, subject: Mapping, files: Mapping, settings: Mapping, folder, *,
              calibrate: Callable[[Sequence[str], object], tuple[int, str]] = calibrate_in_process) -> dict:
    """Calibrate one subject by one route and rank its truth; the route's record."""
    folder = Path(folder)
    out = folder / route
    t0, c0 = time.perf_counter(), time.process_time()
    argv = calibrate_argv(route, files, subject, settings, out)
    code, error = calibrate(argv, folder / f"{route}.log")
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    found = read_route_outputs(out, subject["subject"])
    rec = found["record"] or {}
    flags = [str(f) for f in rec.get("flags") or []]
    ranks, widths, n_failed, rel_error = route_ranks(subject["truth"], found["theta"], found["derived"],
                                                     thin=settings["thin"],
                                                     rng=[int(settings["seed"]), int(subject["index"]), 4,
                                                          ROUTES.index(route)])
    geometry = rec.get("geometry") or {}
    return {"exit_code": int(code), "error": error or None, "converged": rec.get("converged"),
            "flag_kinds": sorted({flag_kind(f) for f in flags}), "flags": [f[:240] for f in flags],
            "ranks": ranks, "width_rel": widths, "median_rel_error": rel_error, "derived_failed": n_failed,
            "geometry_scale": geometry.get("scale"),
            "seed": calibration_seed(settings["seed"], subject["index"], route),
            "seconds": wall, "cpu_seconds": cpu}


def run_subject(index: int, settings: Mapping, workdir, *, calibrate=calibrate_in_process,
                truth_fn: Callable[[Mapping], dict] = simulate_truth, keep_runs: bool = False) -> dict:
    """Everything of one subject: the truth, its files, both routes; the JSON-lines record."""
    t0, c0 = time.perf_counter(), time.process_time()
    folder = Path(workdir) / "runs" / f"{int(index):05d}"
    if folder.exists():
        shutil.rmtree(folder)          # a run killed in flight: start the subject again
    subject = make_subject(settings["seed"], index, truth_fn=truth_fn)
    files = write_subject_files(subject, folder)
    routes = {r: run_route(r, subject, files, settings, folder, calibrate=calibrate) for r in settings["routes"]}
    if not keep_runs:
        shutil.rmtree(folder, ignore_errors=True)
    _release_compiled_programs()
    return {"version": RECORD_VERSION, "index": int(index), "subject": subject["subject"],
            "settings_key": settings_key(settings), "h": subject["h"], "scale": subject["scale"],
            "v_ref_ml": subject["v_ref_ml"], "reference_volume_ml": subject["reference_volume_ml"],
            "truth": subject["truth"], "y": subject["y"], "y_clean": subject["y_clean"],
            "redraws": subject["redraws"], "redraw_reasons": subject["redraw_reasons"],
            "truth_seconds": subject["seconds"], "routes": routes, "seconds": time.perf_counter() - t0,
            "cpu_seconds": time.process_time() - c0, "load_average": _load_average(),
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S")}


def _load_average() -> float | None:
    """The machine's 1-minute load average when the subject finished (None where unknown)."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


def _release_compiled_programs() -> None:
    """Let go of the programs one subject compiled (each subject's geometry is bound into its forward model):
    a process keeps a few memory mappings per program and the kernel caps them (tests/conftest.py)."""
    import gc

    import jax

    from lvcore.inference import samplers, verdict

    samplers.clear_sampler_cache()
    verdict.clear_best_fit_programs()
    jax.clear_caches()
    gc.collect()


# ============================================================================ the resumable store
def default_settings(**kw) -> dict:
    s = {"seed": 0, "warmup": DEFAULT_WARMUP, "samples": DEFAULT_SAMPLES, "chains": DEFAULT_CHAINS,
         "derived_draws": DEFAULT_DERIVED_DRAWS, "derived_pressures": list(CLI_DERIVED_PRESSURES_MMHG),
         "thin": DEFAULT_THIN, "routes": list(ROUTES), "allow_extrapolation": False}
    s.update(kw)
    s["routes"] = list(s["routes"])
    s["derived_pressures"] = [float(p) for p in s["derived_pressures"]]
    return s


def settings_key(settings: Mapping) -> dict:
    """The settings that must agree between the records of one work folder (the number of subjects may grow)."""
    keys = ("seed", "warmup", "samples", "chains", "derived_draws", "derived_pressures", "thin", "routes",
            "allow_extrapolation")
    return {"version": RECORD_VERSION, **{k: settings[k] for k in keys}}


class Store:
    """One work folder: ``settings.json`` and one JSON-lines file per piece (subject index range).

    A record is one line, appended and flushed when its subject is done; a
    half-written last line (a kill mid-write) is ignored when reading and cut
    off before the next append. Subjects recorded in any piece file count as done.
    """

    def __init__(self, workdir):
        self.root = Path(workdir)

    def piece_path(self, start: int, stop: int) -> Path:
        return self.root / f"subjects_{int(start):05d}-{int(stop):05d}.jsonl"

    def check_settings(self, settings: Mapping, n_subjects: int | None = None) -> dict:
        """Write ``settings.json`` on the first run; refuse a folder made with other settings."""
        self.root.mkdir(parents=True, exist_ok=True)
        path = self.root / "settings.json"
        key = settings_key(settings)
        old = json.loads(path.read_text()) if path.is_file() else None
        if old is not None and old.get("key") != key:
            raise LVCoreError(f"work folder {self.root} holds an SBC run with other settings ({old.get('key')}); "
                              f"these are {key}: give another --workdir, or the same settings")
        n = max(int(n_subjects or 0), int((old or {}).get("n_subjects") or 0))
        data = {"key": key, "n_subjects": n}
        if data != old:
            write_json_atomic(path, data)
        return data

    def settings(self) -> dict | None:
        path = self.root / "settings.json"
        return json.loads(path.read_text()) if path.is_file() else None

    def records(self) -> list[dict]:
        """Every complete record, one per subject index (the first one found), sorted by index."""
        out: dict[int, dict] = {}
        for f in sorted(self.root.glob("subjects_*.jsonl")):
            for line in f.read_text(errors="replace").splitlines():
                line = line.strip()
                if not line:
                    continue
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:
                    continue              # a line cut off by a kill
                if isinstance(rec, dict) and "index" in rec and "routes" in rec:
                    out.setdefault(int(rec["index"]), rec)
        return [out[k] for k in sorted(out)]

    def done(self) -> set[int]:
        return {int(r["index"]) for r in self.records()}

    def append(self, path, record: Mapping) -> None:
        """Append one record as a line (a partial last line left by a kill is cut off first)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.is_file() and path.stat().st_size:
            with open(path, "rb+") as f:
                data = f.read()
                if not data.endswith(b"\n"):
                    f.truncate(data.rfind(b"\n") + 1)
        with open(path, "a", encoding="utf-8") as f:
            f.write(json.dumps(clean(record), allow_nan=False) + "\n")
            f.flush()
            os.fsync(f.fileno())


def piece_range(n_subjects: int, piece: str | None = None, start: int | None = None,
                stop: int | None = None) -> tuple[int, int]:
    """Subject indices ``[start, stop)`` of ``--piece K/N`` (K-th of N near-equal parts, 1-based) or of
    ``--start``/``--stop`` (default the whole range)."""
    n = int(n_subjects)
    if piece is not None:
        if start is not None or stop is not None:
            raise LVCoreError("give --piece K/N or --start/--stop, not both")
        try:
            k, m = (int(v) for v in str(piece).split("/"))
        except ValueError:
            raise LVCoreError(f"--piece {piece!r}: write K/N, e.g. 1/2") from None
        if not (1 <= k <= m):
            raise LVCoreError(f"--piece {piece}: need 1 <= K <= N")
        return (k - 1) * n // m, k * n // m
    a = 0 if start is None else int(start)
    b = n if stop is None else int(stop)
    if not 0 <= a <= b:
        raise LVCoreError(f"--start {a} --stop {b}: need 0 <= start <= stop")
    return a, b


def run_piece(start: int, stop: int, settings: Mapping, workdir, *, n_subjects: int | None = None,
              subject_fn: Callable[[int], dict] | None = None, log: Callable[[str], None] | None = None,
              keep_runs: bool = False) -> dict:
    """Run subjects ``start..stop-1`` not yet recorded in ``workdir``; each finished one is appended at once.

    ``subject_fn(index) -> record`` replaces :func:`run_subject` (tests).
    """
    store = Store(workdir)
    store.check_settings(settings, n_subjects if n_subjects is not None else stop)
    done = store.done()
    todo = [i for i in range(start, stop) if i not in done]
    path = store.piece_path(start, stop)
    say = log or (lambda m: None)
    say(f"SBC piece [{start}, {stop}): {len(todo)} to run, {stop - start - len(todo)} already done; "
        f"records -> {path}")
    t0 = time.perf_counter()
    for k, i in enumerate(todo):
        rec = subject_fn(i) if subject_fn is not None else run_subject(i, settings, workdir, keep_runs=keep_runs)
        store.append(path, rec)
        codes = ", ".join(f"{r} exit {v['exit_code']} ({v['seconds']:.0f} s)" for r, v in rec["routes"].items())
        say(f"[{k + 1}/{len(todo)}] {rec['subject']}: {codes}; {rec['seconds']:.0f} s wall, "
            f"{rec.get('cpu_seconds', float('nan')):.0f} CPU-s")
    return {"piece": [start, stop], "ran": len(todo), "seconds": time.perf_counter() - t0, "file": str(path)}


# ============================================================================ the summary (sbc.json)
#: Exit codes of the runs whose ranks enter the statistics: 0 (fine) and 4 (ran, results flagged).
STATISTICS_EXIT_CODES = (0, 4)


def _ranks_of(records: Sequence[Mapping], route: str, quantity: str,
              exit_codes: Iterable[int] | None = STATISTICS_EXIT_CODES) -> tuple[list, list, list, list]:
    ranks, Ls, widths, errors = [], [], [], []
    codes = None if exit_codes is None else set(exit_codes)
    for r in records:
        rr = r["routes"].get(route)
        if rr is None or (codes is not None and rr["exit_code"] not in codes):
            continue
        pair = (rr.get("ranks") or {}).get(quantity)
        if pair is None:
            continue
        ranks.append(int(pair[0]))
        Ls.append(int(pair[1]))
        widths.append((rr.get("width_rel") or {}).get(quantity))
        errors.append((rr.get("median_rel_error") or {}).get(quantity))
    return ranks, Ls, widths, errors


def _stats(values) -> dict:
    v = np.asarray([x for x in values if x is not None], float)
    if not v.size:
        return {"n": 0}
    return {"n": int(v.size), "median": float(np.median(v)), "mean": float(v.mean()), "min": float(v.min()),
            "max": float(v.max()), "total": float(v.sum())}


def route_summary(records: Sequence[Mapping], route: str) -> dict:
    """Per quantity the :func:`quantity_summary`, and the route's exit codes, flag kinds and cost."""
    runs = [r["routes"][route] for r in records if route in r["routes"]]
    out: dict = {}
    for q in QUANTITIES:
        ranks, Ls, widths, errors = _ranks_of(records, route, q)
        out[q] = quantity_summary(ranks, Ls, widths if q in WIDTH_QUANTITIES else None)
        if q in DERIVED_QUANTITIES:
            e = np.abs([v for v in errors if v is not None])
            out[q]["median_abs_rel_error"] = float(np.median(e)) if e.size else None
        # every run that left a posterior, exit 1 (not converged) included: what the selection above changes
        ranks, Ls, _, _ = _ranks_of(records, route, q, exit_codes=None)
        every = quantity_summary(ranks, Ls)
        out[q]["all_runs"] = {k: every[k] for k in ("n", "coverage_90", "coverage_50", "rank_chi2_p")}
    codes: dict[str, int] = {}
    for rr in runs:
        codes[str(rr["exit_code"])] = codes.get(str(rr["exit_code"]), 0) + 1
    flagged = [rr for rr in runs if rr["exit_code"] == 4]
    reasons: dict[str, int] = {}
    for rr in flagged:
        for kind in rr.get("flag_kinds") or ["none recorded"]:
            reasons[kind] = reasons.get(kind, 0) + 1
    errors: dict[str, int] = {}
    for rr in runs:
        if rr["exit_code"] not in (0, 4):
            key = f"exit {rr['exit_code']}: {(rr.get('error') or 'no message')[:160]}"
            errors[key] = errors.get(key, 0) + 1
    out.update({
        "n_runs": len(runs), "exit_codes": codes,
        "exit4_share": len(flagged) / len(runs) if runs else None,
        "exit4_share_ci": list(wilson_interval(len(flagged), len(runs))) if runs else None,
        "exit4_reasons": dict(sorted(reasons.items(), key=lambda kv: -kv[1])),
        "errors": errors,
        "derived_failed_draws": int(sum(rr.get("derived_failed") or 0 for rr in runs)),
        "cost": {"seconds_per_subject": _stats(rr["seconds"] for rr in runs),
                 "cpu_seconds_per_subject": _stats(rr.get("cpu_seconds") for rr in runs)},
    })
    return out


def compact_subject(rec: Mapping) -> dict:
    """One subject's record as shipped: truths, ranks, exit codes, flag kinds, seconds."""
    return {"index": rec["index"], "h": rec["h"], "scale": rec["scale"], "v_ref_ml": rec["v_ref_ml"],
            "reference_volume_ml": rec["reference_volume_ml"], "truth": rec["truth"], "redraws": rec["redraws"],
            "seconds": rec["seconds"], "cpu_seconds": rec.get("cpu_seconds"), "truth_seconds": rec.get("truth_seconds"),
            "routes": {r: {"exit_code": v["exit_code"], "flag_kinds": v.get("flag_kinds", []), "ranks": v["ranks"],
                           "width_rel": v.get("width_rel", {}), "median_rel_error": v.get("median_rel_error", {}),
                           "seconds": v["seconds"],
                           "cpu_seconds": v.get("cpu_seconds"),
                           **({"error": v["error"]} if v.get("error") else {})}
                       for r, v in rec["routes"].items()}}


def summarise_records(records: Sequence[Mapping], settings: Mapping | None = None,
                      n_planned: int | None = None) -> dict:
    """The study's result (sbc.json) from subject records (:meth:`Store.records`)."""
    if not records:
        raise LVCoreError("no finished SBC subjects to summarise; run `lvcore study sbc --piece ...` first")
    keys = {json.dumps(r.get("settings_key"), sort_keys=True) for r in records}
    if len(keys) > 1:
        raise LVCoreError(f"the records come from {len(keys)} different settings; summarise one work folder")
    key = settings or records[0].get("settings_key") or {}
    routes = [r for r in ROUTES if any(r in rec["routes"] for rec in records)]
    redraw_reasons: dict[str, int] = {}
    for rec in records:
        for why in rec.get("redraw_reasons") or []:
            short = why.split(":", 1)[0][:120]
            redraw_reasons[short] = redraw_reasons.get(short, 0) + 1
    per_route = {r: route_summary(records, r) for r in routes}
    n = len(records)
    indices = [int(r["index"]) for r in records]
    result = {
        "study": "sbc",
        "synthetic": True,
        "label": SYNTHETIC_LABEL,
        "n_subjects": n,
        "n_subjects_planned": int(n_planned) if n_planned else None,
        "complete": bool(n_planned) and n >= int(n_planned),
        "subject_indices": {"min": min(indices), "max": max(indices)},
        "quantities": list(QUANTITIES),
        "units": UNITS,
        "settings": {
            **{k: key.get(k) for k in ("seed", "warmup", "samples", "chains", "derived_draws", "derived_pressures",
                                        "thin", "allow_extrapolation")},
            "L_theta": key.get("thin"), "L_derived": key.get("derived_draws"),
            "model": MODEL, "emulator": EMULATOR, "routes": routes,
            "noise": {"sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S, "reference_volume_sd_ml": REFERENCE_VOLUME_SD_ML},
            "edp_mmhg": EDP_MMHG, "edp_note": EDP_NOTE, "angles_deg": list(ANGLES), "base": BASE,
            "resolution": RESOLUTION, "volume_range_ml": list(V_REF_RANGE_ML), "volume_prior": "log-uniform",
            "pc_scores": {"n": N_PC, "prior": "N(0, 1) truncated", "truncation": H_TRUNCATION},
            "theta_prior": "uniform on lvcore.core.space.THETA_BOUNDS",
            "stress_stretch": STRESS_STRETCH, "levels": list(LEVELS), "n_bins": N_BINS, "ci_level": CI_LEVEL,
            "band_level": BAND_LEVEL,
            "ranks": "a, b, af, bf and the fibre stress among L_theta thinned posterior draws; V0, V20, V30 among "
                     "the derived FE draws (failed solves left out); runs exiting 0 or 4 only (all_runs: every run "
                     "that left a posterior, exit 1 included)",
            "statistics_exit_codes": list(STATISTICS_EXIT_CODES),
        },
        "truth_generation": {"simulator": f"FE ({RESOLUTION} mesh, {BASE} base, angles {ANGLES}, EDP {EDP_MMHG:g} "
                                          "mmHg)",
                             "redrawn": int(sum(r.get("redraws", 0) for r in records)),
                             "redraw_reasons": redraw_reasons},
        "routes": per_route,
        "exit4_share": {r: per_route[r]["exit4_share"] for r in routes},
        "exit4_reasons": {r: per_route[r]["exit4_reasons"] for r in routes},
        "cost": {
            "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                        "python": platform.python_version()},
            "seconds_per_subject": _stats(r["seconds"] for r in records),
            "cpu_seconds_per_subject": _stats(r.get("cpu_seconds") for r in records),
            "load_average": _stats(r.get("load_average") for r in records),
            "truth_seconds_per_subject": _stats(r.get("truth_seconds") for r in records),
            "seconds_per_route": {r: per_route[r]["cost"]["seconds_per_subject"] for r in routes},
            "total_s": float(sum(r["seconds"] for r in records)),
            "note": "wall seconds inside the study process, summed over subjects (pieces in parallel overlap); "
                    "CPU seconds of the process (all its threads); load_average: the machine's 1-minute load "
                    "when each subject finished (a shared machine stretches the wall time)",
        },
        "notes": [
            "SYNTHETIC: every subject is a prior draw simulated by the FE model; no patient data.",
            EDP_NOTE,
            "the geometry of the draws is not the infer route's prior (scale log-uniform on 0.5-1.8 there; here "
            "V_ref log-uniform on 40-200 mL, h truncated N(0, 1) as there)",
            "the calibrations use the command's defaults, among them the representation-error floor, which adds "
            "variance for a subject that is exactly a shape-model shape (expect over-coverage from it)",
            "mesh route: V0 is fixed by the given mesh (every derived draw has the same V0), so its rank is 0 or "
            "L and its coverage is near 0 however small the error: read V0's median_abs_rel_error (how well the "
            "size-normalised projection of the mesh reproduces the true V0)",
            "coverage from ranks: inside the central interval when (rank + 0.5)/(L + 1) lies in [(1 - level)/2, "
            "1 - (1 - level)/2]; nominal_*_at_L is what a calibrated posterior gets with the same L",
        ],
        "subjects": [compact_subject(r) for r in records],
    }
    return round_floats(clean(result), 6)


def summarise(workdir, out=None) -> dict:
    """Build the result from whatever ``workdir`` holds; write it to ``out`` (a ``.json`` path, default
    ``workdir/sbc.json``) with ``sbc_subjects.csv`` beside it."""
    store = Store(workdir)
    if not store.root.is_dir():
        raise LVCoreError(f"--workdir {workdir}: no such folder; run `lvcore study sbc --workdir {workdir} ...` "
                          "first")
    meta = store.settings() or {}
    result = summarise_records(store.records(), meta.get("key"), meta.get("n_subjects"))
    out = Path(out) if out is not None else store.root / RESULT_FILE
    write_json_atomic(out, result)
    subjects_table(result).to_csv(out.parent / SUBJECTS_FILE, index=False, float_format="%.6g")
    return result


def subjects_table(result: Mapping):
    """One row per subject and route: truths, exit code, flag kinds, ranks (``rank_<q>``, ``L_<q>``)."""
    import pandas as pd

    rows = []
    for s in result["subjects"]:
        base = {"index": s["index"], "scale": s["scale"], "v_ref_ml": s["v_ref_ml"],
                "reference_volume_ml": s["reference_volume_ml"], "redraws": s["redraws"],
                **{f"h{k + 1}": v for k, v in enumerate(s["h"])},
                **{f"truth_{q}": s["truth"].get(q) for q in QUANTITIES}}
        for route, rr in s["routes"].items():
            row = {**base, "route": route, "exit_code": rr["exit_code"], "flag_kinds": " ".join(rr["flag_kinds"]),
                   "seconds": rr["seconds"], "error": rr.get("error", "")}
            for q in QUANTITIES:
                pair = rr["ranks"].get(q)
                row[f"rank_{q}"], row[f"L_{q}"] = (pair if pair is not None else (None, None))
            for q in WIDTH_QUANTITIES:
                row[f"width_rel_{q}"] = rr.get("width_rel", {}).get(q)
            rows.append(row)
    return pd.DataFrame(rows)


# ============================================================================ saved results: load, tables, figures
TITLES = {
    "fig_sbc_rank_histograms": "SBC: rank histograms of the truth per quantity and route, with the uniform band",
    "fig_sbc_coverage": "SBC: coverage of the central 50 % and 90 % intervals with Wilson 95 % CIs",
    "table_sbc_summary": "SBC: coverage, χ² p-value of the rank histogram and relative widths per route",
}
MISSING: dict = {}


def load(folder) -> dict:
    """``sbc.json`` of a result folder (or the bundled one), with ``folder``."""
    from lvcore.studies.results import read_result

    return read_result(folder, RESULT_FILE)


def _runs_text(result: Mapping) -> str:
    s = result.get("settings", {})
    return (f"{s.get('chains')} chains × ({s.get('warmup')} + {s.get('samples')}), L = {s.get('L_theta')} θ draws, "
            f"{s.get('L_derived')} derived FE draws")


def _n_text(result: Mapping) -> str:
    n, planned = result.get("n_subjects"), result.get("n_subjects_planned")
    if planned and n < planned:
        return f"{n} of {planned} SYNTHETIC subjects (incomplete)"
    return f"{n} SYNTHETIC subjects"


def source_line(result: Mapping) -> str:
    """Where the numbers come from, in one line."""
    from lvcore.studies.results import source_label

    return (f"{RESULT_FILE} ({source_label(result['folder'])}); {_n_text(result)}; `lvcore calibrate` iid, "
            f"{_runs_text(result)}; truth by the FE simulator")


def tables(result: Mapping) -> dict:
    """The data behind each figure, and the per-subject table."""
    import pandas as pd

    routes = result["settings"]["routes"]
    rows_h, rows_c, rows_t = [], [], []
    for route in routes:
        rs = result["routes"][route]
        for q in result["quantities"]:
            s = rs[q]
            for b, (o, e) in enumerate(zip(s["rank_histogram"], s["rank_histogram_expected"])):
                rows_h.append({"route": route, "quantity": q, "bin": b + 1, "count": o, "expected": e,
                               "band_lo": s["rank_band"]["lo"][b], "band_hi": s["rank_band"]["hi"][b]})
            for level in ("50", "90"):
                ci = s.get(f"coverage_{level}_ci") or [None, None]
                rows_c.append({"route": route, "quantity": q, "level": int(level),
                               "coverage": s.get(f"coverage_{level}"),
                               "lo": ci[0], "hi": ci[1], "nominal_at_L": s.get(f"nominal_{level}_at_L"), "n": s["n"]})
            rows_t.append({"route": route, "quantity": LABELS.get(q, q), "n": s["n"],
                           "coverage 90 %": _pct_ci(s.get("coverage_90"), s.get("coverage_90_ci")),
                           "coverage 50 %": _pct_ci(s.get("coverage_50"), s.get("coverage_50_ci")),
                           "nominal at L": _pct(s.get("nominal_90_at_L")) + " / " + _pct(s.get("nominal_50_at_L")),
                           "χ² p": "" if s.get("rank_chi2_p") is None else f"{s['rank_chi2_p']:.3g}",
                           "median (q95−q05)/truth": ("" if s.get("median_width_rel") is None
                                                      else f"{s['median_width_rel']:.3f}"),
                           "median |median−truth|/truth": ("" if s.get("median_abs_rel_error") is None
                                                           else f"{s['median_abs_rel_error']:.3f}")})
    out = {"fig_sbc_rank_histograms": pd.DataFrame(rows_h), "fig_sbc_coverage": pd.DataFrame(rows_c),
           "table_sbc_summary": pd.DataFrame(rows_t)}
    rows_r = []
    for r in routes:
        rs = result["routes"][r]
        cost = rs["cost"]
        rows_r.append({"route": r, "runs": rs["n_runs"],
                       "exit codes": ", ".join(f"{k}: {v}" for k, v in sorted(rs["exit_codes"].items())),
                       "share exit 4": _pct(rs["exit4_share"]),
                       "flag kinds (exit 4)": ", ".join(f"{k} {v}" for k, v in rs["exit4_reasons"].items()),
                       "median s per subject": cost["seconds_per_subject"].get("median"),
                       "median CPU-s per subject": (cost.get("cpu_seconds_per_subject") or {}).get("median")})
    out["runs"] = pd.DataFrame(rows_r)
    return out


def _pct(v) -> str:
    return "" if v is None else f"{100 * v:.0f} %"


def _pct_ci(v, ci) -> str:
    if v is None:
        return ""
    return f"{100 * v:.0f} % [{100 * ci[0]:.0f}, {100 * ci[1]:.0f}]" if ci else f"{100 * v:.0f} %"


def captions(result: Mapping) -> dict:
    n = _n_text(result)
    return {"fig_sbc_rank_histograms": f"{n}; grey: the central {BAND_LEVEL:.0%} range of each bin's count under "
                                       "uniform ranks",
            "fig_sbc_coverage": f"{n}; dotted: the coverage a calibrated posterior gets with the same L"}


def figures(result: Mapping) -> dict:
    """The study's figures by name (:data:`TITLES`)."""
    from lvcore.viz.report_figures import table_figure
    from lvcore.viz.study_figures import sbc_coverage_figure, sbc_rank_histogram_figure

    tabs = tables(result)
    tag = _n_text(result)
    return {
        "fig_sbc_rank_histograms": sbc_rank_histogram_figure(
            tabs["fig_sbc_rank_histograms"].to_dict("records"), labels=LABELS,
            title=f"SBC — {tag}: rank of the truth among the posterior draws<br>"
                  f"<sup>10 bins; grey: {BAND_LEVEL:.0%} range of a bin's count under uniform ranks</sup>"),
        "fig_sbc_coverage": sbc_coverage_figure(
            tabs["fig_sbc_coverage"].to_dict("records"), labels=LABELS,
            title=f"SBC — {tag}: coverage of the central intervals (Wilson 95 % CI)"),
        "table_sbc_summary": table_figure(tabs["table_sbc_summary"],
                                          title=f"SBC ({tag}): coverage, rank uniformity and widths"),
    }


def format_summary(result: Mapping) -> str:
    """A few plain lines: per route the coverage of every quantity and the exit-4 share."""
    lines = [f"SBC of `lvcore calibrate` on {_n_text(result)} ({_runs_text(result)})"]
    for route in result["settings"]["routes"]:
        rs = result["routes"][route]
        parts = [f"{q} {_pct(rs[q].get('coverage_90')) or '-'}/{_pct(rs[q].get('coverage_50')) or '-'}"
                 + (f" (p {rs[q]['rank_chi2_p']:.2g})" if rs[q].get("rank_chi2_p") is not None else "")
                 for q in result["quantities"]]
        lines.append(f"  {route}: coverage 90/50 (χ² p): " + ", ".join(parts))
        lines.append(f"  {route}: exit codes {rs['exit_codes']}, exit 4 {_pct(rs['exit4_share'])} "
                     f"({rs['exit4_reasons']}); median {rs['cost']['seconds_per_subject'].get('median', 0):.0f} s "
                     "per subject")
    return "\n".join(lines)


# ============================================================================ command line
def add_study_parser(study_subparsers) -> None:
    """``lvcore study sbc``."""
    p = study_subparsers.add_parser(
        "sbc", help="simulation-based calibration of `lvcore calibrate` on SYNTHETIC prior draws (FE truth)",
        description="Simulation-based calibration (Talts et al. 2018) of the calibration pipeline: SYNTHETIC "
                    "subjects drawn from the prior, truth by the FE simulator, each calibrated by `lvcore "
                    "calibrate` with a mesh and with --geometry infer. Runs in resumable pieces; --summarise "
                    "builds sbc.json from what is finished.")
    p.add_argument("--n-subjects", type=cli_args.int_in(1, 100_000), default=DEFAULT_N_SUBJECTS,
                   help=f"subjects of the whole study (default {DEFAULT_N_SUBJECTS})")
    p.add_argument("--seed", type=cli_args.seed, default=0, help="seed of the subjects and noise (default 0)")
    p.add_argument("--piece", default=None, metavar="K/N",
                   help="run the K-th of N near-equal parts of the subjects (e.g. 1/2 and 2/2 in two processes)")
    p.add_argument("--start", type=cli_args.int_in(0), default=None, help="first subject index (default 0)")
    p.add_argument("--stop", type=cli_args.int_in(0), default=None,
                   help="one past the last subject index (default --n-subjects)")
    p.add_argument("--workdir", type=cli_args.output_dir, default=DEFAULT_WORKDIR,
                   help=f"work folder with the per-subject records (default {DEFAULT_WORKDIR}); a rerun resumes")
    p.add_argument("--warmup", type=cli_args.int_in(1, 1_000_000), default=DEFAULT_WARMUP,
                   help=f"warm-up iterations per chain (default {DEFAULT_WARMUP})")
    p.add_argument("--samples", type=cli_args.int_in(1, 1_000_000), default=DEFAULT_SAMPLES,
                   help=f"draws kept per chain (default {DEFAULT_SAMPLES})")
    p.add_argument("--chains", type=cli_args.int_in(1, 64), default=DEFAULT_CHAINS,
                   help=f"MCMC chains (default {DEFAULT_CHAINS})")
    p.add_argument("--derived-draws", type=cli_args.int_in(2, 2000), default=DEFAULT_DERIVED_DRAWS,
                   help=f"posterior draws behind the derived FE volumes (default {DEFAULT_DERIVED_DRAWS})")
    p.add_argument("--thin", type=cli_args.int_in(2, 100_000), default=DEFAULT_THIN,
                   help=f"L: posterior draws the θ ranks are taken among (default {DEFAULT_THIN})")
    p.add_argument("--routes", default=",".join(ROUTES), help=f"comma-separated routes (default {','.join(ROUTES)})")
    p.add_argument("--allow-extrapolation", action="store_true",
                   help="pass --allow-extrapolation to `lvcore calibrate` (default: not; a mesh projected outside "
                        "the emulator's box is then refused, exit 2, and counted)")
    p.add_argument("--keep-runs", action="store_true",
                   help="keep each subject's files and calibration output under WORKDIR/runs (default: removed)")
    p.add_argument("--summarise", action="store_true",
                   help="build the result from the finished subjects in --workdir instead of running any")
    p.add_argument("--out", type=cli_args.output_file, default=None,
                   help="with --summarise: the result file (default WORKDIR/sbc.json); sbc_subjects.csv beside it")
    p.add_argument("--json", action="store_true", help="print the result (--summarise) or the piece as JSON")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    if args.summarise:
        res = summarise(args.workdir, args.out)
        out = args.out or Path(args.workdir) / RESULT_FILE
        if args.json:
            print(json.dumps({k: v for k, v in res.items() if k != "subjects"}, indent=1))
        else:
            print(format_summary(res))
            print(f"wrote {out} and {Path(out).parent / SUBJECTS_FILE}")
        return 0
    routes = [r.strip() for r in str(args.routes).split(",") if r.strip()]
    bad = [r for r in routes if r not in ROUTES]
    if bad or not routes:
        raise LVCoreError(f"--routes {args.routes}: choose from {', '.join(ROUTES)}")
    from lvcore.inference import samplers

    samplers.use_host_devices(args.chains)
    check_emulator_conditions()
    start, stop = piece_range(args.n_subjects, args.piece, args.start, args.stop)
    settings = default_settings(seed=args.seed, warmup=args.warmup, samples=args.samples, chains=args.chains,
                                derived_draws=args.derived_draws, thin=args.thin, routes=routes,
                                allow_extrapolation=bool(args.allow_extrapolation))
    res = run_piece(start, stop, settings, args.workdir, n_subjects=args.n_subjects,
                    log=None if args.json else (lambda m: print(m, flush=True)), keep_runs=args.keep_runs)
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        print(f"piece done: {res['ran']} subjects in {res['seconds']:.0f} s; summarise with `lvcore study sbc "
              f"--summarise --workdir {args.workdir} --out DIR/{RESULT_FILE}`")
    return 0


def check_emulator_conditions(name: str = EMULATOR) -> dict:
    """The ``chapter`` emulator's training conditions must be the study's (EDP, angles, base, mesh)."""
    from lvcore.emulator import load_emulator

    emu = load_emulator(name)
    fixed = emu.metadata.get("fixed_inputs", {})
    found = {"edp": fixed.get("edp"), "alpha_endo": fixed.get("alpha_endo"), "alpha_epi": fixed.get("alpha_epi"),
             "base": emu.base, "resolution": emu.resolution}
    want = {"edp": EDP_MMHG, "alpha_endo": ANGLES[0], "alpha_epi": ANGLES[1], "base": BASE, "resolution": RESOLUTION}
    if found != want:
        raise LVCoreError(f"the '{name}' emulator's conditions {found} are not the SBC study's {want}")
    return found


__all__ = ["RESULT_FILE", "SUBJECTS_FILE", "QUANTITIES", "ROUTES", "rank_of_truth", "pit", "inside_central",
           "nominal_coverage", "wilson_interval", "rank_histogram", "rank_chi2", "uniform_band", "quantity_summary",
           "flag_kind", "prior_draw", "noise_draw", "simulate_truth", "make_subject", "write_subject_files",
           "calibrate_argv", "calibrate_in_process", "read_route_outputs", "route_ranks", "run_route",
           "run_subject", "Store", "piece_range", "run_piece", "summarise_records", "summarise", "load", "tables",
           "figures", "source_line", "captions", "format_summary", "add_study_parser", "check_emulator_conditions"]
