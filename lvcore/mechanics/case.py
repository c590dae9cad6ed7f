"""A simulation case: the validated, typed form of a case JSON file.

A case says *what* to simulate (geometry, material law and parameters, fibres,
load, boundary conditions, probe points, output options); the mechanics layer
decides *how* (mesh, solver). :func:`load_case` and :meth:`Case.from_dict`
check every field and raise one :class:`~lvcore.exceptions.CaseError` naming
the field path (e.g. ``material.a``) and what to fix.

The JSON schema is documented in ``docs/case_schema.md``. Units: mm, kPa
(pressure may be given in mmHg), degrees for fibre angles.
"""
from __future__ import annotations

import difflib
import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from lvcore.domain import conditions, units
from lvcore.safety import limits
from lvcore.exceptions import CaseError, LVCoreError
from lvcore.geometry.analytic import DEFAULT_LV, EllipsoidSurface, TruncatedEllipsoidLV
from lvcore.geometry.template import DEFAULT_TEMPLATE, N_REGIONS
from lvcore.mechanics.materials import LAWS, MaterialLaw
from lvcore.domain.outputs import BASE_CONDITIONS, DEFAULT_STRAIN_LAYER, STRAIN_LAYER_ALIASES, STRAIN_LAYERS
from lvcore.mechanics.resolution import (
    BOX_RESOLUTION_PRESET_NAMES,
    BOX_RESOLUTION_PRESETS,
    RESOLUTION_PRESET_NAMES,
    BoxResolution,
    LVResolution,
    ResolutionError,
)

GEOMETRY_KINDS = ("ellipsoid", "default", "mesh", "pca", "box")
#: Largest magnitude of a standardised PC score (sd units) in a case; real shapes are within +-3.
MAX_ABS_PC_SCORE = 10.0
#: Most PC scores in a case.
MAX_PC_SCORES = 100
LV_KINDS = ("ellipsoid", "default", "mesh", "pca")
#: Law names of ``material.law``; parameters, required ones and defaults come from :data:`materials.LAWS`.
MATERIAL_LAWS = tuple(LAWS)
BOX_FACES = ("x0", "x1", "y0", "y1", "z0", "z1")
#: Directions of the epicardial Robin spring: the displacement along the reference normal, or all of it.
SPRING_DIRECTIONS = ("normal", "full")
#: Largest epicardial spring stiffness accepted (kPa/mm); pericardial values are ~0.01-1 kPa/mm.
MAX_SPRING_KPA_PER_MM = 100.0
#: Range of a regional stiffness multiplier.
REGIONAL_FACTOR_RANGE = (0.01, 100.0)
PRESSURE_UNITS = {"kpa": 1.0, "mmhg": units.KPA_PER_MMHG}


# ----------------------------------------------------------------------------
# dataclasses
# ----------------------------------------------------------------------------
#: The element counts of a geometry: an LV resolution, or a box's counts along x, y, z.
Resolution = LVResolution | BoxResolution


@dataclass(frozen=True, eq=False)
class GeometrySpec:
    """The reference (stress-free, early-diastolic) geometry.

    Attributes
    ----------
    kind : {"ellipsoid", "default", "mesh", "pca", "box"}
    resolution : LVResolution (LV kinds), BoxResolution (kind "box") or None
        Explicit element counts; ``None`` means the mechanics uses the preset
        ``preset or "default"`` (:mod:`lvcore.mechanics.resolution`).
    preset : one of ``RESOLUTION_PRESET_NAMES`` (LV) or ``BOX_RESOLUTION_PRESET_NAMES`` (box), or None
    ellipsoid : TruncatedEllipsoidLV or None
        Kinds "ellipsoid" and "default" (the latter is ``DEFAULT_LV``).
    template_nodes : (DEFAULT_TEMPLATE.n_nodes, 3) array or None
        Kinds "mesh" and "pca": node positions on ``DEFAULT_TEMPLATE`` (mm).
    box_size : (Lx, Ly, Lz) or None
        Kind "box": the block [0, Lx] x [0, Ly] x [0, Lz] (mm).
    source : str
        Human-readable origin of the geometry.
    """

    kind: str
    resolution: LVResolution | BoxResolution | None = None
    preset: str | None = None
    ellipsoid: TruncatedEllipsoidLV | None = None
    template_nodes: np.ndarray | None = None
    box_size: tuple[float, float, float] | None = None
    source: str = ""
    #: Extra data needed to write the spec back to JSON (mesh path, PCA scores/model).
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __eq__(self, other):
        if not isinstance(other, GeometrySpec):
            return NotImplemented
        a, b = self.template_nodes, other.template_nodes
        same_nodes = (a is None and b is None) or (
            a is not None and b is not None and np.array_equal(a, b)
        )
        return (
            same_nodes
            and (self.kind, self.resolution, self.preset, self.ellipsoid, self.box_size, self.source)
            == (other.kind, other.resolution, other.preset, other.ellipsoid, other.box_size, other.source)
        )

    __hash__ = None  # holds an array

    @property
    def is_lv(self) -> bool:
        """True for the LV kinds (everything but "box")."""
        return self.kind in LV_KINDS

    def position_map(self) -> Callable | None:
        """Parametric map ``(phi, s, t) -> xyz`` (mm) of an LV geometry; ``None`` for a box."""
        if self.kind in ("ellipsoid", "default"):
            return self.ellipsoid.position
        if self.kind in ("mesh", "pca"):
            return functools.partial(DEFAULT_TEMPLATE.evaluate, self.template_nodes)
        return None

    def base_z(self) -> float:
        """Height of the base plane (mm) of an LV geometry."""
        if self.kind in ("ellipsoid", "default"):
            return float(self.ellipsoid.base_z)
        if self.kind in ("mesh", "pca"):
            return float(np.mean(self.template_nodes[DEFAULT_TEMPLATE.base_nodes, 2]))
        raise CaseError("geometry.kind", "a box has no base plane")


@dataclass(frozen=True)
class FibreSpec:
    """Rule-based fibre helix angles (deg, endo to epi) or one constant direction."""

    alpha_endo_deg: float = conditions.SIMULATOR_DEFAULT_ANGLES[0]
    alpha_epi_deg: float = conditions.SIMULATOR_DEFAULT_ANGLES[1]
    direction: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class LoadSpec:
    """Pressure (kPa) on a surface: "endocardium" (LV) or a box face "x0".."z1"."""

    pressure_kpa: float
    surface: str = "endocardium"


@dataclass(frozen=True)
class BoundarySpec:
    """Boundary conditions.

    Attributes
    ----------
    base : LV base "clamped" or "sliding" (Dirichlet); None for a box.
    clamped_faces : box faces held fixed.
    epicardial_spring : float
        Stiffness k (kPa/mm) of a linear Robin spring on the LV epicardium
        (a pericardium), energy ``k/2 ∫ |u_d|² dA`` over the reference
        epicardium; 0 (default) is no spring.
    spring_direction : {"normal", "full"}
        ``u_d`` is the displacement along the reference outward normal
        (``"normal"``) or the whole displacement (``"full"``).
    """

    base: str | None = "clamped"
    clamped_faces: tuple[str, ...] = ()
    epicardial_spring: float = 0.0
    spring_direction: str = "normal"


@dataclass(frozen=True)
class RegionalStiffness:
    """Multipliers of the law's stiffnesses per strain region (24 LV regions, numbered as the ``region`` VTU field).

    Attributes
    ----------
    factors : mapping
        Stiffness parameter name (one of the law's ``stress_keys``, e.g. ``a``
        and ``af``) -> 24 multipliers; parameters not named keep factor 1.
    """

    factors: Mapping[str, tuple[float, ...]]

    __hash__ = None

    def multipliers(self, law: MaterialLaw) -> np.ndarray:
        """(24, len(law.keys)) per-region parameter multipliers of ``law`` (1 where not scaled)."""
        out = np.ones((N_REGIONS, len(law.keys)))
        for key, f in self.factors.items():
            out[:, law.keys.index(key)] = f
        return out

    def is_uniform(self) -> bool:
        """True when every named parameter has the same factor in every region."""
        return all(len(set(f)) == 1 for f in self.factors.values())


@dataclass(frozen=True)
class OutputSpec:
    """Output options: the wall layer the regional strains are averaged over (a name of
    :data:`lvcore.domain.outputs.STRAIN_LAYERS`; the deprecated ``endocardial`` and ``wall`` are read as
    ``inner_half`` and ``whole_wall``)."""

    strain_layer: str = DEFAULT_STRAIN_LAYER


@dataclass(frozen=True)
class Case:
    """One forward simulation, validated. Build with :meth:`from_dict` or :func:`load_case`.

    ``material`` is the law with its complete parameter set (a
    :class:`~lvcore.mechanics.materials.MaterialLaw`: ``.law`` is the
    case-schema name, ``.params`` the parameters by case-schema name).
    """

    geometry: GeometrySpec
    material: MaterialLaw
    fibres: FibreSpec = field(default_factory=FibreSpec)
    load: LoadSpec = field(default_factory=lambda: LoadSpec(units.mmhg_to_kpa(conditions.SIMULATOR_DEFAULT_EDP_MMHG)))
    boundary: BoundarySpec = field(default_factory=BoundarySpec)
    probes: tuple[tuple[float, float, float], ...] = ()
    outputs: OutputSpec = field(default_factory=OutputSpec)
    #: Regional stiffness multipliers (``material.regional``); None is a homogeneous material.
    regional: RegionalStiffness | None = None

    __hash__ = None  # holds arrays and dicts

    @classmethod
    def from_dict(cls, d: Mapping, base_dir: str | Path | None = None) -> "Case":
        """Validate a case dictionary (the JSON schema) and build a :class:`Case`.

        Parameters
        ----------
        d : mapping
            The parsed case JSON.
        base_dir : path, optional
            Directory that relative file paths (``geometry.path``,
            ``geometry.model``) are resolved against; default the working
            directory. :func:`load_case` passes the case file's directory.

        Raises
        ------
        CaseError
            Naming the first bad field.
        """
        return _parse_case(d, Path(base_dir) if base_dir is not None else None)

    def to_dict(self) -> dict:
        """The case as a JSON-ready dictionary (pressure in kPa, parameters complete).

        ``Case.from_dict(case.to_dict())`` rebuilds an equal case.
        """
        return _case_to_dict(self)

    def to_json(self, indent: int | None = 2) -> str:
        """The case as JSON text."""
        return json.dumps(self.to_dict(), indent=indent)

    # convenience constructors -------------------------------------------------
    @classmethod
    def default_lv(
        cls,
        theta: Mapping[str, float] | None = None,
        alpha_endo_deg: float = conditions.SIMULATOR_DEFAULT_ANGLES[0],
        alpha_epi_deg: float = conditions.SIMULATOR_DEFAULT_ANGLES[1],
        edp_mmhg: float = conditions.SIMULATOR_DEFAULT_EDP_MMHG,
        resolution: str | Mapping[str, int] = "default",
    ) -> "Case":
        """The default LV with the HO law at ``theta`` (default ``THETA_TILDE``)."""
        theta = dict(conditions.THETA_TILDE if theta is None else theta)
        return cls.from_dict(
            {
                "geometry": {"kind": "default", "resolution": resolution},
                "material": {"law": "holzapfel-ogden", **theta},
                "fibres": {"alpha_endo": alpha_endo_deg, "alpha_epi": alpha_epi_deg},
                "load": {"pressure": edp_mmhg, "units": "mmHg"},
            }
        )


def load_case(path: str | Path) -> Case:
    """Read and validate a case JSON file; relative paths inside resolve against its folder."""
    path = Path(path)
    d = limits.read_json_file(path, limits.MAX_CASE_BYTES, "case file", _file_error)
    if not isinstance(d, Mapping):
        raise CaseError("<file>", f"case file '{limits.echo(path)}' must hold a JSON object ({{\"geometry\": ..., "
                                  f"\"material\": ...}}), not {'null' if d is None else type(d).__name__} "
                                  f"{_short(d, 40)}")
    try:
        return Case.from_dict(d, base_dir=path.parent)
    except CaseError as err:  # name the file as well as the field
        raise CaseError(err.field, f"{err.problem} (case file '{limits.echo(path)}')") from None


def loads_case(text: str, base_dir: str | Path | None = None, source: str = "case JSON") -> Case:
    """Validate a case given as JSON text (e.g. typed into the app), with the same limits as a case file.

    Duplicate keys, non-finite numbers, deep nesting and text longer than
    :data:`lvcore.safety.limits.MAX_CASE_BYTES` are refused with a :class:`CaseError`.
    """
    if len(text.encode("utf-8", "replace")) > limits.MAX_CASE_BYTES:
        raise CaseError("<text>", f"{source} is longer than the limit of {limits.MAX_CASE_BYTES // 1024} kB")
    d = limits.loads_json(text, source, lambda msg: CaseError("<text>", msg))
    return Case.from_dict(d, base_dir=base_dir)


def _file_error(message: str) -> CaseError:
    return CaseError("<file>", message)


# ----------------------------------------------------------------------------
# validation helpers
# ----------------------------------------------------------------------------
def _check_keys(d: Any, where: str, allowed, required=()) -> None:
    if not isinstance(d, Mapping):
        raise CaseError(where or "<case>", f"must be a JSON object, got {type(d).__name__}")
    for key in d:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), list(allowed), n=1, cutoff=0.5)
            hint = f"; did you mean '{close[0]}'?" if close else f"; valid keys: {', '.join(allowed)}"
            raise CaseError(_join(where, limits.echo(key, 60)), f"unknown key{hint}")
    for key in required:
        if key not in d:
            raise CaseError(_join(where, key), "missing (required)")


def _short(value, n: int = 80) -> str:
    """``repr(value)``, cut to ``n`` characters for messages."""
    text = repr(value)
    return text if len(text) <= n else text[: n - 3] + "..."


def _join(where: str, key) -> str:
    return f"{where}.{key}" if where else str(key)


def _number(value, where: str, positive=False, nonnegative=False, lo=None, hi=None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise CaseError(where, f"must be a number, got {type(value).__name__} {_short(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise CaseError(where, f"must be finite, got {x}")
    if positive and x <= 0:
        raise CaseError(where, f"must be > 0, got {x}")
    if nonnegative and x < 0:
        raise CaseError(where, f"must be >= 0, got {x}")
    if lo is not None and x < lo or hi is not None and x > hi:
        raise CaseError(where, f"must lie in [{lo}, {hi}], got {x}")
    return x


def _string(value, where: str, choices) -> str:
    if not isinstance(value, str):
        raise CaseError(where, f"must be a string, one of {', '.join(choices)}; got {_short(value)}")
    if value not in choices:
        close = difflib.get_close_matches(value, list(choices), n=1, cutoff=0.5)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise CaseError(where, f"must be one of {', '.join(choices)}; got '{value}'{hint}")
    return value


def _vector(value, where: str, n=3, positive=False) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise CaseError(where, f"must be a list of {n} numbers, got {_short(value)}")
    return tuple(_number(v, f"{where}[{i}]", positive=positive) for i, v in enumerate(value))


def _resolve(path_value, where: str, base_dir: Path | None, suffixes=()) -> Path:
    if not isinstance(path_value, str) or not path_value:
        raise CaseError(where, f"must be a file path string, got {_short(path_value)}")
    p = Path(path_value).expanduser()
    if not p.is_absolute() and base_dir is not None:
        p = base_dir / p
    if not p.is_file() and not any(p.with_suffix(sfx).is_file() for sfx in suffixes):
        # says "does not exist", "not a regular file (a directory)", ... as the case may be
        limits.check_regular_file(p, float("inf"), "file", lambda msg: CaseError(where, msg))
        raise CaseError(where, f"file '{p}' does not exist")
    return p


# ----------------------------------------------------------------------------
# parsing
# ----------------------------------------------------------------------------
_TOP = ("geometry", "material", "fibres", "load", "boundary", "probes", "outputs", "note")
#: Longest ``note`` (characters): a human-readable remark on the case, ignored by the simulator.
MAX_NOTE_CHARS = 4000


def _parse_case(d: Mapping, base_dir: Path | None) -> Case:
    _check_keys(d, "", _TOP, required=("geometry", "material", "load"))
    note = d.get("note", "")
    if not isinstance(note, str) or len(note) > MAX_NOTE_CHARS:
        raise CaseError("note", f"a remark for the reader: a string of at most {MAX_NOTE_CHARS} characters, got "
                                f"{_short(note, 40) if not isinstance(note, str) else f'{len(note)} characters'}")
    geometry = _parse_geometry(d["geometry"], base_dir)
    material, regional = _parse_material(d["material"], geometry)
    fibres = _parse_fibres(d.get("fibres", {}))
    load = _parse_load(d["load"], geometry)
    boundary = _parse_boundary(d.get("boundary", {}), geometry)
    probes = _parse_probes(d.get("probes", []))
    outputs = _parse_outputs(d.get("outputs", {}))
    return Case(geometry, material, fibres, load, boundary, probes, outputs, regional)


def _parse_resolution(value, where: str, kind: str) -> tuple[LVResolution | BoxResolution | None, str | None]:
    """(explicit resolution, preset name); the bounds are checked by the resolution classes."""
    if value is None:
        return None, None
    if isinstance(value, str):
        return None, _string(value, where, BOX_RESOLUTION_PRESET_NAMES if kind == "box" else RESOLUTION_PRESET_NAMES)
    if kind == "box":
        if isinstance(value, (list, tuple)):
            if len(value) != 3:
                raise CaseError(where, f"a box resolution is [nx, ny, nz], got {_short(value)}")
            counts, paths = value, [f"{where}[{i}]" for i in range(3)]
        else:
            _check_keys(value, where, ("x", "y", "z"), required=("x", "y", "z"))
            counts, paths = [value[k] for k in "xyz"], [f"{where}.{k}" for k in "xyz"]
        try:
            return BoxResolution(*counts), None
        except ResolutionError as err:
            raise CaseError(paths[("nx", "ny", "nz").index(err.field)], err.problem) from None
    keys = ("circumferential", "longitudinal", "transmural")
    _check_keys(value, where, keys + ("transmural_gauss_points",), required=keys)
    long = value["longitudinal"]
    gp = value.get("transmural_gauss_points", 3)
    try:
        if isinstance(long, (list, tuple)):
            res = LVResolution.graded(value["circumferential"], long, value["transmural"], gp)
        else:
            res = LVResolution(value["circumferential"], long, value["transmural"], None, gp)
    except ResolutionError as err:
        raise CaseError(f"{where}.{err.field}", err.problem) from None
    return res, None


def _check_size(counts, kind: str, gauss_points: int, where: str) -> None:
    """Refuse meshes over the limits of :mod:`lvcore.safety.limits` before anything is allocated."""
    limits.check_mesh_size(counts, kind, gauss_points, error=lambda msg: CaseError(where, msg), where="too large")


def _parse_surface(d, where: str) -> EllipsoidSurface:
    _check_keys(d, where, ("rs", "rl", "ry"), required=("rs", "rl"))
    ry = _number(d["ry"], f"{where}.ry", positive=True) if "ry" in d else None
    return EllipsoidSurface(
        rs=_number(d["rs"], f"{where}.rs", positive=True), rl=_number(d["rl"], f"{where}.rl", positive=True), ry=ry
    )


def _parse_geometry(g, base_dir: Path | None) -> GeometrySpec:
    _check_keys(g, "geometry", ("kind", "endo", "epi", "base_z", "resolution", "path", "scores", "model", "size"),
                required=("kind",))
    kind = _string(g["kind"], "geometry.kind", GEOMETRY_KINDS)
    allowed = {
        "ellipsoid": ("kind", "endo", "epi", "base_z", "resolution"),
        "default": ("kind", "resolution"),
        "mesh": ("kind", "path", "resolution"),
        "pca": ("kind", "scores", "model", "resolution"),
        "box": ("kind", "size", "resolution"),
    }[kind]
    for key in g:
        if key not in allowed:
            raise CaseError(f"geometry.{key}", f"not used by geometry kind '{kind}' (allowed: {', '.join(allowed)})")
    resolution, preset = _parse_resolution(g.get("resolution"), "geometry.resolution", kind)

    if kind == "default":
        return GeometrySpec(kind, resolution, preset, ellipsoid=DEFAULT_LV, source="default LV")
    if kind == "ellipsoid":
        for key in ("endo", "epi", "base_z"):
            if key not in g:
                raise CaseError(f"geometry.{key}", "missing (required for an ellipsoid)")
        endo = _parse_surface(g["endo"], "geometry.endo")
        epi = _parse_surface(g["epi"], "geometry.epi")
        base_z = _number(g["base_z"], "geometry.base_z")
        for name, a_in, a_out in (("rs", endo.rs, epi.rs), ("rl", endo.rl, epi.rl),
                                  ("ry", endo.ry or endo.rs, epi.ry or epi.rs)):
            if a_out <= a_in:
                raise CaseError(f"geometry.epi.{name}", f"must exceed the endocardial {name} ({a_in}), got {a_out}")
        for name, surf in (("endo", endo), ("epi", epi)):
            if not -surf.rl < base_z < surf.rl:
                raise CaseError("geometry.base_z", f"the plane z={base_z} must cut the {name} ellipsoid "
                                                   f"(|base_z| < rl = {surf.rl})")
        ell = TruncatedEllipsoidLV(endo, epi, base_z)
        return GeometrySpec(kind, resolution, preset, ellipsoid=ell, source="truncated ellipsoid")
    if kind == "mesh":
        if "path" not in g:
            raise CaseError("geometry.path", "missing (required for geometry kind 'mesh')")
        path = _resolve(g["path"], "geometry.path", base_dir)
        from lvcore.geometry.io import read_template_mesh  # lazy: geometry I/O pulls meshio

        try:
            nodes = read_template_mesh(path)
        except LVCoreError as err:
            raise CaseError("geometry.path", f"cannot use '{path}': {err}") from None
        nodes = _template_nodes(nodes, "geometry.path")
        return GeometrySpec(kind, resolution, preset, template_nodes=nodes, source=str(path),
                            extra={"path": str(path)})
    if kind == "pca":
        if "scores" not in g:
            raise CaseError("geometry.scores", "missing (required for geometry kind 'pca')")
        scores = g["scores"]
        if not isinstance(scores, (list, tuple)) or len(scores) == 0:
            raise CaseError("geometry.scores", f"must be a non-empty list of numbers, got {_short(scores)}")
        if len(scores) > MAX_PC_SCORES:
            raise CaseError("geometry.scores", f"{len(scores)} scores; a shape model has at most {MAX_PC_SCORES} modes")
        # standardised scores (units of each mode's sd): beyond +-10 sd the shape is no LV at all
        scores = [_number(v, f"geometry.scores[{i}]", lo=-MAX_ABS_PC_SCORE, hi=MAX_ABS_PC_SCORE)
                  for i, v in enumerate(scores)]
        model = _resolve(g["model"], "geometry.model", base_dir, suffixes=(".json",)) if "model" in g else None
        from lvcore.geometry.shape_model import load_shape_model  # lazy

        try:
            nodes = load_shape_model(model).reconstruct(np.asarray(scores))
        except LVCoreError as err:
            raise CaseError("geometry.scores" if model is None else "geometry.model", str(err)) from None
        nodes = _template_nodes(nodes, "geometry.scores")
        src = f"PCA scores {scores} of " + (f"shape model {model}" if model else "the bundled SYNTHETIC shape model")
        extra = {"scores": scores, **({"model": str(model)} if model else {})}
        return GeometrySpec(kind, resolution, preset, template_nodes=nodes, source=src, extra=extra)
    # box
    if "size" not in g:
        raise CaseError("geometry.size", "missing (required for a box: [Lx, Ly, Lz] in mm)")
    size = _vector(g["size"], "geometry.size", positive=True)
    if resolution is None:  # a preset: the counts follow from the size
        h = min(size) / BOX_RESOLUTION_PRESETS[preset or "default"]
        _check_size([max(1, math.ceil(min(L / h, 1e9) - 1e-9)) for L in size], "box", 27, "geometry.resolution")
    return GeometrySpec(kind, resolution, preset, box_size=size, source=f"box {size[0]:g} x {size[1]:g} x {size[2]:g} mm")


def _template_nodes(nodes, where: str) -> np.ndarray:
    nodes = np.array(nodes, dtype=float)
    if nodes.shape != (DEFAULT_TEMPLATE.n_nodes, 3):
        raise CaseError(where, f"geometry has node array of shape {nodes.shape}, expected "
                               f"{(DEFAULT_TEMPLATE.n_nodes, 3)} (DEFAULT_TEMPLATE)")
    if not np.all(np.isfinite(nodes)):
        raise CaseError(where, "geometry has non-finite node coordinates")
    nodes.setflags(write=False)
    return nodes


def _parse_material(m, geometry: GeometrySpec) -> tuple[MaterialLaw, RegionalStiffness | None]:
    all_keys = tuple(sorted({k for cls in LAWS.values() for k in cls.keys}))
    _check_keys(m, "material", ("law", "regional") + all_keys, required=("law",))
    cls = LAWS[_string(m["law"], "material.law", MATERIAL_LAWS)]
    _check_keys(m, "material", ("law", "regional") + cls.keys, required=cls.required)
    params = {}
    for k in cls.keys:
        if k not in m:
            params[k] = cls.optional[k]
            continue
        params[k] = _number(m[k], f"material.{k}")
        problem = cls.parameter_problem(k, params[k])
        if problem:
            raise CaseError(f"material.{k}", problem)
    law = cls.from_params(params)
    regional = _parse_regional(m["regional"], law, geometry) if "regional" in m else None
    return law, regional


def _parse_regional(r, law: MaterialLaw, geometry: GeometrySpec) -> RegionalStiffness:
    where = "material.regional"
    if not geometry.is_lv:
        raise CaseError(where, "regional stiffness needs an LV geometry (a box has no regions)")
    _check_keys(r, where, law.stress_keys)
    if not r:
        raise CaseError(where, f"give at least one of {', '.join(law.stress_keys)} with {N_REGIONS} multipliers")
    lo, hi = REGIONAL_FACTOR_RANGE
    factors = {}
    for key, v in r.items():
        if not isinstance(v, (list, tuple)) or len(v) != N_REGIONS:
            raise CaseError(f"{where}.{key}", f"must be a list of {N_REGIONS} multipliers (one per region 0-23), "
                                              f"got {_short(v)}")
        factors[key] = tuple(_number(x, f"{where}.{key}[{i}]", lo=lo, hi=hi) for i, x in enumerate(v))
    return RegionalStiffness(factors)


def _parse_fibres(f) -> FibreSpec:
    _check_keys(f, "fibres", ("alpha_endo", "alpha_epi", "direction"))
    if "direction" in f:
        if "alpha_endo" in f or "alpha_epi" in f:
            raise CaseError("fibres.direction", "give either a direction or the angles alpha_endo/alpha_epi, not both")
        v = np.asarray(_vector(f["direction"], "fibres.direction"), dtype=float)
        scale = float(np.max(np.abs(v)))  # scaled first: the norm of (1e308, 1e308, 1e308) overflows to inf
        if not scale > 0.0:
            raise CaseError("fibres.direction", "must be a non-zero vector")
        v = v / scale
        return FibreSpec(direction=tuple(float(x) for x in v / float(np.linalg.norm(v))))
    endo = _number(f.get("alpha_endo", conditions.SIMULATOR_DEFAULT_ANGLES[0]), "fibres.alpha_endo", lo=-180, hi=180)
    epi = _number(f.get("alpha_epi", conditions.SIMULATOR_DEFAULT_ANGLES[1]), "fibres.alpha_epi", lo=-180, hi=180)
    return FibreSpec(endo, epi)


def _parse_load(ld, geometry: GeometrySpec) -> LoadSpec:
    _check_keys(ld, "load", ("pressure", "units", "surface"), required=("pressure", "units"))
    p = _number(ld["pressure"], "load.pressure", nonnegative=True)
    u = ld["units"]
    if not isinstance(u, str) or u.lower() not in PRESSURE_UNITS:
        raise CaseError("load.units", f"must be 'kPa' or 'mmHg', got {_short(u)}")
    p_kpa = p * PRESSURE_UNITS[u.lower()]
    if geometry.is_lv:
        surface = _string(ld.get("surface", "endocardium"), "load.surface", ("endocardium",))
    else:
        if "surface" not in ld:
            raise CaseError("load.surface", f"missing (required for a box: one of {', '.join(BOX_FACES)})")
        surface = _string(ld["surface"], "load.surface", BOX_FACES)
    return LoadSpec(p_kpa, surface)


def _parse_boundary(b, geometry: GeometrySpec) -> BoundarySpec:
    if geometry.is_lv:
        _check_keys(b, "boundary", ("base", "epicardial_spring"))
        k, direction = 0.0, "normal"
        if "epicardial_spring" in b:
            sp = b["epicardial_spring"]
            _check_keys(sp, "boundary.epicardial_spring", ("k", "direction"), required=("k",))
            k = _number(sp["k"], "boundary.epicardial_spring.k", lo=0.0, hi=MAX_SPRING_KPA_PER_MM)
            direction = _string(sp.get("direction", "normal"), "boundary.epicardial_spring.direction",
                                SPRING_DIRECTIONS)
        return BoundarySpec(_string(b.get("base", "clamped"), "boundary.base", BASE_CONDITIONS), (), k, direction)
    if "epicardial_spring" in b:
        raise CaseError("boundary.epicardial_spring", "needs an LV geometry (a box has no epicardium)")
    _check_keys(b, "boundary", ("clamped",), required=("clamped",))
    faces = b["clamped"]
    if not isinstance(faces, (list, tuple)) or not faces:
        raise CaseError("boundary.clamped", f"must be a non-empty list of faces ({', '.join(BOX_FACES)}), got {_short(faces)}")
    faces = tuple(_string(v, f"boundary.clamped[{i}]", BOX_FACES) for i, v in enumerate(faces))
    return BoundarySpec(None, faces)


def _parse_probes(p) -> tuple[tuple[float, float, float], ...]:
    if not isinstance(p, (list, tuple)):
        raise CaseError("probes", f"must be a list of [x, y, z] points (mm), got {_short(p)}")
    if len(p) > limits.MAX_PROBES:
        raise CaseError("probes", f"{len(p):,} points is more than the limit of {limits.MAX_PROBES:,} "
                                  "(lvcore.safety.limits.MAX_PROBES)")
    return tuple(_vector(v, f"probes[{i}]") for i, v in enumerate(p))


def _parse_outputs(o) -> OutputSpec:
    _check_keys(o, "outputs", ("strain_layer",))
    name = _string(o.get("strain_layer", DEFAULT_STRAIN_LAYER), "outputs.strain_layer",
                   tuple(STRAIN_LAYERS) + tuple(STRAIN_LAYER_ALIASES))
    return OutputSpec(STRAIN_LAYER_ALIASES.get(name, name))


# ----------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------
def _case_to_dict(case: Case) -> dict:
    g = case.geometry
    gd: dict[str, Any] = {"kind": g.kind}
    if g.kind == "ellipsoid":
        for name, surf in (("endo", g.ellipsoid.endo), ("epi", g.ellipsoid.epi)):
            gd[name] = {"rs": surf.rs, "rl": surf.rl, **({"ry": surf.ry} if surf.ry is not None else {})}
        gd["base_z"] = g.ellipsoid.base_z
    elif g.kind == "mesh":
        gd["path"] = g.extra["path"]
    elif g.kind == "pca":
        gd["scores"] = list(g.extra["scores"])
        if "model" in g.extra:
            gd["model"] = g.extra["model"]
    elif g.kind == "box":
        gd["size"] = list(g.box_size)
    if g.kind == "box" and g.resolution is not None:
        gd["resolution"] = list(g.resolution.xyz)
    elif g.resolution is not None:
        gd["resolution"] = g.resolution.case_dict()
    elif g.preset is not None:
        gd["resolution"] = g.preset

    f = case.fibres
    fd = {"direction": list(f.direction)} if f.direction is not None else {
        "alpha_endo": f.alpha_endo_deg, "alpha_epi": f.alpha_epi_deg}
    bd = {"base": case.boundary.base} if g.is_lv else {"clamped": list(case.boundary.clamped_faces)}
    if g.is_lv and case.boundary.epicardial_spring > 0:
        bd["epicardial_spring"] = {"k": case.boundary.epicardial_spring, "direction": case.boundary.spring_direction}
    md = {"law": case.material.law, **{k: float(v) for k, v in case.material.params.items()}}
    if case.regional is not None:
        md["regional"] = {k: list(v) for k, v in case.regional.factors.items()}
    return {
        "geometry": gd,
        "material": md,
        "fibres": fd,
        "load": {"pressure": case.load.pressure_kpa, "units": "kPa", "surface": case.load.surface},
        "boundary": bd,
        "probes": [list(p) for p in case.probes],
        "outputs": {"strain_layer": case.outputs.strain_layer},
    }
