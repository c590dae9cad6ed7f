"""The conditions of simulations and of the chapter's studies, each named once.

Two sets of fibre angles and EDPs are easy to confuse, so they are named apart:

* the **simulator's defaults** (:data:`SIMULATOR_DEFAULT_ANGLES`,
  :data:`SIMULATOR_DEFAULT_EDP_MMHG`): what a case file, the app's sliders
  and a calibration get when they do not say (the common rule-based helix
  angles, also the fixed angles of the chapter's Table 9.2), and
  :data:`SIMULATOR_DEFAULT_THETA`, the stiffness of the bundled
  ``default_lv.json`` case and the Simulator page's starting point (a
  typical healthy LV, not the chapter's θ̃);
* the **chapter's emulator conditions** (:data:`CHAPTER_ANGLES`,
  :data:`CHAPTER_EDP`): the angles and EDP at which the chapter's emulator
  was trained, the fixed inputs of the ``chapter`` campaign space and what
  :func:`lvcore.mechanics.case_inputs.build_case` fills in.

The chapter's fibre-angle pairs (:data:`CHAPTER_ANGLE_PAIRS`, and those of
the fibre-discrepancy study's data, :data:`FIBRE_DISCREPANCY_ANGLE_PAIRS`),
its reference material point θ̃, the noise levels of its SYNTHETIC data sets
and the Holzapfel–Ogden terms every case holds at population values
(:data:`HO_FIXED`) live here too. Units: degrees, mmHg, kPa (a, af, as, afs), mL.
"""
from __future__ import annotations

#: The simulator's default rule-based fibre helix angles (deg), endocardium and epicardium.
SIMULATOR_DEFAULT_ANGLES = (-60.0, 90.0)
#: The simulator's default end-diastolic pressure (mmHg).
SIMULATOR_DEFAULT_EDP_MMHG = 8.0

#: The stiffness θ = (a, b, a_f, b_f) of a typical healthy LV (kPa for a, af): the Simulator page's starting point
#: and the material of the bundled case ``assets/cases/default_lv.json``. These are the healthy-volunteer
#: Holzapfel–Ogden values of the Glasgow LV models that go with the fixed sheet terms of
#: :data:`HO_FIXED` (a_s = 0.69 kPa, b_s = 1.11, a_fs = 0.31 kPa, b_fs = 2.58; Gao et al. 2017, after
#: Gao et al. 2015, J Eng Math 95:231, doi:10.1007/s10665-014-9740-3; quoted from those papers as remembered, not
#: re-read here: check before citing). On the default LV at 8 mmHg they give EDV/V₀ = 1.85 (LVV 159.1 mL on
#: V₀ = 86.1 mL, ``default`` mesh), inside the typical 1.66–1.99 of :func:`lvcore.domain.physiology.typical_edv_ratio`
#: (central 1.81). The chapter's θ̃ (:data:`THETA_TILDE`) has a 3.3× softer fibre term (a_f = 1.00 kPa) and a
#: softer-rising matrix (b = 1.30) and inflates the same LV to 2.14 × V₀ (184.7 mL), above that range: it stays the
#: truth of the SYNTHETIC studies and the emulators' pages' starting point, not the default heart.
SIMULATOR_DEFAULT_THETA = {"a": 0.18, "b": 2.60, "af": 3.34, "bf": 2.73}

#: Fibre angles (deg) at which the chapter's emulator was trained.
CHAPTER_ANGLES = (-60.0, 60.0)
#: EDP (mmHg) at which the chapter's emulator was trained.
CHAPTER_EDP = 8.0
#: The fibre-angle pairs (α_endo, α_epi) in degrees of the chapter's angle study (§9.3.2, Fig 9.5): the simulator's
#: defaults, the emulator's training angles and two more.
CHAPTER_ANGLE_PAIRS = (SIMULATOR_DEFAULT_ANGLES, CHAPTER_ANGLES, (-30.0, 60.0), (0.0, 90.0))
#: The angle pairs (deg) of the fibre-discrepancy study's SYNTHETIC data (§9.4.3): the chapter's pairs other than the
#: emulator's training angles, so that the fibres are the discrepancy a calibration at :data:`CHAPTER_ANGLES` meets.
FIBRE_DISCREPANCY_ANGLE_PAIRS = tuple(p for p in CHAPTER_ANGLE_PAIRS if p != CHAPTER_ANGLES)

#: θ̃, the chapter's reference material point (kPa for a, af; b, bf dimensionless): the truth of the SYNTHETIC
#: studies and the app's starting point.
THETA_TILDE = {"a": 0.60, "b": 1.30, "af": 1.00, "bf": 3.60}
#: Strain noise standard deviation σ_S (-) of the SYNTHETIC data (the chapter's 0.03).
SIGMA_S = 0.03
#: Fixed LVV noise standard deviation σ_V (mL) of every calibration likelihood (chapter Table E.1).
SIGMA_V_ML = 5.0

#: The Holzapfel–Ogden sheet and fibre-sheet terms every case holds at population values unless it says otherwise
#: (Gao et al. 2017): a_s, a_fs in kPa, b_s, b_fs dimensionless; case keys ``as, bs, afs, bfs``.
HO_FIXED = {"as": 0.69, "bs": 1.11, "afs": 0.31, "bfs": 2.58}

__all__ = ["SIMULATOR_DEFAULT_ANGLES", "SIMULATOR_DEFAULT_EDP_MMHG", "SIMULATOR_DEFAULT_THETA", "CHAPTER_ANGLES", "CHAPTER_EDP",
           "CHAPTER_ANGLE_PAIRS", "FIBRE_DISCREPANCY_ANGLE_PAIRS", "THETA_TILDE", "SIGMA_S", "SIGMA_V_ML", "HO_FIXED"]
