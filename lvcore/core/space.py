"""Parameter spaces and the prior box (the core layer's inputs side).

Every layer that names the model inputs uses this module: campaigns (named
design spaces), optimisation (boxes), inference (prior bounds) and the app
(slider ranges). Units: ``a``, ``af`` in kPa; ``b``, ``bf`` dimensionless;
``alpha_endo``, ``alpha_epi`` in degrees; ``edp`` in mmHg; PC scores
``h1..hk`` in the shape model's (standardised) score units.

* :class:`Parameter` and :class:`ParameterSpace`: an ordered set of varied
  inputs (bounds, linear or log scale) plus inputs held fixed; maps the unit
  cube of a design to physical values.
* :data:`THETA_BOUNDS` (the chapter's Table 9.1 prior box),
  :data:`ANGLES_THETA_BOUNDS`, :data:`ANGLE_BOUNDS`, :data:`EDP_BOUNDS`
  (the angles and EDP themselves are in :mod:`lvcore.domain.conditions`).

The simulator's case dictionary for named inputs is written by
:func:`lvcore.mechanics.case_inputs.build_case` (the case format's layer);
``build_case`` here is a deprecated alias.
"""
from __future__ import annotations

import importlib
import json
import warnings
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from lvcore._exports import moved_names
from lvcore.exceptions import CampaignError
from lvcore.domain.outputs import BASE_CONDITIONS, is_pc_name

#: Material bounds of the calibration prior (Table 9.1): kPa for a, af.
THETA_BOUNDS = {"a": (0.05, 10.0), "b": (0.1, 30.0), "af": (0.05, 10.0), "bf": (0.1, 30.0)}
#: Material bounds of the ``angles`` emulator: Table 9.1's, except b, bf >= 0.5. Below 0.5 the
#: exponential stiffening that defines myocardium is gone; with a soft matrix those corners give
#: 700-2,500 mL LVs at 6-14 mmHg, which no patient has and which cost the emulator most of its error.
ANGLES_THETA_BOUNDS = {**THETA_BOUNDS, "b": (0.5, 30.0), "bf": (0.5, 30.0)}
#: Range of the rule-based fibre helix angles (degrees): the calibration prior when they are
#: inferred and the ``angles`` emulator's training box.
ANGLE_BOUNDS = {"alpha_endo": (-90.0, 0.0), "alpha_epi": (0.0, 90.0)}
#: Range of the end-diastolic pressure (mmHg) of the ``angles`` emulator.
EDP_BOUNDS = (6.0, 14.0)

SCALES = ("linear", "log")


@dataclass(frozen=True)
class Parameter:
    """One varied input.

    Parameters
    ----------
    name : str
        Input name (see :mod:`lvcore.domain.outputs`).
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
    base : {"clamped", "sliding"}
        LV base boundary condition of every case built from this space
        (recorded in designs and stores; descriptions without it read as
        ``"clamped"``, the condition of every store before it existed).
    """

    name: str
    parameters: tuple[Parameter, ...]
    fixed: tuple[tuple[str, float], ...] = field(default_factory=tuple)
    base: str = "clamped"

    def __post_init__(self):
        if self.base not in BASE_CONDITIONS:
            raise CampaignError(f"space '{self.name}': base must be one of {BASE_CONDITIONS}, got {self.base!r}")
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
        """Deprecated: the case for one design row is :func:`lvcore.mechanics.case_inputs.space_case`
        (writing cases is the simulator's job, a layer above this one)."""
        warnings.warn("ParameterSpace.case is deprecated; use lvcore.mechanics.case_inputs.space_case(space, row, "
                      "resolution)", DeprecationWarning, stacklevel=2)
        return importlib.import_module("lvcore.mechanics.case_inputs").space_case(self, row, resolution)

    # ----- serialisation ----------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "parameters": [{"name": p.name, "lower": p.lower, "upper": p.upper, "scale": p.scale} for p in self.parameters],
            "fixed": {k: v for k, v in self.fixed},
            "base": self.base,
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, d: Mapping) -> "ParameterSpace":
        try:
            params = tuple(Parameter(str(p["name"]), float(p["lower"]), float(p["upper"]), str(p.get("scale", "linear"))) for p in d["parameters"])
            fixed = tuple((str(k), float(v)) for k, v in dict(d.get("fixed", {})).items())
            return cls(str(d["name"]), params, fixed, str(d.get("base", "clamped")))
        except (KeyError, TypeError, ValueError) as err:
            raise CampaignError(f"malformed parameter-space description: {err!r}") from err

    @classmethod
    def from_json(cls, text: str) -> "ParameterSpace":
        try:
            return cls.from_dict(json.loads(text))
        except json.JSONDecodeError as err:
            raise CampaignError(f"parameter-space description is not valid JSON: {err}") from err


#: Moved to the simulator's layer, with the case format they write.
__getattr__ = moved_names(__name__, {"build_case": "lvcore.mechanics.case_inputs:build_case",
                                     "CASE_LAW": "lvcore.mechanics.case_inputs:CASE_LAW"})

__all__ = [
    "Parameter", "ParameterSpace", "THETA_BOUNDS", "ANGLES_THETA_BOUNDS", "ANGLE_BOUNDS",
    "EDP_BOUNDS", "SCALES",
]
