"""Plotly figures for calibration results (ArviZ InferenceData in, ``go.Figure`` out).

Trace and rank plots, the R-hat/ESS table, a pair plot of theta, posterior
predictive densities of all 25 outputs with the measured values as dashed
lines (chapter Fig. 9.1 style), the discrepancy b on the 6 x 4 strain grid,
and the fibre-discrepancy study figures (Figs. 9.6, 9.7, 9.9).
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from lvcore.domain.conditions import SIGMA_S
from lvcore.domain.outputs import DISPLAY_NAMES, OUTPUT_NAMES, STRAIN_NAMES, THETA_NAMES
from lvcore.viz.figures import SERIES_COLOURS, strain_heatmap, violin

UNITS = {"a": "kPa", "b": "-", "af": "kPa", "bf": "-", "alpha_endo": "deg", "alpha_epi": "deg",
         "sigma_s2": "strain²", "v": "strain", "c": "rad", "tau": "-", "lam": "levels",
         "sigma1_sq": "strain²", "sigma2_sq": "strain²"}


def display_name(name: str) -> str:
    """The user-facing name of parameter ``name`` (``af`` -> ``a_f``, ``bf`` -> ``b_f``; others unchanged)."""
    return DISPLAY_NAMES.get(str(name), str(name))


def display_label(name: str) -> str:
    """``"a_f (kPa)"``: the user-facing name with the unit of :data:`UNITS`."""
    return f"{display_name(name)} ({UNITS.get(name, '')})"


def _draws(idata, name) -> np.ndarray:
    """(chain, draw[, ...]) array of a posterior variable."""
    return np.asarray(idata.posterior[name].values)


def _scalar_vars(idata, var_names=None) -> list[str]:
    if var_names is not None:
        return [v for v in var_names if v in idata.posterior]
    return [v for v in idata.posterior.data_vars if idata.posterior[v].ndim == 2]


#: Pixels between stacked subplots: room for a subplot title above each (tick labels only under the last).
STACK_GAP_PX = 34
_STACK_MARGIN = dict(l=60, r=10, t=70, b=50)


def _stack_spacing(n_rows: int, height: int) -> float:
    """``vertical_spacing`` of ``make_subplots`` giving :data:`STACK_GAP_PX` between rows of a figure ``height`` tall."""
    plot = height - _STACK_MARGIN["t"] - _STACK_MARGIN["b"]
    return min(0.3, STACK_GAP_PX / plot) if n_rows > 1 else 0.0


def trace_figure(idata, var_names=None, *, height_per_var: int = 160) -> go.Figure:
    """Trace plots: one row per parameter, one line per chain (x axis shared, labelled under the last row)."""
    names = _scalar_vars(idata, var_names)
    height = max(300, height_per_var * len(names))
    fig = make_subplots(rows=len(names), cols=1, shared_xaxes=True,
                        vertical_spacing=_stack_spacing(len(names), height),
                        subplot_titles=[display_label(n) for n in names])
    for i, n in enumerate(names):
        d = _draws(idata, n)
        for c in range(d.shape[0]):
            fig.add_scatter(y=d[c], mode="lines", line=dict(width=0.8, color=SERIES_COLOURS[c % 8]),
                            name=f"chain {c}", legendgroup=f"chain {c}", showlegend=i == 0, row=i + 1, col=1)
        fig.update_yaxes(title_text=UNITS.get(n, "") or "value", row=i + 1, col=1)
    fig.update_layout(height=height, title="Trace plots", margin=_STACK_MARGIN)
    fig.update_xaxes(title_text="draw", row=len(names), col=1)
    return fig


def rank_figure(idata, var_names=None, *, bins: int = 20, height_per_var: int = 150) -> go.Figure:
    """Rank plots: histograms of each chain's ranks in the pooled draws (flat = well mixed)."""
    from scipy.stats import rankdata

    names = _scalar_vars(idata, var_names)
    height = max(300, height_per_var * len(names))
    fig = make_subplots(rows=len(names), cols=1, shared_xaxes=True, vertical_spacing=_stack_spacing(len(names), height),
                        subplot_titles=[display_name(n) for n in names])
    for i, n in enumerate(names):
        d = _draws(idata, n)
        ranks = rankdata(d.reshape(-1)).reshape(d.shape)
        edges = np.linspace(0, ranks.size, bins + 1)
        for c in range(d.shape[0]):
            counts, _ = np.histogram(ranks[c], bins=edges)
            fig.add_scatter(x=0.5 * (edges[1:] + edges[:-1]), y=counts, mode="lines", line_shape="hvh",
                            line=dict(color=SERIES_COLOURS[c % 8]), name=f"chain {c}",
                            legendgroup=f"chain {c}", showlegend=i == 0, row=i + 1, col=1)
        fig.add_hline(y=d.shape[1] / bins, line=dict(color="grey", dash="dot"), row=i + 1, col=1)
        fig.update_yaxes(title_text="count", row=i + 1, col=1)
    fig.update_layout(height=height, title="Rank plots (uniform if chains agree)", margin=_STACK_MARGIN)
    fig.update_xaxes(title_text="rank in the pooled draws", row=len(names), col=1)
    return fig


def diagnostics_table(idata, var_names=None) -> pd.DataFrame:
    """ArviZ summary of scalar parameters with the 90 % equal-tailed interval (q05, q95: the 5 % and 95 % quantiles
    of the pooled draws, the convention of lvcore.inference.diagnostics.summary_table and the verdict) in place of
    ArviZ's HDI: mean, sd, median, q05, q95, MCSE, ESS bulk/tail, R-hat."""
    import arviz as az

    table = az.summary(idata, var_names=_scalar_vars(idata, var_names), hdi_prob=0.9)
    table = table.drop(columns=[c for c in table.columns if str(c).startswith("hdi_")])
    at = list(table.columns).index("sd") + 1
    for k, (col, p) in enumerate((("median", 0.5), ("q05", 0.05), ("q95", 0.95))):
        table.insert(at + k, col, [float(np.quantile(np.asarray(idata.posterior[n]).reshape(-1), p))
                                   for n in table.index])
    return table


def pair_figure(idata, var_names=THETA_NAMES, *, max_points: int = 1500, truth: Mapping | None = None) -> go.Figure:
    """Pair plot (scatter matrix) of posterior draws, thinned to ``max_points``."""
    names = [n for n in var_names if n in idata.posterior]
    flat = {n: _draws(idata, n).reshape(-1) for n in names}
    m = len(next(iter(flat.values())))
    idx = np.linspace(0, m - 1, min(m, max_points)).astype(int)
    fig = go.Figure(go.Splom(
        dimensions=[dict(label=display_label(n), values=flat[n][idx]) for n in names],
        marker=dict(size=3, opacity=0.4, color=SERIES_COLOURS[0]), diagonal_visible=False, showupperhalf=False,
        name="posterior"))
    if truth:
        fig.add_trace(go.Splom(dimensions=[dict(label=display_label(n), values=[truth[n]]) for n in names],
                               marker=dict(size=10, color="red", symbol="x"), diagonal_visible=False,
                               showupperhalf=False, name="truth"))
    fig.update_layout(title="Posterior pair plot", height=650, margin=dict(l=10, r=10, t=50, b=10))
    return fig


def geometry_posterior_figure(scores: Mapping[str, np.ndarray], scale: np.ndarray, cavity_ml: np.ndarray, *,
                              box: tuple[float, float] | None = None, measured_ml: float | None = None,
                              measured_sd_ml: float | None = None, title: str = "Inferred geometry") -> go.Figure:
    """Posterior of an inferred geometry (``--geometry infer``): the PC scores, the scale and the implied reference
    cavity.

    Parameters
    ----------
    scores : mapping name -> draws
        PC scores ``h1..hk`` (standard deviations of the shape model).
    scale : array
        Draws of the uniform scale ``s`` (-).
    cavity_ml : array
        Draws of the implied reference (early-diastolic) cavity volume ``s^3 V_cav(h)`` (mL).
    box : (float, float), optional
        The emulator's training box of the scores, drawn as dotted lines.
    measured_ml, measured_sd_ml : float, optional
        The measured reference volume and its standard deviation (mL), drawn as a line and a band.
    """
    fig = make_subplots(rows=1, cols=3, column_widths=[0.5, 0.2, 0.3], horizontal_spacing=0.08,
                        subplot_titles=("PC scores h (SD)", "scale s (–)", "reference cavity (mL)"))
    for k, (name, v) in enumerate(scores.items()):
        fig.add_trace(go.Violin(y=np.asarray(v, float).reshape(-1), name=name, spanmode="hard", box_visible=True,
                                meanline_visible=False, showlegend=False,
                                line_color=SERIES_COLOURS[k % len(SERIES_COLOURS)]), row=1, col=1)
    if box is not None:
        for edge in box:
            fig.add_hline(y=float(edge), line=dict(dash="dot", color="grey"), row=1, col=1)
    fig.add_trace(go.Histogram(x=np.asarray(scale, float).reshape(-1), nbinsx=30, showlegend=False,
                               marker_color=SERIES_COLOURS[0]), row=1, col=2)
    fig.add_trace(go.Histogram(x=np.asarray(cavity_ml, float).reshape(-1), nbinsx=30, name="posterior",
                               showlegend=False, marker_color=SERIES_COLOURS[1 % len(SERIES_COLOURS)]), row=1, col=3)
    if measured_ml is not None:
        if measured_sd_ml:
            fig.add_vrect(x0=measured_ml - measured_sd_ml, x1=measured_ml + measured_sd_ml, fillcolor="red",
                          opacity=0.12, line_width=0, row=1, col=3)
        fig.add_vline(x=float(measured_ml), line=dict(color="red", dash="dash"), row=1, col=3)
    fig.update_xaxes(title_text="s", row=1, col=2)
    fig.update_yaxes(title_text="draws", row=1, col=2)
    fig.update_xaxes(title_text="s³·V_cav(h), mL" + ("; red: measured ± SD" if measured_ml is not None else ""),
                     row=1, col=3)
    fig.update_layout(title=title, height=420, margin=dict(l=50, r=10, t=80, b=50))
    return fig


def predictive_density_figure(results: Mapping[str, object], y_measured, *, kind: str = "y_rep",
                              n_grid: int = 120) -> go.Figure:
    """Posterior predictive densities of all 25 outputs, measured values as dashed lines (Fig. 9.1 style).

    Parameters
    ----------
    results : dict label -> InferenceData
        One entry per model (overlaid).
    y_measured : (25,) array
    kind : str
        ``"y_rep"`` (posterior predictive, with noise) or ``"eta"`` (forward model at the draws).
    """
    from scipy.stats import gaussian_kde

    y_measured = np.asarray(y_measured, dtype=float)
    fig = make_subplots(rows=5, cols=5, subplot_titles=[f"{OUTPUT_NAMES[0]} (mL)"] + list(STRAIN_NAMES),
                        horizontal_spacing=0.03, vertical_spacing=0.07)
    for k, (label, idata) in enumerate(results.items()):
        arr = (np.asarray(idata.posterior_predictive["y_rep"].values) if kind == "y_rep"
               else np.asarray(idata.posterior["eta"].values)).reshape(-1, 25)
        for j in range(25):
            a = arr[:, j]
            lo, hi = np.quantile(a, [0.001, 0.999])
            lo, hi = min(lo, y_measured[j]), max(hi, y_measured[j])
            xs = np.linspace(lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo), n_grid)
            dens = gaussian_kde(a)(xs) if np.ptp(a) > 0 else np.zeros_like(xs)
            fig.add_scatter(x=xs, y=dens, mode="lines", line=dict(color=SERIES_COLOURS[k % 8], width=1.2), name=label,
                            legendgroup=label, showlegend=j == 0, row=j // 5 + 1, col=j % 5 + 1)
    for j in range(25):
        fig.add_vline(x=float(y_measured[j]), line=dict(color="black", dash="dash", width=1), row=j // 5 + 1,
                      col=j % 5 + 1)
    fig.update_yaxes(showticklabels=False)
    fig.update_layout(height=900, title=("Posterior predictive" if kind == "y_rep" else "Emulator at posterior draws")
                      + " of the 25 outputs; dashed: measured", margin=dict(l=10, r=10, t=70, b=10),
                      font=dict(size=10))
    return fig


def discrepancy_figure(idata, *, include_v: bool = True) -> go.Figure:
    """Posterior median of the discrepancy b (+ v) on the 4 x 6 strain grid (levels x sectors)."""
    d = _draws(idata, "disc").reshape(-1, 24)
    if include_v and "v" in idata.posterior:
        d = d + _draws(idata, "v").reshape(-1, 1)
    med = np.median(d, axis=0)
    title = "Discrepancy b(x) + v, posterior median" if include_v else "Discrepancy b(x), posterior median"
    return strain_heatmap(med, title=title)


def sigma_s_figure(samples: Mapping[str, np.ndarray], truth: float | None = SIGMA_S) -> go.Figure:
    """Posterior densities of sigma_S per model with the true value dashed (Fig. 9.7)."""
    from lvcore.viz.figures import density_overlay

    return density_overlay({k: np.asarray(v) for k, v in samples.items()},
                           reference=None if truth is None else {"truth": truth},
                           title="Posterior of the strain noise sd σ_S", xaxis_title="σ_S (strain)")


def strain_predictive_figure(bands: Mapping[str, Mapping[str, np.ndarray]], y_measured) -> go.Figure:
    """Posterior predictive 5-95% bands and medians of the 24 strains per model vs the data (Fig. 9.6).

    ``bands[label]`` has arrays ``q05``, ``q50``, ``q95`` of length 24.
    """
    y = np.asarray(y_measured, dtype=float)[-24:]
    x = np.arange(1, 25)
    fig = go.Figure()
    for k, (label, b) in enumerate(bands.items()):
        off = (k - (len(bands) - 1) / 2) * 0.25
        fig.add_scatter(x=x + off, y=b["q50"], mode="markers", name=label, marker=dict(color=SERIES_COLOURS[k % 8]),
                        error_y=dict(type="data", symmetric=False, array=np.asarray(b["q95"]) - b["q50"],
                                     arrayminus=np.asarray(b["q50"]) - b["q05"]))
    fig.add_scatter(x=x, y=y, mode="markers", name="data", marker=dict(color="black", symbol="line-ew-open", size=14))
    fig.update_layout(title="Posterior predictive of the 24 strains (median, 5–95%) vs data",
                      xaxis=dict(title="region r + 1 (6·level + sector)", tickvals=x), yaxis_title="E_cc (-)",
                      height=420, margin=dict(l=10, r=10, t=50, b=10))
    return fig


def error_violin_figure(errors: Mapping[str, np.ndarray]) -> go.Figure:
    """Violins of |eta(theta_post, h) - eta(theta_true, h)| per model over all test sets (Fig. 9.9)."""
    return violin(errors, title="|η(θ_post, h) − η(θ̃, h)| over the 24 strains and all test sets",
                  yaxis_title="absolute strain error (-)", xaxis_title="likelihood model", nonnegative=True)


def cohort_figure(record: Mapping, name: str = "a", *, truth: Mapping | None = None) -> go.Figure:
    """A cohort's subjects: the 90 % interval and median of ``name`` per subject in the joint (hierarchical)
    posterior and, where given, in the subject's separate fit, with each group's population median exp(mu)
    (its 90 % interval shaded); log x axis.

    ``record``: summary.json's ``hierarchical`` section (:func:`lvcore.inference.hierarchical.summarise`);
    ``truth``: subject -> true value (SYNTHETIC cohorts), drawn as crosses.
    """
    from lvcore.viz.report_figures import interval_figure

    subjects = list(record["subjects"])
    rows = [{"label": s, "series": "joint (hierarchical)", **record["subjects"][s][name]} for s in subjects]
    rows += [{"label": s, "series": "separate fit", **record["separate"][s][name]}
             for s in subjects if s in record.get("separate", {})]
    n = len(subjects)
    fig = interval_figure(rows, truth=None, title=f"{display_name(name)}: joint posterior vs separate fits, "
                          f"{n} subjects (median, 90 % interval)", xaxis_title=display_label(name), yaxis_title="subject",
                          height=max(360, 22 * n + 140))
    for k, (g, grp) in enumerate(record["population"]["groups"].items()):
        q = grp["median_theta"][name]
        colour = SERIES_COLOURS[(k + 2) % len(SERIES_COLOURS)]
        fig.add_vrect(x0=q["q05"], x1=q["q95"], fillcolor=colour, opacity=0.12, line_width=0)
        fig.add_vline(x=q["median"], line=dict(color=colour, dash="dot"),
                      annotation_text=f"population {g}" if len(record["population"]["groups"]) > 1 else "population")
    if truth:
        fig.add_scatter(x=[truth[s] for s in subjects if s in truth], y=[s for s in subjects if s in truth],
                        mode="markers", name="truth (SYNTHETIC)", marker=dict(symbol="x", color="black", size=8))
    fig.update_xaxes(type="log")
    return fig


def write_html(fig: go.Figure, path) -> Path:
    """Write a self-contained HTML file of ``fig``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.write_html(str(path), include_plotlyjs=True)
    return path


__all__ = ["DISPLAY_NAMES", "display_name", "display_label", "trace_figure", "rank_figure", "diagnostics_table", "pair_figure", "geometry_posterior_figure",
           "predictive_density_figure",
           "discrepancy_figure", "sigma_s_figure", "strain_predictive_figure", "error_violin_figure", "write_html",
           "cohort_figure"]
