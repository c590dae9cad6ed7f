"""F6 as a real test (issue 26 item 3): fixed vs free fibre angles on data with a known mismatch.

The chapter found that freeing the fibre angles in the Bayesian optimisation
cut the LVV error for 8/8 real volunteers (Tables 9.2 vs 9.3). Our bundled
SYNTHETIC volunteers carry no mismatch the angles could absorb, so the
shipped bo-fibres study cannot test that. Here the data of each volunteer
(bundled HV1–HV8: their PCA geometry h and hidden θ,
:func:`lvcore.studies.mismatch.bundled_volunteers`) are simulated with one
**kind** of mismatch, built by :func:`lvcore.studies.mismatch.mismatch_case`:

=========  ====================================================  ==================
kind       the data-generating simulator has                      angles can absorb?
=========  ====================================================  ==================
``angles``  hidden helix angles (−30°, 80°) (fixed model: −60°, 90°)   yes
``sheet``   sheet and fibre-sheet stiffnesses ``as``, ``afs`` × 8      no
``base``    clamped base (the model: sliding)                       no
=========  ====================================================  ==================

Otherwise data and model agree (same PCA geometry, EDP, law; for ``sheet``
and ``base`` the data's angles are the fixed pair). Noise σ_V = 5 mL,
σ_S = 0.03 is added (seeded per volunteer and kind). The BO of
:func:`lvcore.studies.bo_fibres.run_one` then runs in both modes, ``fixed``
(θ, angles at (−60°, 90°)) and ``free`` (θ and both angles), on the FE
simulator (warm-started continuation chains, :mod:`lvcore.execution.chains`) with a
**reduced budget** (default 30 + 30 per run; the chapter used 300 + 300).

The comparison is made on a **common objective scale**: the chapter's
standardised RSS with one standardisation for both modes (the standard
deviation of each output over the union of both modes' initial designs),
evaluated at each mode's optimum and as the lowest value each mode reached.
Also reported: the LVV error and strain RMSE against the measured (noisy)
data and against the noise-free mismatched outputs, the angles found, and
per kind the mean change fixed − free with a 90 % bootstrap CI over
volunteers. The verdict per kind (reproduced / not reproduced / refuted) is
data (``verdicts`` in the result file, :data:`RESULT_FILE`). Everything is SYNTHETIC.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from lvcore import cli_args
from lvcore.domain.conditions import CHAPTER_EDP, SIGMA_S, SIGMA_V_ML
from lvcore.exceptions import LVCoreError
from lvcore.domain.outputs import EDP_NAME, THETA_NAMES
from lvcore.studies import bo_fibres, registry
from lvcore.studies._common import (add_simulator_options, bootstrap_ci, clean, comma_list, print_result, save_figure,
                                    study_executor, write_json_atomic)

#: Hidden angles of the ``angles`` kind (deg): far from the fixed pair, inside the free box.
HIDDEN_ANGLES = (-30.0, 80.0)
#: Mismatch kinds: the source and dose of :func:`lvcore.studies.mismatch.mismatch_case`, the data's angles, and
#: whether free angles can absorb the mismatch.
KINDS = {
    "angles": {"source": None, "dose": 0.0, "angles": HIDDEN_ANGLES, "absorbable": True,
               "what": "hidden helix angles (-30, 80) deg, fixed model (-60, 90) deg"},
    "sheet": {"source": "sheet", "dose": 8.0, "angles": tuple(bo_fibres.FIXED_ANGLES), "absorbable": False,
              "what": "sheet and fibre-sheet stiffnesses as, afs x 8"},
    "base": {"source": "base", "dose": 1.0, "angles": tuple(bo_fibres.FIXED_ANGLES), "absorbable": False,
             "what": "clamped base (the model: sliding)"},
}
#: Default volunteers (3 per kind) and the reduced budget per run.
DEFAULT_VOLUNTEERS = ("HV1", "HV2", "HV3")
DEFAULT_INITIAL, DEFAULT_ITERATIONS = 30, 30
#: LVV weight of the chapter's objective.
LVV_WEIGHT = 2.0
RESULT_FILE = registry.result_file("bo-mismatch")
RUNS_FILE = "bo_mismatch_runs.csv"
COMMAND = "lvcore study bo-mismatch --out RESULTS"
N_BOOT, LEVEL = 2000, 0.9
TITLES = {"fig_errors": "F6 test: LVV and strain errors at the BO optimum, fixed vs free angles, per mismatch kind",
          "fig_common_objective": "F6 test: best objective on a common scale, fixed vs free angles"}


# ----------------------------------------------------------------------------- data
def data_case(volunteer, kind: str, resolution: str = "default") -> dict:
    """The simulator case of ``volunteer``'s data with mismatch ``kind`` (``None``: the model's own condition)."""
    from lvcore.studies.mismatch import mismatch_case

    if kind is not None and kind not in KINDS:
        raise LVCoreError(f"--kinds: unknown mismatch kind {kind!r}; choose from {', '.join(KINDS)}")
    k = KINDS[kind] if kind else {"source": None, "dose": 0.0, "angles": tuple(bo_fibres.FIXED_ANGLES)}
    case = mismatch_case(volunteer.theta, volunteer.h, k["source"], k["dose"], resolution=resolution,
                         geometry=volunteer.geometry)
    case["fibres"] = {"alpha_endo": float(k["angles"][0]), "alpha_epi": float(k["angles"][1])}
    return case


def noise(seed_key: Sequence[int]) -> np.ndarray:
    """Measurement noise (σ_V = 5 mL on LVV, σ_S = 0.03 on the strains), seeded by ``seed_key``."""
    rng = np.random.default_rng(list(seed_key))
    return rng.standard_normal(25) * np.r_[SIGMA_V_ML, np.full(24, SIGMA_S)]


def make_data(volunteer, kind: str, out: Path, *, resolution: str = "default", simulate=None, seed: int = 0) -> dict:
    """Noise-free and noisy data of one volunteer and kind (and its nominal outputs); cached in ``out/data``."""
    if simulate is None:
        from lvcore.mechanics.simulate import simulate as _sim

        def simulate(case):
            return _sim(case, raise_on_failure=True).outputs()
    path = Path(out) / "data" / f"{volunteer.name}__{kind}.json"
    settings = {"resolution": resolution, "seed": int(seed), "kind": KINDS[kind]["what"]}
    if path.is_file():
        d = json.loads(path.read_text())
        if d.get("settings") == settings:
            return d
    clean_y = np.asarray(simulate(data_case(volunteer, kind, resolution)), float)
    nominal = np.asarray(simulate(data_case(volunteer, None, resolution)), float)
    idx = list(KINDS).index(kind)
    vi = int("".join(c for c in volunteer.name if c.isdigit()) or 0)
    d = {"settings": settings, "volunteer": volunteer.name, "kind": kind, "clean": clean_y.tolist(),
         "nominal": nominal.tolist(), "measured": (clean_y + noise((seed, vi, idx))).tolist(),
         "strain_rms_mismatch": float(np.sqrt(np.mean((clean_y[1:] - nominal[1:]) ** 2))),
         "lvv_mismatch_ml": float(clean_y[0] - nominal[0])}
    write_json_atomic(path, d)
    return d


def subject_name(volunteer, kind: str) -> str:
    """The BO subject of one volunteer and kind: ``SYNTHETIC-HV1-angles``; the real LV's geometry is a patient's,
    its data are simulated: ``REAL-LV-angles``."""
    return f"{volunteer.name if volunteer.geometry else 'SYNTHETIC-' + volunteer.name}-{kind}"


def model_forward(volunteer, mode: str, resolution: str = "default", kind: str = ""):
    """The BO's forward model: the FE simulator on the volunteer's PCA geometry (the real LV: its mesh), sliding
    base, reading the mode's inputs."""
    from lvcore.mechanics.forward import SimulatorForward
    from lvcore.studies.mismatch import MODEL_BASE

    space = bo_fibres.bo_space(mode)
    cond = {**space.fixed_dict(), EDP_NAME: CHAPTER_EDP, **{f"h{i + 1}": float(v) for i, v in enumerate(volunteer.h)}}
    where = (f"the {volunteer.name} mesh" if volunteer.geometry
             else f"SYNTHETIC-{volunteer.name} PCA geometry")
    return SimulatorForward(input_names=space.names, conditions=cond, base=MODEL_BASE, resolution=resolution,
                            geometry=volunteer.geometry,
                            label=f"FE simulator on {where} ({resolution}, {MODEL_BASE} base; data: {kind})",
                            warm_start=True)


# ----------------------------------------------------------------------------- common scale
def common_scale(states: Sequence[dict], n_initial: int) -> np.ndarray:
    """One standardisation for both modes: the SD of each output over the union of the initial designs."""
    Y = np.vstack([np.asarray(s["Y"], float)[:n_initial] for s in states])
    scale = np.nanstd(Y, axis=0)
    scale[~(scale > 0)] = 1.0
    return scale


def common_objective(Y, measured, scale, lvv_weight: float = LVV_WEIGHT) -> np.ndarray:
    """The chapter's standardised RSS (:class:`lvcore.optimise.bayesopt.StandardisedRSS`) with a given scale."""
    from lvcore.optimise.bayesopt import StandardisedRSS

    return StandardisedRSS(np.asarray(measured, float), np.asarray(scale, float), lvv_weight)(np.asarray(Y, float))


def compare(entries: dict, states: dict, data: dict, n_initial: int) -> dict:
    """Fixed vs free for one volunteer and kind on the common scale, and by the noise model's χ² (σ_V, σ_S: one
    scale for both modes and both objectives); ``entries``/``states`` by mode."""
    from lvcore.optimise.bayesopt import PosteriorObjective

    chi2 = PosteriorObjective(np.asarray(data["measured"], float), SIGMA_V_ML, SIGMA_S, {}, {}).misfit
    scale = common_scale([states[m] for m in bo_fibres.MODES], n_initial)
    measured, clean_y = np.asarray(data["measured"]), np.asarray(data["clean"])
    out = {"scale": scale.tolist()}
    for m in bo_fibres.MODES:
        e = entries[m]
        y_best = measured.copy()
        y_best[0] = e["lvv_model_ml"]
        y_best[1:] = measured[1:] + np.asarray(e["strain_residuals"])
        Y = np.asarray(states[m]["Y"], float)
        f_all = common_objective(Y, measured, scale)
        out[m] = {"objective_common_at_best": float(common_objective(y_best, measured, scale)[0]),
                  "objective_common_min": float(np.nanmin(f_all)),
                  "objective_own_scale": float(e["objective_best"]),
                  "chi2_at_best": float(chi2(y_best)[0]),
                  "lvv_abs_error_ml": float(abs(y_best[0] - measured[0])),
                  "strain_rmse": float(np.sqrt(np.mean((y_best[1:] - measured[1:]) ** 2))),
                  "lvv_abs_error_vs_noise_free_ml": float(abs(y_best[0] - clean_y[0])),
                  "strain_rmse_vs_noise_free": float(np.sqrt(np.mean((y_best[1:] - clean_y[1:]) ** 2))),
                  "alpha_endo": e["alpha_endo"], "alpha_epi": e["alpha_epi"], "theta": e["theta"],
                  "evaluations": e["evaluations"], "failed": bo_fibres._failed_count(e["failed_evaluations"]),
                  "seconds": e["seconds"]}
    return out


# ----------------------------------------------------------------------------- the study
def run_study(volunteers: Sequence[str] = DEFAULT_VOLUNTEERS, kinds: Sequence[str] = tuple(KINDS), *, out,
              n_initial: int = DEFAULT_INITIAL, n_iterations: int = DEFAULT_ITERATIONS, workers: int = 1,
              scheduler: str | None = None, seed: int = 0, resolution: str = "default", progress: bool = False,
              forward_factory=None, simulate=None, log=None, n_boot: int = N_BOOT, objective: str = "chapter") -> dict:
    """Data with each mismatch kind, BO fixed and free per volunteer, the common-scale comparison; resumable.

    ``volunteers``: bundled SYNTHETIC volunteers (``HV1``) and :data:`lvcore.studies.mismatch.REAL_LV`, the real
    LV's mesh at the volunteers' median θ (its data simulated on it). ``objective``: the chapter's
    standardised RSS or the regularised ``posterior`` (:func:`lvcore.studies.bo_fibres.posterior_objective`).
    ``forward_factory(volunteer, mode, kind)`` and ``simulate(case) -> outputs`` replace the simulator (tests).
    State files (every evaluation) go to ``out/state``, data to ``out/data``.
    """
    from lvcore.studies.mismatch import study_volunteers

    for k in kinds:
        if k not in KINDS:
            raise LVCoreError(f"--kinds: unknown mismatch kind {k!r}; choose from {', '.join(KINDS)}")
    if objective not in bo_fibres.OBJECTIVES:
        raise LVCoreError(f"--objective: choose from {', '.join(bo_fibres.OBJECTIVES)}, not {objective!r}")
    vols = study_volunteers(list(volunteers))
    out = Path(out)
    t0 = time.perf_counter()
    runs = []
    with study_executor(workers, scheduler, local=forward_factory is not None) as executor:
        for kind in kinds:
            for v in vols:
                d = make_data(v, kind, out, resolution=resolution, simulate=simulate, seed=seed)
                subject = bo_fibres.Subject(subject_name(v, kind), np.asarray(d["measured"]), Path("pca"))
                entries, states = {}, {}
                for mode in bo_fibres.MODES:
                    fwd = (forward_factory(v, mode, kind) if forward_factory is not None
                           else model_forward(v, mode, resolution, kind))
                    entries[mode] = bo_fibres.run_one(subject, mode, n_initial=n_initial, n_iterations=n_iterations,
                                                      seed=seed, resolution=resolution, state_dir=out / "state",
                                                      executor=executor, workers=workers, forward=fwd,
                                                      progress=progress, objective=objective)
                    states[mode] = json.loads((out / "state" / f"{subject.stem}_{mode}.json").read_text())
                c = compare(entries, states, d, n_initial)
                run = {"volunteer": v.name, "kind": kind, "strain_rms_mismatch": d["strain_rms_mismatch"],
                       "lvv_mismatch_ml": d["lvv_mismatch_ml"], **{m: c[m] for m in bo_fibres.MODES}}
                runs.append(run)
                if log is not None:
                    log(f"{v.name} {kind:6s}: LVV error fixed {run['fixed']['lvv_abs_error_ml']:.2f} / free "
                        f"{run['free']['lvv_abs_error_ml']:.2f} mL; common objective fixed "
                        f"{run['fixed']['objective_common_at_best']:.3g} / free {run['free']['objective_common_at_best']:.3g}; "
                        f"free angles ({run['free']['alpha_endo']:.0f}, {run['free']['alpha_epi']:.0f})")
    real = [v.name for v in vols if v.geometry]
    meta = {"study": "bo-mismatch", "label": "SYNTHETIC volunteers with a known model-data mismatch (F6 test)"
                                             + (f"; {', '.join(real)}: a real LV's mesh, its data simulated"
                                                if real else ""),
            "volunteers": [v.name for v in vols], "kinds": {k: KINDS[k] for k in kinds},
            "objective": objective_meta(objective),
            "fixed_angles": list(bo_fibres.FIXED_ANGLES),
            "budget": {"n_initial": n_initial, "n_iterations": n_iterations,
                       "label": bo_fibres.budget_label(n_initial, n_iterations)},
            "noise": {"sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S}, "seed": seed, "resolution": resolution,
            "workers": workers, "executor": "dask" if scheduler else "local",
            "seconds_this_session": round(time.perf_counter() - t0, 1),
            "bo_seconds_total": round(sum(r[m]["seconds"] for r in runs for m in bo_fibres.MODES), 1),
            "common_scale": "SD of each output over the union of both modes' initial designs (one standardisation "
                            "for fixed and free); LVV weight 2",
            "command": (f"lvcore study bo-mismatch --volunteers {','.join(v.name for v in vols)} --kinds "
                        f"{','.join(kinds)} --initial {n_initial} --iterations {n_iterations}"
                        + (f" --objective {objective}" if objective != "chapter" else "") + " --out RESULTS")}
    result = summarise(runs, meta, n_boot=n_boot)
    write_outputs(result, out)
    return result


def objective_meta(objective: str) -> dict:
    """What the BO minimised, for the result's meta: the name and, for the regularised objective, its terms."""
    if objective == "chapter":
        return {"name": "chapter", "what": "the chapter's standardised RSS (each output scaled by its SD over the "
                                           f"initial design; LVV weight {LVV_WEIGHT:g})"}
    med, sd = bo_fibres.THETA_PRIOR
    return {"name": objective,
            "what": (f"regularised (not the chapter's): chi2 with sigma_V {SIGMA_V_ML:g} mL and sigma_S {SIGMA_S:g}, "
                     f"plus a log-normal prior on a, b, af, bf (median {med:g} kPa, log-SD {sd:.3f}: the box's "
                     f"edges at 2 SD) and, with free angles, a normal prior on each about its box's middle, SD a "
                     f"quarter of its width ("
                     + ", ".join(f"{n} {mean:g} +- {width:g} deg" for n, (mean, width) in bo_fibres.ANGLE_PRIOR.items())
                     + ")"),
            "theta_prior": {"median": med, "log_sd": sd},
            "angle_prior": {n: {"mean": m, "sd": s} for n, (m, s) in bo_fibres.ANGLE_PRIOR.items()}}


# ----------------------------------------------------------------------------- findings
def _mean_diff(runs, key):
    return lambda units: float(np.mean([r["fixed"][key] - r["free"][key] for r in units]))


def kind_summary(runs: Sequence[dict], n_boot: int = N_BOOT, seed: int = 0) -> dict:
    """Per kind: fixed − free (> 0: free better) with 90 % bootstrap CIs over volunteers, and counts."""
    out = {}
    for kind in dict.fromkeys(r["kind"] for r in runs):
        rs = [r for r in runs if r["kind"] == kind]
        kw = dict(n_boot=n_boot, seed=seed, level=LEVEL)
        rel = lambda units: float(np.mean([1.0 - r["free"]["objective_common_at_best"]  # noqa: E731
                                           / r["fixed"]["objective_common_at_best"] for r in units]))
        out[kind] = {
            "n_volunteers": len(rs),
            "strain_rms_mismatch": [r["strain_rms_mismatch"] for r in rs],
            "lvv_mismatch_ml": [r.get("lvv_mismatch_ml", float("nan")) for r in rs],
            "free_lvv_error_lower": int(sum(r["free"]["lvv_abs_error_ml"] < r["fixed"]["lvv_abs_error_ml"] for r in rs)),
            "free_strain_rmse_lower": int(sum(r["free"]["strain_rmse"] < r["fixed"]["strain_rmse"] for r in rs)),
            "free_common_objective_lower": int(sum(r["free"]["objective_common_at_best"]
                                                   < r["fixed"]["objective_common_at_best"] for r in rs)),
            "lvv_error_reduction_ml": bootstrap_ci(rs, _mean_diff(rs, "lvv_abs_error_ml"), **kw),
            "strain_rmse_reduction": bootstrap_ci(rs, _mean_diff(rs, "strain_rmse"), **kw),
            "lvv_error_vs_noise_free_reduction_ml": bootstrap_ci(rs, _mean_diff(rs, "lvv_abs_error_vs_noise_free_ml"),
                                                                 **kw),
            "common_objective_relative_reduction": bootstrap_ci(rs, rel, **kw),
            "median_lvv_abs_error_ml": {m: float(np.median([r[m]["lvv_abs_error_ml"] for r in rs]))
                                        for m in bo_fibres.MODES},
            "median_strain_rmse": {m: float(np.median([r[m]["strain_rmse"] for r in rs])) for m in bo_fibres.MODES},
        }
    return out


def verdicts(summary: dict) -> dict:
    """F6 as data: per kind, "freeing the angles cuts the LVV error" reproduced / not reproduced / refuted.

    *Reproduced*: the 90 % CI of the mean LVV-error reduction (fixed − free) lies above 0;
    *refuted*: below 0; otherwise *not reproduced*.
    """
    by_kind = {}
    for kind, s in summary.items():
        b = s["lvv_error_reduction_ml"]
        lo, hi = b["ci"] or [b["value"]] * 2
        v = "reproduced" if lo > 0 else "refuted" if hi < 0 else "not reproduced"
        o = s["common_objective_relative_reduction"]
        by_kind[kind] = {
            "what": KINDS[kind]["what"], "angles_can_absorb": KINDS[kind]["absorbable"],
            "value": b["value"], "ci": b["ci"], "verdict": v,
            "note": (f"free lower LVV error for {s['free_lvv_error_lower']}/{s['n_volunteers']}; common-scale "
                     f"objective {100 * o['value']:.0f} % lower with free angles (CI "
                     + (f"{100 * o['ci'][0]:.0f} to {100 * o['ci'][1]:.0f} %" if o["ci"] else "n/a")
                     + f"), lower for {s['free_common_objective_lower']}/{s['n_volunteers']}; the mismatch's own size: "
                     f"strain RMS {min(s['strain_rms_mismatch']):.2g}-{max(s['strain_rms_mismatch']):.2g}, LVV "
                     f"{min(s['lvv_mismatch_ml']):.3g} to {max(s['lvv_mismatch_ml']):.3g} mL"
                     + (f" (below the strain noise {SIGMA_S:g}/10: effectively no mismatch, a control)"
                        if max(s["strain_rms_mismatch"]) < SIGMA_S / 10 else ""))}
    absorbable = [k for k in by_kind if KINDS[k]["absorbable"]]
    main = by_kind[absorbable[0]] if absorbable else next(iter(by_kind.values()), None)
    return {"F6": {
        "finding": "F6: freeing the fibre angles cuts the LVV error (Tables 9.2 vs 9.3)",
        "chapter": "8/8 volunteers, median 18.9 -> 5.9 mL",
        "quantity": "mean over volunteers of LVV |error| fixed - free (mL), at each mode's BO optimum",
        "value": None if main is None else main["value"], "ci": None if main is None else main["ci"],
        "level": LEVEL, "verdict": None if main is None else main["verdict"],
        "note": ("verdict for data whose mismatch the angles can absorb; by_kind gives the kinds they cannot "
                 "absorb (if F6 also appears there, freeing the angles absorbs other mismatch)"),
        "by_kind": by_kind}}


def summarise(runs: Sequence[dict], meta: dict, n_boot: int = N_BOOT) -> dict:
    s = kind_summary(runs, n_boot=n_boot)
    return {"runs": list(runs), "summary": s, "verdicts": verdicts(s),
            "meta": {**meta, "n_boot": n_boot, "ci_level": LEVEL, "bootstrap_units": "volunteers"}}


# ----------------------------------------------------------------------------- results interface
def load(folder) -> dict:
    """The result (:data:`RESULT_FILE`) in ``folder``: the ``--out`` folder of ``lvcore study bo-mismatch``, or the
    bundled results folder.

    Returns
    -------
    dict
        ``runs`` (one per volunteer and mismatch kind: the mismatch's size, and the ``fixed`` and ``free`` BO
        optima), ``summary``, ``verdicts`` (``F6``: the mean over volunteers of LVV |error| fixed − free in mL,
        its 90 % bootstrap CI over volunteers and the verdict, overall and ``by_kind``), ``meta`` and ``folder``.

    Raises
    ------
    LVCoreError
        The file is missing, too large or not JSON (naming it).

    Examples
    --------
    The bundled (SYNTHETIC) result: one run per volunteer and kind of mismatch, and F6's verdict per kind:

    >>> from lvcore.studies import bo_mismatch
    >>> from lvcore.studies.results import bundled_studies_dir
    >>> result = bo_mismatch.load(bundled_studies_dir())
    >>> len(result["runs"]) == len(result["meta"]["volunteers"]) * len(result["meta"]["kinds"])
    True
    >>> f6 = result["verdicts"]["F6"]
    >>> sorted(f6["by_kind"]) == sorted(result["meta"]["kinds"]), f6["level"]
    (True, 0.9)
    >>> all(k["verdict"] in ("reproduced", "not reproduced", "refuted") for k in f6["by_kind"].values())
    True
    """
    from lvcore.studies.results import read_result

    return read_result(folder, RESULT_FILE)


def source_line(result: dict) -> str:
    from lvcore.studies.results import source_label

    m = result.get("meta", {})
    return (f"{RESULT_FILE} ({source_label(result['folder'])}); volunteers {', '.join(m.get('volunteers', []))}; "
            f"kinds {', '.join(m.get('kinds', {}))}; budget {m.get('budget', {}).get('label', '?')}")


def run_rows(result: dict) -> list[dict]:
    """One row per volunteer, kind and mode."""
    rows = []
    for r in result.get("runs", []):
        for m in bo_fibres.MODES:
            e = r[m]
            rows.append({"volunteer": r["volunteer"], "kind": r["kind"], "mode": m,
                         "strain_rms_mismatch": r["strain_rms_mismatch"], "lvv_abs_error_ml": e["lvv_abs_error_ml"],
                         "strain_rmse": e["strain_rmse"], "objective_common_at_best": e["objective_common_at_best"],
                         "objective_common_min": e["objective_common_min"],
                         "objective_own_scale": e["objective_own_scale"],
                         "lvv_abs_error_vs_noise_free_ml": e["lvv_abs_error_vs_noise_free_ml"],
                         "strain_rmse_vs_noise_free": e["strain_rmse_vs_noise_free"],
                         "alpha_endo": e["alpha_endo"], "alpha_epi": e["alpha_epi"],
                         **{n: e["theta"][n] for n in THETA_NAMES}, "evaluations": e["evaluations"],
                         "failed": e["failed"], "seconds": e["seconds"]})
    return rows


def verdict_rows(result: dict) -> list[dict]:
    """The F6 verdict per kind, of the chapter's objective and, when shipped, of the regularised one
    (:data:`POSTERIOR_KEY`)."""
    rows = []
    for part, objective in ((result, "chapter"), (result.get(POSTERIOR_KEY) or {}, "regularised")):
        f6 = part.get("verdicts", {}).get("F6")
        for kind, v in (f6 or {}).get("by_kind", {}).items():
            ci = f"[{v['ci'][0]:.2f}, {v['ci'][1]:.2f}]" if v["ci"] else "(no CI)"
            rows.append({"finding": "F6", "objective": objective, "kind": kind, "data": v["what"],
                         "angles can absorb": v["angles_can_absorb"],
                         "volunteers": part.get("summary", {}).get(kind, {}).get("n_volunteers"),
                         "LVV error reduction (mL, 90 % CI)": f"{v['value']:.2f} {ci}", "verdict": v["verdict"],
                         "note": v["note"]})
    return rows


def tables(result: dict) -> dict:
    import pandas as pd

    runs = pd.DataFrame(run_rows(result))
    out = {"verdicts": pd.DataFrame(verdict_rows(result)), "runs": runs, "fig_errors": runs,
           "fig_common_objective": runs}
    if result.get(POSTERIOR_KEY):
        out["runs_regularised"] = pd.DataFrame(run_rows(result[POSTERIOR_KEY]))
    return out


def figures(result: dict) -> dict:
    """Bars of the errors per volunteer × kind, fixed vs free, and of the common-scale objective (at each mode's
    optimum, the lowest reached where lower, and the change with free angles)."""
    from lvcore.viz.study_figures import bo_error_bars, common_objective_bars

    rows = run_rows(result)
    if not rows:
        return {}
    import pandas as pd

    df = pd.DataFrame(rows)
    df["subject"] = df["volunteer"] + " " + df["kind"]
    df["median_abs_strain_error"] = df["strain_rmse"]
    fig = bo_error_bars(df)
    fig.update_yaxes(title_text="strain RMSE (-)", row=1, col=2)
    fig.layout.annotations[1].text = "strain RMSE (-)"
    fig.update_layout(title=f"{TITLES['fig_errors']} (SYNTHETIC; {result['meta']['budget']['label']})")
    # the optimum's common-scale value and, where lower, the lowest reached; beside it the change with free angles
    # (two panels of the optimum's value and of the lowest reached were the same bars in every bundled run)
    fig2 = common_objective_bars(df)
    fig2.update_layout(title=f"{TITLES['fig_common_objective']} (SYNTHETIC)")
    return {"fig_errors": fig, "fig_common_objective": fig2}


def write_outputs(result: dict, out) -> dict:
    import pandas as pd

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": str(write_json_atomic(out / RESULT_FILE, clean(result)))}
    pd.DataFrame(run_rows(result)).to_csv(out / RUNS_FILE, index=False)
    paths["csv"] = str(out / RUNS_FILE)
    for name, fig in figures(result).items():
        paths[name] = save_figure(fig, out / name)
    return paths


def format_findings(result: dict) -> str:
    return "\n".join(f"F6 [{r['kind']}: {r['data']}]: LVV error reduction {r['LVV error reduction (mL, 90 % CI)']} "
                     f"-> {r['verdict']}; {r['note']}" for r in verdict_rows(result))


def markdown_table(result: dict) -> str:
    """The F6 verdicts as the Markdown table docs/studies.md quotes (tests compare the two)."""
    lines = ["| data (kind) | angles can absorb | LVV error fixed − free, mean (90 % CI over volunteers) | "
             "free lower LVV error | common-scale objective | verdict |", "|---|---|---|---|---|---|"]
    f6 = result["verdicts"]["F6"]
    for kind, v in f6["by_kind"].items():
        s = result["summary"][kind]
        o = s["common_objective_relative_reduction"]
        ci = f" [{v['ci'][0]:.2f}, {v['ci'][1]:.2f}]" if v["ci"] else ""
        oci = f" [{100 * o['ci'][0]:.0f}, {100 * o['ci'][1]:.0f}]" if o["ci"] else ""
        lines.append(f"| {kind}: {v['what']} | {'yes' if v['angles_can_absorb'] else 'no'} | {v['value']:.2f} mL{ci} | "
                     f"{s['free_lvv_error_lower']}/{s['n_volunteers']} | {100 * o['value']:.0f} % lower{oci} | "
                     f"**{v['verdict']}** |")
    return "\n".join(lines)


#: Where the shipped result keeps the run with the regularised objective (``--objective posterior``), beside the
#: chapter's: its ``runs``, ``summary``, ``verdicts`` and ``meta`` (``scripts/ship_f6_regularised.py``).
POSTERIOR_KEY = "posterior"
DOCS_BEGIN = "<!-- F6 regularised: begin (generated by lvcore.studies.bo_mismatch.posterior_markdown) -->"
DOCS_END = "<!-- F6 regularised: end -->"


def posterior_markdown(result: dict) -> str:
    """The regularised run (``result[POSTERIOR_KEY]``) as docs/studies.md quotes it: the run, one row per
    volunteer (mismatch size, LVV error and χ² fixed / free, the free angles, parameters on the BO box), and the
    mean LVV-error cut over volunteers. Empty without that run."""
    from lvcore.studies.findings_rule import fmt_ci
    from lvcore.studies.findings_tests import bo_on_bound

    post = result.get(POSTERIOR_KEY)
    if not post or not post.get("runs"):
        return ""
    m = post["meta"]
    lines = [f"Shipped run: {', '.join(m['volunteers'])} ({len(m['volunteers'])} volunteers: "
             f"{m['label']}), kinds {', '.join(m['kinds'])}, {m['budget']['label']}, `{m['resolution']}` mesh, "
             f"objective: {m['objective']['what']}. The hidden truth is never read by the fit.", "",
             "| volunteer | kind | strain RMS of the mismatch | LVV error fixed / free (mL) | χ² fixed / free | "
             "free angles (α_endo, α_epi) | on the BO box: fixed / free |", "|---|---|---|---|---|---|---|"]
    for r in post["runs"]:
        fx, fr = r["fixed"], r["free"]
        edge = (", ".join(bo_on_bound(fx["theta"])) or "none") + " / " + (
            ", ".join(bo_on_bound(fr["theta"], fr["alpha_endo"], fr["alpha_epi"], True)) or "none")
        lines.append(f"| {r['volunteer']} | {r['kind']} | {r['strain_rms_mismatch']:.4f} | "
                     f"{fx['lvv_abs_error_ml']:.2f} / {fr['lvv_abs_error_ml']:.2f} | "
                     f"{fx['chi2_at_best']:.1f} / {fr['chi2_at_best']:.1f} | "
                     f"({fr['alpha_endo']:.0f}°, {fr['alpha_epi']:.0f}°) | {edge} |")
    for kind, s in post["summary"].items():
        lines += ["", f"{kind}: LVV error fixed − free {fmt_ci(s['lvv_error_reduction_ml'], '.2f', ' mL')} (mean over "
                      f"{s['n_volunteers']} volunteers, 90 % CI resampling volunteers); free angles lower the LVV error for "
                      f"{s['free_lvv_error_lower']}/{s['n_volunteers']}; median LVV error fixed "
                      f"{s['median_lvv_abs_error_ml']['fixed']:.2f} / free {s['median_lvv_abs_error_ml']['free']:.2f} mL."]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- CLI
def add_study_parser(study_subparsers) -> None:
    """``lvcore study bo-mismatch``."""
    p = study_subparsers.add_parser("bo-mismatch", help="finding F6 as a real test: BO with fixed vs free fibre "
                                                        "angles on data with a known mismatch (SYNTHETIC)")
    p.add_argument("--volunteers", default=",".join(DEFAULT_VOLUNTEERS),
                   help=f"comma-separated bundled volunteers, and REAL-LV for the real LV's mesh (default "
                        f"{','.join(DEFAULT_VOLUNTEERS)})")
    p.add_argument("--objective", choices=bo_fibres.OBJECTIVES, default="chapter",
                   help="what the BO minimises: the chapter's standardised RSS, or 'posterior', the noise model's "
                        "chi2 plus a weakly informative prior that keeps fits off the box's edges where the data do "
                        "not decide (default 'chapter')")
    p.add_argument("--kinds", default=",".join(KINDS), help=f"mismatch kinds (default {','.join(KINDS)})")
    bo_fibres.add_budget_options(p, DEFAULT_INITIAL, DEFAULT_ITERATIONS, per_run=True)
    add_simulator_options(p)
    p.add_argument("--seed", type=cli_args.seed, default=0, help="seed of the designs and the noise (default 0)")
    p.add_argument("--json", action="store_true", help="print the verdicts as JSON")
    p.add_argument("--out", type=cli_args.output_dir, required=True,
                   help="output folder (state files in OUT/state, data in OUT/data, for resuming)")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    vols, kinds = comma_list(args.volunteers), comma_list(args.kinds)
    try:
        from lvcore.studies.mismatch import study_volunteers

        study_volunteers(vols)
    except ValueError as err:
        raise LVCoreError(f"--volunteers: {err}") from None
    res = run_study(vols, kinds, out=args.out, n_initial=args.initial, n_iterations=args.iterations,
                    workers=args.workers, scheduler=args.scheduler, seed=args.seed, resolution=args.resolution,
                    progress=not args.json, log=None if args.json else print, objective=args.objective)
    return print_result(args.json, clean({"verdicts": res["verdicts"], "meta": res["meta"]}),
                        lambda: f"{format_findings(res)}\nbudget: {res['meta']['budget']['label']}; wrote "
                                f"{args.out}/{RESULT_FILE}, {RUNS_FILE} and figures")
