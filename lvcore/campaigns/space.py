"""Named parameter spaces for simulation campaigns, built on :mod:`lvcore.core.space`.

:class:`~lvcore.core.space.ParameterSpace`, the prior box and the case
builder live in the core layer; this module only names the spaces that
campaigns, emulators and the optimisation studies use.

Units: ``a``, ``af`` in kPa; ``b``, ``bf`` dimensionless; ``alpha_endo``,
``alpha_epi`` in degrees; ``edp`` in mmHg; PC scores ``h1..hk`` in the shape
model's score units.

Named spaces (see :func:`get_space`):

``material``
    ``a, b, af, bf`` log-uniform (a, af in [0.05, 10] kPa; b, bf in [0.1, 30]),
    default geometry, fibre angles (-60°, 60°), EDP 8 mmHg.
``chapter``
    the chapter's emulator: ``material`` plus ``h1..h5`` uniform over
    +/- 2 score standard deviations of the bundled PCA shape model (its
    scores are standardised, so [-2, 2]; at +/- 3 corners the geometry
    inverts), with a **sliding** base (as ``angles``; every other space: clamped).
``angles``
    ``chapter`` plus ``alpha_endo`` in [-90, 0]°, ``alpha_epi`` in [0, 90]°
    and ``edp`` in [6, 14] mmHg, all uniform, with ``b, bf`` in [0.5, 30]
    instead of [0.1, 30] (:data:`ANGLES_THETA_BOUNDS`).
``bo4`` / ``bo6``
    the chapter's Bayesian-optimisation start: ``a, b, af, bf`` in [0.1, 10]
    (linear scale; use with the ``exp`` design), default geometry; ``bo6``
    adds the two fibre angles.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP
from lvcore.core.space import ANGLE_BOUNDS, ANGLES_THETA_BOUNDS, EDP_BOUNDS, THETA_BOUNDS, Parameter, ParameterSpace
from lvcore.exceptions import CampaignError
from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME, THETA_NAMES, pc_names

#: How many score standard deviations the PC bounds span on each side.
PC_SPAN_SD = 2.0


# ----- named spaces ---------------------------------------------------------

def theta_parameters(scale: str = "log", bounds: Mapping[str, tuple[float, float]] = THETA_BOUNDS) -> tuple[Parameter, ...]:
    """The four free HO parameters with the given bounds and scale."""
    return tuple(Parameter(n, *bounds[n], scale=scale) for n in THETA_NAMES)


def pc_parameters(k: int, score_sd: Sequence[float] | None = None, span_sd: float = PC_SPAN_SD) -> tuple[Parameter, ...]:
    """Uniform bounds ``+/- span_sd * sd_i`` for the first ``k`` PC scores.

    ``score_sd`` defaults to the bundled shape model's score standard
    deviations (:func:`pc_score_sd`).
    """
    sd = np.asarray(pc_score_sd(k) if score_sd is None else score_sd, dtype=float)
    if sd.shape[0] < k or np.any(sd[:k] <= 0):
        raise CampaignError(f"need {k} positive PC score standard deviations, got {sd}")
    return tuple(Parameter(n, -span_sd * s, span_sd * s) for n, s in zip(pc_names(k), sd[:k]))


def pc_score_sd(k: int) -> np.ndarray:
    """Standard deviations of the first ``k`` PC scores of the bundled shape model.

    :mod:`lvcore.geometry.shape_model` standardises its scores (unit variance
    over the training population), so these are ones; the call checks that
    the bundled model exists and has at least ``k`` modes.
    """
    try:
        from lvcore.geometry.shape_model import load_shape_model
    except ImportError as err:  # pragma: no cover - depends on another module landing
        raise CampaignError("spaces with PC scores need lvcore.geometry.shape_model (not available)") from err
    try:
        model = load_shape_model()
    except Exception as err:  # GeometryError with a hint how to build it
        raise CampaignError(f"spaces with PC scores need the bundled shape model: {err}") from err
    if model.n_modes < k:
        raise CampaignError(f"the shape model has {model.n_modes} modes, a space asks for {k}")
    return np.ones(k)


def _fixed(angles=CHAPTER_ANGLES, edp_mmhg=CHAPTER_EDP) -> tuple[tuple[str, float], ...]:
    out = []
    if angles is not None:
        out += [(ANGLE_NAMES[0], float(angles[0])), (ANGLE_NAMES[1], float(angles[1]))]
    if edp_mmhg is not None:
        out.append((EDP_NAME, float(edp_mmhg)))
    return tuple(out)


def get_space(name: str, n_pcs: int | None = None, score_sd: Sequence[float] | None = None) -> ParameterSpace:
    """Build a named parameter space.

    Parameters
    ----------
    name : {"material", "chapter", "angles", "bo4", "bo6"}
        See the module docstring.
    n_pcs : int, optional
        Override the number of PC scores (default 5 for ``chapter`` and
        ``angles``, 0 otherwise).
    score_sd : sequence of float, optional
        PC score standard deviations; default: the bundled shape model's.
    """
    theta = theta_parameters("log")
    angles = tuple(Parameter(n, *ANGLE_BOUNDS[n]) for n in ANGLE_NAMES)
    if name == "material":
        k = n_pcs or 0
        params, fixed = theta, _fixed()
    elif name == "chapter":
        k = 5 if n_pcs is None else n_pcs
        params, fixed = theta, _fixed()
    elif name == "angles":
        k = 5 if n_pcs is None else n_pcs
        params, fixed = theta_parameters("log", ANGLES_THETA_BOUNDS) + angles + (Parameter(EDP_NAME, *EDP_BOUNDS),), ()
    elif name in ("bo4", "bo6"):
        k = n_pcs or 0
        bo = theta_parameters("linear", {n: (0.1, 10.0) for n in THETA_NAMES})
        if name == "bo4":
            params, fixed = bo, _fixed()
        else:
            params, fixed = bo + angles, _fixed(angles=None)
    else:
        raise CampaignError(f"unknown parameter space '{name}'; choose one of {SPACE_NAMES}")
    if k:
        params = params + pc_parameters(k, score_sd)
    # the shipped emulators' spaces (chapter, angles) use the sliding base of the Glasgow HO LV models
    # (docs/simulator.md, "Base boundary condition"; one base across the shipped emulators, issue 24); the
    # others keep the simulator's default, clamped
    return ParameterSpace(name, params, fixed, base="sliding" if name in ("chapter", "angles") else "clamped")


SPACE_NAMES = ("material", "chapter", "angles", "bo4", "bo6")

__all__ = ["get_space", "SPACE_NAMES", "theta_parameters", "pc_parameters", "pc_score_sd", "PC_SPAN_SD"]
