"""Mesh resolutions of the simulator: LV and box element counts and their named presets.

This module is the one source of truth for resolutions:

* :class:`LVResolution` - elements around, base to apex (evenly or per
  short-axis level) and through the wall of an LV mesh, and the Gauss
  points through the wall. Every bound is checked once, here, in
  ``__post_init__`` (including the size limits of :mod:`lvcore.safety.limits`:
  elements, degrees of freedom, estimated memory); a violation raises :class:`ResolutionError` naming the
  case-schema field (``circumferential``, ``longitudinal``, ``transmural``,
  ``transmural_gauss_points``), which :mod:`lvcore.mechanics.case` turns into
  a :class:`~lvcore.exceptions.CaseError`.
* :class:`BoxResolution` - elements along x, y and z of a box mesh.
* :data:`RESOLUTION_PRESETS` and :data:`BOX_RESOLUTION_PRESETS` - the named
  presets; :data:`RESOLUTION_PRESET_NAMES` and
  :data:`BOX_RESOLUTION_PRESET_NAMES` are their keys, for CLIs and the app.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from lvcore.exceptions import GeometryError
from lvcore.geometry.template import N_LEVELS, LVTemplate
from lvcore.safety.limits import check_mesh_size

#: Largest number of Gauss points through the wall (the 1-D Gauss rule is exact to degree 19).
MAX_TRANSMURAL_GAUSS_POINTS = 10
#: Fewest elements around an LV (fewer cannot close the ring of quadratic elements).
MIN_CIRCUMFERENTIAL = 3


class ResolutionError(GeometryError):
    """A resolution count is out of its bounds; ``field`` is the case-schema key."""

    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f"resolution {field}: {problem}")


def _positive_int(value, field: str) -> int:
    """``value`` as an int >= 1 (integral floats such as 4.0 allowed)."""
    ok = isinstance(value, numbers.Integral) or (isinstance(value, numbers.Real) and float(value).is_integer())
    if isinstance(value, bool) or not ok or value < 1:
        raise ResolutionError(field, f"must be a positive integer, got {value!r}")
    return int(value)


def _check_limits(counts, fields, kind: str, gauss_points: int) -> None:
    """Refuse meshes over the limits of :mod:`lvcore.safety.limits` (elements, dofs, estimated memory),
    before anything is allocated; the error names the field of the largest count."""
    field = fields[max(range(len(counts)), key=lambda i: counts[i])]
    check_mesh_size(counts, kind, gauss_points, error=lambda msg: ResolutionError(field, msg), where="mesh too large")


def _levels(level_elements) -> tuple[int, ...]:
    """Per-level element rows, checked: one positive count for each of the 4 short-axis levels."""
    le = tuple(level_elements) if isinstance(level_elements, (list, tuple)) else (level_elements,)
    if len(le) != N_LEVELS:
        raise ResolutionError("longitudinal", "give one element count or four counts, one per short-axis level "
                              f"from base to apex, e.g. [2, 1, 1, 2]; got {list(le)!r}")
    return tuple(_positive_int(v, f"longitudinal[{i}]") for i, v in enumerate(le))


@dataclass(frozen=True)
class LVResolution:
    """Discretisation of an LV mesh.

    Attributes
    ----------
    n_circ : quadratic elements around (>= 3; a multiple of 6 puts every element in one sector).
    n_long : element rows base to apex (a multiple of 4 puts every element in one level).
    n_trans : elements through the wall.
    level_elements : optional element rows in each of the 4 short-axis levels,
        base to apex, summing to ``n_long`` (``(2, 1, 1, 2)`` refines the
        clamped base and the apex, where the strains vary fastest); None spaces
        the rows evenly.
    transmural_gauss_points : Gauss points through the wall per element,
        1..10 (3 integrates a Q2 element of smooth material; with one element
        through the wall the helix angle turns by 150° across it, and the
        fibre terms need 5).

    Raises
    ------
    ResolutionError
        Naming the case-schema field that is out of bounds.
    """

    n_circ: int
    n_long: int
    n_trans: int
    level_elements: tuple[int, ...] | None = None
    transmural_gauss_points: int = 3

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "n_circ", _positive_int(self.n_circ, "circumferential"))
        set_(self, "n_long", _positive_int(self.n_long, "longitudinal"))
        set_(self, "n_trans", _positive_int(self.n_trans, "transmural"))
        gp = _positive_int(self.transmural_gauss_points, "transmural_gauss_points")
        if gp > MAX_TRANSMURAL_GAUSS_POINTS:
            raise ResolutionError("transmural_gauss_points",
                                  f"must be 1..{MAX_TRANSMURAL_GAUSS_POINTS}, got {gp}")
        set_(self, "transmural_gauss_points", gp)
        if self.n_circ < MIN_CIRCUMFERENTIAL:
            raise ResolutionError("circumferential", f"must be >= {MIN_CIRCUMFERENTIAL}, got {self.n_circ}")
        if self.level_elements is not None:
            le = _levels(self.level_elements)
            if sum(le) != self.n_long:
                raise ResolutionError("longitudinal", f"level counts {le} must sum to n_long={self.n_long}")
            set_(self, "level_elements", le)
        _check_limits(self.counts, ("circumferential", "longitudinal", "transmural"), "lv", 9 * gp)

    @classmethod
    def graded(cls, n_circ: int, level_elements, n_trans: int, transmural_gauss_points: int = 3) -> "LVResolution":
        """``level_elements[l]`` element rows in short-axis level ``l``."""
        le = _levels(level_elements)
        return cls(n_circ, sum(le), n_trans, le, transmural_gauss_points)

    @classmethod
    def from_spec(cls, spec: str) -> "LVResolution":
        """A preset name, or ``"NC,NL,NT[,GP]"`` with NL an integer or per-level counts ``"2+1+1+2"`` (benchmark CLIs)."""
        if spec in RESOLUTION_PRESETS:
            return RESOLUTION_PRESETS[spec]
        parts = [p.strip() for p in str(spec).split(",")]
        if len(parts) not in (3, 4):
            raise ValueError(f"resolution spec is 'NC,NL,NT[,GP]' (NL may be '2+1+1+2'), got {spec!r}")
        gp = int(parts[3]) if len(parts) == 4 else 3
        if "+" in parts[1]:
            return cls.graded(int(parts[0]), [int(v) for v in parts[1].split("+")], int(parts[2]), gp)
        return cls(int(parts[0]), int(parts[1]), int(parts[2]), None, gp)

    def case_dict(self) -> dict:
        """The case-schema ``geometry.resolution`` dict of this resolution."""
        d = {"circumferential": self.n_circ,
             "longitudinal": list(self.level_elements) if self.level_elements is not None else self.n_long,
             "transmural": self.n_trans}
        if self.transmural_gauss_points != 3:
            d["transmural_gauss_points"] = self.transmural_gauss_points
        return d

    @property
    def counts(self) -> tuple[int, int, int]:
        """(n_circ, n_long, n_trans) element counts."""
        return (self.n_circ, self.n_long, self.n_trans)

    @property
    def is_uniform(self) -> bool:
        """True when the element rows are evenly spaced base to apex."""
        return self.level_elements is None or len(set(self.level_elements)) == 1

    def template(self) -> LVTemplate:
        """The mesh topology of this resolution."""
        if self.is_uniform:
            return LVTemplate(self.n_circ, self.n_long, self.n_trans)
        return LVTemplate.graded(self.n_circ, self.level_elements, self.n_trans)

    def describe(self) -> str:
        """Short label, e.g. ``"6x(2,1,1,2)x1, 5 GP"``."""
        long = str(self.n_long) if self.is_uniform else "(" + ",".join(map(str, self.level_elements)) + ")"
        gp = "" if self.transmural_gauss_points == 3 else f", {self.transmural_gauss_points} GP"
        return f"{self.n_circ}x{long}x{self.n_trans}{gp}"


@dataclass(frozen=True)
class BoxResolution:
    """Elements along x, y and z of a box mesh (each >= 1)."""

    nx: int
    ny: int
    nz: int

    def __post_init__(self):
        for name in ("nx", "ny", "nz"):
            object.__setattr__(self, name, _positive_int(getattr(self, name), name))
        _check_limits(self.xyz, ("nx", "ny", "nz"), "box", 27)

    @property
    def xyz(self) -> tuple[int, int, int]:
        """(nx, ny, nz) element counts."""
        return (self.nx, self.ny, self.nz)

    @classmethod
    def from_preset(cls, size, preset: str) -> "BoxResolution":
        """Counts of preset ``preset`` for a box of ``size`` (Lx, Ly, Lz) mm: equal element sizes, rounded up."""
        per_min = BOX_RESOLUTION_PRESETS[preset]
        h = min(size) / per_min
        return cls(*(max(1, int(math.ceil(L / h - 1e-9))) for L in size))


#: LV resolutions. ``default`` is the cheapest mesh found whose 25 default-LV
#: outputs are within 1 % of ``accurate``, the same mesh with twice the elements
#: in every direction, which meets the Land et al. (2015) problem 2 apex
#: positions to ±0.05 mm (docs/simulator.md); ``coarse`` was the default of
#: lvcore 0.1 (the bundled emulators were trained on it).
RESOLUTION_PRESETS = {
    "fast": LVResolution(6, 4, 1),
    "coarse": LVResolution(12, 4, 1),
    "default": LVResolution.graded(6, (2, 1, 1, 2), 1, transmural_gauss_points=5),
    "accurate": LVResolution.graded(12, (4, 2, 2, 4), 2, transmural_gauss_points=5),
}
#: Box resolutions as elements across the smallest box dimension; other
#: directions get the same element size (rounded up).
BOX_RESOLUTION_PRESETS = {"fast": 1, "default": 2, "accurate": 3}
#: Names of the LV presets, cheapest first.
RESOLUTION_PRESET_NAMES = tuple(RESOLUTION_PRESETS)
#: Names of the box presets, cheapest first.
BOX_RESOLUTION_PRESET_NAMES = tuple(BOX_RESOLUTION_PRESETS)


def resolution_label(spec: str) -> str:
    """Table label of a benchmark resolution spec: ``"default: 6x(2,1,1,2)x1, 5 GP"`` or ``"12x8x2"``."""
    described = LVResolution.from_spec(spec).describe()
    return f"{spec}: {described}" if spec in RESOLUTION_PRESETS else described


def recorded_resolution(resolution: str, simulator_versions) -> str:
    """The preset name that reproduces rows recorded as ``resolution`` by ``simulator_versions``.

    lvcore 0.1's ``"default"`` mesh (12 x 4 x 1 elements, 3 Gauss points
    through the wall) is called ``"coarse"`` since lvcore 0.2, whose
    ``"default"`` is a graded mesh that meets the 1 % mesh-convergence check.
    Stores and emulators made by 0.1 keep saying ``"default"``; this maps
    them to the mesh they used (for resuming a campaign or checking an
    emulator against a live solve).
    """
    versions = [str(v) for v in (simulator_versions or [])]
    if resolution == "default" and versions and all(v.startswith("0.1.") for v in versions):
        return "coarse"
    return resolution


__all__ = ["LVResolution", "BoxResolution", "ResolutionError", "RESOLUTION_PRESETS", "BOX_RESOLUTION_PRESETS",
           "RESOLUTION_PRESET_NAMES", "BOX_RESOLUTION_PRESET_NAMES", "MAX_TRANSMURAL_GAUSS_POINTS",
           "resolution_label", "recorded_resolution"]
