"""LV geometries: analytic ellipsoids, the template mesh, fitting, the shape model and the cohort.

Names are imported from their submodules on first use.
"""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    "EllipsoidSurface": "analytic", "TruncatedEllipsoidLV": "analytic", "DEFAULT_LV": "analytic",
    "LAND_LV": "analytic",
    "LVTemplate": "template", "DEFAULT_TEMPLATE": "template", "N_LEVELS": "template", "N_SECTORS": "template",
    "N_REGIONS": "template",
    "read_template_mesh": "io", "write_template_mesh": "io", "write_vtu": "io",
    "cavity_volume": "measures", "node_mse_cm2": "measures", "geometry_info": "measures",
    "read_contours": "contours", "ContourStack": "contours",
    "read_surface": "surfaces",
    "fit_contours": "fitting", "fit_surfaces": "fitting", "FitResult": "fitting",
    "analyse_base": "base_plane", "BaseCut": "base_plane", "synthetic_surface_pair": "synthetic_surfaces",
    "fit_volume_mesh": "volume_mesh", "extract_lv_boundary": "volume_mesh", "VolumeMeshFit": "volume_mesh",
    "ellipsoid_tet_mesh": "meshing",
    "ShapeModel": "shape_model", "load_shape_model": "shape_model", "fit_shape_model": "shape_model",
    "Cohort": "cohort", "load_cohort": "cohort", "load_operator_geometries": "cohort",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
