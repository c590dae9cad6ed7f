"""Plotly builders for the report's chapter figures that the app's builders do not cover.

Pure functions of plain data (dicts, arrays, DataFrames) returning
``plotly.graph_objects.Figure``; nothing here reads files or runs a model.
The shared builders (strain bars, violins, densities, contours) are in
:mod:`lvcore.viz.figures` and :mod:`lvcore.viz.inference_figures`.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import pandas as pd
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from lvcore.geometry.template import N_REGIONS, N_SECTORS
from lvcore.domain.outputs import LEVEL_NAMES
from lvcore.viz.figures import SERIES_COLOURS, plain_text

#: Region tick labels "basal S1" ... for 24-strain line plots (r = 6 * level + sector).
REGION_TICKS = tuple(f"{LEVEL_NAMES[r // N_SECTORS]} S{r % N_SECTORS + 1}" for r in range(N_REGIONS))


def _strains24(values) -> np.ndarray:
    y = np.asarray(values, dtype=float).ravel()
    if y.size == N_REGIONS + 1:
        y = y[1:]
    if y.size != N_REGIONS:
        raise ValueError(f"expected {N_REGIONS} strains (or 25 outputs), got {y.size} values")
    return y


#: Title line height (px), room of subplot titles above a plot (px), width of a title character (px, 17 px font).
TITLE_LINE_PX, SUBPLOT_TITLE_PX, TITLE_CHAR_PX = 24, 26, 9.0
#: Width (px) of a static export whose figure sets none (tables set their own, to fit their columns).
EXPORT_WIDTH_PX = 1100


#: A plotly text tag (``<br>``, ``<sup>``, ``</b>``...), not a "<=" in the text.
_TAG = r"</?[a-zA-Z][^<>]*>"


def _visible_len(line: str) -> int:
    import re

    return len(re.sub(_TAG, "", line))


def wrap_title(fig: go.Figure, width: int = 105) -> go.Figure:
    """Break a long title into lines of at most ``width`` characters and anchor it at the top of the figure; Markdown
    code marks (backticks, which Plotly shows as they are) are dropped.

    Static exports do not wrap titles. Each ``<br>``-separated part is wrapped
    on its own; the title is pinned to the top of the figure (``yanchor="top"``)
    and the top margin grows to hold every line plus, when the figure has subplot
    titles, their row, so the title never overlaps them.
    """
    import re
    import textwrap

    text = plain_text(fig.layout.title.text)  # no literal Markdown backticks in a title
    if not text:
        return fig
    # never wider than the figure itself (tables set their own, narrower width)
    width = min(width, int(((fig.layout.width or EXPORT_WIDTH_PX) - 40) / TITLE_CHAR_PX))
    lines = []
    for part in text.split("<br>"):
        tagged = re.search(_TAG, part) is not None  # a <sup> subtitle stays one line
        lines += [part] if _visible_len(part) <= width or tagged else textwrap.wrap(part, width)
    subplot_titles = any(getattr(a, "yref", None) == "paper" and (a.y or 0) >= 0.99 and a.yanchor == "bottom"
                         for a in fig.layout.annotations)
    # plotly places a multi-line title anchored at the top a little higher per extra line (the first line was
    # cut off at the image's top edge in PNG exports): the pad grows with the lines (measured on kaleido's output)
    pad = 12 + 6 * (len(lines) - 1)
    need = pad + TITLE_LINE_PX * len(lines) + (SUBPLOT_TITLE_PX if subplot_titles else 6)
    top = max(fig.layout.margin.t or 0, need)
    grow = top - (fig.layout.margin.t if fig.layout.margin.t is not None else 100)
    fig.update_layout(title=dict(text="<br>".join(lines), y=1, yref="container", yanchor="top", pad=dict(t=pad)),
                      margin=dict(t=top))
    if fig.layout.height and grow > 0:
        fig.update_layout(height=fig.layout.height + grow)
    return fig


def strain_lines(series: Mapping[str, Sequence[float]], *, title: str, height: int = 440) -> go.Figure:
    """One line per series over the 24 regions (chapter Figs 9.5 and 9.10 style).

    Parameters
    ----------
    series : dict label -> (24,) or (25,) array
        Circumferential Green strains (-); a 25-vector's first entry (LVV) is dropped.
    """
    fig = go.Figure()
    x = np.arange(1, N_REGIONS + 1)
    for n, (label, values) in enumerate(series.items()):
        fig.add_scatter(x=x, y=_strains24(values), mode="lines+markers", name=label,
                        line=dict(color=SERIES_COLOURS[n % len(SERIES_COLOURS)]))
    fig.update_layout(title=title, height=height, yaxis_title="E_cc (-)",
                      xaxis=dict(title="region", tickvals=x, ticktext=list(REGION_TICKS), tickangle=-60),
                      legend=dict(orientation="h", y=-0.45), margin=dict(l=50, r=20, t=60, b=10))
    return fig


def eta_band_grid(cases: Sequence[Mapping], models: Sequence[str], *, title: str, height: int = 720) -> go.Figure:
    """Posterior 5–95 % bands and medians of eta's 24 strains against the benchmark (chapter Fig 9.8).

    Parameters
    ----------
    cases : sequence of dict
        Each with ``title`` (str), ``benchmark`` ((25,) eta(θ̃, h)) and
        ``bands`` {model: {"q05", "q50", "q95"} each (25,)}.
    models : sequence of str
        Row order (one row per likelihood model).
    """
    fig = make_subplots(rows=len(models), cols=len(cases), shared_xaxes=True, shared_yaxes=True,
                        subplot_titles=[c["title"] for c in cases] + [""] * (len(cases) * (len(models) - 1)),
                        vertical_spacing=0.05, horizontal_spacing=0.03)
    x = np.arange(1, N_REGIONS + 1)
    for i, m in enumerate(models):
        colour = SERIES_COLOURS[i % len(SERIES_COLOURS)]
        for j, c in enumerate(cases):
            b = c["bands"][m]
            q05, q50, q95 = (_strains24(b[k]) for k in ("q05", "q50", "q95"))
            first = j == 0
            fig.add_scatter(x=np.r_[x, x[::-1]], y=np.r_[q95, q05[::-1]], fill="toself", mode="lines",
                            line=dict(width=0), fillcolor=colour, opacity=0.3, name=f"{m} 5–95 %",
                            legendgroup=m, showlegend=first, row=i + 1, col=j + 1)
            fig.add_scatter(x=x, y=q50, mode="lines", line=dict(color=colour), name=f"{m} median",
                            legendgroup=m, showlegend=first, row=i + 1, col=j + 1)
            fig.add_scatter(x=x, y=_strains24(c["benchmark"]), mode="lines", line=dict(color="black", dash="dash"),
                            name="benchmark η(θ̃, h)", legendgroup="bench", showlegend=i == 0 and first,
                            row=i + 1, col=j + 1)
    fig.update_xaxes(title_text="region r + 1", row=len(models))
    for i, m in enumerate(models):
        fig.update_yaxes(title_text=f"{m}<br>E_cc (-)", row=i + 1, col=1)
    fig.update_layout(title=title, height=height, margin=dict(l=70, r=20, t=90, b=130), font=dict(size=11),
                      legend=dict(orientation="h", y=-0.12, yanchor="top"))
    return fig


#: Pixels per character and padding of table columns (plotly's default 12 px table font).
TABLE_CHAR_PX, TABLE_PAD_PX = 7.5, 16
#: A table wider than TABLE_MAX_WIDTH_PX wraps its longest cells (at spaces) onto more lines, never narrower than
#: TABLE_MIN_WRAP characters a line; each extra line adds TABLE_LINE_PX to its row (issue 49: the findings
#: table was 2,986 px wide, its text unreadable once the image was scaled to a page).
TABLE_MAX_WIDTH_PX, TABLE_MIN_WRAP, TABLE_LINE_PX = EXPORT_WIDTH_PX, 24, 17


def _wrap_limit(longest: Sequence[int]) -> int | None:
    """Characters a line so the columns fit TABLE_MAX_WIDTH_PX (None: no wrapping needed); long columns shrink first."""
    budget = (TABLE_MAX_WIDTH_PX - 40 - TABLE_PAD_PX * len(longest)) / TABLE_CHAR_PX
    if sum(longest) <= budget:
        return None
    for limit in range(max(longest), TABLE_MIN_WRAP - 1, -1):
        if sum(min(n, limit) for n in longest) <= budget:
            return limit
    return TABLE_MIN_WRAP


def _wrap_cell(text: str, limit: int | None) -> list[str]:
    import re
    import textwrap

    if limit is None or len(text) <= limit or re.search(_TAG, text):
        return [text]
    return textwrap.wrap(text, limit, break_long_words=False, break_on_hyphens=False) or [text]


def table_figure(df: pd.DataFrame, *, title: str, float_format: str = ".4g", height: int | None = None,
                 bold: Sequence[tuple[int, str]] = ()) -> go.Figure:
    """A DataFrame drawn as a plotly table (for PNG/SVG export of the chapter's tables).

    Each column is as wide as its longest line (``columnwidth`` in pixels) and
    ``layout.width`` is the sum, so nothing is clipped on the right: the static
    export uses that width, and the HTML figure scrolls sideways. A table that
    would be wider than :data:`TABLE_MAX_WIDTH_PX` wraps its longest cells onto
    several lines (``<br>``) instead, and its rows grow to hold them.

    Parameters
    ----------
    bold : sequence of (row index, column name)
        Cells shown in bold (e.g. Table 9.4's first k beating both operators).
    """
    def fmt(v):
        if isinstance(v, (float, np.floating)):
            return "" if not np.isfinite(v) else format(float(v), float_format)
        return "" if v is None else str(v)

    bold = set(bold)
    texts = {col: [fmt(v) for v in df[col].tolist()] for col in df.columns}
    limit = _wrap_limit([max([len(str(col)) + 1] + [len(t) + 1 for t in texts[col]]) for col in df.columns])
    cells, widths, headers = [], [], []
    row_lines, header_lines = [1] * len(df), 1
    for col in df.columns:
        head = _wrap_cell(str(col), limit)
        header_lines = max(header_lines, len(head))
        headers.append("<br>".join(f"<b>{h}</b>" for h in head))
        column, longest = [], max(len(h) + 1 for h in head)
        for r, t in enumerate(texts[col]):
            lines = _wrap_cell(t, limit)
            row_lines[r] = max(row_lines[r], len(lines))
            extra = 1 if (r, col) in bold else 0
            longest = max([longest] + [len(x) + extra for x in lines])
            column.append("<br>".join(f"<b>{x}</b>" if extra else x for x in lines))
        cells.append(column)
        widths.append(int(np.ceil(TABLE_PAD_PX + TABLE_CHAR_PX * longest)))
    fig = go.Figure(go.Table(columnwidth=widths,
                             header=dict(values=headers, fill_color="#e8ecf4",
                                         font=dict(color="#2a3f5f"), align="center", line_color="#c8d0e0"),
                             cells=dict(values=cells, align="center", height=26, fill_color="white",
                                        font=dict(color="#2a3f5f"), line_color="#d8dee9")))
    extra_lines = header_lines - 1 + sum(n - 1 for n in row_lines)
    fig.update_layout(title=title, height=height or 110 + 32 * (len(df) + 1) + TABLE_LINE_PX * extra_lines,
                      width=max(700, sum(widths) + 40), margin=dict(l=10, r=10, t=60, b=10))
    return fig


def _panel_column(df: pd.DataFrame, panel: str, panel_label: str | None) -> tuple[list, go.Figure]:
    """The values of ``df[panel]`` (first appearance) and a figure of one subplot row per value, titled
    "<panel_label>: <value>" (default label: the column name with spaces)."""
    panels = list(dict.fromkeys(df[panel]))
    label = panel_label or panel.replace("_", " ")
    fig = make_subplots(rows=len(panels), cols=1, subplot_titles=[f"{label}: {p}" for p in panels],
                        vertical_spacing=0.12)
    return panels, fig


def _panels_layout(fig: go.Figure, title: str, n_panels: int, height_per_panel: int) -> go.Figure:
    """Title, height (``height_per_panel`` px a panel, at least 360) and margins of a figure of stacked panels."""
    fig.update_layout(title=title, height=max(360, height_per_panel * n_panels), margin=dict(l=50, r=20, t=70, b=30))
    return fig


def grouped_violins(df: pd.DataFrame, *, panel: str, x: str, y: str, title: str, yaxis_title: str,
                    order: Sequence[str] | None = None, height_per_panel: int = 300, panel_label: str | None = None,
                    nonnegative: bool = False) -> go.Figure:
    """Violins of ``df[y]`` by ``df[x]``, one panel per value of ``df[panel]`` (chapter Figs 9.11 and 9.14).

    Parameters
    ----------
    df : DataFrame in long form
    panel, x, y : str
        Column names: the panel (e.g. main operator), the violin category (e.g. test geometry) and the value.
    order : sequence of str, optional
        Order of the x categories (default: first appearance).
    panel_label : str, optional
        Subplot titles read "<panel_label>: <value>" (default: the column name with spaces).
    nonnegative : bool
        The quantity cannot be negative (an error's size, an RMSE, a distance): the
        violins end at the data (``spanmode="hard"``) and the axis starts at 0.
    """
    panels, fig = _panel_column(df, panel, panel_label)
    cats = list(order) if order is not None else list(dict.fromkeys(df[x]))
    for i, p in enumerate(panels):
        sub = df[df[panel] == p]
        for k, c in enumerate(cats):
            vals = sub.loc[sub[x] == c, y].to_numpy(dtype=float)
            if vals.size == 0:
                continue
            fig.add_violin(y=vals, name=str(c), box_visible=True, meanline_visible=True, points="all",
                           spanmode="hard" if nonnegative else "soft",
                           line_color=SERIES_COLOURS[k % len(SERIES_COLOURS)], showlegend=False, row=i + 1, col=1)
        fig.update_yaxes(title_text=yaxis_title, rangemode="nonnegative" if nonnegative else "normal", row=i + 1,
                         col=1)
        fig.update_xaxes(title_text=x.replace("_", " "), row=i + 1, col=1)
    return _panels_layout(fig, title, len(panels), height_per_panel)


def error_strips(df: pd.DataFrame, *, panel: str, param: str, x: str, y: str, title: str, yaxis_title: str,
                 height_per_panel: int = 300, panel_label: str | None = None) -> go.Figure:
    """Per-case markers and median ticks of errors by parameter and test geometry (chapter Fig 9.12).

    One panel per ``df[panel]``; within a panel the x axis is ``param`` × ``x``
    (e.g. a: op2, op3, pc5, pc10; b: ...), every case a small marker and the
    median a wide tick.
    """
    panels, fig = _panel_column(df, panel, panel_label)
    params = list(dict.fromkeys(df[param]))
    cats = list(dict.fromkeys(df[x]))
    for i, p in enumerate(panels):
        sub = df[df[panel] == p]
        for k, c in enumerate(cats):
            colour = SERIES_COLOURS[k % len(SERIES_COLOURS)]
            px, py, mx, my = ([], []), [], ([], []), []
            for q in params:
                vals = sub.loc[(sub[x] == c) & (sub[param] == q), y].to_numpy(dtype=float)
                px[0].extend([q] * vals.size)
                px[1].extend([str(c)] * vals.size)
                py.extend(vals.tolist())
                if vals.size:
                    mx[0].append(q)
                    mx[1].append(str(c))
                    my.append(float(np.median(vals)))
            fig.add_scatter(x=[list(px[0]), list(px[1])], y=py, mode="markers", name=str(c),
                            marker=dict(symbol="line-ew-open", size=10, color=colour), legendgroup=str(c),
                            showlegend=i == 0, row=i + 1, col=1)
            fig.add_scatter(x=[list(mx[0]), list(mx[1])], y=my, mode="markers",
                            marker=dict(symbol="line-ew-open", size=26, color=colour, line=dict(width=3)),
                            name=f"{c} median", legendgroup=str(c), showlegend=False, row=i + 1, col=1)
        fig.update_yaxes(title_text=yaxis_title, rangemode="nonnegative", row=i + 1, col=1)
        fig.update_xaxes(title_text=f"{param} / {x.replace('_', ' ')}", row=i + 1, col=1)
    return _panels_layout(fig, title, len(panels), height_per_panel)


def posterior_prior_figure(draws: Mapping[str, Sequence[float]], bounds: Mapping[str, tuple[float, float]], *,
                           truth: Mapping[str, float] | None = None, units: Mapping[str, str] | None = None,
                           title: str, bins: int = 40, height: int = 360) -> go.Figure:
    """Posterior histograms (density) of each parameter with the uniform prior overlaid and the truth marked.

    Parameters
    ----------
    draws : dict name -> 1-D array of posterior draws
    bounds : dict name -> (lo, hi)
        Uniform prior bounds; the prior density 1/(hi - lo) is drawn over them.
    truth : dict name -> float, optional
        The generating value of a SYNTHETIC subject (red dashed line).
    """
    from lvcore.viz.inference_figures import display_name

    names = list(draws)
    units = units or {}
    fig = make_subplots(rows=1, cols=len(names),
                        subplot_titles=[f"{display_name(n)} ({units.get(n, '-')})" for n in names],
                        horizontal_spacing=0.05)
    for j, n in enumerate(names):
        d = np.asarray(draws[n], dtype=float).ravel()
        lo, hi = bounds[n]
        fig.add_histogram(x=d, histnorm="probability density", nbinsx=bins, marker_color=SERIES_COLOURS[0],
                          opacity=0.75, name="posterior", legendgroup="post", showlegend=j == 0, row=1, col=j + 1)
        fig.add_scatter(x=[lo, lo, hi, hi], y=[0, 1.0 / (hi - lo), 1.0 / (hi - lo), 0], mode="lines",
                        line=dict(color="grey", dash="dot"), name="prior (uniform)", legendgroup="prior",
                        showlegend=j == 0, row=1, col=j + 1)
        if truth and n in truth:
            fig.add_vline(x=float(truth[n]), line=dict(color="red", dash="dash", width=2), row=1, col=j + 1)
        fig.update_xaxes(range=[lo, hi], title_text=f"{display_name(n)} ({units.get(n, '-')})", row=1,
                         col=j + 1)
    if truth:
        fig.add_scatter(x=[None], y=[None], mode="lines", line=dict(color="red", dash="dash"), name="truth (SYNTHETIC)")
    fig.update_yaxes(title_text="density", col=1)
    fig.update_layout(title=plain_text(title), height=height, bargap=0.02, margin=dict(l=50, r=20, t=80, b=40),
                      legend=dict(orientation="h", y=-0.2))
    return fig


def interval_figure(rows: Sequence[Mapping], *, truth: float | None, title: str, xaxis_title: str,
                    yaxis_title: str = "test set", height: int = 420) -> go.Figure:
    """Median and 5–95 % interval per (label, series) row, e.g. σ_S per test set and model (Fig 9.7 summary).

    ``rows``: dicts with ``label``, ``series``, ``median``, ``q05``, ``q95``.
    """
    fig = go.Figure()
    series = list(dict.fromkeys(r["series"] for r in rows))
    for k, s in enumerate(series):
        rs = [r for r in rows if r["series"] == s]
        med = np.array([r["median"] for r in rs])
        fig.add_scatter(x=med, y=[r["label"] for r in rs], mode="markers", name=s,
                        marker=dict(color=SERIES_COLOURS[k % len(SERIES_COLOURS)], size=8),
                        error_x=dict(type="data", symmetric=False, array=np.array([r["q95"] for r in rs]) - med,
                                     arrayminus=med - np.array([r["q05"] for r in rs])))
    if truth is not None:
        fig.add_vline(x=truth, line=dict(color="black", dash="dash"), annotation_text="truth")
    fig.update_layout(title=title, xaxis_title=xaxis_title, yaxis_title=yaxis_title, height=height,
                      margin=dict(l=10, r=20, t=60, b=40))
    return fig


__all__ = ["wrap_title", "strain_lines", "eta_band_grid", "table_figure", "grouped_violins", "error_strips",
           "posterior_prior_figure", "interval_figure", "REGION_TICKS"]
