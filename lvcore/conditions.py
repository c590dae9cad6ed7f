"""The conditions of simulations and of the chapter's studies, each named once.

Two sets of fibre angles and EDPs are easy to confuse, so they are named apart:

* the **simulator's defaults** (:data:`SIMULATOR_DEFAULT_ANGLES`,
  :data:`SIMULATOR_DEFAULT_EDP_MMHG`): what a case file, the app's sliders
  and a calibration get when they do not say (the common rule-based helix
  angles, also the fixed angles of the chapter's Table 9.2);
* the **chapter's emulator conditions** (:data:`CHAPTER_ANGLES`,
  :data:`CHAPTER_EDP`): the angles and EDP at which the chapter's emulator
  was trained, the fixed inputs of the ``chapter`` campaign space and what
  :func:`lvcore.core.space.build_case` fills in.

The chapter's reference material point θ̃ and the noise levels of its
SYNTHETIC data sets live here too. Units: degrees, mmHg, kPa (a, af), mL.
"""
from __future__ import annotations

#: The simulator's default rule-based fibre helix angles (deg), endocardium and epicardium.
SIMULATOR_DEFAULT_ANGLES = (-60.0, 90.0)
#: The simulator's default end-diastolic pressure (mmHg).
SIMULATOR_DEFAULT_EDP_MMHG = 8.0

#: Fibre angles (deg) at which the chapter's emulator was trained.
CHAPTER_ANGLES = (-60.0, 60.0)
#: EDP (mmHg) at which the chapter's emulator was trained.
CHAPTER_EDP = 8.0

#: θ̃, the chapter's reference material point (kPa for a, af; b, bf dimensionless): the truth of the SYNTHETIC
#: studies and the app's starting point.
THETA_TILDE = {"a": 0.60, "b": 1.30, "af": 1.00, "bf": 3.60}
#: Strain noise standard deviation σ_S (-) of the SYNTHETIC data (the chapter's 0.03).
SIGMA_S = 0.03
#: Fixed LVV noise standard deviation σ_V (mL) of every calibration likelihood (chapter Table E.1).
SIGMA_V_ML = 5.0

__all__ = ["SIMULATOR_DEFAULT_ANGLES", "SIMULATOR_DEFAULT_EDP_MMHG", "CHAPTER_ANGLES", "CHAPTER_EDP", "THETA_TILDE",
           "SIGMA_S", "SIGMA_V_ML"]
