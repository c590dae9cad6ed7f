"""Units and unit conversions (the conditions of simulations and studies are in :mod:`lvcore.domain.conditions`).

Conventions used throughout :mod:`lvcore`:

* lengths in millimetres (mm), volumes in mm³ internally and millilitres (mL)
  at the interface (1 mL = 1000 mm³);
* stresses and stiffness parameters in kilopascals (kPa); exponents
  (b, b_f, ...) are dimensionless;
* pressures in kPa internally; mmHg accepted at the interface
  (1 mmHg = 0.133322 kPa);
* angles in degrees at the interface, radians internally.
"""
from __future__ import annotations

from lvcore._exports import moved_names

KPA_PER_MMHG = 0.1333223684
MM3_PER_ML = 1000.0

#: Material values are not units: the fixed Holzapfel–Ogden terms moved to :data:`lvcore.domain.conditions.HO_FIXED`.
__getattr__ = moved_names(__name__, {"HO_FIXED": "lvcore.domain.conditions:HO_FIXED"})


def mmhg_to_kpa(p_mmhg: float) -> float:
    """Convert a pressure from mmHg to kPa."""
    return float(p_mmhg) * KPA_PER_MMHG


def kpa_to_mmhg(p_kpa: float) -> float:
    """Convert a pressure from kPa to mmHg."""
    return float(p_kpa) / KPA_PER_MMHG


def mm3_to_ml(v_mm3: float) -> float:
    """Convert a volume from mm³ to mL."""
    return float(v_mm3) / MM3_PER_ML


def rms_mm_from_mse_cm2(mse_cm2: float) -> float:
    """Root-mean-square distance (mm) of a mean squared node distance given in cm² (10·√MSE)."""
    return 10.0 * float(mse_cm2) ** 0.5


def ml_to_mm3(v_ml: float) -> float:
    """Convert a volume from mL to mm³."""
    return float(v_ml) * MM3_PER_ML
