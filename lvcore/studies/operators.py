"""Three-operator parameter-estimation study (chapter §9.3.3, Figs 9.11–9.14; findings F4/F5).

For each SYNTHETIC patient of the operator study and each of the 3
(imitation) operators taken as the *main* one, data are simulated at the
truth θ̃ = (0.60, 1.30, 1.00, 3.60) on the main operator's geometry g:
``y* = ζ(θ̃, g)``. θ is then refitted from θ̃ on each *test* geometry ĝ —
the two other operators' geometries and the 5- and 10-PC reconstructions of
g — by SLSQP on the chapter's loss (9.11)
(:func:`lvcore.optimise.sqp.refit_theta`) with the simulator's adjoint
gradients (:class:`lvcore.mechanics.AdjointSimulatorForward`). 6 patients × 3 mains × 4
tests = 72 fits.

Each fit records:

* ``strain_rmse_forward`` — RMS over the 24 regions of ζ(θ̃, ĝ) − y*
  (the forward strain error of the geometry alone, Fig 9.11);
* ``theta_hat``, ``theta_abs_error`` (Fig 9.12);
* ``output_rmse_refit`` — RMS over the 24 strains of ζ(θ̂, g) − y*, the
  refitted parameters run on the main (true) geometry against the benchmark
  simulation (Fig 9.14: parameter errors measured in output space);
* beyond the chapter: the Gauss–Newton/Laplace covariance of θ̂ and the
  Mahalanobis distance of θ̂ from θ̃. Loss (9.11) is a sum of 25 squared
  residuals r(θ); read as the negative log-likelihood of i.i.d. Gaussian
  residuals of standard deviation σ (:data:`SIGMA_RESIDUAL`, the volunteers'
  strain noise), the Laplace covariance at θ̂ is ``Σ = σ² (JᵀJ)⁻¹`` with J =
  dr/dθ from the adjoint Jacobian, and ``d = sqrt(Δθᵀ Σ⁻¹ Δθ)``;
* the loss surface over each parameter pair around θ̂ (Fig 9.13): by default
  its Gauss–Newton model ``|r(θ̂) + J Δθ|²`` (no extra simulations), with
  ``--surface-grid N`` the simulator's loss on an N × N grid per pair.

Fits run in parallel on the campaign executors (local pool or Dask); each
finished fit is written to ``DIR/fits/`` so an interrupted study resumes.
Everything is SYNTHETIC: the operators are imitations
(:mod:`lvcore.geometry.cohort`).
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from lvcore import cli_args
from lvcore.exceptions import LVCoreError  # noqa: F401 - the study's error, as before the split
from lvcore.domain.outputs import THETA_NAMES
from lvcore.studies import registry
from lvcore.studies._common import clean, progress_bar, save_figure, write_json_atomic
from lvcore.studies.operators_fit import (BOUND_TOL, CHAPTER_SHARE_10PC, GN_GRID, PAIRS, PC_TESTS,  # noqa: F401
                                          SIGMA_RESIDUAL, SQP_TOL, SURFACE_SPAN, THETA_TRUE, CachedForward,
                                          data_task, early_volume_ml, fit_one, gauss_newton_surfaces,
                                          laplace_covariance, mahalanobis, on_bound, operator_names,
                                          patient_geometries, residual_jacobian, simulator_surfaces, surface_axes,
                                          surface_for_fit, test_geometries, test_geometry_name, theta_dict)

#: Result file of :func:`write_outputs` (the shipped one is under ``assets/studies/``), read by :func:`load`.
RESULT_FILE = registry.result_file("operators")
#: ``_data_task``: the former name of :func:`data_task` (``y* = ζ(θ̃, g_main)``, a worker task).
_data_task = data_task


# ----------------------------------------------------------------------------- the study
def run_study(patients: Sequence[str] | None = None, *, out, workers: int = 1, scheduler: str | None = None,
              resolution: str = "default", surface_grid: int = 0, forward_factory=None, progress: bool = False,
              operator_geometries=None, shape_model=None, collect_only: bool = False, mains=None,
              sqp_tol: float = SQP_TOL) -> dict:
    """Run every fit of ``patients`` (default: all 6) and write the result file (:data:`RESULT_FILE`) and the
    figures under ``out``.

    ``mains(patient) -> operators``: the main operators of each patient (default: every operator, the
    chapter's design; the realistic-operator study rotates one main per patient to save simulations).
    ``sqp_tol``: SLSQP's ``ftol`` (recorded in the settings when it is not the default).

    Returns ``{"fits": [...], "findings": {...}, "meta": {...}}``. Finished
    fits are kept in ``out/fits/`` and not repeated when the study is re-run
    with the same ``out``. ``collect_only``: run nothing, summarise the fits
    already in ``out/fits/`` (the result is then marked partial).
    """
    from lvcore.geometry.cohort import load_operator_geometries

    og = operator_geometries or load_operator_geometries()
    patients = list(patients) if patients else list(og.patients)
    out = Path(out)
    fits_dir = out / "fits"
    fits_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    geoms = {p: patient_geometries(p, out / "geometries", og, shape_model) for p in patients}
    ops = list(og.operators)
    mains_of = (lambda p: ops) if mains is None else (lambda p: [m for m in mains(p) if m in ops])
    settings = {"resolution": resolution if forward_factory is None else "stand-in", "theta_true": THETA_TRUE,
                "surface_grid": surface_grid, **({} if sqp_tol == SQP_TOL else {"sqp_tol": sqp_tol})}
    executor = None
    if not collect_only and (scheduler or workers > 1):
        from lvcore.execution.parallel import make_executor

        executor = make_executor(workers=workers, scheduler=scheduler)

    def submit(fn, *args):
        if executor is None:
            class _Done:
                def __init__(self, v):
                    self.v = v

                def result(self):
                    return self.v
            return _Done(fn(*args))
        return executor.submit(fn, *args)

    def fit_path(p, m, t):
        return fits_dir / f"{p}_{m}_{t}.json".replace("-", "_")

    records = {}
    try:
        todo = []
        for p in patients:
            for m in mains_of(p):
                for t, _ in test_geometries(m, ops):
                    fp = fit_path(p, m, t)
                    if fp.is_file():
                        d = json.loads(fp.read_text())
                        if d.get("settings") == clean(settings):
                            records[(p, m, t)] = d["fit"]
                            continue
                    todo.append((p, m, t))
        if collect_only:
            todo = []
        with progress_bar(len(todo) + len({(p, m) for p, m, _ in todo}), "operators", progress) as bar:
            main_pairs = sorted({(p, m) for p, m, _ in todo})
            data_f = {pm: submit(data_task, pm[0], pm[1], geoms[pm[0]], resolution, forward_factory) for pm in main_pairs}
            y_star = {}
            for pm, f in data_f.items():
                y_star[pm] = f.result()
                bar.update(1)
            fut = {submit(fit_one, p, m, t, y_star[(p, m)], geoms[p], resolution, forward_factory,
                          surface_grid, sqp_tol): (p, m, t) for p, m, t in todo}
            pending = list(fut)
            done_iter = executor.as_completed(pending) if executor is not None else pending
            for f in done_iter:
                key = fut[f]
                rec = f.result()
                records[key] = rec
                write_json_atomic(fit_path(*key), {"settings": clean(settings), "fit": clean(rec)})
                bar.update(1)
    finally:
        if executor is not None:
            executor.close()
    order = [(p, m, t) for p in patients for m in mains_of(p) for t, _ in test_geometries(m, ops)]
    fits = [records[k] for k in order if k in records]
    n_design = (len(og.patients) * len(ops) * (len(ops) - 1 + len(PC_TESTS)) if mains is None
                else sum(len(mains_of(p)) for p in og.patients) * (len(ops) - 1 + len(PC_TESTS)))
    result = {"fits": fits, "findings": findings(fits, ops),
              "meta": {"study": "operators", "label": "SYNTHETIC operator study (imitation operators on synthetic LVs)",
                       "patients": patients, "operators": ops, "n_fits": len(fits),
                       "complete_study": len(fits) == n_design,
                       "budget": (f"{len(fits)} of {n_design} fits "
                                  f"({', '.join(sorted({f['patient'] for f in fits}))})" +
                                  ("" if len(fits) == n_design else " (PARTIAL run; the chapter made all 72)")),
                       "settings": settings, "seconds_this_session": round(time.perf_counter() - t0, 1),
                       "simulations": int(sum(f.get("simulations", 0) for f in fits)),
                       "fit_seconds_total": round(sum(f.get("seconds", 0.0) for f in fits), 1),
                       "workers": workers, "executor": "dask" if scheduler else "local"}}
    write_outputs(result, out)
    return result


# ----------------------------------------------------------------------------- findings and outputs
def findings(fits: Sequence[dict], operators: Sequence[str]) -> dict:
    """F4/F5 on this data: PCs vs new operators, in forward strain error and in output space after the refit."""
    ok = [f for f in fits if "strain_rmse_forward" in f]
    by = {(f["patient"], f["main_operator"], f["test_geometry"]): f for f in ok}
    cases = sorted({(f["patient"], f["main_operator"]) for f in ok})
    out = {"n_fits": len(fits), "n_fits_ok": len(ok), "n_converged": int(sum(f["converged"] for f in fits)),
           "chapter_share_10pc_beats_operator_geometry": CHAPTER_SHARE_10PC}
    for metric in ("strain_rmse_forward", "output_rmse_refit"):
        res = {}
        for k in PC_TESTS:
            beats_both, no_worse, comps = [], [], 0
            for p, m in cases:
                pc = by.get((p, m, f"pc{k}"))
                others = [by.get((p, m, o)) for o in operators if o != m]
                others = [o for o in others if o is not None]
                if pc is None or not others:
                    continue
                beats_both.append(all(pc[metric] < o[metric] for o in others))
                no_worse += [pc[metric] <= o[metric] for o in others]
                comps += len(others)
            res[f"pc{k}"] = {"share_beats_both_operators": float(np.mean(beats_both)) if beats_both else None,
                             "share_no_worse_than_an_operator": float(np.mean(no_worse)) if no_worse else None,
                             "n_cases": len(beats_both), "n_comparisons": comps}
        res["median"] = {t: float(np.median([f[metric] for f in ok if _group(f) == t]))
                         for t in ("operator", "pc5", "pc10") if any(_group(f) == t for f in ok)}
        out[metric] = res
    if ok:
        groups = [t for t in ("operator", "pc5", "pc10") if any(_group(f) == t for f in ok)]
        out["median_mahalanobis"] = {t: float(np.median([f["mahalanobis"] for f in ok if _group(f) == t]))
                                     for t in groups}
        # the Laplace approximation needs an interior mode: fits with θ̂ on a prior bound are flagged and left out
        interior = [f for f in ok if not on_bound(f["theta_hat"])]
        out["n_on_bound"] = {t: int(sum(_group(f) == t for f in ok) - sum(_group(f) == t for f in interior))
                             for t in groups}
        out["median_mahalanobis_interior"] = {
            t: (float(np.median([f["mahalanobis"] for f in interior if _group(f) == t]))
                if any(_group(f) == t for f in interior) else None) for t in groups}
        out["mahalanobis_note"] = ("median_mahalanobis: every fit (Laplace, sigma = 0.03); "
                                   "median_mahalanobis_interior: fits with no parameter on a prior bound only, "
                                   "where the Laplace approximation applies (n_on_bound left out)")
        out["median_theta_abs_error"] = {t: dict(zip(THETA_NAMES, np.median(
            [f["theta_abs_error"] for f in ok if _group(f) == t], axis=0).tolist()))
            for t in ("operator", "pc5", "pc10") if any(_group(f) == t for f in ok)}
    return out


def _group(f: dict) -> str:
    return f["test_geometry"] if f["test_geometry"].startswith("pc") else "operator"


def fits_frame(fits: Sequence[dict]):
    """One row per fit (CSV behind the figures)."""
    import pandas as pd

    rows = []
    for f in fits:
        row = {k: f.get(k) for k in ("patient", "main_operator", "test_geometry", "converged", "strain_rmse_forward",
                                      "output_rmse_refit", "mahalanobis", "loss", "sqp_evaluations", "seconds")}
        row["on_bound"] = ",".join(on_bound(f["theta_hat"])) if "theta_hat" in f else None
        hat = theta_dict(f["theta_hat"]) if "theta_hat" in f else {}
        err = theta_dict(f["theta_abs_error"]) if "theta_abs_error" in f else {}
        for n in THETA_NAMES:
            row[f"{n}_hat"] = hat.get(n)
            row[f"{n}_abs_error"] = err.get(n)
        row["message"] = f.get("message", "")
        rows.append(row)
    return pd.DataFrame(rows)


#: The command that makes the results.
COMMAND = "lvcore study operators --out RESULTS"
#: Loss-surface files of a result folder, simulator surfaces first (the flat copy in the result file is the fallback).
SURFACE_FILES = ("rss_surfaces_simulator.json", "rss_surfaces.json")
#: Figures :func:`figures` draws, with their titles.
TITLES = {"fig9_11_forward_strain_error": "Fig 9.11: forward strain error at θ̃ per test geometry",
          "fig9_12_parameter_error": "Fig 9.12: absolute parameter errors of the SQP refits",
          "fig9_13_rss_surface": "Fig 9.13: RSS surface over parameter pairs",
          "fig9_14_output_error": "Fig 9.14: output-space error at θ̂ per test geometry",
          "fig_mahalanobis": "Beyond the chapter: Mahalanobis distance of θ̂ from θ̃"}
#: The violin figures: name -> (fit key, y-axis title, title after "Fig N — SYNTHETIC patients: ").
VIOLINS = {"fig9_11_forward_strain_error": ("strain_rmse_forward", "strain RMSE at θ̃ (-)", "Fig 9.11"),
           "fig9_14_output_error": ("output_rmse_refit", "strain RMSE at θ̂ (-)", "Fig 9.14"),
           "fig_mahalanobis": ("mahalanobis", "Mahalanobis distance (-)", "Beyond the chapter")}


def load(folder) -> dict:
    """The results of an operators ``--out`` folder (or the bundled one).

    Returns
    -------
    dict
        The result file (:data:`RESULT_FILE`: ``fits``, ``findings``, ``meta``, ``rss_surfaces``) plus
        ``surfaces``: loss surfaces grouped by fit (each ``patient``, ``main_operator``,
        ``test_geometry``, ``method``, ``theta_hat``, ``pairs``), from the surface files
        when present, else regrouped from the flat ``rss_surfaces``; and ``folder``.

    Examples
    --------
    The bundled (SYNTHETIC) result:

    >>> from lvcore.studies import operators
    >>> from lvcore.studies.results import bundled_studies_dir
    >>> result = operators.load(bundled_studies_dir())
    >>> sorted(k for k in result if k != "folder")
    ['findings', 'fits', 'meta', 'rss_surfaces', 'surfaces']
    """
    from lvcore.studies.results import read_json

    folder = Path(folder)
    data = read_json(folder / RESULT_FILE)
    surfaces = []
    for name in SURFACE_FILES:
        if (folder / name).is_file():
            surfaces += read_json(folder / name)
    data["surfaces"] = surfaces or group_surfaces(data.get("rss_surfaces") or [], data.get("fits", []))
    data["folder"] = str(folder)
    return data


def group_surfaces(flat: Sequence[dict], fits: Sequence[dict] = ()) -> list[dict]:
    """The inverse of :func:`flat_surfaces`: one record per fit with its ``pairs``; θ̂ taken from ``fits``."""
    groups: dict = {}
    for s in flat:
        key = (s.get("patient"), s.get("main_operator"), s.get("test_geometry"), s.get("method", ""))
        g = groups.setdefault(key, {"patient": key[0], "main_operator": key[1], "test_geometry": key[2],
                                    "method": key[3], "pairs": []})
        p, q = s["params"]
        g["pairs"].append({"x": p, "y": q, "x_values": s["x"], "y_values": s["y"], "rss": s["rss"]})
    for g in groups.values():
        fit = next((f for f in fits if (f.get("patient"), f.get("main_operator"), f.get("test_geometry"))
                    == (g["patient"], g["main_operator"], g["test_geometry"]) and "theta_hat" in f), None)
        if fit is not None:
            g["theta_hat"] = fit["theta_hat"]
    return list(groups.values())


def source_line(result: dict) -> str:
    """Where the numbers come from, as one readable line."""
    from lvcore.studies.results import source_label

    budget = result.get("meta", {}).get("budget")
    return f"{RESULT_FILE} ({source_label(result['folder'])})" + (f"; {budget}" if budget else "")



def test_order(fits: Sequence[dict]) -> list[str]:
    """Test geometries in order of appearance, the PC reconstructions last."""
    order = list(dict.fromkeys(f["test_geometry"] for f in fits))
    pcs = [f"pc{k}" for k in PC_TESTS]
    return [g for g in order if g not in pcs] + [g for g in pcs if g in order]


def tables(result: dict) -> dict:
    """The study's tables (DataFrames) by name: the data of each figure, and ``fits`` (one row per fit)."""
    import pandas as pd

    fits = result.get("fits", [])
    frame = pd.DataFrame(fits)
    out = {}
    for name, (col, _, _) in VIOLINS.items():
        if col in frame:
            out[name] = frame[["patient", "main_operator", "test_geometry", col]]
    if "theta_abs_error" in frame:
        out["fig9_12_parameter_error"] = pd.DataFrame(
            [{"patient": f["patient"], "main_operator": f["main_operator"], "test_geometry": f["test_geometry"],
              "parameter": n, "abs_error": v} for f in fits if "theta_abs_error" in f
             for n, v in theta_dict(f["theta_abs_error"]).items()])
    if result.get("surfaces"):
        out["fig9_13_rss_surface"] = result["surfaces"][0]
    if fits:
        out["fits"] = fits_frame(fits)
    return out


def surface_title(surface: dict) -> str:
    """Fig 9.13's title for one fit's surfaces: the patient, the main and test geometries."""
    who = surface.get("patient") or "patient not recorded"
    who = who if "SYNTHETIC" in who else f"SYNTHETIC {who}"
    return (f"Fig 9.13 — {who}: loss (9.11) over parameter pairs, data from main operator "
            f"{surface.get('main_operator') or '?'}'s geometry, θ refitted on test geometry "
            f"{surface.get('test_geometry') or '?'}")


def figures(result: dict) -> dict:
    """The study's figures by name (see :data:`TITLES`); figures whose data the results lack are left out."""
    from lvcore.viz.report_figures import error_strips, grouped_violins

    tabs = tables(result)
    fits = result.get("fits", [])
    order = test_order(fits) if fits else None
    out = {}
    for name, (col, ytitle, fig_no) in VIOLINS.items():
        if name in tabs:
            what = TITLES[name].split(": ", 1)[1]
            out[name] = grouped_violins(tabs[name], panel="main_operator", panel_label="main operator",
                                        x="test_geometry", y=col, order=order, yaxis_title=ytitle, nonnegative=True,
                                        title=f"{fig_no} — SYNTHETIC patients: {what}")
    if "fig9_12_parameter_error" in tabs:
        out["fig9_12_parameter_error"] = error_strips(
            tabs["fig9_12_parameter_error"], panel="main_operator", panel_label="main operator", param="parameter",
            x="test_geometry", y="abs_error", yaxis_title="|θ̂ − θ̃|",
            title="Fig 9.12 — SYNTHETIC patients: absolute parameter errors of the SQP refits (ticks: patients; "
                  "wide: median)")
    if result.get("surfaces"):
        out["fig9_13_rss_surface"] = surface_figure(result, 0)
    # in chapter order
    return {n: out[n] for n in TITLES if n in out}


def surface_figure(result: dict, index: int = 0):
    """Fig 9.13 for the ``index``-th fit with loss surfaces: every parameter pair, θ̂ and the truth θ̃ marked."""
    from lvcore.viz import study_figures

    s = result["surfaces"][index]
    return study_figures.surface_figure(s, THETA_TRUE, title=surface_title(s))


def write_outputs(result: dict, out) -> dict:
    """The result file (:data:`RESULT_FILE`, fits without the surfaces), ``rss_surfaces.json``, CSVs and figures."""
    from lvcore.studies.results import read_json

    out = Path(out)
    fits = result["fits"]
    slim = [{k: v for k, v in f.items() if k != "rss_surface"} for f in fits]
    surfaces = [{"patient": f["patient"], "main_operator": f["main_operator"], "test_geometry": f["test_geometry"],
                 **f["rss_surface"]} for f in fits if "rss_surface" in f]
    sim = out / "rss_surfaces_simulator.json"
    examples = (read_json(sim) if sim.is_file() else []) + surfaces[:1]
    paths = {"json": str(write_json_atomic(out / RESULT_FILE, clean(
        {**{k: v for k, v in result.items() if k not in ("surfaces", "folder")}, "fits": slim,
         "rss_surfaces": flat_surfaces(examples)})))}
    paths["surfaces"] = str(write_json_atomic(out / "rss_surfaces.json", clean([_rounded(r) for r in surfaces])))
    fits_frame(fits).to_csv(out / "operators_fits.csv", index=False)
    paths["csv"] = str(out / "operators_fits.csv")
    ok = [f for f in fits if "strain_rmse_forward" in f]
    if ok:
        ex = next((f for f in ok if f["test_geometry"] == "pc5"), ok[0])
        figs = figures({**result, "fits": ok, "surfaces": [{**{k: ex[k] for k in ("patient", "main_operator",
                                                                                  "test_geometry")},
                                                             **ex["rss_surface"]}]})
        for key, stem in (("fig9_11_forward_strain_error", "fig_9_11_forward_strain_errors"),
                          ("fig9_14_output_error", "fig_9_14_output_errors"), ("fig_mahalanobis", "fig_mahalanobis"),
                          ("fig9_13_rss_surface", "fig_9_13_loss_surface")):
            if key in figs:
                paths[key] = save_figure(figs[key], out / stem)
    return paths


def _sig(values, digits: int = 4):
    """``values`` (nested lists) rounded to ``digits`` significant digits (smaller files; NaN kept)."""
    a = np.asarray(values, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = np.where(np.isfinite(a) & (a != 0), np.floor(np.log10(np.abs(a))), 0)
    scale = 10.0 ** (digits - 1 - mag)
    return (np.round(a * scale) / scale).tolist()


def _rounded(record: dict) -> dict:
    pairs = [{**p, **{k: _sig(p[k]) for k in ("x_values", "y_values", "rss")}} for p in record.get("pairs", [])]
    return {**record, "pairs": pairs}


def flat_surfaces(records: Sequence[dict]) -> list[dict]:
    """One record per parameter pair (``params``, ``x``, ``y``, ``rss``, ``truth``, ``method``, fit keys).

    The form kept inside the result file (``rss_surfaces``) for reports;
    ``rss_surfaces.json`` keeps every fit's surfaces grouped by fit.
    """
    flat = []
    for r in records:
        for p in r["pairs"]:
            i, j = THETA_NAMES.index(p["x"]), THETA_NAMES.index(p["y"])
            flat.append({"patient": r["patient"], "main_operator": r["main_operator"],
                         "test_geometry": r["test_geometry"], "method": r["method"], "params": [p["x"], p["y"]],
                         "x": p["x_values"], "y": p["y_values"], "rss": p["rss"],
                         "truth": [THETA_TRUE[i], THETA_TRUE[j]]})
    return flat


def format_findings(f: dict) -> str:
    lines = [f"{f['n_converged']}/{f['n_fits']} fits converged ({f['n_fits_ok']} completed)"]
    for metric, what in (("strain_rmse_forward", "forward strain RMSE at θ̃ (Fig 9.11)"),
                         ("output_rmse_refit", "output-space RMSE at θ̂ (Fig 9.14)")):
        if metric not in f:
            continue
        for k in PC_TESTS:
            d = f[metric][f"pc{k}"]
            if d["share_beats_both_operators"] is None:
                continue
            lines.append(f"{what}: {k} PCs beat both other operators in {100 * d['share_beats_both_operators']:.0f} % "
                         f"of {d['n_cases']} cases, no worse than an operator in "
                         f"{100 * d['share_no_worse_than_an_operator']:.0f} % of {d['n_comparisons']} comparisons")
        lines.append("  medians: " + ", ".join(f"{k} {v:.4f}" for k, v in f[metric]["median"].items()))
    if "median_mahalanobis" in f:
        lines.append("median Mahalanobis distance: " + ", ".join(f"{k} {v:.2f}" for k, v in f["median_mahalanobis"].items()))
    if "median_mahalanobis_interior" in f:
        lines.append("  without fits on a prior bound (Laplace valid): " + ", ".join(
            f"{k} {'n/a' if v is None else f'{v:.2f}'} ({f['n_on_bound'][k]} on a bound left out)"
            for k, v in f["median_mahalanobis_interior"].items()))
    lines.append(f"(chapter, geometry domain: 10 PCs beat a new operator in {100 * CHAPTER_SHARE_10PC:.0f} % of cases)")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- CLI
def add_study_parser(study_subparsers) -> None:
    """``lvcore study operators``."""
    p = study_subparsers.add_parser("operators", help="§9.3.3: SQP refits of theta on other operators' and PCA "
                                                      "geometries (adjoint gradients; Figs 9.11-9.14, SYNTHETIC)")
    p.add_argument("--patients", default=None, help="comma-separated, e.g. SYNTHETIC-P01,SYNTHETIC-P02 (default: all 6)")
    p.add_argument("--workers", type=cli_args.workers, default=1,
                   help="local worker processes (fits run in parallel), up to 4 per core (default 1)")
    p.add_argument("--scheduler", default=None, help="tcp://HOST:PORT of a Dask scheduler (default: none, local workers)")
    p.add_argument("--resolution", default="default", help="simulator mesh preset (default 'default')")
    p.add_argument("--surface-grid", type=int, default=0,
                   help="N > 0: simulator loss surfaces on N x N grids per parameter pair (6 N^2 runs per fit); "
                        "default 0: Gauss-Newton model surfaces")
    p.add_argument("--collect-only", action="store_true",
                   help="run nothing: summarise the fits already saved in OUT/fits (an interrupted run)")
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    p.add_argument("--out", type=cli_args.output_dir, required=True, help="output folder (finished fits are kept in OUT/fits for resuming)")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    patients = [s.strip() for s in args.patients.split(",") if s.strip()] if args.patients else None
    res = run_study(patients, out=args.out, workers=args.workers, scheduler=args.scheduler,
                    resolution=args.resolution, surface_grid=args.surface_grid, progress=not args.json,
                    collect_only=args.collect_only)
    if args.json:
        print(json.dumps(clean({"findings": res["findings"], "meta": res["meta"]}), indent=1))
    else:
        print(format_findings(res["findings"]))
        print(f"{res['meta']['budget']}; wrote {args.out}/{RESULT_FILE}, operators_fits.csv and figures")
    return 0


__all__ = ["THETA_TRUE", "PC_TESTS", "SIGMA_RESIDUAL", "PAIRS", "GN_GRID", "SURFACE_SPAN", "CHAPTER_SHARE_10PC",
           "SQP_TOL", "BOUND_TOL", "LVCoreError", "early_volume_ml", "patient_geometries", "test_geometries",
           "operator_names", "test_geometry_name", "CachedForward", "residual_jacobian", "laplace_covariance",
           "mahalanobis", "on_bound", "gauss_newton_surfaces", "surface_axes", "simulator_surfaces",
           "surface_for_fit", "fit_one", "data_task", "theta_dict", "run_study", "findings", "fits_frame",
           "RESULT_FILE", "COMMAND", "SURFACE_FILES", "TITLES", "VIOLINS", "load", "group_surfaces", "source_line",
           "test_order", "tables", "surface_title", "figures", "surface_figure", "write_outputs", "flat_surfaces",
           "format_findings", "add_study_parser"]
