"""Reproductions of the chapter's studies (fibre angles, fibre discrepancy, geometry operators, the volunteer
calibration, fibre-angle BO, operator SQP refits, the mismatch dose-response, the findings with verdicts, realistic
operators, BO with a known mismatch), the simulation-based calibration of the calibration pipeline (``sbc``) and
what more loaded states, a population EDPVR prior and a cohort add to the stiffness (``information``).

Each study is a submodule listed in the one registry, :data:`lvcore.studies.registry.STUDIES` (its name, result
file, ``load``/``tables``/``figures`` and its ``lvcore study`` sub-command); this package exports every study module
of the registry, imported on first use.
"""
from __future__ import annotations

from lvcore._exports import lazy_exports
from lvcore.studies.registry import STUDIES

_EXPORTS = {
    **{s.module: s.module for s in STUDIES.values()},
    "registry": "registry", "results": "results",
    "angle_sweep": "fibre_angles", "angle_map": "fibre_angles", "emulator_angle_map": "fibre_angles",
    "operator_table": "geometry_operators",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
