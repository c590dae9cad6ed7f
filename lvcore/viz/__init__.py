"""Figures (Plotly) and 3-D renderings (PyVista) for the app and reports; pure functions of arrays.

Names are imported from their submodules on first use (Plotly and PyVista
load only when needed).
"""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    "strain_heatmap": "figures", "strain_bars": "figures", "strain_bullseye": "figures", "violin": "figures",
    "density_overlay": "figures", "contour": "figures", "SECTOR_NAMES": "figures",
    "trace_figure": "inference_figures", "rank_figure": "inference_figures", "pair_figure": "inference_figures",
    "diagnostics_table": "inference_figures", "predictive_density_figure": "inference_figures",
    "strain_predictive_figure": "inference_figures",
    "render_meshes": "mesh3d", "render_reference_and_deformed": "mesh3d", "png_bytes": "mesh3d",
    "render_shape": "geometry_views", "explained_variance_figure": "geometry_views",
    # modules, for the remaining builders
    "figures": "figures", "inference_figures": "inference_figures", "mesh3d": "mesh3d",
    "geometry_views": "geometry_views", "report_figures": "report_figures", "study_figures": "study_figures",
    "information_figures": "information_figures",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
