"""A shape's reference (stress-free) cavity volume V₀, as the simulator meshes it.

The simulated EDPVR of a posterior (warm-chained FE load paths over draws and
pressures) is :func:`lvcore.inference.derived.fe_load_path`; the relations it is
compared with (Klotz et al. 2006, the typical EDV/V₀) are pure functions in
:mod:`lvcore.domain.physiology`.
"""
from __future__ import annotations

from typing import Sequence

from lvcore.domain import conditions, units
from lvcore.mechanics.case import Case
from lvcore.mechanics.simulate import prepare_case


def pca_reference_volume_ml(scores: Sequence[float], resolution: str = "default") -> float:
    """Reference (stress-free) cavity volume V₀ (mL) of the bundled shape model's LV with PC ``scores``,
    as the simulator meshes it at ``resolution``."""
    case = Case.from_dict({"geometry": {"kind": "pca", "scores": [float(s) for s in scores], "resolution": resolution},
                           "material": {"law": "holzapfel-ogden", **conditions.THETA_TILDE},
                           "load": {"pressure": 8, "units": "mmHg"}})
    return float(prepare_case(case).v_ref) / units.MM3_PER_ML


__all__ = ["pca_reference_volume_ml"]
