"""Named parameter spaces for simulation campaigns.

A :class:`ParameterSpace` is an ordered set of :class:`Parameter` (name,
bounds, scale) plus the inputs held fixed. It maps points of the unit cube
(the output of a design) to physical values and turns one design row into the
simulator's case dictionary.

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
    inverts).
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

import json
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from lvcore.exceptions import CampaignError
from lvcore.outputs import ANGLE_NAMES, EDP_NAME, THETA_NAMES, is_pc_name, pc_names

#: Fibre angles (deg) at which the chapter's emulator was trained.
CHAPTER_ANGLES = (-60.0, 60.0)
#: EDP (mmHg) used for the chapter's emulator.
CHAPTER_EDP = 8.0
#: Material bounds of the calibration prior (Table 9.1): kPa for a, af.
THETA_BOUNDS = {"a": (0.05, 10.0), "b": (0.1, 30.0), "af": (0.05, 10.0), "bf": (0.1, 30.0)}
#: Material bounds of the ``angles`` emulator: Table 9.1's, except b, bf >= 0.5. Below 0.5 the
#: exponential stiffening that defines myocardium is gone; with a soft matrix those corners give
#: 700-2,500 mL LVs at 6-14 mmHg, which no patient has and which cost the emulator most of its error.
ANGLES_THETA_BOUNDS = {**THETA_BOUNDS, "b": (0.5, 30.0), "bf": (0.5, 30.0)}
#: How many score standard deviations the PC bounds span on each side.
PC_SPAN_SD = 2.0

SCALES = ("linear", "log")


@dataclass(frozen=True)
class Parameter:
    """One varied input.

    Parameters
    ----------
    name : str
        Input name (see :mod:`lvcore.outputs`).
    lower, upper : float
        Bounds in physical units (kPa, -, deg, mmHg or score units).
    scale : {"linear", "log"}
        Uniform on this scale: ``"log"`` means log-uniform (needs lower > 0).
    """

    name: str
    lower: float
    upper: float
    scale: str = "linear"

    def __post_init__(self):
        if self.scale not in SCALES:
            raise CampaignError(f"parameter '{self.name}': scale must be one of {SCALES}, got {self.scale!r}")
        if not (np.isfinite(self.lower) and np.isfinite(self.upper) and self.lower < self.upper):
            raise CampaignError(f"parameter '{self.name}': need finite lower < upper, got [{self.lower}, {self.upper}]")
        if self.scale == "log" and self.lower <= 0:
            raise CampaignError(f"parameter '{self.name}': a log scale needs lower > 0, got {self.lower}")

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Map ``u`` in [0, 1] to physical values on this parameter's scale."""
        u = np.asarray(u, dtype=float)
        if self.scale == "log":
            lo, hi = np.log(self.lower), np.log(self.upper)
            return np.exp(lo + u * (hi - lo))
        return self.lower + u * (self.upper - self.lower)

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`from_unit`."""
        x = np.asarray(x, dtype=float)
        if self.scale == "log":
            lo, hi = np.log(self.lower), np.log(self.upper)
            return (np.log(x) - lo) / (hi - lo)
        return (x - self.lower) / (self.upper - self.lower)


@dataclass(frozen=True)
class ParameterSpace:
    """An ordered set of varied inputs plus fixed ones.

    Parameters
    ----------
    name : str
        Name of the space (recorded in designs and stores).
    parameters : tuple of Parameter
        Varied inputs, in design-column order.
    fixed : tuple of (str, float)
        Inputs held fixed (e.g. ``("alpha_endo", -60.0)``).
    """

    name: str
    parameters: tuple[Parameter, ...]
    fixed: tuple[tuple[str, float], ...] = field(default_factory=tuple)

    def __post_init__(self):
        names = [p.name for p in self.parameters] + [k for k, _ in self.fixed]
        if len(set(names)) != len(names):
            raise CampaignError(f"space '{self.name}': duplicate input names in {names}")
        if not self.parameters:
            raise CampaignError(f"space '{self.name}': needs at least one varied parameter")

    # ----- shape ------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Names of the varied inputs (design columns)."""
        return tuple(p.name for p in self.parameters)

    @property
    def dim(self) -> int:
        return len(self.parameters)

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters])

    @property
    def n_pcs(self) -> int:
        """Number of PCA scores among the varied inputs (they must be h1..hk)."""
        return sum(1 for n in self.names if is_pc_name(n))

    def fixed_dict(self) -> dict[str, float]:
        return dict(self.fixed)

    # ----- mapping ----------------------------------------------------------
    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Map unit-cube points ``(n, dim)`` to physical values ``(n, dim)``."""
        u = np.atleast_2d(np.asarray(u, dtype=float))
        if u.shape[1] != self.dim:
            raise CampaignError(f"space '{self.name}' has {self.dim} dimensions, got points with {u.shape[1]}")
        return np.column_stack([p.from_unit(u[:, i]) for i, p in enumerate(self.parameters)])

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, dtype=float))
        return np.column_stack([p.to_unit(x[:, i]) for i, p in enumerate(self.parameters)])

    def contains(self, x: np.ndarray, rtol: float = 1e-9) -> np.ndarray:
        """Boolean per row: inside the bounds (with a relative tolerance)."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        span = self.upper - self.lower
        return np.all((x >= self.lower - rtol * span) & (x <= self.upper + rtol * span), axis=1)

    def full_inputs(self, row: Sequence[float]) -> dict[str, float]:
        """Every input of one row (varied and fixed) by name."""
        values = {n: float(v) for n, v in zip(self.names, row)}
        values.update(self.fixed_dict())
        return values

    def case(self, row: Sequence[float], resolution: str = "default") -> dict:
        """The simulator case dictionary for one design row.

        Parameters
        ----------
        row : sequence of float
            Values of :attr:`names`, physical units.
        resolution : {"fast", "default", ...}
            Mesh resolution passed to the simulator's geometry section.
        """
        v = self.full_inputs(row)
        missing = [n for n in THETA_NAMES if n not in v]
        if missing:
            raise CampaignError(f"space '{self.name}' does not define material parameter(s) {missing}")
        k = self.n_pcs
        if k:
            geometry = {"kind": "pca", "scores": [v[n] for n in pc_names(k)], "resolution": resolution}
        else:
            geometry = {"kind": "default", "resolution": resolution}
        return {
            "geometry": geometry,
            "material": {"law": "holzapfel-ogden", **{n: v[n] for n in THETA_NAMES}},
            "fibres": {"alpha_endo": v.get("alpha_endo", CHAPTER_ANGLES[0]), "alpha_epi": v.get("alpha_epi", CHAPTER_ANGLES[1])},
            "load": {"pressure": v.get(EDP_NAME, CHAPTER_EDP), "units": "mmHg"},
            "boundary": {"base": "clamped"},
        }

    # ----- serialisation ----------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "parameters": [{"name": p.name, "lower": p.lower, "upper": p.upper, "scale": p.scale} for p in self.parameters],
            "fixed": {k: v for k, v in self.fixed},
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, d: Mapping) -> "ParameterSpace":
        try:
            params = tuple(Parameter(str(p["name"]), float(p["lower"]), float(p["upper"]), str(p.get("scale", "linear"))) for p in d["parameters"])
            fixed = tuple((str(k), float(v)) for k, v in dict(d.get("fixed", {})).items())
            return cls(str(d["name"]), params, fixed)
        except (KeyError, TypeError, ValueError) as err:
            raise CampaignError(f"malformed parameter-space description: {err!r}") from err

    @classmethod
    def from_json(cls, text: str) -> "ParameterSpace":
        try:
            return cls.from_dict(json.loads(text))
        except json.JSONDecodeError as err:
            raise CampaignError(f"parameter-space description is not valid JSON: {err}") from err


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


def _fixed(angles=CHAPTER_ANGLES, edp=CHAPTER_EDP) -> tuple[tuple[str, float], ...]:
    out = []
    if angles is not None:
        out += [(ANGLE_NAMES[0], float(angles[0])), (ANGLE_NAMES[1], float(angles[1]))]
    if edp is not None:
        out.append((EDP_NAME, float(edp)))
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
    angles = (Parameter("alpha_endo", -90.0, 0.0), Parameter("alpha_epi", 0.0, 90.0))
    if name == "material":
        k = n_pcs or 0
        params, fixed = theta, _fixed()
    elif name == "chapter":
        k = 5 if n_pcs is None else n_pcs
        params, fixed = theta, _fixed()
    elif name == "angles":
        k = 5 if n_pcs is None else n_pcs
        params, fixed = theta_parameters("log", ANGLES_THETA_BOUNDS) + angles + (Parameter(EDP_NAME, 6.0, 14.0),), ()
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
    return ParameterSpace(name, params, fixed)


SPACE_NAMES = ("material", "chapter", "angles", "bo4", "bo6")
