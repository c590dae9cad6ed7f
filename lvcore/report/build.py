"""Build the report: every reproduced figure and table of the chapter, with its data, in one folder.

Layout of ``DIR`` (all paths in the manifest are relative to it)::

    index.html            one page with every figure (PNG linking to the interactive HTML)
    manifest.json         {"figures": [{"name", "title", "png", "svg", "html", "data", ...}, ...]}
    figures/<name>.png|svg|html   (the HTML files share figures/plotly.min.js)
    data/<name>.csv|json  what each figure was drawn from

Sections and where their numbers come from:

* Fig 9.5 (angle sweep): the bundled ``angles`` emulator (milliseconds) or, with
  ``sweep="simulator"``, the FE simulator on the default LV's fast mesh.
* Figs 9.6–9.9 (fibre discrepancy): saved results of ``lvcore study
  fibre-discrepancy`` (``fibre_discrepancy.json``); the MCMC takes minutes, so
  the report never re-runs it.
* Table 9.4 and Fig 9.10 (operators / PCA): computed here from the bundled
  SYNTHETIC cohort and shape model (seconds); Fig 9.10 evaluates the
  ``chapter`` emulator on the patients' 5-PC projections.
* Calibration posterior: a short live NUTS run on the bundled SYNTHETIC
  volunteer HV3 (its PC scores lie inside the emulator box; HV1 and HV5 do not), prior overlaid, hidden truth marked.
* Tables 9.2/9.3 and Figs 9.11–9.14 (optimisation studies): saved results of
  ``lvcore study bo-fibres`` (``bo_fibres.json``) and ``lvcore study operators``
  (``operators.json``); listed as missing when absent.

Study results are looked up in ``results_dir`` first, then in the package's
bundled ``lvcore/assets/studies``.
"""
from __future__ import annotations

import html
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from lvcore.exceptions import LVCoreError


class ReportError(LVCoreError):
    """The report could not be written (e.g. no Chromium for the static export)."""


#: Every figure/table the report produces, in order (the manifest lists each, present or missing).
FIGURE_NAMES = (
    "fig9_5_angle_sweep", "fig9_5_angle_map",
    "fig9_6_strain_predictive", "fig9_7_sigma_s", "fig9_7_sigma_s_all_sets", "fig9_8_eta_vs_benchmark",
    "fig9_9_error_violins", "table_fibre_discrepancy_findings",
    "table9_4_operators_pca", "fig_pca_vs_operators", "fig9_10_geometry_effect",
    "fig_calibration_posterior", "table_calibration_summary",
    "table9_2_bo_fixed_angles", "table9_3_bo_free_angles", "fig_bo_lvv_error",
    "fig9_11_forward_strain_error", "fig9_12_parameter_error", "fig9_13_rss_surface", "fig9_14_output_error",
)

#: Commands that produce each study's saved results.
STUDY_COMMANDS = {
    "fibre_discrepancy.json": "lvcore study fibre-discrepancy --out RESULTS",
    "bo_fibres.json": "lvcore study bo-fibres --out RESULTS",
    "operators.json": "lvcore study operators --out RESULTS",
}


@dataclass(frozen=True)
class ReportItem:
    """One figure or table of the report.

    Attributes
    ----------
    name : str
        File stem (see :data:`FIGURE_NAMES`).
    title : str
        Shown in index.html and the manifest (the figure carries its own title).
    fig : plotly Figure or None
        None when ``missing``.
    data : DataFrame, dict or list, or None
        What the figure was drawn from (CSV for a DataFrame, JSON otherwise).
    source : str
        Where the numbers come from (file, emulator, live run).
    missing : str or None
        Why the item is absent and the command that makes it.
    notes : str
        Free text shown under the figure in index.html (findings, caveats).
    """

    name: str
    title: str
    fig: object = field(default=None, repr=False)
    data: object = field(default=None, repr=False)
    source: str = ""
    missing: str | None = None
    notes: str = ""


def studies_dir() -> Path:
    """The package's bundled study results folder (``lvcore/assets/studies``)."""
    from lvcore.resources import asset_path

    return asset_path("studies")


def find_study_file(name: str, results_dir=None) -> Path | None:
    """``results_dir/name`` if it exists, else the bundled ``lvcore/assets/studies/name``, else None."""
    for d in ([Path(results_dir)] if results_dir else []) + [studies_dir()]:
        if (d / name).is_file():
            return d / name
    return None


def _missing(name: str, title: str, study_file: str, results_dir, why: str = "") -> ReportItem:
    where = f"{results_dir} or {studies_dir()}" if results_dir else str(studies_dir())
    cmd = STUDY_COMMANDS[study_file]
    reason = why or f"{study_file} not found in {where}"
    return ReportItem(name, title, missing=f"missing: run {cmd}, then lvcore report --from RESULTS ({reason})",
                      source=study_file)


# ----------------------------------------------------------------------------- Fig 9.5
def angle_sweep_items(sweep: str = "emulator") -> list[ReportItem]:
    """Fig 9.5: strains and EDV at the chapter's four angle pairs, plus the (α_endo, α_epi) map."""
    import pandas as pd

    from lvcore import units
    from lvcore.studies.fibre_angles import CHAPTER_ANGLE_PAIRS, angle_sweep, emulator_angle_map, strain_table
    from lvcore.viz import figures
    from lvcore.viz.report_figures import strain_lines

    theta = dict(units.HO_REFERENCE_THETA)
    th = ", ".join(f"{k} {v:g}" for k, v in theta.items())
    items = []
    emulator = None
    if sweep == "simulator":
        runs = angle_sweep(CHAPTER_ANGLE_PAIRS, theta=theta, resolution="fast")
        engine = "FE simulator, default (analytic) LV, fast mesh"
    else:
        from lvcore.emulator.io import load_emulator

        emulator = load_emulator("angles")
        runs = [emulator_angle_map(emulator, [e], [p], theta=theta).runs[0] for e, p in CHAPTER_ANGLE_PAIRS]
        engine = "bundled `angles` emulator, SYNTHETIC shape model's mean LV"
    data = pd.DataFrame([{"alpha_endo_deg": r.alpha_endo, "alpha_epi_deg": r.alpha_epi, "converged": r.converged,
                          "message": r.message, "lvv_ml": r.lvv_ml,
                          **{f"strain_{k + 1:02d}": (None if r.strains is None else float(r.strains[k]))
                             for k in range(24)}} for r in runs])
    fig = strain_lines(strain_table(runs),
                       title=f"Fig 9.5 — strains and EDV at four fibre-angle pairs ({engine}; θ: {th}; EDP 8 mmHg)")
    failed = [r.label for r in runs if not r.converged]
    items.append(ReportItem("fig9_5_angle_sweep", "Fig 9.5: effect of the fibre angles on the strains and LVV", fig,
                            data, source=engine, notes=("failed: " + "; ".join(failed)) if failed else ""))
    if emulator is None:
        from lvcore.emulator.io import available_emulators, load_emulator

        if "angles" not in available_emulators():
            items.append(ReportItem("fig9_5_angle_map", "Fig 9.5 (map): LVV over (α_endo, α_epi)",
                                    missing="missing: the `angles` emulator is not installed; build it with "
                                            "python scripts/build_emulators.py --emulators angles"))
            return items
        emulator = load_emulator("angles")
    endo, epi = np.linspace(-90, 0, 31), np.linspace(0, 90, 31)
    amap = emulator_angle_map(emulator, endo, epi, theta=theta)
    fig = figures.contour(amap.alpha_endo, amap.alpha_epi, amap.lvv_ml,
                          title="Fig 9.5 (map) — EDV (mL) over the fibre angles, `angles` emulator, SYNTHETIC mean "
                                f"LV (θ: {th}); markers: the chapter's pairs",
                          xaxis_title="α_endo (°)", yaxis_title="α_epi (°)", colorbar_title="mL",
                          points={"chapter pairs": ([e for e, _ in CHAPTER_ANGLE_PAIRS],
                                                    [p for _, p in CHAPTER_ANGLE_PAIRS])})
    grid = pd.DataFrame({"alpha_endo_deg": np.tile(endo, epi.size), "alpha_epi_deg": np.repeat(epi, endo.size),
                         "lvv_ml": amap.lvv_ml.ravel(), "mean_strain": amap.mean_strain.ravel()})
    items.append(ReportItem("fig9_5_angle_map", "Fig 9.5 (map): EDV over (α_endo, α_epi) by the `angles` emulator",
                            fig, grid, source="bundled `angles` emulator"))
    return items


# ----------------------------------------------------------------------------- Figs 9.6-9.9
FD_NAMES = ("fig9_6_strain_predictive", "fig9_7_sigma_s", "fig9_7_sigma_s_all_sets", "fig9_8_eta_vs_benchmark",
            "fig9_9_error_violins", "table_fibre_discrepancy_findings")
FD_TITLES = {
    "fig9_6_strain_predictive": "Fig 9.6: posterior predictive of the strains, iid vs discrepancy model",
    "fig9_7_sigma_s": "Fig 9.7: posterior of the strain noise sd σ_S vs the truth 0.03",
    "fig9_7_sigma_s_all_sets": "Fig 9.7 (all sets): σ_S median and 90 % interval per test set",
    "fig9_8_eta_vs_benchmark": "Fig 9.8: posterior of η(θ, h) vs the benchmark η(θ̃, h), three test sets",
    "fig9_9_error_violins": "Fig 9.9: |η(θ_post, h) − η(θ̃, h)| over the 12 test sets, per likelihood",
    "table_fibre_discrepancy_findings": "Fibre-discrepancy findings against the chapter",
}
MODEL_LABELS = {"volume": "volume only", "iid": "iid (chapter: None)", "discrepancy": "polar-GP discrepancy"}



def _build_label(build) -> str:
    """``(emulator of <date>, <mesh> mesh, <base> base)`` from a study's ``forward_build`` record."""
    if not build:
        return "(build not recorded)"
    parts = [f"built {build['created_at'][:10]}" if build.get("created_at") else None,
             f"{build['resolution']} mesh" if build.get("resolution") else None,
             f"{build['base']} base" if build.get("base") else None]
    return "(" + ", ".join(p for p in parts if p) + ")"

def fibre_discrepancy_items(results_dir=None) -> list[ReportItem]:
    """Figs 9.6–9.9 and the findings table from a saved ``fibre_discrepancy.json``."""
    import pandas as pd

    from lvcore.studies import fibre_discrepancy as fd
    from lvcore.viz import inference_figures as ifig
    from lvcore.viz.report_figures import eta_band_grid, interval_figure, table_figure

    path = find_study_file("fibre_discrepancy.json", results_dir)
    if path is None:
        return [_missing(n, FD_TITLES[n], "fibre_discrepancy.json", results_dir) for n in FD_NAMES]
    res = json.loads(path.read_text())
    src = f"{path.name} ({'bundled' if path.parent == studies_dir() else path.parent}), forward model " \
          f"{res.get('forward_model', '?')} {_build_label(res.get('forward_build'))}, sampler {res.get('sampler', {})}"
    sets = res["sets"]
    tag = "SYNTHETIC"
    ex = next((s for s in sets if (s["alpha_endo"], s["alpha_epi"]) == (0.0, 90.0)), sets[-1])
    ex_label = f"set {ex['set']}, angles ({ex['alpha_endo']:g}°, {ex['alpha_epi']:g}°)"
    items = []
    # Fig 9.6
    bands = {MODEL_LABELS[m]: {k: np.asarray(v) for k, v in ex["models"][m]["strain_predictive"].items()}
             for m in ("iid", "discrepancy")}
    fig = ifig.strain_predictive_figure(bands, ex["y"])
    fig.update_layout(title=f"Fig 9.6 — {tag} {ex_label}: posterior predictive of the 24 strains (median, 5–95 %) "
                            "vs data")
    data = pd.DataFrame([{"set": ex["set"], "model": m, "region": r + 1, "data": ex["y"][1 + r],
                          **{q: ex["models"][m]["strain_predictive"][q][r] for q in ("q05", "q50", "q95")}}
                         for m in ("iid", "discrepancy") for r in range(24)])
    items.append(ReportItem("fig9_6_strain_predictive", FD_TITLES["fig9_6_strain_predictive"], fig, data, src))
    # Fig 9.7: density of the example set's draws (when shipped), and intervals of all sets
    if all("draws" in ex["models"][m]["sigma_s"] for m in ("iid", "discrepancy")):
        draws = {MODEL_LABELS[m]: np.asarray(ex["models"][m]["sigma_s"]["draws"]) for m in ("iid", "discrepancy")}
        fig = ifig.sigma_s_figure(draws, truth=fd.SIGMA_S)
        fig.update_layout(title=f"Fig 9.7 — {tag} {ex_label}: posterior of σ_S; dashed: truth {fd.SIGMA_S}")
        items.append(ReportItem("fig9_7_sigma_s", FD_TITLES["fig9_7_sigma_s"], fig,
                                {"set": ex["set"], "truth": fd.SIGMA_S, "draws": {k: v.tolist() for k, v in draws.items()}},
                                src))
    else:
        items.append(ReportItem("fig9_7_sigma_s", FD_TITLES["fig9_7_sigma_s"], source=src,
                                missing="missing: the results hold no σ_S draws (older study output); re-run "
                                        "lvcore study fibre-discrepancy or scripts/ship_fibre_discrepancy.py"))
    rows = [{"label": f"set {s['set']} ({s['alpha_endo']:g}°, {s['alpha_epi']:g}°)", "series": MODEL_LABELS[m],
             **{k: s["models"][m]["sigma_s"][k] for k in ("median", "q05", "q95")}}
            for s in sets for m in ("iid", "discrepancy")]
    fig = interval_figure(rows, truth=fd.SIGMA_S, xaxis_title="σ_S (strain)",
                          title=f"Fig 9.7 (all sets) — {tag}: posterior median and 5–95 % of σ_S per test set; "
                                f"dashed: truth {fd.SIGMA_S}")
    items.append(ReportItem("fig9_7_sigma_s_all_sets", FD_TITLES["fig9_7_sigma_s_all_sets"], fig,
                            pd.DataFrame(rows), src))
    # Fig 9.8: three cases, the example first, then the same theta at the other two angle pairs
    k = sets.index(ex)
    same_theta = [s for s in sets if s["theta"] == ex["theta"] and s is not ex]
    cases = [ex] + (same_theta or [s for j, s in enumerate(sets) if j != k])[:2]
    if all("eta_quantiles" in c["models"][m] for c in cases for m in fd.MODELS):
        spec = [{"title": f"set {c['set']} ({c['alpha_endo']:g}°, {c['alpha_epi']:g}°)", "benchmark": c["benchmark"],
                 "bands": {MODEL_LABELS[m]: c["models"][m]["eta_quantiles"] for m in fd.MODELS}} for c in cases]
        fig = eta_band_grid(spec, [MODEL_LABELS[m] for m in fd.MODELS],
                            title=f"Fig 9.8 — {tag}: posterior of η(θ, h) (5–95 %, median) vs the benchmark "
                                  "η(θ̃, h) (dashed)")
        data = pd.DataFrame([{"set": c["set"], "model": m, "region": r + 1, "benchmark": c["benchmark"][1 + r],
                              **{q: c["models"][m]["eta_quantiles"][q][1 + r] for q in ("q05", "q50", "q95")}}
                             for c in cases for m in fd.MODELS for r in range(24)])
        items.append(ReportItem("fig9_8_eta_vs_benchmark", FD_TITLES["fig9_8_eta_vs_benchmark"], fig, data, src))
    else:
        items.append(ReportItem("fig9_8_eta_vs_benchmark", FD_TITLES["fig9_8_eta_vs_benchmark"], source=src,
                                missing="missing: the results hold no η quantiles (older study output); re-run "
                                        "lvcore study fibre-discrepancy or scripts/ship_fibre_discrepancy.py"))
    # Fig 9.9
    errs = {MODEL_LABELS[m]: np.asarray(v) for m, v in res["error_draws"].items()}
    fig = ifig.error_violin_figure(errs)
    fig.update_layout(title=f"Fig 9.9 — {tag}: mean |η(θ_post, h) − η(θ̃, h)| over the 24 strains, all "
                            f"{len(sets)} test sets, per likelihood")
    thinned = res.get("error_draws_thinned_to_per_set")
    items.append(ReportItem("fig9_9_error_violins", FD_TITLES["fig9_9_error_violins"], fig,
                            pd.DataFrame([{"model": m, "mean_abs_strain_error": e} for m, es in res["error_draws"].items()
                                          for e in es]),
                            src, notes=f"posterior draws thinned to {thinned} per set" if thinned else ""))
    # findings table
    f = res["findings"]
    rows = [
        {"finding": "iid inflates σ_S (median / 0.03)", "ours": f["iid_sigma_s_inflation"],
         "chapter": f["chapter"]["iid_sigma_s_inflation"], "holds": f["iid_inflates_sigma_s_about_2x"]},
        {"finding": "discrepancy model σ_S median", "ours": f["discrepancy_sigma_s_median"],
         "chapter": f["chapter"]["discrepancy_sigma_s_median"], "holds": f["discrepancy_sigma_s_near_truth"]},
        {"finding": "discrepancy beats iid (median |error|)", "ours": f"{f['median_abs_error']['discrepancy']:.4f} vs "
                                                                      f"{f['median_abs_error']['iid']:.4f}",
         "chapter": "yes", "holds": f["discrepancy_beats_iid"]},
        {"finding": "volume-only beats iid (median |error|)", "ours": f"{f['median_abs_error']['volume']:.4f} vs "
                                                                        f"{f['median_abs_error']['iid']:.4f}",
         "chapter": "yes", "holds": f["volume_beats_iid"]},
    ]
    df = pd.DataFrame(rows)
    items.append(ReportItem("table_fibre_discrepancy_findings", FD_TITLES["table_fibre_discrepancy_findings"],
                            table_figure(df, title=f"Fibre-discrepancy study ({tag}): findings vs the chapter"),
                            df, src))
    return items


# ----------------------------------------------------------------------------- Table 9.4, Fig 9.10
def operators_items() -> list[ReportItem]:
    """Table 9.4 (operators vs PCA, geometry space), the per-operator error plots and Fig 9.10."""
    import pandas as pd

    from lvcore import units
    from lvcore.geometry.cohort import load_operator_geometries
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.studies.geometry_operators import operator_table
    from lvcore.viz.geometry_views import operator_mse_figure
    from lvcore.viz.report_figures import strain_lines, table_figure

    og, sm = load_operator_geometries(), load_shape_model()
    table = operator_table(og, sm)
    ks = table["ks"]
    rows, bold = [], []
    for b in table["blocks"]:
        for r in b["rows"]:
            row = {"main": b["main"], "patient": r["patient"].replace("SYNTHETIC-", "")}
            for j, o in enumerate(b["others"]):
                row[f"test op {j + 1}"] = f"{o}: {r['operator_mse'][o]:.4f}"
            row.update({f"{k}PC": r["pca_mse"][str(k)] for k in ks})
            if r["first_k_beating_both"]:
                bold.append((len(rows), f"{r['first_k_beating_both']}PC"))
            rows.append(row)
    rows.append({"main": "share", "patient": "k beats both",
                 **{f"{k}PC": table["share_beating_both"][str(k)] for k in ks}})
    rows.append({"main": "chapter", "patient": "(real data)",
                 **{f"{k}PC": table["chapter_share"].get(str(k), float("nan")) for k in ks}})
    df = pd.DataFrame(rows)
    items = [ReportItem("table9_4_operators_pca", "Table 9.4: inter-operator vs k-mode PCA reconstruction error (cm²)",
                        table_figure(df, title="Table 9.4 — SYNTHETIC cohort: mean squared node distance to the main "
                                               "operator's geometry (cm²); bold: first k beating both operators",
                                     bold=bold), table, "bundled SYNTHETIC cohort and shape model",
                        notes=f"operators differ by {table['operator_mse_range'][0]:.4f}–"
                              f"{table['operator_mse_range'][1]:.4f} cm² (chapter: 0.003–0.03 cm²)")]
    # one figure with the three main operators as consecutive figures would need subplots of a builder that
    # draws one operator: keep the first main operator's plot (the page shows all three)
    main = table["operators"][0]
    fig = operator_mse_figure(table, main)
    fig.update_layout(title=f"Reconstruction error vs k, main operator {main} (SYNTHETIC cohort)")
    items.append(ReportItem("fig_pca_vs_operators", f"PCA reconstruction error vs k, main operator {main}", fig,
                            next(b for b in table["blocks"] if b["main"] == main), "bundled SYNTHETIC cohort"))
    # Fig 9.10: the same theta on each patient's geometry (main operator), by the chapter emulator
    from lvcore.emulator.io import available_emulators

    if "chapter" not in available_emulators():
        items.append(ReportItem("fig9_10_geometry_effect", "Fig 9.10: effect of the LV geometry on strains and LVV",
                                missing="missing: the `chapter` emulator is not installed; build it with "
                                        "python scripts/build_emulators.py --emulators chapter"))
        return items
    from lvcore.emulator.forward import load_emulator_forward as load_forward

    theta = dict(units.HO_REFERENCE_THETA)
    series, data = {}, []
    op = og.operators[0]
    for p, pid in enumerate(og.patients):
        h = np.asarray(sm.project(og.nodes[p, 0]), dtype=float)[:5]
        y = np.asarray(load_forward("chapter", h)(theta), dtype=float)
        series[f"{pid.replace('SYNTHETIC-', '')} (EDV {y[0]:.1f} mL)"] = y[1:]
        data.append({"patient": pid, "operator": op, **{f"h{i + 1}": float(v) for i, v in enumerate(h)},
                     "lvv_ml": float(y[0]), **{f"strain_{k + 1:02d}": float(y[1 + k]) for k in range(24)}})
    th = ", ".join(f"{k} {v:g}" for k, v in theta.items())
    fig = strain_lines(series, title=f"Fig 9.10 — SYNTHETIC patients ({op}'s geometries, 5-PC projections): strains "
                                     f"and EDV at the same θ ({th}), `chapter` emulator")
    items.append(ReportItem("fig9_10_geometry_effect", "Fig 9.10: effect of the LV geometry on strains and LVV", fig,
                            pd.DataFrame(data), "`chapter` emulator on the 5-PC projections of the SYNTHETIC patients",
                            notes="the emulator sees the geometry through 5 PC scores only; the FE simulator on the "
                                  "full geometries would show more spread"))
    return items


# ----------------------------------------------------------------------------- calibration
def calibration_items(subject: str = "SYNTHETIC-HV3", *, num_warmup: int = 500, num_samples: int = 500,
                      num_chains: int = 4) -> list[ReportItem]:
    """Posterior of θ for a bundled SYNTHETIC volunteer (iid model, ``chapter`` emulator), prior and truth shown."""
    import pandas as pd

    from lvcore.emulator.io import available_emulators
    from lvcore.inference import models
    from lvcore.inference.calibrate import calibrate, read_pc_scores
    from lvcore.inference.data import read_measured_csv
    from lvcore.emulator.forward import load_emulator_forward as load_forward
    from lvcore.inference.samplers import SamplerConfig
    from lvcore.outputs import THETA_NAMES
    from lvcore.viz.inference_figures import UNITS
    from lvcore.viz.report_figures import posterior_prior_figure, table_figure

    titles = {"fig_calibration_posterior": f"Calibration posterior of θ, {subject} (prior and truth shown)",
              "table_calibration_summary": f"Calibration summary, {subject}"}
    if "chapter" not in available_emulators():
        why = ("missing: the `chapter` emulator is not installed; build it with python scripts/build_emulators.py "
               "--emulators chapter")
        return [ReportItem(n, t, missing=why) for n, t in titles.items()]
    from lvcore.resources import volunteer_files, volunteers_dir

    files = volunteer_files(subject.replace("-", "_"))
    row = read_measured_csv(files.measured)[0]
    h = read_pc_scores(files.geometry)
    forward = load_forward("chapter", h)
    config = SamplerConfig(num_warmup=num_warmup, num_samples=num_samples, num_chains=num_chains, seed=0)
    res = calibrate(row.y, forward, "iid", config=config, max_rounds=1)
    truth_file = volunteers_dir() / "truth" / "SYNTHETIC_volunteers_truth.json"
    truth = None
    if truth_file.is_file():  # the hidden truth scores the fit; it never enters it
        truth = next((t["theta"] for t in json.loads(truth_file.read_text())["volunteers"]
                      if t["subject"] == row.subject), None)
    bounds = models.prior_bounds(forward=forward)
    draws = {n: np.asarray(res.idata.posterior[n]).reshape(-1) for n in THETA_NAMES}
    conv = res.convergence
    n_div = int(np.asarray(res.idata.sample_stats["diverging"]).sum()) if "diverging" in res.idata.sample_stats else 0
    status = f"{conv.message()}; {n_div} divergent transitions"
    fig = posterior_prior_figure(draws, bounds, truth=truth, units=UNITS,
                                 title=f"Calibration — {row.subject} (SYNTHETIC volunteer), iid model, `chapter` "
                                       f"emulator, {num_chains}×({num_warmup}+{num_samples}) NUTS: posterior, "
                                       "uniform prior (dotted), hidden truth (red)")
    summary = res.summary.reset_index().rename(columns={"index": "parameter"})
    if truth:
        summary["truth"] = summary["parameter"].map(truth)
    src = f"live NUTS run ({res.wall_s:.1f} s) on {row.subject}'s measured CSV, h = 5-PC projection of its geometry"
    return [
        ReportItem("fig_calibration_posterior", titles["fig_calibration_posterior"], fig,
                   pd.DataFrame({n: d[:: max(1, d.size // 1000)] for n, d in draws.items()}), src, notes=status),
        ReportItem("table_calibration_summary", titles["table_calibration_summary"],
                   table_figure(summary, title=f"Calibration summary — {row.subject} (SYNTHETIC), iid model: "
                                               + status), summary, src, notes=status),
    ]


# ----------------------------------------------------------------------------- optimisation studies (issue 13)
BO_TITLES = {"table9_2_bo_fixed_angles": "Table 9.2: BO of θ with the angles fixed at (−60°, 90°)",
             "table9_3_bo_free_angles": "Table 9.3: BO of θ and the fibre angles",
             "fig_bo_lvv_error": "Tables 9.2/9.3: LVV and strain errors, fixed vs free angles"}
OP_TITLES = {"fig9_11_forward_strain_error": "Fig 9.11: forward strain error at θ̃ per test geometry",
             "fig9_12_parameter_error": "Fig 9.12: absolute parameter errors of the SQP refits",
             "fig9_13_rss_surface": "Fig 9.13: RSS surface over parameter pairs",
             "fig9_14_output_error": "Fig 9.14: output-space error at θ̂ per test geometry"}


def _as_theta(v) -> dict:
    from lvcore.outputs import THETA_NAMES

    if isinstance(v, dict):
        return {n: float(v[n]) for n in THETA_NAMES if n in v}
    return dict(zip(THETA_NAMES, (float(x) for x in v)))


def bo_items(results_dir=None) -> list[ReportItem]:
    """Tables 9.2/9.3 from ``bo_fibres.json`` (a list of per-subject, per-mode records)."""
    import pandas as pd

    from lvcore.viz.report_figures import table_figure

    path = find_study_file("bo_fibres.json", results_dir)
    if path is None:
        return [_missing(n, t, "bo_fibres.json", results_dir) for n, t in BO_TITLES.items()]
    recs = json.loads(path.read_text())
    recs = recs.get("results", recs) if isinstance(recs, dict) else recs
    src = f"{path.name} ({'bundled' if path.parent == studies_dir() else path.parent})"
    rows = []
    for r in recs:
        th = _as_theta(r.get("theta", {}))
        rows.append({"subject": r["subject"], "mode": r["mode"], **th,
                     "alpha_endo": r.get("alpha_endo"), "alpha_epi": r.get("alpha_epi"),
                     "LVV |error| (mL)": r.get("lvv_abs_error_ml"),
                     "median |strain error|": r.get("median_abs_strain_error"),
                     "evaluations": r.get("evaluations"), "failed": r.get("failed_evaluations")})
    df = pd.DataFrame(rows)
    items = []
    for name, mode, label in (("table9_2_bo_fixed_angles", "fixed", "Table 9.2 — angles fixed at (−60°, 90°)"),
                              ("table9_3_bo_free_angles", "free", "Table 9.3 — θ and the fibre angles optimised")):
        sub = df[df["mode"] == mode].drop(columns=["mode"]).reset_index(drop=True)
        if sub.empty:
            items.append(_missing(name, BO_TITLES[name], "bo_fibres.json", results_dir,
                                  why=f"{path} has no '{mode}' records"))
            continue
        items.append(ReportItem(name, BO_TITLES[name],
                                table_figure(sub, title=f"{label} (SYNTHETIC volunteers, Bayesian optimisation)"),
                                sub, src))
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=2, subplot_titles=["LVV |error| (mL)", "median |strain error|"])
    for k, mode in enumerate(("fixed", "free")):
        sub = df[df["mode"] == mode]
        for j, col in enumerate(("LVV |error| (mL)", "median |strain error|")):
            fig.add_bar(x=sub["subject"], y=sub[col], name=f"{mode} angles", legendgroup=mode, showlegend=j == 0,
                        marker_color=("#636EFA", "#EF553B")[k], row=1, col=j + 1)
    fig.update_layout(title="Tables 9.2/9.3 — SYNTHETIC volunteers: errors at the BO optimum, fixed vs free angles",
                      barmode="group", height=420, margin=dict(l=50, r=20, t=70, b=40))
    items.append(ReportItem("fig_bo_lvv_error", BO_TITLES["fig_bo_lvv_error"], fig, df, src))
    return items


def operators_study_items(results_dir=None) -> list[ReportItem]:
    """Figs 9.11–9.14 from ``operators.json`` (``fits`` list; ``rss_surfaces`` for Fig 9.13)."""
    import pandas as pd

    from lvcore.viz import figures
    from lvcore.viz.report_figures import error_strips, grouped_violins

    path = find_study_file("operators.json", results_dir)
    if path is None:
        return [_missing(n, t, "operators.json", results_dir) for n, t in OP_TITLES.items()]
    res = json.loads(path.read_text())
    src = f"{path.name} ({'bundled' if path.parent == studies_dir() else path.parent})"
    fits = pd.DataFrame(res["fits"])
    order = list(dict.fromkeys(fits["test_geometry"]))
    order = [g for g in order if g not in ("pc5", "pc10")] + [g for g in ("pc5", "pc10") if g in order]
    items = []
    for name, col, ytitle, fig_no in (("fig9_11_forward_strain_error", "strain_rmse_forward", "strain RMSE at θ̃ (-)", "9.11"),
                                      ("fig9_14_output_error", "output_rmse_refit", "strain RMSE at θ̂ (-)", "9.14")):
        if col not in fits:
            items.append(_missing(name, OP_TITLES[name], "operators.json", results_dir,
                                  why=f"{path} has no '{col}' in its fits"))
            continue
        df = fits[["patient", "main_operator", "test_geometry", col]]
        fig = grouped_violins(df, panel="main_operator", x="test_geometry", y=col, order=order, yaxis_title=ytitle,
                              title=f"Fig {fig_no} — SYNTHETIC patients: {OP_TITLES[name].split(': ', 1)[1]}")
        items.append(ReportItem(name, OP_TITLES[name], fig, df, src))
    if "theta_abs_error" in fits:
        long = pd.DataFrame([{"patient": r["patient"], "main_operator": r["main_operator"],
                              "test_geometry": r["test_geometry"], "parameter": n, "abs_error": v}
                             for _, r in fits.iterrows() for n, v in _as_theta(r["theta_abs_error"]).items()])
        fig = error_strips(long, panel="main_operator", param="parameter", x="test_geometry", y="abs_error",
                           yaxis_title="|θ̂ − θ̃|", title="Fig 9.12 — SYNTHETIC patients: absolute parameter errors "
                                                         "of the SQP refits (ticks: patients; wide: median)")
        items.append(ReportItem("fig9_12_parameter_error", OP_TITLES["fig9_12_parameter_error"], fig, long, src))
    else:
        items.append(_missing("fig9_12_parameter_error", OP_TITLES["fig9_12_parameter_error"], "operators.json",
                              results_dir, why=f"{path} has no 'theta_abs_error' in its fits"))
    surfaces = res.get("rss_surfaces") or []
    if surfaces:
        s = surfaces[0]
        p, q = s["params"]
        truth = s.get("truth")
        fig = figures.contour(s["x"], s["y"], np.log10(np.asarray(s["rss"], dtype=float)),
                              title=f"Fig 9.13 — SYNTHETIC: log10 RSS over ({p}, {q}); x: truth",
                              xaxis_title=p, yaxis_title=q, colorbar_title="log10 RSS",
                              points={"truth": ([truth[0]], [truth[1]])} if truth else None)
        items.append(ReportItem("fig9_13_rss_surface", OP_TITLES["fig9_13_rss_surface"], fig, s, src))
    else:
        items.append(_missing("fig9_13_rss_surface", OP_TITLES["fig9_13_rss_surface"], "operators.json", results_dir,
                              why=f"{path} has no 'rss_surfaces'"))
    return items


# ----------------------------------------------------------------------------- writing
def _write_data(data, base: Path) -> Path | None:
    import pandas as pd

    if data is None:
        return None
    if isinstance(data, pd.DataFrame):
        path = base.with_suffix(".csv")
        data.to_csv(path, index=False)
    else:
        path = base.with_suffix(".json")
        path.write_text(json.dumps(data, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
    return path


def export_static(figs: list, paths: list[Path]) -> None:
    """PNG/SVG of every figure in one Chromium session (kaleido); a clear error without Chromium."""
    if not figs:
        return
    import plotly.io as pio

    widths = [1100] * len(figs)
    heights = [int(f.layout.height or 500) for f in figs]  # kaleido would use 500 px whatever the layout says
    try:
        pio.write_images(figs, [str(p) for p in paths], width=widths, height=heights)
    except Exception as err:  # kaleido raises its own types (ChromeNotFoundError, ...)
        raise ReportError(
            f"static export (PNG/SVG) failed: {type(err).__name__}: {err}. It needs kaleido "
            "(pip install 'lvcore[report]') and a Chromium: install Debian's chromium (apt-get install chromium); "
            "or write HTML only with --formats ''") from err


def _index_html(manifest: dict) -> str:
    esc = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>LV Calibration Lab report</title>",
             "<style>body{font-family:sans-serif;max-width:1150px;margin:auto;padding:1em}"
             "figure{margin:1.5em 0;border-bottom:1px solid #ddd;padding-bottom:1em}img{max-width:100%}"
             ".missing{background:#fff3f0;border:1px solid #f0b0a0;padding:.6em}.note{color:#555}</style>"
             "</head><body>",
             "<h1>LV Calibration Lab: the chapter's figures and tables</h1>",
             f"<p>Generated {esc(manifest['generated'])} by <code>lvcore report</code> (lvcore {esc(manifest['lvcore'])}) "
             f"in {manifest['wall_s']:.0f} s. All data are SYNTHETIC. Study results from: "
             f"{esc(', '.join(manifest['results_dirs']))}.</p><ul>"]
    for f in manifest["figures"]:
        mark = "" if f["status"] == "ok" else " (missing)"
        parts.append(f"<li><a href='#{esc(f['name'])}'>{esc(f['title'])}</a>{mark}</li>")
    parts.append("</ul>")
    for f in manifest["figures"]:
        parts.append(f"<figure id='{esc(f['name'])}'><h3>{esc(f['title'])}</h3>")
        if f["status"] != "ok":
            parts.append(f"<p class='missing'>{esc(f['missing'])}</p></figure>")
            continue
        img = f["png"] or f["svg"]
        if img:
            parts.append(f"<a href='{esc(f['html'])}'><img src='{esc(img)}' alt='{esc(f['title'])}'></a>")
        links = [f"<a href='{esc(f[k])}'>{k.upper()}</a>" for k in ("html", "png", "svg", "data") if f.get(k)]
        parts.append(f"<figcaption>{' · '.join(links)}<br><span class='note'>source: {esc(f['source'])}"
                     + (f"<br>{esc(f['notes'])}" if f.get("notes") else "") + "</span></figcaption></figure>")
    parts.append("</body></html>")
    return "\n".join(parts)


def build_report(out, results_dir=None, *, sweep: str = "emulator", calibration: bool = True,
                 formats: tuple[str, ...] = ("png", "svg"), progress: Callable[[str], None] | None = None) -> dict:
    """Write the report under ``out`` and return the manifest (also written as ``out/manifest.json``).

    Parameters
    ----------
    out : path
        Output folder (created).
    results_dir : path, optional
        Folder with saved study results (``fibre_discrepancy.json``, ``bo_fibres.json``,
        ``operators.json``); each file falls back to the bundled ``lvcore/assets/studies``.
    sweep : {"emulator", "simulator"}
        Fig 9.5 by the bundled ``angles`` emulator or by the FE simulator (fast mesh).
    calibration : bool
        Run the short live calibration of SYNTHETIC-HV3 (~10–40 s).
    formats : tuple of str
        Static formats (``png``, ``svg``); empty for HTML only.

    Returns
    -------
    dict
        ``{"figures": [{"name", "title", "png", "svg", "html", "data", "status", "missing",
        "source", "notes"}, ...], "timings_s", "wall_s", ...}`` with paths relative to ``out``.
    """
    import lvcore
    from lvcore.viz.report_figures import wrap_title

    t0 = time.perf_counter()
    say = progress or (lambda m: None)
    out = Path(out)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    (out / "data").mkdir(parents=True, exist_ok=True)
    if results_dir is not None and not Path(results_dir).is_dir():
        raise ReportError(f"--from {results_dir}: no such folder; give the --out folder of `lvcore study ...`")
    sections = [
        ("Fig 9.5 angle sweep", lambda: angle_sweep_items(sweep)),
        ("Figs 9.6-9.9 fibre discrepancy", lambda: fibre_discrepancy_items(results_dir)),
        ("Table 9.4 / Fig 9.10 operators and PCA", operators_items),
        ("calibration posterior", calibration_items if calibration else None),
        ("Tables 9.2/9.3 BO of fibre angles", lambda: bo_items(results_dir)),
        ("Figs 9.11-9.14 operator study", lambda: operators_study_items(results_dir)),
    ]
    items, timings = [], {}
    for label, fn in sections:
        if fn is None:
            continue
        t = time.perf_counter()
        say(f"{label}...")
        items += fn()
        timings[label] = round(time.perf_counter() - t, 2)
    if not calibration:
        items += [ReportItem(n, n.replace("_", " "), missing="skipped: lvcore report --no-calibration")
                  for n in ("fig_calibration_posterior", "table_calibration_summary")]
    order = {n: k for k, n in enumerate(FIGURE_NAMES)}
    items.sort(key=lambda it: order.get(it.name, len(order)))
    entries, figs, static_paths = [], [], []
    for it in items:
        entry = {"name": it.name, "title": it.title, "png": None, "svg": None, "html": None, "data": None,
                 "status": "missing" if it.fig is None else "ok", "missing": it.missing, "source": it.source,
                 "notes": it.notes}
        if it.fig is not None:
            wrap_title(it.fig)
            base = out / "figures" / it.name
            it.fig.write_html(str(base.with_suffix(".html")), include_plotlyjs="directory")
            entry["html"] = f"figures/{it.name}.html"
            for fmt in formats:
                figs.append(it.fig)
                static_paths.append(base.with_suffix(f".{fmt}"))
                entry[fmt] = f"figures/{it.name}.{fmt}"
            data_path = _write_data(it.data, out / "data" / it.name)
            entry["data"] = None if data_path is None else str(data_path.relative_to(out))
        entries.append(entry)
    t = time.perf_counter()
    say(f"static export of {len(figs)} images...")
    export_static(figs, static_paths)
    timings["static export"] = round(time.perf_counter() - t, 2)
    manifest = {
        "figures": entries,
        "generated": time.strftime("%Y-%m-%d %H:%M:%S"),
        "lvcore": getattr(lvcore, "__version__", "?"),
        "results_dirs": ([str(results_dir)] if results_dir else []) + [str(studies_dir())],
        "timings_s": timings,
        "wall_s": round(time.perf_counter() - t0, 2),
    }
    (out / "index.html").write_text(_index_html(manifest))
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1))
    say(f"done in {manifest['wall_s']:.0f} s")
    return manifest
