"""Figures of the optimisation studies (bo-fibres, operators) from their saved results (plotly).

Every function takes the plain data the studies write (``bo_fibres.json``
entries, ``operators.json`` fits, ``rss_surfaces.json`` records) and returns
a :class:`plotly.graph_objects.Figure`; the study commands and the app's
Studies page draw the same figures.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from lvcore.outputs import THETA_NAMES

#: Modes of the BO study, in table order.
BO_MODES = ("fixed", "free")
#: The operator study's truth (a, b, af, bf), marked on the loss surfaces.
THETA_TRUE = (0.60, 1.30, 1.00, 3.60)


def residual_figure(entries: Sequence[dict]):
    """Strain residuals (model − data) at the best point, fixed vs free angles, per subject (box plot)."""
    import plotly.graph_objects as go

    fig = go.Figure()
    colours = {"fixed": "#d62728", "free": "#1f77b4"}
    for m in BO_MODES:
        xs, ys = [], []
        for e in entries:
            if e["mode"] == m:
                xs += [e["subject"].replace("SYNTHETIC-", "")] * len(e["strain_residuals"])
                ys += e["strain_residuals"]
        if ys:
            label = "before: angles fixed (−60°, 90°)" if m == "fixed" else "after: angles optimised"
            fig.add_trace(go.Box(x=xs, y=ys, name=label, marker_color=colours[m], boxpoints="all", jitter=0.4,
                                 pointpos=0))
    fig.add_hline(y=0, line_dash="dot")
    fig.update_layout(boxmode="group", title="SYNTHETIC volunteers: strain residuals at the BO optimum",
                      xaxis_title="volunteer", yaxis_title="model − measured circumferential strain")
    return fig


def convergence_figure(entries: Sequence[dict]):
    """Best objective so far against evaluations, one line per subject and mode."""
    import plotly.graph_objects as go

    fig = go.Figure()
    for e in entries:
        c = e.get("convergence") or []
        fig.add_trace(go.Scatter(y=c, mode="lines", name=f"{e['subject'].replace('SYNTHETIC-', '')} {e['mode']}",
                                 line={"dash": "solid" if e["mode"] == "free" else "dot"}))
        if e.get("n_initial"):
            pass
    if entries:
        fig.add_vline(x=entries[0].get("n_initial", 0) - 0.5, line_dash="dash",
                      annotation_text="end of initial design")
    fig.update_layout(title="SYNTHETIC volunteers: BO convergence (best standardised RSS so far)",
                      xaxis_title="evaluation", yaxis_title="best objective", yaxis_type="log")
    return fig


def violin_figure(fits: Sequence[dict], metric: str, title: str, yaxis: str, per_region: bool = False):
    """Violins of ``metric`` per test geometry, one panel per main operator (Figs 9.11 and 9.14)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    mains = sorted({f["main_operator"] for f in fits})
    fig = make_subplots(rows=1, cols=max(1, len(mains)), subplot_titles=[f"main operator {m}" for m in mains],
                        shared_yaxes=True)
    for c, m in enumerate(mains, start=1):
        tests = [t for t in dict.fromkeys(f["test_geometry"] for f in fits if f["main_operator"] == m)]
        for t in tests:
            vals = []
            for f in fits:
                if f["main_operator"] == m and f["test_geometry"] == t and metric in f:
                    vals += list(np.abs(f[metric])) if per_region else [f[metric]]
            fig.add_trace(go.Violin(x=[t] * len(vals), y=vals, name=t, box_visible=True, points="all",
                                    showlegend=False, line_color="#1f77b4" if t.startswith("pc") else "#d62728"),
                          row=1, col=c)
    fig.update_layout(title=title, height=450)
    fig.update_yaxes(title_text=yaxis, col=1)
    return fig


def surface_figure(fit: dict, theta_true=THETA_TRUE):
    """Contours of the loss over the parameter pairs of one fit (Fig 9.13), θ̃ marked."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    pairs = fit["rss_surface"]["pairs"]
    fig = make_subplots(rows=2, cols=3, subplot_titles=[f"{p['x']}–{p['y']}" for p in pairs])
    for i, p in enumerate(pairs):
        r, c = divmod(i, 3)
        z = np.log10(np.maximum(np.asarray(p["rss"], float), 1e-12))
        fig.add_trace(go.Contour(x=p["x_values"], y=p["y_values"], z=z, showscale=i == 0, colorscale="Viridis",
                                 colorbar={"title": "log10 loss"}), row=r + 1, col=c + 1)
        ti, tj = THETA_NAMES.index(p["x"]), THETA_NAMES.index(p["y"])
        fig.add_trace(go.Scatter(x=[theta_true[ti]], y=[theta_true[tj]], mode="markers", showlegend=False,
                                 marker={"symbol": "x", "color": "red", "size": 11}), row=r + 1, col=c + 1)
        th = fit.get("theta_hat") or fit["rss_surface"].get("theta_hat")
        if th is not None:
            fig.add_trace(go.Scatter(x=[th[ti]], y=[th[tj]], mode="markers", showlegend=False,
                                     marker={"symbol": "circle-open", "color": "white", "size": 11,
                                             "line": {"width": 2}}), row=r + 1, col=c + 1)
        fig.update_xaxes(type="log", title_text=p["x"], row=r + 1, col=c + 1)
        fig.update_yaxes(type="log", title_text=p["y"], row=r + 1, col=c + 1)
    fig.update_layout(title=f"Loss (9.11) around θ̂: {fit['patient']}, main {fit['main_operator']}, test "
                            f"{fit['test_geometry']}<br><sup>{fit['rss_surface']['method']}; red X: θ̃, white circle: θ̂</sup>",
                      height=680)
    return fig
