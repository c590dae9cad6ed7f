"""A subject's geometry for a subject emulator: what the user has, as the simulator's case ``geometry`` section.

:func:`resolve_subject_geometry` turns a template mesh, a volumetric tet/hex mesh, a contour stack, a case file,
PC scores or ``default`` into a :class:`SubjectGeometry`; :func:`subject_template_nodes` gives the template nodes
(mm) of any case geometry section. Used by :mod:`lvcore.emulator.subject` (which re-exports these names).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from lvcore.safety import limits
from lvcore.exceptions import GeometryError
from lvcore.domain.outputs import THETA_NAMES

#: The geometry file written into the emulator directory (template nodes, mm).
GEOMETRY_FILE = "geometry.vtu"
#: Suffixes read as volumetric meshes only (fitted with :mod:`lvcore.geometry.volume_mesh`).
VOLUME_MESH_SUFFIXES = (".inp", ".msh", ".med", ".mesh")
#: Template-mesh suffixes; a file that is not the template's 27-node hexahedra is fitted as a volume mesh.
MESH_SUFFIXES = (".vtu", ".vtk", ".xdmf")


@dataclass(frozen=True)
class SubjectGeometry:
    """A subject's geometry as the simulator's case section.

    Attributes
    ----------
    section : dict
        The case's ``geometry`` section (``kind`` ``mesh``, ``pca``,
        ``default`` or ``ellipsoid``), without a resolution.
    source : str
        What it came from (the file, or ``default``).
    kind : str
        ``template-mesh``, ``volume-mesh`` (fitted), ``contours`` (fitted),
        ``case``, ``scores`` or ``default``.
    nodes : ndarray or None
        Template node positions (mm) for geometries fitted or read as a mesh.
    record : dict
        Fit residuals and the like (JSON-ready).
    warnings : tuple of str
    """

    section: dict
    source: str
    kind: str
    nodes: np.ndarray | None = field(default=None, repr=False)
    record: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()


def resolve_subject_geometry(spec, *, units: str = "mm") -> SubjectGeometry:
    """The case geometry of ``spec``: a file path or ``"default"``.

    Parameters
    ----------
    spec : str or Path
        ``default`` (the default LV); a template mesh (``.vtu``: the one
        ``lvcore geometry fit --out`` writes); a volumetric tet/hex mesh
        (``.inp``, ``.msh``, ``.med``, ``.mesh``, or a ``.vtu``/``.vtk``/
        ``.xdmf`` that is not a template mesh), fitted as ``lvcore geometry
        fit --mesh`` does; a contour stack (JSON, schema ``lvcore.contours``),
        fitted; a case file (JSON with a ``geometry`` section); or PC scores
        (JSON/CSV, reconstructed by the shape model exactly as a ``pca``
        case geometry is).
    units : {"mm", "cm", "m"}
        Units of a volumetric mesh.

    Raises
    ------
    GeometryError
        Naming the file and what to give instead.
    """
    if spec is None or str(spec).strip() == "":
        raise GeometryError("--geometry is required: a template mesh (.vtu), a volumetric mesh (.inp/.msh/.vtu), "
                            "a contour stack or case file (.json), PC scores (.json/.csv) or 'default'")
    if str(spec).strip().lower() == "default":
        return SubjectGeometry({"kind": "default"}, "default", "default")
    path = Path(spec)
    if not path.is_file():
        raise GeometryError(f"--geometry {spec}: no such file (give a mesh, contour stack, case file or PC scores, "
                            "or 'default')")
    suffix = path.suffix.lower()
    if suffix in VOLUME_MESH_SUFFIXES:
        return _volume_mesh(path, units)
    if suffix in MESH_SUFFIXES:
        from lvcore.geometry.io import read_template_mesh

        try:
            nodes = read_template_mesh(path)
        except GeometryError as err:
            if "27-node hexahedra" in str(err) or "points, the template has" in str(err):
                return _volume_mesh(path, units)
            raise
        return _nodes_geometry(nodes, str(path), "template-mesh", {})
    if suffix == ".json":
        obj = limits.read_json_file(path, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
        if isinstance(obj, dict) and str(obj.get("schema", "")).startswith("lvcore.contours"):
            from lvcore.geometry.fitting import fit_contours

            res = fit_contours(path)
            return _nodes_geometry(res.nodes, str(path), "contours", {"fit_residual_mm": float(res.residual_mean_mm)},
                                   tuple(getattr(res, "warnings", ()) or ()))
        if isinstance(obj, dict) and "geometry" in obj:
            return _case_geometry(obj["geometry"], path)
    if suffix in (".json", ".csv"):
        from lvcore.geometry.scores import read_pc_scores

        read_pc_scores(path, n_pc=1)  # a clear error for a file that holds no scores
        h = _all_scores(path)
        return SubjectGeometry({"kind": "pca", "scores": [float(v) for v in h]}, str(path), "scores")
    raise GeometryError(f"--geometry {path.name}: unknown format '{suffix}'; give a template mesh (.vtu), a volumetric "
                        f"mesh ({', '.join(VOLUME_MESH_SUFFIXES)}, .vtu), a contour stack or case file (.json), "
                        "PC scores (.json/.csv) or 'default'")


def _all_scores(path: Path) -> list[float]:
    """Every PC score of a scores file, up to the shape model's number of modes (a case uses them all)."""
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.geometry.scores import read_pc_scores

    for n in range(int(load_shape_model().n_modes), 1, -1):
        try:
            return [float(v) for v in read_pc_scores(path, n_pc=n)]
        except GeometryError:
            continue
    return [float(v) for v in read_pc_scores(path, n_pc=1)]


def _volume_mesh(path: Path, units: str) -> SubjectGeometry:
    from lvcore.geometry.volume_mesh import fit_volume_mesh

    res = fit_volume_mesh(path, units=units)
    record = {"fit_residual_mm": float(res.fit.residual_mean_mm),
              "mesh_cavity_volume_ml": float(res.boundary.cavity_volume_ml)}
    return _nodes_geometry(res.fit.nodes, str(path), "volume-mesh", record,
                           tuple(res.boundary.warnings) + tuple(res.fit.warnings))


def _nodes_geometry(nodes, source: str, kind: str, record: dict, warnings: tuple = ()) -> SubjectGeometry:
    from lvcore.geometry.measures import geometry_info

    nodes = np.asarray(nodes, dtype=float)
    info = geometry_info(nodes)
    record = {**record, **{k: v for k, v in info.items() if isinstance(v, (int, float))}}
    return SubjectGeometry({"kind": "mesh", "path": None}, source, kind, nodes, record, tuple(warnings))


def _case_geometry(section, path: Path) -> SubjectGeometry:
    from lvcore.mechanics.case import Case

    if not isinstance(section, dict) or "kind" not in section:
        raise GeometryError(f"{path.name}: the case's 'geometry' section must be an object with a 'kind'")
    section = {k: v for k, v in section.items() if k != "resolution"}
    if section.get("kind") == "box":
        raise GeometryError(f"{path.name}: a box is not an LV geometry; give an LV case, mesh or contours")
    for key in ("path", "model"):  # relative to the case file, as the case reader does
        if key in section and not Path(str(section[key])).is_absolute():
            section[key] = str((path.parent / str(section[key])).resolve())
    from lvcore.mechanics.case_inputs import build_case

    try:
        Case.from_dict(build_case({n: 1.0 for n in THETA_NAMES}, geometry=section, resolution="coarse"))
    except Exception as err:  # noqa: BLE001 - reported with the file's name
        raise GeometryError(f"{path.name}: its geometry section cannot be used: {err}") from None
    if section["kind"] == "mesh":
        from lvcore.geometry.io import read_template_mesh

        return _nodes_geometry(read_template_mesh(section["path"]), str(path), "case", {})
    return SubjectGeometry(section, str(path), "case")



def subject_template_nodes(section: Mapping) -> np.ndarray:
    """Template node positions (mm) of a case ``geometry`` section (mesh, PC scores, ellipsoid or default)."""
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.geometry.template import DEFAULT_TEMPLATE
    from lvcore.mechanics.case import Case

    spec = Case.from_dict(build_case({n: 1.0 for n in THETA_NAMES}, geometry=dict(section),
                                     resolution="coarse")).geometry
    if spec.template_nodes is not None:
        return np.asarray(spec.template_nodes, dtype=float)
    if spec.ellipsoid is not None:
        return np.asarray(spec.ellipsoid.nodes(DEFAULT_TEMPLATE), dtype=float)
    raise GeometryError(f"geometry kind '{spec.kind}' has no LV template nodes")


__all__ = ["SubjectGeometry", "GEOMETRY_FILE", "VOLUME_MESH_SUFFIXES", "MESH_SUFFIXES", "resolve_subject_geometry",
           "subject_template_nodes"]
