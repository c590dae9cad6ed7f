"""Pictures and figures of LV geometries, operators and the shape model.

3-D pictures reuse :mod:`lvcore.viz.mesh3d` (off-screen PyVista, PNG bytes);
charts are plotly figures. No science here: inputs are node arrays on
:data:`~lvcore.geometry.template.DEFAULT_TEMPLATE` and the plain data of
:func:`lvcore.studies.geometry_operators.operator_table`.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import plotly.graph_objects as go

from lvcore.geometry.template import DEFAULT_TEMPLATE

#: Colours of up to three operators (and a fourth for reconstructions).
OPERATOR_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")


def node_distances(nodes_a, nodes_b) -> np.ndarray:
    """Per-node distance between two geometries on one template (mm)."""
    return np.linalg.norm(np.asarray(nodes_a, float) - np.asarray(nodes_b, float), axis=1)


def template_surface(nodes, field=None, *, n_phi: int = 96, n_s: int = 48, name: str = "field"):
    """Triangulated boundary (endocardium, epicardium, base ring) of a template geometry.

    The surface samples the isoparametric map itself (``DEFAULT_TEMPLATE.evaluate``)
    on an ``n_phi`` × ``n_s`` grid, so it follows the curved quadratic faces.
    ``field`` (n_nodes,) is interpolated with the same shape functions and
    attached as point data ``name``.
    """
    import pyvista as pv

    T = DEFAULT_TEMPLATE
    nodes = np.asarray(nodes, float)
    phi = np.linspace(0.0, 2 * np.pi, n_phi, endpoint=False)
    s = np.linspace(0.0, 1.0, n_s + 1)[:-1]
    pts, vals, tris = [], [], []
    f3 = None if field is None else np.repeat(np.asarray(field, float)[:, None], 3, axis=1)

    def add(P, S, Tt, closed_apex):
        off = sum(len(p) for p in pts)
        x = T.evaluate(nodes, P, S, Tt).reshape(-1, 3)
        v = None if f3 is None else T.evaluate(f3, P, S, Tt)[..., 0].ravel()
        if closed_apex:
            x = np.vstack([x, T.evaluate(nodes, 0.0, 1.0, Tt.flat[0]).reshape(1, 3)])
            if v is not None:
                v = np.r_[v, T.evaluate(f3, 0.0, 1.0, Tt.flat[0])[..., 0].ravel()]
        pts.append(x)
        if v is not None:
            vals.append(v)
        n_a, n_b = P.shape
        idx = off + np.arange(n_a * n_b).reshape(n_a, n_b)
        i1 = np.roll(idx, -1, axis=0)
        tris.append(np.stack([idx[:, :-1], i1[:, :-1], i1[:, 1:]], -1).reshape(-1, 3))
        tris.append(np.stack([idx[:, :-1], i1[:, 1:], idx[:, 1:]], -1).reshape(-1, 3))
        if closed_apex:
            tris.append(np.stack([idx[:, -1], i1[:, -1], np.full(n_a, off + n_a * n_b)], -1))

    P, S = np.meshgrid(phi, s, indexing="ij")
    add(P, S, np.zeros_like(P), True)  # endocardium
    add(P, S, np.ones_like(P), True)  # epicardium
    Pb, Tb = np.meshgrid(phi, np.linspace(0.0, 1.0, 5), indexing="ij")
    add(Pb, np.zeros_like(Pb), Tb, False)  # base ring
    tri = np.vstack(tris)
    poly = pv.PolyData(np.vstack(pts), np.hstack([np.full((len(tri), 1), 3), tri]).ravel())
    if vals:
        poly.point_data[name] = np.concatenate(vals)
    return poly.compute_normals(auto_orient_normals=False, split_vertices=False)


def render_overlay(geometries: Mapping[str, np.ndarray], *, view="iso", window_size=(700, 560), title=None,
                   colors: Sequence[str] = OPERATOR_COLORS) -> bytes:
    """Overlay of several geometries: curved element edges of each in its own colour (PNG bytes)."""
    from lvcore.viz.mesh3d import MeshLayer, element_edges, render_meshes

    layers = []
    for (label, nodes), color in zip(geometries.items(), colors):
        layers.append(MeshLayer(element_edges(nodes, DEFAULT_TEMPLATE.elements), color=color, style="wireframe",
                                label=label, line_width=2.0))
    first = next(iter(geometries.values()))
    layers.append(MeshLayer(template_surface(first), color="lightgrey", opacity=0.25))
    return render_meshes(layers, view=view, window_size=window_size, title=title)


def render_distance_map(nodes_a, nodes_b, *, label="distance (mm)", view="iso", window_size=(700, 560),
                        title=None, clim=None) -> bytes:
    """Geometry A coloured by the per-node distance to geometry B (PNG bytes)."""
    from lvcore.viz.mesh3d import MeshLayer, render_meshes

    d = node_distances(nodes_a, nodes_b)
    surf = template_surface(nodes_a, d, name=label)
    return render_meshes([MeshLayer(surf, scalars=label, label=label, cmap="magma",
                                    clim=clim or (0.0, max(float(d.max()), 1e-6)))],
                         view=view, window_size=window_size, title=title)


def render_shape(nodes, *, color="#c9a27e", view="side", window_size=(420, 420), title=None) -> bytes:
    """One geometry as a shaded surface (PNG bytes)."""
    from lvcore.viz.mesh3d import MeshLayer, render_meshes

    return render_meshes([MeshLayer(template_surface(nodes), color=color)],
                         view=view, window_size=window_size, title=title, legend=False)


def explained_variance_figure(explained_variance_ratio, k_max: int = 15, title="Explained variance (SYNTHETIC)"):
    """Bars of the per-mode explained variance and a line of the cumulative share."""
    evr = np.asarray(explained_variance_ratio)[:k_max]
    k = np.arange(1, evr.size + 1)
    fig = go.Figure()
    fig.add_bar(x=k, y=evr, name="per mode")
    fig.add_scatter(x=k, y=np.cumsum(evr), mode="lines+markers", name="cumulative")
    fig.update_layout(title=title, xaxis_title="mode k", yaxis_title="share of variance", yaxis_range=[0, 1.02],
                      height=360, margin=dict(l=40, r=20, t=50, b=40))
    return fig


def operator_mse_figure(table: Mapping, main: str, log_y: bool = True):
    """MSE of k-mode reconstructions against k for each patient, with the operators' MSE as dashed lines.

    ``table`` is :func:`lvcore.studies.geometry_operators.operator_table`'s output.
    """
    block = next(b for b in table["blocks"] if b["main"] == main)
    ks = list(table["ks"])
    fig = go.Figure()
    palette = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")
    others: list[str] = []
    for i, row in enumerate(block["rows"]):
        c = palette[i % len(palette)]
        name = row["patient"].replace("SYNTHETIC-", "")
        fig.add_scatter(x=ks, y=[row["pca_mse"][str(k)] for k in ks], mode="lines+markers", line=dict(color=c),
                        name=name, legendgroup=name)
        for j, (other, v) in enumerate(row["operator_mse"].items()):
            if other not in others:
                others.append(other)
            fig.add_scatter(x=[ks[0], ks[-1]], y=[v, v], mode="lines",
                            line=dict(color=c, dash="dash" if j == 0 else "dot"),
                            name=f"{name}: vs {other}", legendgroup=name, showlegend=False,
                            hovertemplate=f"{name} vs {other}: %{{y:.4f}} cm²<extra></extra>")
    # one legend entry per patient (colour) plus one per line style, not one per line
    fig.add_scatter(x=[None], y=[None], mode="lines", line=dict(color="grey"), name="solid: k-mode PCA")
    for j, other in enumerate(others[:2]):
        fig.add_scatter(x=[None], y=[None], mode="lines", line=dict(color="grey", dash="dash" if j == 0 else "dot"),
                        name=f"{'dashed' if j == 0 else 'dotted'}: vs {other}")
    fig.update_layout(title=f"Reconstruction error vs k; main operator {main} (SYNTHETIC)",
                      xaxis_title="number of PCA modes k", yaxis_title="mean squared node distance (cm²)",
                      height=460, margin=dict(l=50, r=20, t=50, b=40))
    if log_y:  # a labelled tick at every decade (0.001, 0.01, 0.1), at least two of them, minor grid between
        from lvcore.viz.figures import decade_log_axis

        values = [v for row in block["rows"] for v in [*row["pca_mse"].values(), *row["operator_mse"].values()]]
        fig.update_yaxes(**decade_log_axis(values))
    return fig
