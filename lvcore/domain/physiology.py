"""Physiology outputs: EDV/V₀ with its typical range, and the end-diastolic pressure–volume relation (EDPVR).

V₀ is the model's reference (stress-free, "early-diastolic") cavity volume; EDV the loaded
cavity volume at the end-diastolic pressure (EDP). The normal EDPVR is the one of
Klotz et al. (2006), "Single-beat estimation of end-diastolic pressure-volume relationship:
a novel method with potential for noninvasive application", Am J Physiol Heart Circ Physiol
291:H403–H412: with the normalised volume ``EDVn = (V − V0)/(V30 − V0)`` (V30 the volume at
30 mmHg), normal hearts of several species follow ``EDP = An · EDVn^Bn`` with An = 27.78 mmHg
and Bn = 2.76; the same paper estimates the zero-pressure volume from one measured point as
``V0 = EDV · (0.6 − 0.006 · EDP)`` (EDP in mmHg).

Typical EDV/V₀: ``1 / (0.6 − 0.006 · EDP)`` from that estimate (1.81 at 8 mmHg), with a band of
:data:`V0_FRACTION_TOLERANCE` on V₀/EDV around it. The band's width is this package's choice
(the paper gives the relation, not a population range), so it is a screening range, not a
diagnosis. All volumes in mL, pressures in mmHg.

Pure functions only: the simulated EDPVR of posterior draws is in :mod:`lvcore.inference.derived` and a
shape's reference volume in :mod:`lvcore.mechanics.edpvr` (they run the simulator, layers above this module).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


#: Klotz et al. (2006) normal EDPVR: EDP = KLOTZ_AN_MMHG * EDVn ** KLOTZ_BN.
KLOTZ_AN_MMHG = 27.78
KLOTZ_BN = 2.76
#: Klotz et al. (2006) single-beat estimate V0/EDV = KLOTZ_V0_INTERCEPT - KLOTZ_V0_SLOPE_PER_MMHG * EDP.
KLOTZ_V0_INTERCEPT = 0.6
KLOTZ_V0_SLOPE_PER_MMHG = 0.006
#: Half-width of the typical band on V0/EDV around the Klotz estimate (this package's choice, see the module text).
V0_FRACTION_TOLERANCE = 0.05
#: Relative tolerance of the "unusual EDV/V₀" note (:func:`edv_ratio_note`): the ratio's own numerical uncertainty.
#: The simulator's ``default`` mesh gives the 25 outputs within 1 % of the ``accurate`` mesh
#: (:mod:`lvcore.mechanics.resolution`; EDV and V₀ are both mesh volumes, and EDV/V₀ of the default LV moves by 0.07 %
#: from ``fast`` to ``default``), an emulator's LVV adds up to about 1 % more (its test error, below 1 mL on 150-190 mL),
#: and the ratio is shown to two decimals; together about 2 %. A ratio within 2 % of the band (e.g. 1.65 against
#: 1.66–1.99 at 8 mmHg) is therefore not called unusual; one further out is.
EDV_RATIO_NOTE_TOLERANCE = 0.02
#: Pressures (mmHg) at which the EDV/V₀ screening applies (passive filling of a living LV); outside it (e.g. the
#: Land et al. 2015 benchmark at 10 kPa = 75 mmHg) the ratio is a property of the test, not of physiology.
PHYSIOLOGICAL_EDP_RANGE_MMHG = (0.0, 30.0)
#: The EDPVR's pressure range (mmHg) and the default pressures of a simulated curve.
EDPVR_PRESSURES_MMHG = (2.0, 4.0, 6.0, 8.0, 12.0, 16.0, 20.0, 25.0, 30.0)


def klotz_edvn(edp_mmhg):
    """Normalised volume EDVn = (V − V0)/(V30 − V0) of the normal Klotz EDPVR at ``edp_mmhg`` (mmHg)."""
    p = np.asarray(edp_mmhg, dtype=float)
    if np.any(p < 0):
        raise ValueError("the Klotz EDPVR is defined for pressures >= 0 mmHg")
    return (p / KLOTZ_AN_MMHG) ** (1.0 / KLOTZ_BN)


def klotz_edp(edvn):
    """Pressure (mmHg) of the normal Klotz EDPVR at normalised volume ``edvn`` (EDP = An · EDVn^Bn)."""
    return KLOTZ_AN_MMHG * np.asarray(edvn, dtype=float) ** KLOTZ_BN


def klotz_volume(edp_mmhg, v0_ml: float, v30_ml: float):
    """Volume (mL) on the normal Klotz EDPVR through V0 (0 mmHg) and V30 (30 mmHg) at ``edp_mmhg``."""
    return float(v0_ml) + (float(v30_ml) - float(v0_ml)) * klotz_edvn(edp_mmhg)


def klotz_v30(edv_ml: float, edp_mmhg: float, v0_ml: float) -> float:
    """V30 (mL) of the normal Klotz curve through (V0, 0) and the point (EDV, EDP), EDP > 0."""
    if not edp_mmhg > 0:
        raise ValueError("a Klotz curve through one point needs EDP > 0 mmHg")
    return float(v0_ml) + (float(edv_ml) - float(v0_ml)) / float(klotz_edvn(edp_mmhg))


@dataclass(frozen=True)
class TypicalRange:
    """Typical EDV/V₀ at one EDP: ``low <= central <= high`` (dimensionless) and where it comes from."""

    edp_mmhg: float
    low: float
    central: float
    high: float
    source: str

    def text(self) -> str:
        return (f"typical EDV/V₀ at {self.edp_mmhg:g} mmHg: {self.low:.2f}–{self.high:.2f} (central {self.central:.2f}; "
                f"{self.source})")


def typical_edv_ratio(edp_mmhg: float) -> TypicalRange:
    """Typical EDV/V₀ at ``edp_mmhg`` (mmHg) from the Klotz et al. (2006) single-beat V0 estimate.

    Raises
    ------
    ValueError
        Outside :data:`PHYSIOLOGICAL_EDP_RANGE_MMHG`, where no typical value is claimed.
    """
    p = float(edp_mmhg)
    lo_p, hi_p = PHYSIOLOGICAL_EDP_RANGE_MMHG
    if not lo_p <= p <= hi_p:
        raise ValueError(f"no typical EDV/V₀ outside {lo_p:g}–{hi_p:g} mmHg (got {p:g} mmHg)")
    frac = KLOTZ_V0_INTERCEPT - KLOTZ_V0_SLOPE_PER_MMHG * p
    return TypicalRange(p, 1.0 / (frac + V0_FRACTION_TOLERANCE), 1.0 / frac, 1.0 / (frac - V0_FRACTION_TOLERANCE),
                        f"V₀/EDV = 0.6 − 0.006·EDP ± {V0_FRACTION_TOLERANCE:g}, Klotz et al. 2006")


def edv_ratio(edv_ml, v0_ml: float):
    """EDV/V₀ (dimensionless) of end-diastolic volume(s) ``edv_ml`` over the reference cavity ``v0_ml`` (mL)."""
    if not v0_ml > 0:
        raise ValueError(f"the reference cavity volume must be > 0 mL, got {v0_ml}")
    return np.asarray(edv_ml, dtype=float) / float(v0_ml)


def is_physiological_pressure(edp_mmhg: float | None) -> bool:
    """Whether ``edp_mmhg`` lies in :data:`PHYSIOLOGICAL_EDP_RANGE_MMHG` (``None``: unknown, False)."""
    lo, hi = PHYSIOLOGICAL_EDP_RANGE_MMHG
    return edp_mmhg is not None and lo < float(edp_mmhg) <= hi


def edv_ratio_note(ratio: float, edp_mmhg: float) -> str | None:
    """A sentence when EDV/V₀ is outside its typical range at ``edp_mmhg`` by more than the ratio's own uncertainty
    (:data:`EDV_RATIO_NOTE_TOLERANCE`, relative); ``None`` inside that or when the pressure is not physiological
    (see :func:`is_physiological_pressure`). Above the range the model inflates more than a normal LV (soft or
    thin-walled), below it less (stiff or thick-walled)."""
    if not is_physiological_pressure(edp_mmhg):
        return None
    rng = typical_edv_ratio(edp_mmhg)
    r = float(ratio)
    tol = EDV_RATIO_NOTE_TOLERANCE
    if rng.low / (1.0 + tol) <= r <= rng.high * (1.0 + tol):
        return None
    if r > rng.high:
        why = "a soft or thin-walled model inflates more than a normal LV"
        side = "above"
    else:
        why = "a stiff or thick-walled model inflates less than a normal LV"
        side = "below"
    return (f"unusual result: EDV/V₀ = {r:.2f} at {float(edp_mmhg):g} mmHg is {side} the "
            f"{rng.text()}, by more than the ratio's own {100 * tol:g} % uncertainty; the model's V₀ is its "
            f"stress-free reference cavity, so {why}")


@dataclass(frozen=True)
class PosteriorRatio:
    """Posterior of EDV/V₀: quantiles of the draws, the measured ratio and the typical range."""

    v0_ml: float
    q05: float
    median: float
    q95: float
    measured: float | None
    typical: TypicalRange


def posterior_edv_ratio(lvv_draws_ml, v0_ml: float, edp_mmhg: float,
                        measured_lvv_ml: float | None = None) -> PosteriorRatio:
    """EDV/V₀ of posterior draws of the model's LVV (mL; e.g. ``eta[..., 0]`` of a calibration), with the
    measured LVV's ratio and the typical range at ``edp_mmhg``."""
    r = edv_ratio(np.asarray(lvv_draws_ml, dtype=float).reshape(-1), v0_ml)
    q05, q50, q95 = np.quantile(r, [0.05, 0.5, 0.95])
    meas = None if measured_lvv_ml is None else float(edv_ratio(measured_lvv_ml, v0_ml))
    return PosteriorRatio(float(v0_ml), float(q05), float(q50), float(q95), meas, typical_edv_ratio(edp_mmhg))


__all__ = ["KLOTZ_AN_MMHG", "KLOTZ_BN", "V0_FRACTION_TOLERANCE", "EDV_RATIO_NOTE_TOLERANCE", "PHYSIOLOGICAL_EDP_RANGE_MMHG", "EDPVR_PRESSURES_MMHG",
           "klotz_edvn", "klotz_edp", "klotz_volume", "klotz_v30", "TypicalRange", "typical_edv_ratio", "edv_ratio",
           "is_physiological_pressure", "edv_ratio_note", "PosteriorRatio", "posterior_edv_ratio"]
