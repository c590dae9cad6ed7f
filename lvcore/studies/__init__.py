"""Reproductions of the chapter's studies (fibre angles, fibre discrepancy, geometry operators, fibre-angle BO, operator SQP refits)
and the simulation-based calibration of the calibration pipeline (``sbc``).

Each study is a submodule with a ``run``-style entry point and an ``lvcore
study`` sub-command; names are imported on first use.
"""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    "fibre_angles": "fibre_angles", "fibre_discrepancy": "fibre_discrepancy",
    "geometry_operators": "geometry_operators", "bo_fibres": "bo_fibres", "operators": "operators",
    "results": "results", "sbc": "sbc",
    "angle_sweep": "fibre_angles", "angle_map": "fibre_angles", "emulator_angle_map": "fibre_angles",
    "operator_table": "geometry_operators",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
