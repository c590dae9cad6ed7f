"""Plotly figure builders shared by the app pages and reports.

Every builder is a pure function of plain arrays and returns a
``plotly.graph_objects.Figure``; nothing here runs a simulation or reads
files. Strain figures follow :mod:`lvcore.domain.outputs`: region
``r = 6 * level + sector`` (level 0 basal ... 3 apical; sector 0 spans
0°–60° counter-clockwise from +x seen from the base).
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import plotly.graph_objects as go

from lvcore.geometry.template import N_LEVELS, N_REGIONS, N_SECTORS
from lvcore.domain.outputs import LEVEL_NAMES, STRAIN_NAMES, strain_vector, strains_by_level

#: Sector labels: "S1 (0–60°)" ... "S6 (300–360°)".
SECTOR_NAMES = tuple(f"S{k + 1} ({60 * k}–{60 * (k + 1)}°)" for k in range(N_SECTORS))
#: Two-line sector tick labels for plots.
#: Sector tick labels: the name over the angular range, each on its own line (one line ran together at the width of a
#: half-page column: "60–120°120–180°…"); the unit (°) is in the axis title.
_SECTOR_TICKS = tuple(f"S{k + 1}<br>{60 * k}–<br>{60 * (k + 1)}" for k in range(N_SECTORS))
#: The colour bar's title beside the bar, read bottom to top (above the bar it overlapped the top tick label).
_COLORBAR_ECC = {"title": {"text": "E_cc (-)", "side": "right"}}
#: Colour sequence for series (plotly's default qualitative palette).
SERIES_COLOURS = ("#636EFA", "#EF553B", "#00CC96", "#AB63FA", "#FFA15A", "#19D3F3", "#FF6692", "#B6E880")


def plain_text(text: str | None) -> str:
    """A figure text without Markdown code marks: Plotly shows a backtick as it is ("`chapter` emulator"), so
    ```x``` becomes x. Plotly's own tags (``<br>``, ``<sup>``) are kept."""
    import re

    return re.sub(r"`+([^`]*)`+", r"\1", text or "")


def strain_heatmap(strains, *, title: str = "Circumferential strain E_cc", zmin: float | None = None,
                   zmax: float | None = None, colorscale: str = "RdBu", text_format: str = ".3f",
                   height: int = 360) -> go.Figure:
    """Heat map of the 24 strains: 4 levels (rows, basal on top) × 6 sectors (columns).

    Parameters
    ----------
    strains : (24,) or (25,) array
        Regional strains (-), or a full output vector whose first entry (LVV) is dropped.
    zmin, zmax : float, optional
        Colour range; default symmetric about zero over the data.
    """
    grid = strains_by_level(strains)
    if zmin is None or zmax is None:
        m = float(np.nanmax(np.abs(grid))) or 1.0
        zmin = -m if zmin is None else zmin
        zmax = m if zmax is None else zmax
    names = np.asarray(STRAIN_NAMES).reshape(N_LEVELS, N_SECTORS)
    fig = go.Figure(
        go.Heatmap(
            z=grid, x=list(_SECTOR_TICKS), y=list(LEVEL_NAMES), zmin=zmin, zmax=zmax, colorscale=colorscale,
            xgap=2, ygap=2,
            customdata=names, texttemplate="%{z:" + text_format + "}",
            hovertemplate="%{customdata}<br>%{y}, %{x}<br>E_cc = %{z:.4f}<extra></extra>",
            colorbar=_COLORBAR_ECC,
        )
    )
    fig.update_yaxes(autorange="reversed", title="level (base → apex)")
    fig.update_xaxes(title="sector, degrees counter-clockwise from +x (seen from the base)", tickangle=0,
                     tickfont=dict(size=11))
    fig.update_layout(title=title, height=height, margin=dict(l=10, r=10, t=50, b=10))
    return fig


def strain_bars(series: Mapping[str, Sequence[float]] | Sequence[float], *, errors: Mapping[str, Sequence[float]] | None = None,
                title: str = "Circumferential strain by region", height: int = 420) -> go.Figure:
    """Grouped bars of the 24 strains, one subplot-like block per level.

    Parameters
    ----------
    series : dict label -> (24,) or (25,) array, or one array
        Several series (e.g. "measured", "simulated") are drawn side by side.
    errors : dict label -> (24,) array, optional
        Symmetric error bars (e.g. posterior predictive sd) per series.
    """
    if not isinstance(series, Mapping):
        series = {"strain": series}
    x = [[LEVEL_NAMES[r // N_SECTORS] for r in range(N_REGIONS)], [f"S{r % N_SECTORS + 1}" for r in range(N_REGIONS)]]
    fig = go.Figure()
    for n, (label, values) in enumerate(series.items()):
        y = strain_vector(values, f"series '{label}'")
        err = None
        if errors and label in errors:
            err = {"type": "data", "array": strain_vector(errors[label], f"errors '{label}'"), "visible": True}
        fig.add_bar(x=x, y=y, name=label, error_y=err, marker_color=SERIES_COLOURS[n % len(SERIES_COLOURS)],
                    customdata=np.asarray(STRAIN_NAMES), hovertemplate="%{customdata}: %{y:.4f}<extra>" + label + "</extra>")
    fig.update_layout(barmode="group", title=title, height=height, yaxis_title="E_cc (-)",
                      legend=dict(orientation="h", y=1.02, x=1, xanchor="right", yanchor="bottom"),
                      margin=dict(l=10, r=10, t=60, b=10))
    return fig


def strain_bullseye(strains, *, title: str = "Circumferential strain (bull's eye)", colorscale: str = "RdBu",
                    zmin: float | None = None, zmax: float | None = None, height: int = 420) -> go.Figure:
    """Bull's-eye plot: 4 rings (basal outside, apical inside) × 6 sectors.

    Sector k spans the polar angles [60k°, 60(k+1)°) counter-clockwise, as seen from the base.
    """
    grid = strains_by_level(strains)
    if zmin is None or zmax is None:
        m = float(np.nanmax(np.abs(grid))) or 1.0
        zmin = -m if zmin is None else zmin
        zmax = m if zmax is None else zmax
    level = np.repeat(np.arange(N_LEVELS), N_SECTORS)
    sector = np.tile(np.arange(N_SECTORS), N_LEVELS)
    fig = go.Figure(
        go.Barpolar(
            r=np.ones(N_REGIONS), base=(N_LEVELS - 1 - level).astype(float), theta=60.0 * sector + 30.0,
            width=np.full(N_REGIONS, 60.0), marker=dict(color=grid.ravel(), colorscale=colorscale, cmin=zmin,
                                                        cmax=zmax, colorbar=_COLORBAR_ECC,
                                                        line=dict(color="white", width=1)),
            customdata=np.stack([np.asarray(STRAIN_NAMES), grid.ravel()], axis=1),
            hovertemplate="%{customdata[0]}: %{customdata[1]:.4f}<extra></extra>",
        )
    )
    fig.update_layout(
        title=title, height=height, margin=dict(l=20, r=20, t=50, b=20),
        polar=dict(radialaxis=dict(visible=False, range=[0, N_LEVELS]),
                   angularaxis=dict(direction="counterclockwise", rotation=0, tickvals=[0, 60, 120, 180, 240, 300])),
    )
    return fig


def violin(samples: Mapping[str, Sequence[float]], *, reference: Mapping[str, float] | None = None,
           title: str = "", yaxis_title: str = "", xaxis_title: str = "", log_y: bool = False, height: int = 420,
           nonnegative: bool = False) -> go.Figure:
    """Violins of several sample sets side by side, with optional reference markers.

    Parameters
    ----------
    samples : dict label -> 1-D array
        E.g. posterior draws per parameter or per likelihood model.
    reference : dict label -> value, optional
        Shown as a red dashed horizontal segment over the matching violin (e.g. the truth).
    nonnegative : bool
        The quantity cannot be negative (an absolute error, an RMSE, a distance): the
        violins end at the data (``spanmode="hard"``) instead of running past it below 0.
    """
    fig = go.Figure()
    labels = list(samples)
    for n, label in enumerate(labels):
        fig.add_violin(y=np.asarray(samples[label], dtype=float).ravel(), name=label, box_visible=True,
                       meanline_visible=True, points=False, line_color=SERIES_COLOURS[n % len(SERIES_COLOURS)],
                       spanmode="hard" if nonnegative else "soft")
    for label, value in (reference or {}).items():
        if label in samples:
            k = labels.index(label)
            fig.add_shape(type="line", x0=k - 0.4, x1=k + 0.4, y0=value, y1=value, xref="x", yref="y",
                          line=dict(color="red", dash="dash", width=2))
    if reference:
        fig.add_scatter(x=[None], y=[None], mode="lines", line=dict(color="red", dash="dash"), name="reference")
    fig.update_layout(title=title, yaxis_title=yaxis_title, xaxis_title=xaxis_title, height=height,
                      showlegend=bool(reference),
                      margin=dict(l=10, r=10, t=50, b=10))
    if log_y:
        fig.update_yaxes(type="log")
    elif nonnegative:
        fig.update_yaxes(rangemode="nonnegative")
    return fig


def decade_log_axis(values, min_decades: int = 2) -> dict:
    """Settings of a log axis over ``values`` with a labelled tick at every decade, at least ``min_decades`` of them.

    A log axis over data spanning less than a decade gets one tick label or none;
    this widens the range to whole decades (at least ``min_decades`` + 1 labels).
    Pass the result to ``fig.update_xaxes``/``update_yaxes``.
    """
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        return dict(type="log")
    lo, hi = np.floor(np.log10(v.min())), np.ceil(np.log10(v.max()))
    while hi - lo < min_decades:
        lo, hi = (lo - 1, hi) if (np.log10(v.min()) - lo) < (hi - np.log10(v.max())) else (lo, hi + 1)
    return dict(type="log", range=[float(lo), float(hi)], dtick=1, tickformat="~g",
                minor=dict(showgrid=True, ticks="", dtick="D1"))


def density_overlay(samples: Mapping[str, Sequence[float]], *, reference: float | Mapping[str, float] | None = None,
                    title: str = "", xaxis_title: str = "", n_grid: int = 200, x_range: tuple[float, float] | None = None,
                    height: int = 360) -> go.Figure:
    """Kernel density estimates of several sample sets on one axis, with dashed reference lines.

    Parameters
    ----------
    samples : dict label -> 1-D array
    reference : float or dict label -> float, optional
        Vertical dashed line(s), e.g. the true value.
    x_range : (lo, hi), optional
        Grid of the densities; default the pooled sample range padded by 10 %.
    """
    from scipy.stats import gaussian_kde

    arrays = {k: np.asarray(v, dtype=float).ravel() for k, v in samples.items()}
    pooled = np.concatenate([a[np.isfinite(a)] for a in arrays.values()]) if arrays else np.zeros(1)
    if x_range is None:
        lo, hi = float(pooled.min()), float(pooled.max())
        pad = 0.1 * (hi - lo) if hi > lo else 1.0
        x_range = (lo - pad, hi + pad)
    xs = np.linspace(x_range[0], x_range[1], n_grid)
    fig = go.Figure()
    for n, (label, a) in enumerate(arrays.items()):
        a = a[np.isfinite(a)]
        colour = SERIES_COLOURS[n % len(SERIES_COLOURS)]
        if a.size >= 2 and np.ptp(a) > 0:
            fig.add_scatter(x=xs, y=gaussian_kde(a)(xs), mode="lines", name=label, line=dict(color=colour))
        elif a.size:  # a point mass: show as a vertical line
            fig.add_vline(x=float(a[0]), line=dict(color=colour))
    refs = reference if isinstance(reference, Mapping) else ({} if reference is None else {"reference": reference})
    for label, value in refs.items():
        fig.add_vline(x=float(value), line=dict(color="black", dash="dash"), annotation_text=str(label),
                      annotation_position="top")
    fig.update_layout(title=title, xaxis_title=xaxis_title, yaxis_title="density", height=height,
                      margin=dict(l=10, r=10, t=50, b=10))
    return fig


def _grid(x, y, *zs):
    """``x``, ``y`` and each ``z`` as float arrays; every ``z`` must be ``(len(y), len(x))`` (``z[j, i]`` at
    ``(x[i], y[j])``)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    out = [np.asarray(z, dtype=float) for z in zs]
    for z in out:
        if z.shape != (y.size, x.size):
            raise ValueError(f"z must have shape (len(y), len(x)) = {(y.size, x.size)}, got {z.shape}")
    return (x, y, *out)


def contour(x, y, z, *, title: str = "", xaxis_title: str = "", yaxis_title: str = "", colorbar_title: str = "",
            points: Mapping[str, tuple[Sequence[float], Sequence[float]]] | None = None, log_x: bool = False,
            log_y: bool = False, colorscale: str = "Viridis", height: int = 420) -> go.Figure:
    """Filled contour plot of ``z[j, i]`` over the grid ``x[i]``, ``y[j]``, with optional point overlays.

    Parameters
    ----------
    x : (nx,) array; y : (ny,) array; z : (ny, nx) array
    points : dict label -> (xs, ys), optional
        Scatter overlays (e.g. design points, the optimum, the truth).
    """
    x, y, z = _grid(x, y, z)
    fig = go.Figure(go.Contour(x=x, y=y, z=z, colorscale=colorscale, colorbar={"title": colorbar_title},
                               contours=dict(showlabels=True)))
    symbols = ("x", "star", "circle", "diamond", "cross", "triangle-up")
    for n, (label, (px, py)) in enumerate((points or {}).items()):
        fig.add_scatter(x=np.asarray(px, float), y=np.asarray(py, float), mode="markers", name=label,
                        marker=dict(symbol=symbols[n % len(symbols)], size=10, color="white",
                                    line=dict(color="black", width=1)))
    fig.update_layout(title=plain_text(title), xaxis_title=xaxis_title, yaxis_title=yaxis_title, height=height,
                      margin=dict(l=10, r=10, t=50, b=10), legend=dict(orientation="h", y=-0.2))
    if log_x:
        fig.update_xaxes(type="log")
    if log_y:
        fig.update_yaxes(type="log")
    return fig


def map_pair(x, y, z_left, z_right, *, titles: tuple[str, str] = ("", ""), colorbar_titles: tuple[str, str] = ("", ""),
             xaxis_title: str = "", yaxis_title: str = "", colorscales: tuple[str, str] = ("Viridis", "Viridis"),
             height: int = 420) -> go.Figure:
    """Two maps over the same grid side by side in ONE figure (heat maps, smoothed in the browser).

    Made for live redraws (the Fibre-angles page's emulator map): one figure
    and two image-like heat-map traces cost the browser far less per redraw
    than two labelled :func:`contour` figures (the contour lines and their
    labels are recomputed in JavaScript on every update).

    Parameters
    ----------
    x : (nx,) array; y : (ny,) array; z_left, z_right : (ny, nx) arrays
        ``z[j, i]`` at ``(x[i], y[j])``.
    """
    from plotly.subplots import make_subplots

    x, y, *zs = _grid(x, y, z_left, z_right)
    # the left map's colour bar sits in the gap between the maps; the shared y axis is titled once, on the left,
    # so the right map's axis title cannot run into that colour bar
    fig = make_subplots(rows=1, cols=2, subplot_titles=titles, horizontal_spacing=0.16)
    for k, z in enumerate(zs):
        fig.add_trace(go.Heatmap(x=x, y=y, z=z, zsmooth="fast", colorscale=colorscales[k],
                                 colorbar=dict(title=colorbar_titles[k], x=0.43 if k == 0 else 1.0, len=0.9,
                                               thickness=15),
                                 hovertemplate=f"{xaxis_title} %{{x:.3g}}<br>{yaxis_title} %{{y:.3g}}<br>"
                                               f"{titles[k]} %{{z:.4g}}<extra></extra>"), row=1, col=k + 1)
        fig.update_xaxes(title_text=xaxis_title, row=1, col=k + 1)
    fig.update_yaxes(title_text=yaxis_title, row=1, col=1)
    fig.update_layout(height=height, margin=dict(l=10, r=10, t=50, b=10))
    return fig


def derived_edpvr_figure(record: Mapping, *, title: str = "End-diastolic pressure–volume relation (EDPVR)",
                         subtitle: str = "", height: int = 480) -> go.Figure:
    """The EDPVR of a calibration's derived record (``lvcore.inference.derived.derive``) as one figure.

    The posterior 90 % band (q05 → q95) with its median from ``record["edpvr"]`` (0 mmHg is V₀, so the band
    starts at the derived reference cavity), the measured (EDV, EDP) with the 99 % posterior predictive interval
    of the FE volume at the EDP drawn as a horizontal error bar (``record["edpvr_check"]["predictive_99"]``),
    and the normal Klotz et al. (2006) curve through the derived V₀ and the measured point
    (``edpvr_check["klotz"]``).

    Traces: "posterior 90% band", "posterior median", "99% predictive interval at the EDP", "measured (EDV, EDP)",
    "Klotz et al. 2006 normal".
    """
    from lvcore.domain import physiology

    rows = [r for r in record["edpvr"] if r.get("median") is not None]
    p = np.array([r["pressure_mmhg"] for r in rows], float)
    lo, mid, hi = (np.array([r[k] for r in rows], float) for k in ("q05", "median", "q95"))
    n = record.get("n_draws")
    fig = go.Figure()
    fig.add_trace(go.Scatter(x=np.concatenate([lo, hi[::-1]]), y=np.concatenate([p, p[::-1]]), fill="toself",
                             mode="lines", line=dict(width=0), fillcolor="rgba(99,110,250,0.25)",
                             name="posterior 90% band" + (f" ({n} draws)" if n else ""), hoverinfo="skip"))
    fig.add_trace(go.Scatter(x=mid, y=p, mode="lines+markers", line=dict(color=SERIES_COLOURS[0]),
                             name="posterior median",
                             hovertemplate="%{y:g} mmHg: %{x:.1f} mL<extra>posterior median</extra>"))
    check = record.get("edpvr_check") or {}
    if "measured_edv_ml" in check:
        edp, edv = float(check["edp_mmhg"]), float(check["measured_edv_ml"])
        plo, phi = (float(v) for v in check["predictive_99"])
        fig.add_trace(go.Scatter(x=[plo, phi], y=[edp, edp], mode="lines+markers",
                                 line=dict(color=SERIES_COLOURS[1], width=2),
                                 marker=dict(symbol="line-ns-open", size=14, color=SERIES_COLOURS[1]),
                                 name="99% predictive interval at the EDP",
                                 hovertemplate=f"99% predictive interval at {edp:g} mmHg: "
                                               f"{plo:.1f}–{phi:.1f} mL<extra></extra>"))
        fig.add_trace(go.Scatter(x=[edv], y=[edp], mode="markers", name="measured (EDV, EDP)",
                                 marker=dict(color=SERIES_COLOURS[1], size=12, symbol="x"),
                                 hovertemplate=f"measured: {edv:.1f} mL at {edp:g} mmHg<extra></extra>"))
    klotz = check.get("klotz")
    if klotz:
        pk = np.linspace(0.0, 30.0, 61)
        fig.add_trace(go.Scatter(x=physiology.klotz_volume(pk, klotz["v0_ml"], klotz["v30_ml"]), y=pk, mode="lines",
                                 line=dict(color="black", dash="dash"), name="Klotz et al. 2006 normal"))
    # the title and its subtitle above the plot, the legend below the axis title: nothing overlaps
    fig.update_layout(title=dict(text=title + (f"<br><sup>{subtitle}</sup>" if subtitle else ""), y=0.97,
                                 yanchor="top"),
                      height=height, xaxis_title="cavity volume (mL)", yaxis_title="pressure (mmHg)",
                      yaxis=dict(range=[0, 31]), margin=dict(t=70, b=40),
                      legend=dict(orientation="h", y=-0.18, yanchor="top", x=0, xanchor="left"))
    return fig
