"""The end-diastolic pressure–volume relation (EDPVR) by the FE simulator, and a shape's reference volume.

The relations it is compared with (Klotz et al. 2006, the typical EDV/V₀) are
pure functions in :mod:`lvcore.physiology`; this module runs the simulator
(one warm-started solve per pressure and θ draw), so it sits in the mechanics
layer above them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from lvcore import conditions, units
from lvcore.exceptions import LVCoreError
from lvcore.mechanics.case import Case
from lvcore.mechanics.simulate import prepare_case, simulate
from lvcore.physiology import EDPVR_PRESSURES_MMHG


def pca_reference_volume_ml(scores: Sequence[float], resolution: str = "default") -> float:
    """Reference (stress-free) cavity volume V₀ (mL) of the bundled shape model's LV with PC ``scores``,
    as the simulator meshes it at ``resolution``."""
    case = Case.from_dict({"geometry": {"kind": "pca", "scores": [float(s) for s in scores], "resolution": resolution},
                           "material": {"law": "holzapfel-ogden", **conditions.THETA_TILDE},
                           "load": {"pressure": 8, "units": "mmHg"}})
    return float(prepare_case(case).v_ref) / units.MM3_PER_ML


@dataclass(frozen=True)
class EDPVR:
    """Simulated pressure–volume curves: ``volumes_ml[k, j]`` of draw k at ``pressures_mmhg[j]``; NaN where the
    solve failed (counted in ``n_failed``). ``v0_ml`` is the reference cavity (the curve's 0 mmHg point)."""

    pressures_mmhg: np.ndarray
    volumes_ml: np.ndarray
    v0_ml: float
    n_failed: int
    resolution: str

    def band(self, q=(0.05, 0.5, 0.95)) -> np.ndarray:
        """Quantiles over the draws at each pressure, shape ``(len(q), n_pressures)`` (mL, NaN-aware)."""
        return np.nanquantile(self.volumes_ml, q, axis=0)


def simulate_edpvr(thetas: Sequence[Mapping[str, float]], geometry: Mapping, *,
                   angles: tuple[float, float] = conditions.SIMULATOR_DEFAULT_ANGLES,
                   pressures_mmhg: Sequence[float] = EDPVR_PRESSURES_MMHG, resolution: str = "fast",
                   progress=None) -> EDPVR:
    """EDPVR of each θ draw by the FE simulator: one solve per pressure, each warm-started from the previous.

    Parameters
    ----------
    thetas : θ draws, each ``{"a", "b", "af", "bf"}`` (kPa, –, kPa, –).
    geometry : the case's geometry section without ``resolution`` (e.g. ``{"kind": "pca", "scores": h}``).
    angles : fibre angles (α_endo, α_epi) in degrees.
    pressures_mmhg : increasing pressures (mmHg), > 0 and <= 30.
    resolution : mesh preset.
    progress : optional ``callable(done, total)``.
    """
    p = np.asarray(pressures_mmhg, dtype=float)
    if p.ndim != 1 or p.size == 0 or np.any(np.diff(p) <= 0) or p[0] <= 0 or p[-1] > 30.0:
        raise ValueError("pressures_mmhg must increase, within (0, 30] mmHg")
    vols = np.full((len(thetas), p.size), np.nan)
    v0 = None
    failed = 0
    for k, theta in enumerate(thetas):
        warm = None
        for j, pj in enumerate(p):
            case = Case.from_dict({"geometry": {**dict(geometry), "resolution": resolution},
                                   "material": {"law": "holzapfel-ogden", **{n: float(theta[n]) for n in
                                                                            ("a", "b", "af", "bf")}},
                                   "fibres": {"alpha_endo": float(angles[0]), "alpha_epi": float(angles[1])},
                                   "load": {"pressure": float(pj), "units": "mmHg"}})
            try:
                res = simulate(case, initial=warm)
            except LVCoreError:
                res = None
            if res is None or not res.converged:
                failed += p.size - j  # the rest of this curve is not attempted
                break
            warm = res.warm_state
            v0 = res.cavity_volume_mm3[0] / units.MM3_PER_ML
            vols[k, j] = res.cavity_volume_mm3[1] / units.MM3_PER_ML
            if progress is not None:
                progress(k * p.size + j + 1, len(thetas) * p.size)
    if v0 is None:
        raise ValueError("no EDPVR solve converged")
    return EDPVR(p, vols, float(v0), failed, resolution)


__all__ = ["pca_reference_volume_ml", "EDPVR", "simulate_edpvr"]
