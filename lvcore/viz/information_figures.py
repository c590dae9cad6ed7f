"""Figures of the information study (``lvcore study information``) from its saved result (plotly).

One figure kind: a per-subject value (a's 90 % interval width as q95/q05, or V30's 90 % width in mL) for each
variant of the study, one marker per SYNTHETIC subject and a bar at the median over subjects, with the study's two
parts (loaded states, cohorts) in panels side by side. The study module
(:func:`lvcore.studies.information.figures`) builds the rows from the result file and calls it.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from lvcore.viz.figures import SERIES_COLOURS

#: Horizontal spread of a variant's subject markers around its position (category units).
JITTER = 0.28


def _jitter(n: int) -> np.ndarray:
    """Evenly spread offsets of ``n`` markers in ``[-JITTER/2, JITTER/2]`` (0 for one marker)."""
    return np.zeros(n) if n < 2 else np.linspace(-JITTER / 2, JITTER / 2, n)


def per_variant_figure(rows: Sequence[dict], *, title: str, yaxis_title: str, panels: Sequence[str],
                       panel_titles: dict | None = None, log_y: bool = False, height: int = 500):
    """A value per subject and variant: a marker per subject, a bar at the median, one panel per part (plotly).

    Parameters
    ----------
    rows : sequence of dict
        One per subject and variant: ``panel`` (one of ``panels``), ``variant`` (its label on the x axis, in order of
        first appearance), ``series`` (the colour group, e.g. the prior or the method), ``subject`` and ``value``
        (rows whose value is None are left out).
    panels : sequence of str
        The panels in order; a panel without rows is left out.
    panel_titles : dict, optional
        Panel -> its title (default: the panel's name).
    log_y : bool
        A log y axis (all panels share it).
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    rows = [r for r in rows if r.get("value") is not None]
    names = [p for p in panels if any(r["panel"] == p for r in rows)] or [None]
    widths = [max(1, len({r["variant"] for r in rows if r["panel"] == p})) for p in names]
    fig = make_subplots(rows=1, cols=len(names), shared_yaxes=True, horizontal_spacing=0.06,
                        column_widths=[w / sum(widths) for w in widths],
                        subplot_titles=[(panel_titles or {}).get(p, p or "") for p in names])
    series = list(dict.fromkeys(r["series"] for r in rows))
    for c, panel in enumerate(names):
        sub = [r for r in rows if r["panel"] == panel]
        variants = list(dict.fromkeys(r["variant"] for r in sub))
        for k, s in enumerate(series):
            x, y, text = [], [], []
            for i, v in enumerate(variants):
                vr = [r for r in sub if r["variant"] == v and r["series"] == s]
                x += (i + _jitter(len(vr))).tolist()
                y += [float(r["value"]) for r in vr]
                text += [f"{r['subject']}<br>{v}" for r in vr]
            if x:
                colour = SERIES_COLOURS[k % len(SERIES_COLOURS)]
                fig.add_trace(go.Scatter(x=x, y=y, mode="markers", name=s, legendgroup=s,
                                         showlegend=s not in {t.name for t in fig.data},
                                         marker=dict(size=8, opacity=0.8, color=colour),
                                         text=text, hovertemplate="%{text}: %{y:.3g}<extra></extra>"),
                              row=1, col=c + 1)
        med = [float(np.median([r["value"] for r in sub if r["variant"] == v])) for v in variants]
        counts = [sum(r["variant"] == v for r in sub) for v in variants]
        fig.add_trace(go.Scatter(x=list(range(len(variants))), y=med, mode="markers", name="median over subjects",
                                 legendgroup="median", showlegend=c == 0,
                                 marker=dict(symbol="line-ew-open", size=34, color="black", line=dict(width=3)),
                                 text=[f"{v}: median of {n}" for v, n in zip(variants, counts)],
                                 hovertemplate="%{text}: %{y:.3g}<extra></extra>"), row=1, col=c + 1)
        fig.update_xaxes(tickmode="array", tickvals=list(range(len(variants))), ticktext=variants,
                         range=[-0.6, len(variants) - 0.4], tickangle=-30, title_text="variant", row=1, col=c + 1)
    fig.update_yaxes(title_text=yaxis_title, row=1, col=1)
    if log_y:
        fig.update_yaxes(type="log")
    else:
        fig.update_yaxes(rangemode="tozero")
    fig.update_layout(title=title, height=height, margin=dict(l=70, r=20, t=110, b=110),
                      legend=dict(orientation="h", y=-0.32, yanchor="top"))
    return fig


__all__ = ["JITTER", "per_variant_figure"]
