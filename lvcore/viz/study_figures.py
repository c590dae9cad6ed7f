"""Figures of the optimisation studies (bo-fibres, operators) and of SBC from their saved results (plotly).

Every function takes the plain data the studies write (the fibre-angle BO's
entries, the operator study's fits, ``rss_surfaces.json`` records) and returns
a :class:`plotly.graph_objects.Figure`. The study modules' ``figures(result)``
call them; the study commands, the app's Studies page and ``lvcore report``
all draw through those.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from lvcore.domain.outputs import THETA_NAMES
from lvcore.viz.figures import SERIES_COLOURS

#: Modes of the BO study, in table order.
BO_MODES = ("fixed", "free")
_MODE_COLOURS = {"fixed": "#d62728", "free": "#1f77b4"}


def _short(subject: str) -> str:
    return subject.replace("SYNTHETIC-", "")


def residual_figure(entries: Sequence[dict]):
    """Strain residuals (model − data) at the best point, fixed vs free angles, per subject (box plot)."""
    import plotly.graph_objects as go

    fig = go.Figure()
    for m in BO_MODES:
        xs, ys = [], []
        for e in entries:
            if e["mode"] == m and e.get("strain_residuals"):
                xs += [_short(e["subject"])] * len(e["strain_residuals"])
                ys += e["strain_residuals"]
        if ys:
            label = "before: angles fixed (−60°, 90°)" if m == "fixed" else "after: angles optimised"
            fig.add_trace(go.Box(x=xs, y=ys, name=label, marker_color=_MODE_COLOURS[m], boxpoints="all", jitter=0.4,
                                 pointpos=0))
    fig.add_hline(y=0, line_dash="dot")
    fig.update_layout(boxmode="group", title="SYNTHETIC volunteers:<br>strain residuals at the BO optimum",
                      xaxis_title="volunteer", yaxis_title="model − measured E_cc (-)", height=480,
                      legend=dict(orientation="h", y=-0.2, yanchor="top"), margin=dict(l=60, r=20, t=80, b=40))
    return fig


def convergence_figure(entries: Sequence[dict]):
    """Best objective so far against evaluations: one colour per subject, dotted fixed angles, solid free.

    The legend holds one entry per subject and one per line style (not one per
    line), laid out under the plot, so it fits whatever the number of subjects.
    """
    import plotly.graph_objects as go

    from lvcore.viz.figures import decade_log_axis

    fig = go.Figure()
    subjects = list(dict.fromkeys(e["subject"] for e in entries))
    values = []
    for e in entries:
        c = e.get("convergence") or []
        values += [v for v in c if v and v > 0]
        k = subjects.index(e["subject"])
        first = next(x for x in entries if x["subject"] == e["subject"]) is e
        fig.add_trace(go.Scatter(y=c, mode="lines", name=_short(e["subject"]), legendgroup=e["subject"],
                                 showlegend=first,
                                 line={"dash": "solid" if e["mode"] == "free" else "dot",
                                       "color": SERIES_COLOURS[k % len(SERIES_COLOURS)]},
                                 hovertemplate=f"{_short(e['subject'])} {e['mode']}: %{{y:.4g}}<extra></extra>"))
    for m, dash in (("fixed angles", "dot"), ("free angles", "solid")):
        fig.add_trace(go.Scatter(x=[None], y=[None], mode="lines", name=m, line={"dash": dash, "color": "grey"}))
    if entries and entries[0].get("n_initial"):
        fig.add_vline(x=entries[0]["n_initial"] - 0.5, line_dash="dash", annotation_text="end of initial design")
    fig.update_layout(title="SYNTHETIC volunteers: BO convergence<br>(best standardised RSS so far)",
                      xaxis_title="evaluation", yaxis_title="best objective (-)", height=520,
                      legend=dict(orientation="h", y=-0.18, yanchor="top"), margin=dict(l=60, r=20, t=80, b=40))
    if values:
        fig.update_yaxes(**decade_log_axis(values))
    return fig


def bo_error_bars(rows):
    """Bars of the LVV and median strain errors at the BO optimum per subject, fixed vs free angles.

    ``rows``: a DataFrame with ``subject``, ``mode``, ``lvv_abs_error_ml``, ``median_abs_strain_error``.
    """
    from plotly.subplots import make_subplots

    cols = (("lvv_abs_error_ml", "LVV |error| (mL)"), ("median_abs_strain_error", "median |strain error| (-)"))
    fig = make_subplots(rows=1, cols=2, subplot_titles=[t for _, t in cols])
    for k, mode in enumerate(BO_MODES):
        sub = rows[rows["mode"] == mode]
        for j, (col, title) in enumerate(cols):
            fig.add_bar(x=sub["subject"], y=sub[col], name=f"{mode} angles", legendgroup=mode, showlegend=j == 0,
                        marker_color=SERIES_COLOURS[k], row=1, col=j + 1)
            fig.update_yaxes(title_text=title, rangemode="nonnegative", row=1, col=j + 1)
            fig.update_xaxes(title_text="volunteer", row=1, col=j + 1)
    fig.update_layout(title="Tables 9.2/9.3 — SYNTHETIC volunteers: errors at the BO optimum, fixed vs free angles",
                      barmode="group", height=440, margin=dict(l=60, r=20, t=90, b=40))
    return fig


def common_objective_bars(rows, *, same_tol: float = 1e-9):
    """The F6 test's comparison on one objective scale, fixed vs free angles, per volunteer and mismatch kind.

    Left: the common-scale objective (the chapter's standardised RSS with one standardisation for both modes) at
    each mode's BO optimum, bars fixed vs free; where the lowest common-scale value a run reached is lower than at
    its optimum (the BO minimised its own standardisation), it is marked as a diamond, else the panel's title says
    that the two are the same in every run. Right: the change with free angles, 100 (1 − free / fixed) % per
    volunteer and kind (> 0: free angles reach a lower objective).

    ``rows``: a DataFrame with ``subject``, ``mode``, ``objective_common_at_best``, ``objective_common_min``.
    """
    from plotly.subplots import make_subplots

    at_best = rows.pivot(index="subject", columns="mode", values="objective_common_at_best")
    lowest = rows.pivot(index="subject", columns="mode", values="objective_common_min")
    order = list(dict.fromkeys(rows["subject"]))
    at_best, lowest = at_best.loc[order], lowest.loc[order]
    lower = (lowest < at_best * (1.0 - same_tol)).to_numpy()
    left = "common-scale objective at each mode's optimum (-)"
    if not lower.any():
        left += "<br>(no run reached a lower common-scale value elsewhere)"
    change = 100.0 * (1.0 - at_best["free"] / at_best["fixed"])
    fig = make_subplots(rows=1, cols=2, column_widths=[0.6, 0.4], horizontal_spacing=0.1,
                        subplot_titles=[left, "change with free angles: 100 (1 − free / fixed) (%)"])
    for k, mode in enumerate(BO_MODES):
        fig.add_bar(x=order, y=at_best[mode], name=f"{mode} angles", legendgroup=mode, offsetgroup=mode,
                    marker_color=SERIES_COLOURS[k], row=1, col=1)
        if lower[:, k].any():
            idx = np.flatnonzero(lower[:, k])
            fig.add_scatter(x=[order[i] for i in idx], y=lowest[mode].to_numpy()[idx], mode="markers",
                            marker=dict(symbol="diamond", size=9, color=SERIES_COLOURS[k],
                                        line=dict(color="black", width=1)),
                            name=f"{mode}: lowest common-scale value reached", row=1, col=1)
    fig.add_bar(x=order, y=change, name="free lower (> 0) or higher (< 0)", showlegend=False,
                marker_color=[SERIES_COLOURS[1] if c > 0 else SERIES_COLOURS[0] for c in change], row=1, col=2)
    fig.add_hline(y=0, line=dict(color="grey", width=1), row=1, col=2)
    fig.update_yaxes(title_text="objective (-)", rangemode="tozero", row=1, col=1)
    fig.update_yaxes(title_text="lower with free angles (%)", row=1, col=2)
    fig.update_xaxes(title_text="volunteer and mismatch kind")
    fig.update_layout(barmode="group", height=460, margin=dict(l=60, r=20, t=110, b=40))
    return fig


def surface_figure(surface: dict, theta_true: Sequence[float], *, title: str):
    """Contours of the loss over the parameter pairs of one fit (Fig 9.13), θ̂ and the truth θ̃ marked.

    Parameters
    ----------
    surface : dict
        ``pairs`` (each ``x``, ``y`` parameter names, ``x_values``, ``y_values``,
        ``rss`` (len(y), len(x))), ``method`` and ``theta_hat`` (optional).
    theta_true : (4,) sequence
        The truth θ̃ (a, b, af, bf).
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    pairs = surface["pairs"]
    n_cols = 3 if len(pairs) > 1 else 1
    n_rows = -(-len(pairs) // n_cols)
    fig = make_subplots(rows=n_rows, cols=n_cols, subplot_titles=[f"{p['x']}–{p['y']}" for p in pairs],
                        horizontal_spacing=0.09, vertical_spacing=0.16)
    th = surface.get("theta_hat")
    for i, p in enumerate(pairs):
        r, c = divmod(i, n_cols)
        z = np.log10(np.maximum(np.asarray(p["rss"], float), 1e-12))
        fig.add_trace(go.Contour(x=p["x_values"], y=p["y_values"], z=z, showscale=i == 0, colorscale="Viridis",
                                 colorbar={"title": "log10 loss", "x": 1.02}), row=r + 1, col=c + 1)
        ti, tj = THETA_NAMES.index(p["x"]), THETA_NAMES.index(p["y"])
        fig.add_trace(go.Scatter(x=[theta_true[ti]], y=[theta_true[tj]], mode="markers", name="truth θ̃",
                                 legendgroup="truth", showlegend=i == 0,
                                 marker={"symbol": "x", "color": "red", "size": 11}), row=r + 1, col=c + 1)
        if th is not None:
            fig.add_trace(go.Scatter(x=[th[ti]], y=[th[tj]], mode="markers", name="refit θ̂", legendgroup="hat",
                                     showlegend=i == 0,
                                     marker={"symbol": "circle-open", "color": "white", "size": 12,
                                             "line": {"width": 2}}), row=r + 1, col=c + 1)
        fig.update_xaxes(type="log", title_text=p["x"], row=r + 1, col=c + 1)
        fig.update_yaxes(type="log", title_text=p["y"], row=r + 1, col=c + 1)
    method = surface.get("method") or "method not recorded"
    fig.update_layout(title=f"{title}<br><sup>{method}</sup>", height=330 * n_rows + 170,
                      legend=dict(orientation="h", y=-0.1, yanchor="top"), margin=dict(l=60, r=20, t=120, b=60))
    return fig


def _rgba(hex_colour: str, alpha: float) -> str:
    h = hex_colour.lstrip("#")
    return f"rgba({int(h[0:2], 16)}, {int(h[2:4], 16)}, {int(h[4:6], 16)}, {alpha})"


def dose_response_figure(rows: Sequence[dict], *, title: str, xaxis_title: str, yaxis_title: str,
                         panels: Sequence[str] | None = None, refs: Sequence[tuple[float, str]] = (),
                         height: int | None = None):
    """Value against dose with a CI band per series, optionally one panel per group (plotly).

    Parameters
    ----------
    rows : sequence of dict
        Each with ``series``, ``x``, ``value``, ``lo``, ``hi`` (the CI) and, for
        panels, ``panel``; optional ``label`` (hover text, e.g. the dose).
    panels : sequence of str, optional
        Panel names in order (one subplot each, shared y axis); None: one panel.
    refs : sequence of (y, text)
        Dotted horizontal reference lines (e.g. the truth, the chapter's value).

    Each series is a line through its medians and a shaded band between the
    CI ends (a trace named ``"<series> CI"``).
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    names = list(panels) if panels else [None]
    cols = min(3, len(names))
    nrows = int(np.ceil(len(names) / cols))
    fig = make_subplots(rows=nrows, cols=cols, subplot_titles=[n or "" for n in names], shared_yaxes=True,
                        horizontal_spacing=0.06, vertical_spacing=0.16 if nrows > 1 else 0.1)
    series = list(dict.fromkeys(r["series"] for r in rows))
    for p, panel in enumerate(names):
        r_, c_ = p // cols + 1, p % cols + 1
        for k, s in enumerate(series):
            rs = sorted((r for r in rows if r["series"] == s and (panel is None or r.get("panel") == panel)
                         and r.get("value") is not None and r.get("x") is not None), key=lambda r: r["x"])
            if not rs:
                continue
            colour = SERIES_COLOURS[k % len(SERIES_COLOURS)]
            x = [r["x"] for r in rs]
            fig.add_trace(go.Scatter(x=x + x[::-1], y=[r["hi"] for r in rs] + [r["lo"] for r in rs][::-1],
                                     fill="toself", fillcolor=_rgba(colour, 0.18), line=dict(width=0),
                                     hoverinfo="skip", name=f"{s} CI", legendgroup=s, showlegend=False),
                          row=r_, col=c_)
            fig.add_trace(go.Scatter(x=x, y=[r["value"] for r in rs], mode="lines+markers", name=s, legendgroup=s,
                                     line=dict(color=colour), showlegend=p == 0,
                                     text=[r.get("label", "") for r in rs],
                                     hovertemplate="%{text}<br>x %{x:.4f}<br>%{y:.4g}<extra>" + str(s) + "</extra>"),
                          row=r_, col=c_)
        for y, text in refs:
            fig.add_hline(y=y, line=dict(color="black", dash="dot", width=1), row=r_, col=c_,
                          annotation_text=text if p == 0 else None)
    fig.update_xaxes(title_text=xaxis_title, rangemode="tozero")
    fig.update_yaxes(title_text=yaxis_title, col=1, rangemode="tozero")
    fig.update_layout(title=title, height=height or 360 + 300 * nrows, margin=dict(l=60, r=20, t=90, b=60),
                      legend=dict(orientation="h", y=-0.12, yanchor="top"))
    return fig


__all__ = ["residual_figure", "convergence_figure", "bo_error_bars", "surface_figure", "dose_response_figure",
           "sbc_rank_histogram_figure", "sbc_coverage_figure"]


def ci_dots(rows: Sequence[dict], *, title: str, reference: float | None = None, percent: bool = True):
    """Estimates with their bootstrap CIs as dots with error bars, one colour per ``test``.

    ``rows``: dicts with ``quantity`` (x category), ``test`` (series), ``value``, ``lo``, ``hi`` (CI ends or None).
    ``reference``: a horizontal line (e.g. 0.5, where a "most cases" claim starts to hold).
    """
    import plotly.graph_objects as go

    scale = 100.0 if percent else 1.0
    fig = go.Figure()
    for k, test in enumerate(dict.fromkeys(r["test"] for r in rows)):
        sub = [r for r in rows if r["test"] == test]
        y = np.array([r["value"] for r in sub], float) * scale
        lo = np.array([r["lo"] if r["lo"] is not None else r["value"] for r in sub], float) * scale
        hi = np.array([r["hi"] if r["hi"] is not None else r["value"] for r in sub], float) * scale
        fig.add_scatter(x=[r["quantity"] for r in sub], y=y, mode="markers", name=test,
                        marker=dict(size=11, color=SERIES_COLOURS[k % len(SERIES_COLOURS)]),
                        error_y=dict(type="data", symmetric=False, array=hi - y, arrayminus=y - lo))
    if reference is not None:
        fig.add_hline(y=reference * scale, line_dash="dot", line_color="grey")
    fig.update_layout(title=title, scattermode="group", height=440, margin=dict(l=60, r=20, t=90, b=40),
                      yaxis_title="share (%)" if percent else "value")
    return fig


# --------------------------------------------------------------------------- simulation-based calibration (sbc)
#: Route order and colours of the SBC figures.
SBC_ROUTES = ("mesh", "infer")


def sbc_rank_histogram_figure(rows: Sequence[dict], *, title: str, labels: dict | None = None, n_cols: int = 4):
    """Rank histograms of SBC, one panel per (route, quantity), each with the band of uniform ranks (plotly).

    Parameters
    ----------
    rows : sequence of dict
        One per bin: ``route``, ``quantity``, ``bin`` (1-based), ``count``, ``expected`` and ``band_lo`` /
        ``band_hi`` (the range of the bin's count under uniform ranks).
    labels : dict, optional
        Display names of the quantities.
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    labels = labels or {}
    routes = [r for r in SBC_ROUTES if any(x["route"] == r for x in rows)] + sorted(
        {x["route"] for x in rows} - set(SBC_ROUTES))
    quantities = list(dict.fromkeys(x["quantity"] for x in rows))
    panels = [(r, q) for r in routes for q in quantities]
    n_rows = max(1, -(-len(panels) // n_cols))
    fig = make_subplots(rows=n_rows, cols=n_cols, subplot_titles=[f"{r}: {labels.get(q, q)}" for r, q in panels],
                        horizontal_spacing=0.05, vertical_spacing=0.32 / max(1, n_rows - 1) if n_rows > 1 else 0.1)
    for k, (route, q) in enumerate(panels):
        rr, cc = divmod(k, n_cols)
        sub = sorted((x for x in rows if x["route"] == route and x["quantity"] == q), key=lambda x: x["bin"])
        if not sub:
            continue
        n_bins = len(sub)
        edges = np.arange(n_bins + 1) / n_bins
        # the band: a step shape between the lower and upper ends of each bin's range
        xs = np.repeat(edges, 2)[1:-1].tolist()
        lo = np.repeat([x["band_lo"] for x in sub], 2).tolist()
        hi = np.repeat([x["band_hi"] for x in sub], 2).tolist()
        fig.add_trace(go.Scatter(x=xs + xs[::-1], y=hi + lo[::-1], fill="toself", fillcolor="rgba(128,128,128,0.25)",
                                 line=dict(width=0), hoverinfo="skip", name="uniform ranks: range of a bin's count",
                                 legendgroup="band", showlegend=k == 0), row=rr + 1, col=cc + 1)
        fig.add_trace(go.Bar(x=(edges[:-1] + 0.5 / n_bins).tolist(), y=[x["count"] for x in sub], width=0.9 / n_bins,
                             marker_color=SERIES_COLOURS[routes.index(route) % len(SERIES_COLOURS)],
                             name=f"route {route}", legendgroup=route,
                             showlegend=quantities.index(q) == 0,
                             hovertemplate="%{y} subjects<extra>" + f"{route}: {labels.get(q, q)}" + "</extra>"),
                      row=rr + 1, col=cc + 1)
        fig.add_trace(go.Scatter(x=xs, y=np.repeat([x["expected"] for x in sub], 2).tolist(), mode="lines",
                                 line=dict(color="black", dash="dot", width=1), name="expected (uniform ranks)",
                                 legendgroup="expected", showlegend=k == 0, hoverinfo="skip"),
                      row=rr + 1, col=cc + 1)
        fig.update_xaxes(range=[0, 1], row=rr + 1, col=cc + 1)
    for rr in range(n_rows):
        fig.update_yaxes(title_text="subjects", rangemode="tozero", row=rr + 1, col=1)
    for cc in range(n_cols):
        fig.update_xaxes(title_text="(rank + ½)/(L + 1)", row=n_rows, col=cc + 1)
    fig.update_layout(title=title, height=230 * n_rows + 220, bargap=0.05, margin=dict(l=60, r=20, t=130, b=80),
                      legend=dict(orientation="h", y=-0.08, yanchor="top"))
    return fig


def sbc_coverage_figure(rows: Sequence[dict], *, title: str, labels: dict | None = None):
    """SBC coverage per quantity with its CI, one colour per route, one panel per level (plotly).

    ``rows``: dicts with ``route``, ``quantity``, ``level`` (percent), ``coverage``, ``lo``, ``hi`` (CI ends) and
    ``nominal_at_L`` (the coverage of a calibrated posterior with the same number of draws; dotted marks).
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    labels = labels or {}
    levels = sorted({int(r["level"]) for r in rows}, reverse=True)
    routes = [r for r in SBC_ROUTES if any(x["route"] == r for x in rows)] + sorted(
        {x["route"] for x in rows} - set(SBC_ROUTES))
    fig = make_subplots(rows=1, cols=max(1, len(levels)), subplot_titles=[f"central {lv} % interval" for lv in levels],
                        horizontal_spacing=0.08)
    for j, level in enumerate(levels):
        for k, route in enumerate(routes):
            sub = [r for r in rows if r["route"] == route and int(r["level"]) == level and r["coverage"] is not None]
            if not sub:
                continue
            y = np.array([r["coverage"] for r in sub], float) * 100
            lo = np.array([r["lo"] if r["lo"] is not None else r["coverage"] for r in sub], float) * 100
            hi = np.array([r["hi"] if r["hi"] is not None else r["coverage"] for r in sub], float) * 100
            x = [labels.get(r["quantity"], r["quantity"]) for r in sub]
            colour = SERIES_COLOURS[k % len(SERIES_COLOURS)]
            fig.add_trace(go.Scatter(x=x, y=y, mode="markers", name=f"route {route}", legendgroup=route,
                                     showlegend=j == 0, marker=dict(size=10, color=colour),
                                     error_y=dict(type="data", symmetric=False, array=hi - y, arrayminus=y - lo),
                                     text=[f"n = {r['n']}" for r in sub],
                                     hovertemplate="%{x}: %{y:.0f} % (%{text})<extra>" + route + "</extra>"),
                          row=1, col=j + 1)
            nominal = [r.get("nominal_at_L") for r in sub]
            if all(v is not None for v in nominal):
                fig.add_trace(go.Scatter(x=x, y=np.array(nominal, float) * 100, mode="markers",
                                         marker=dict(symbol="line-ew-open", size=16, color=colour),
                                         name="calibrated, same L", legendgroup="nominal",
                                         showlegend=j == 0 and k == 0, hoverinfo="skip"), row=1, col=j + 1)
        fig.add_hline(y=level, line=dict(color="grey", dash="dot", width=1), row=1, col=j + 1)
        fig.update_yaxes(title_text="coverage (%)", range=[0, 102], row=1, col=j + 1)
        fig.update_xaxes(title_text="quantity", row=1, col=j + 1)
    fig.update_layout(title=title, scattermode="group", height=470, margin=dict(l=60, r=20, t=120, b=60),
                      legend=dict(orientation="h", y=-0.2, yanchor="top"))
    return fig
