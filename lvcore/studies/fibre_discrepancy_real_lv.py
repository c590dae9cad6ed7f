"""The fibre-discrepancy study on the real LV, per strain layer, beside the SYNTHETIC shape-model volunteers.

The geometry is the shipped REAL, patient-derived LV (Dalton et al. 2022, MIT licence; ``assets/real_lv/``,
:func:`lvcore.resources.real_lv_files`), not a synthetic shape. Its data are still simulated: the chapter's 12
test sets (3 fibre-angle pairs x 4 θ, noise σ_V = 5 mL and σ_S = 0.03) are FE-simulated on the real LV's template
mesh, and the calibration uses a subject emulator trained on FE runs on that mesh at the emulator's angles
(−60°, 60°), 8 mmHg and the same basal condition (:func:`lvcore.studies.fibre_discrepancy.run_study` with
``geometry="real-lv"``).

Reported per strain layer (:data:`LAYERS`; the inner half is lvcore's default):

* the regional pattern of the chapter's Fig 9.5: the change of the 24 regional strains and of the LVV when the
  fibre angles move from (−60°, 60°) to (0°, 90°) at the study's 4 θ (FE, noise-free), its mean over the regions
  and its *regional spread* (the standard deviation over the 24 regions), on the real LV and on the SYNTHETIC
  geometries of the shape model (the study's PCA geometry ``h`` and the bundled volunteers), side by side;
* the iid likelihood's σ_S inflation (median over the 12 sets of the posterior median of σ_S, over the true 0.03)
  and the discrepancy model's σ_S, each with a bootstrap CI that resamples the 12 test sets (the independent unit:
  each set has its own noise draw; the posterior draws within a set are not independent of each other);
* the median |η(θ_post) − η(θ̃)| of each likelihood.

:func:`assemble` builds the result file from the per-layer study runs and FE sweeps; ``scripts/
ship_fibre_discrepancy_real_lv.py`` runs them and writes it.
"""
from __future__ import annotations

from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore.domain.conditions import CHAPTER_ANGLES, SIGMA_S
from lvcore.domain.outputs import ANGLE_NAMES, THETA_NAMES
from lvcore.studies import registry

#: Result file of the study, read by :func:`load`.
RESULT_FILE = registry.result_file("fibre-discrepancy-real-lv")
#: The command that makes it (about 12.5 min of FE and MCMC per layer on 2 shared cores, 2 x (500 + 500) per fit).
COMMAND = "python scripts/ship_fibre_discrepancy_real_lv.py --layer inner_half"
#: The strain layers the study is run for, in order (lvcore's default first).
LAYERS = ("inner_half", "whole_wall")
#: The fibre-angle change of the chapter's Fig 9.5 pattern reported here: the emulator's angles -> (0°, 90°).
FROM_ANGLES = tuple(float(a) for a in CHAPTER_ANGLES)
TO_ANGLES = (0.0, 90.0)
#: The regional spread of the strain change in the chapter's Fig 9.5, as quoted in the project's issue.
CHAPTER_REGIONAL_SPREAD = 0.048
#: Bootstrap resamples of the 12 test sets and the two-sided level of the CI.
N_BOOT, CI_LEVEL = 4000, 0.90

TITLES = {
    "fig_real_lv_regional_pattern": "Fig 9.5 pattern: regional strain change (−60°, 60°) → (0°, 90°), real LV vs "
                                    "SYNTHETIC shapes",
    "fig_real_lv_regional_spread": "Regional spread of the strain change per geometry and layer",
    "fig_real_lv_sigma_s_inflation": "iid σ_S inflation with its CI (bootstrap over the 12 test sets), per layer",
    "table_real_lv_findings": "Fibre discrepancy on the real LV, per strain layer",
    "regional": "Regional change per geometry, θ and layer",
}


# ----------------------------------------------------------------------------- computing
def regional_change(simulator, theta: Mapping[str, float], *, from_angles=FROM_ANGLES, to_angles=TO_ANGLES,
                    to_outputs: Sequence[float] | None = None) -> dict:
    """The change of the LVV and the 24 strains when the fibre angles move ``from_angles`` -> ``to_angles``.

    Parameters
    ----------
    simulator : Forward
        Reads θ and the fibre angles (deg), e.g. :func:`lvcore.studies.fibre_discrepancy.data_simulator`.
    theta : mapping
        a, b, af, bf (kPa, -, kPa, -).
    to_outputs : sequence of 25 floats, optional
        The outputs at ``to_angles`` when already simulated (the study's noise-free test data); else simulated.

    Returns
    -------
    dict
        ``delta_lvv_ml`` (mL), ``delta_strain`` (24), ``mean`` and ``spread`` (standard deviation over the 24
        regions) of the strain change, and the LVV at both angles (mL); JSON-ready.
    """
    pairs = [from_angles] + ([] if to_outputs is not None else [to_angles])
    points = [{**theta, ANGLE_NAMES[0]: float(e), ANGLE_NAMES[1]: float(p)} for e, p in pairs]
    batch = simulator.evaluate({n: [pt[n] for pt in points] for n in simulator.input_names}).raise_on_failure()
    y0 = np.asarray(batch.outputs[0], dtype=float)
    y1 = np.asarray(to_outputs if to_outputs is not None else batch.outputs[1], dtype=float)
    d = y1[1:] - y0[1:]
    return {"theta": {n: float(theta[n]) for n in THETA_NAMES}, "lvv_from_ml": float(y0[0]), "lvv_to_ml": float(y1[0]),
            "delta_lvv_ml": float(y1[0] - y0[0]), "delta_strain": d.tolist(), "mean": float(d.mean()),
            "spread": float(d.std())}


def regional_changes(simulator, thetas: Sequence[Sequence[float]], *, to_outputs: Sequence | None = None,
                     progress: Callable[[str], None] | None = None) -> list[dict]:
    """:func:`regional_change` at each θ of ``thetas`` (``to_outputs[i]``: the outputs at (0°, 90°) if known)."""
    out = []
    for i, th in enumerate(thetas):
        if progress:
            progress(f"  regional change at θ {tuple(th)}")
        out.append(regional_change(simulator, dict(zip(THETA_NAMES, th)),
                                   to_outputs=None if to_outputs is None else to_outputs[i]))
    return out


def bootstrap_median(values: Sequence[float], *, scale: float = 1.0, n_boot: int = N_BOOT, level: float = CI_LEVEL,
                     seed: int = 0) -> dict:
    """Median of ``values / scale`` with a percentile bootstrap CI that resamples the values (the independent units).

    Returns ``{"estimate", "lo", "hi", "level", "n", "n_boot"}``.
    """
    v = np.asarray(values, dtype=float) / float(scale)
    rng = np.random.default_rng(seed)
    boots = np.median(v[rng.integers(0, v.size, size=(int(n_boot), v.size))], axis=1)
    lo, hi = np.quantile(boots, [(1 - level) / 2, (1 + level) / 2])
    return {"estimate": float(np.median(v)), "lo": float(lo), "hi": float(hi), "level": float(level),
            "n": int(v.size), "n_boot": int(n_boot)}


def layer_summary(study: Mapping, *, seed: int = 0) -> dict:
    """The σ_S findings of one layer's study result (:func:`lvcore.studies.fibre_discrepancy.run_study`).

    The iid inflation is the median over the test sets of the iid posterior median of σ_S over the true
    :data:`~lvcore.domain.conditions.SIGMA_S`; its CI resamples the test sets (:func:`bootstrap_median`).
    """
    sets = study["sets"]
    iid = [s["models"]["iid"]["sigma_s"]["median"] for s in sets]
    disc = [s["models"]["discrepancy"]["sigma_s"]["median"] for s in sets]
    per_pair = {}
    for s, v in zip(sets, iid):
        per_pair.setdefault(f"({s['alpha_endo']:g}, {s['alpha_epi']:g})", []).append(v / SIGMA_S)
    rhat = max(r["rhat_max"] for s in sets for r in s["models"].values())
    return {"iid_sigma_s_inflation": bootstrap_median(iid, scale=SIGMA_S, seed=seed),
            "discrepancy_sigma_s": bootstrap_median(disc, seed=seed + 1),
            "iid_inflation_per_angle_pair": {k: float(np.median(v)) for k, v in per_pair.items()},
            "median_abs_error": dict(study["findings"]["median_abs_error"]), "rhat_max": float(rhat),
            "n_sets": len(sets)}


def compact_study(study: Mapping, keep: int = 100) -> dict:
    """The parts of a study result this file keeps: per set its angles, θ, data, benchmark and each model's σ_S and
    |error| summaries; the error draws thinned to ``keep`` per set and model."""
    sets = []
    for s in study["sets"]:
        models = {m: {k: r[k] for k in ("rhat_max", "abs_error_median", "theta_median") if k in r}
                  | ({"sigma_s": {k: r["sigma_s"][k] for k in ("median", "q05", "q95")}} if "sigma_s" in r else {})
                  for m, r in s["models"].items()}
        sets.append({k: s[k] for k in ("set", "alpha_endo", "alpha_epi", "theta", "z", "y", "benchmark")}
                    | {"models": models})
    n = len(study["sets"])
    draws = {m: np.asarray(v, dtype=float).reshape(n, -1) for m, v in study["error_draws"].items()}
    idx = {m: np.linspace(0, d.shape[1] - 1, min(keep, d.shape[1])).astype(int) for m, d in draws.items()}
    return {k: study.get(k) for k in ("forward_model", "forward_build", "geometry", "noise", "sampler", "timings_s",
                                      "findings")} | {
        "sets": sets, "error_draws": {m: d[:, idx[m]].ravel().tolist() for m, d in draws.items()}}


def assemble(layers: Mapping[str, Mapping], synthetic: Mapping[str, Mapping[str, list]], *, seed: int = 0) -> dict:
    """The result file from the runs.

    Parameters
    ----------
    layers : mapping
        Layer -> ``{"study": run_study's result on the real LV (None: not run), "regional": regional_changes on
        the real LV, "emulator": the subject emulator's held-out accuracy and build, "resolution": the FE mesh}``.
    synthetic : mapping
        Layer -> SYNTHETIC geometry label -> its :func:`regional_changes`.
    """
    from lvcore.resources import REAL_LV_LABEL

    out = {"study": "fibre-discrepancy-real-lv", "geometry": {"label": REAL_LV_LABEL, "synthetic": False},
           "data": "SYNTHETIC: FE-simulated on the real LV with noise", "from_angles": list(FROM_ANGLES),
           "to_angles": list(TO_ANGLES), "chapter_regional_spread": CHAPTER_REGIONAL_SPREAD,
           "ci": {"level": CI_LEVEL, "n_boot": N_BOOT, "unit": "test set (12; each its own noise draw)"},
           "layers": {}}
    for layer in [k for k in LAYERS if k in layers] + [k for k in layers if k not in LAYERS]:
        run, study = layers[layer], layers[layer].get("study")  # no study: the FE sweeps alone (σ_S not run)
        out["layers"][layer] = {"summary": layer_summary(study, seed=seed) if study else None,
                                "regional": list(run["regional"]), "synthetic_regional": dict(synthetic.get(layer, {})),
                                "resolution": run.get("resolution", "default"),
                                "emulator": dict(run.get("emulator") or {}), "study": compact_study(study) if study else None}
    return out


# ----------------------------------------------------------------------------- saved results: load, tables, figures
def load(folder) -> dict:
    """The result file (:data:`RESULT_FILE`) of a result folder (or the bundled one), with ``folder``."""
    from lvcore.studies.results import read_result

    return read_result(folder, RESULT_FILE)


def _spreads(rows: Sequence[Mapping]) -> np.ndarray:
    return np.asarray([r["spread"] for r in rows], dtype=float)


def _ci(d: Mapping, fmt: str = ".2f") -> str:
    return f"{d['estimate']:{fmt}} [{d['lo']:{fmt}}, {d['hi']:{fmt}}]"


def tables(result: dict) -> dict:
    """The data behind each figure, by name."""
    import pandas as pd

    rows, regional = [], []
    for layer, L in result["layers"].items():
        real, syn, s = L["regional"], L["synthetic_regional"], L["summary"]
        syn_spread = np.concatenate([_spreads(v) for v in syn.values()]) if syn else None
        med = s["median_abs_error"] if s else None
        rows.append({
            "layer": layer.replace("_", " "), "ΔLVV real LV (mL)": float(np.mean([r["delta_lvv_ml"] for r in real])),
            "mean Δstrain real LV": float(np.mean([r["mean"] for r in real])),
            "regional spread real LV": float(np.mean(_spreads(real))),
            "regional spread SYNTHETIC (min–max)": "not run" if syn_spread is None else
            f"{syn_spread.min():.4f}–{syn_spread.max():.4f}",
            "chapter spread": result.get("chapter_regional_spread"),
            "iid σ_S inflation [CI]": _ci(s["iid_sigma_s_inflation"]) if s else "not run",
            "discrepancy σ_S [CI]": _ci(s["discrepancy_sigma_s"], ".4f") if s else "not run",
            "median |error| volume / iid / discrepancy": (f"{med['volume']:.4f} / {med['iid']:.4f} / "
                                                          f"{med['discrepancy']:.4f}") if s else "not run"})
        for geo, rs in [("REAL LV", real)] + list(syn.items()):
            for r in rs:
                regional.append({"layer": layer, "geometry": geo, "theta": tuple(r["theta"][n] for n in THETA_NAMES),
                                 "ΔLVV (mL)": r["delta_lvv_ml"], "mean Δstrain": r["mean"], "spread": r["spread"]})
    return {"table_real_lv_findings": pd.DataFrame(rows), "regional": pd.DataFrame(regional)}


def figures(result: dict) -> dict:
    """The study's figures by name (see :data:`TITLES`)."""
    import plotly.graph_objects as go

    from lvcore.viz.report_figures import interval_figure, strain_lines, table_figure

    tabs = tables(result)
    out = {}
    series = {}
    for layer, L in result["layers"].items():
        lab = layer.replace("_", " ")
        series[f"REAL LV, {lab}"] = np.mean([r["delta_strain"] for r in L["regional"]], axis=0)
        for geo, rs in L["synthetic_regional"].items():
            series[f"{geo}, {lab}"] = np.mean([r["delta_strain"] for r in rs], axis=0)
    fig = strain_lines(series, title="Fig 9.5 pattern — strain change (−60°, 60°) → (0°, 90°), mean over the 4 θ: "
                                     "REAL patient-derived LV vs SYNTHETIC shape-model geometries (FE, noise-free)")
    fig.update_layout(yaxis_title="ΔE_cc (-)")
    real = [tr for tr in fig.data if tr.name.startswith("REAL")]
    for tr in fig.data:  # the real LV stands out: thick and dark, one dash per layer
        if tr in real:
            tr.update(line=dict(color="black", width=4, dash=("solid", "dash")[real.index(tr) % 2]), marker=dict(size=8))
        else:
            tr.update(line=dict(width=1), opacity=0.6)
    out["fig_real_lv_regional_pattern"] = fig
    reg = tabs["regional"]
    fig = go.Figure()
    for layer in dict.fromkeys(reg["layer"]):
        sub = reg[reg["layer"] == layer]
        fig.add_box(x=sub["geometry"], y=sub["spread"], name=layer.replace("_", " "), boxpoints="all")
    fig.add_hline(y=result.get("chapter_regional_spread", CHAPTER_REGIONAL_SPREAD), line=dict(dash="dash"),
                  annotation_text="chapter")
    fig.update_layout(boxmode="group", yaxis_title="SD over the 24 regions of ΔE_cc (-)", xaxis_title="geometry",
                      title="Regional spread of the strain change (−60°, 60°) → (0°, 90°) at the 4 θ, per geometry "
                            "and layer (REAL LV vs SYNTHETIC)")
    out["fig_real_lv_regional_spread"] = fig
    rows = []
    for layer, L in result["layers"].items():
        for key, label in (("iid_sigma_s_inflation", f"iid σ_S / {SIGMA_S:g}"),) if L["summary"] else ():
            d = L["summary"][key]
            rows.append({"label": layer.replace("_", " "), "series": label, "median": d["estimate"], "q05": d["lo"],
                         "q95": d["hi"]})
    out["fig_real_lv_sigma_s_inflation"] = interval_figure(
        rows, truth=1.0, xaxis_title="iid σ_S median over sets / true σ_S", yaxis_title="strain layer",
        title=f"REAL LV, SYNTHETIC data: iid σ_S inflation, median over the 12 test sets with its "
              f"{result['ci']['level']:.0%} bootstrap CI (test sets resampled); chapter ≈ 2")
    out["table_real_lv_findings"] = table_figure(tabs["table_real_lv_findings"], title=TITLES["table_real_lv_findings"])
    return out


def source_line(result: dict) -> str:
    """Where the numbers come from, as one readable line."""
    from lvcore.studies.results import source_label

    parts = []
    for layer, L in result["layers"].items():
        if not L["study"]:
            parts.append(f"{layer.replace('_', ' ')}: FE sweeps only (mesh {L.get('resolution', 'default')})")
            continue
        smp, em = L["study"].get("sampler") or {}, L.get("emulator") or {}
        parts.append(f"{layer.replace('_', ' ')}: emulator {em.get('name', '?')} (held-out LVV RMSE "
                     f"{em.get('lvv_rmse_ml', float('nan')):.2f} mL, strain {em.get('strain_rmse', float('nan')):.4f}), "
                     f"{smp.get('num_chains', '?')} chains × ({smp.get('num_warmup', '?')} + {smp.get('num_samples', '?')})")
    return (f"{RESULT_FILE} ({source_label(result['folder'])}); geometry: {result['geometry']['label']}; data "
            f"FE-simulated (SYNTHETIC); " + "; ".join(parts))


#: Markers of the block of docs/studies.md written by :func:`docs_markdown` (a test compares the two).
DOCS_BEGIN = "<!-- real-LV fibre discrepancy: begin (generated by lvcore.studies.fibre_discrepancy_real_lv.docs_markdown) -->"
DOCS_END = "<!-- real-LV fibre discrepancy: end -->"


def docs_markdown(result: dict) -> str:
    """The docs' tables of the shipped result: docs/studies.md quotes them between :data:`DOCS_BEGIN` and
    :data:`DOCS_END` (``scripts/ship_fibre_discrepancy_real_lv.py --steps docs`` rewrites the block)."""
    def row(values) -> str:
        return "| " + " | ".join((f"{v:.4f}" if isinstance(v, float) else str(v)).replace("|", "\\|")
                                 for v in values) + " |"

    tab = tables(result)
    find = tab["table_real_lv_findings"]
    lines = [row(find.columns), "|" + "---|" * len(find.columns)] + [row(r.values()) for r in find.to_dict("records")]
    lines += ["", row(["layer", "geometry", "ΔLVV (mL), mean over θ", "mean Δstrain", "regional spread, mean [min, max] "
                       "over the 4 θ"]), "|---|---|---|---|---|"]
    for (layer, geo), g in tab["regional"].groupby(["layer", "geometry"], sort=False):
        sp = g["spread"]
        lines.append(row([layer.replace("_", " "), geo, f"{g['ΔLVV (mL)'].mean():.2f}", f"{g['mean Δstrain'].mean():.4f}",
                          f"{sp.mean():.4f} [{sp.min():.4f}, {sp.max():.4f}]"]))
    lines += ["", row(["layer", f"iid σ_S / {SIGMA_S:g} per angle pair (median over its 4 sets)", "largest R-hat",
                       "emulator held-out LVV / strain RMSE", "sampler"]), "|---|---|---|---|---|"]
    for layer, L in [(k, v) for k, v in result["layers"].items() if v["summary"]]:
        s, em, smp = L["summary"], L.get("emulator") or {}, L["study"].get("sampler") or {}
        pairs = ", ".join(f"{k}: {v:.2f}" for k, v in s["iid_inflation_per_angle_pair"].items())
        lines.append(row([layer.replace("_", " "), pairs, f"{s['rhat_max']:.3f}",
                          f"{em.get('lvv_rmse_ml', float('nan')):.2f} mL / {em.get('strain_rmse', float('nan')):.4f}",
                          f"{smp.get('num_chains')} × ({smp.get('num_warmup')} + {smp.get('num_samples')})"]))
    return "\n".join(lines)


__all__ = ["RESULT_FILE", "COMMAND", "LAYERS", "TITLES", "regional_change", "regional_changes", "bootstrap_median",
           "layer_summary", "compact_study", "assemble", "load", "DOCS_BEGIN", "DOCS_END", "tables", "figures", "source_line", "docs_markdown"]
