"""Endocardial and epicardial surface meshes: reading and validation.

Any format PyVista reads (VTK, VTP, VTU, STL, PLY, OBJ, ...) is accepted, with
meshio as a fall-back reader. The surfaces must be open at the base (the LV is
truncated at the base plane): the boundary loop of the endocardium defines the
base. Lengths in mm (metres and centimetres are detected by size).
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lvcore.exceptions import GeometryError
from lvcore.geometry.io import check_extent_is_mm

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

#: Extensions handed to PyVista first.
SURFACE_EXTENSIONS = (".vtk", ".vtp", ".vtu", ".stl", ".ply", ".obj", ".off", ".gii")


@dataclass(frozen=True)
class LVSurface:
    """A triangulated surface (mm): vertices, triangles and its open boundary points."""

    name: str
    points: np.ndarray  # (n, 3)
    triangles: np.ndarray  # (m, 3) int
    boundary: np.ndarray  # (b, 3) points on open boundary edges (may be empty)
    source: str = ""

    def sample(self, n_min: int = 3000) -> np.ndarray:
        """Vertices plus triangle centroids (and more, if needed) as a point cloud (mm)."""
        tri = self.points[self.triangles]
        pts = [self.points, tri.mean(axis=1)]
        total = sum(len(p) for p in pts)
        if total < n_min and len(tri):
            rng = np.random.default_rng(0)
            k = int(np.ceil((n_min - total) / len(tri)))
            w = rng.dirichlet(np.ones(3), size=(len(tri), k))
            pts.append(np.einsum("tkj,tjd->tkd", w, tri).reshape(-1, 3))
        return np.concatenate(pts, axis=0)

    def area(self) -> float:
        tri = self.points[self.triangles]
        return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())


def read_surface(path_or_mesh, name: str = "surface", units: str = "mm") -> LVSurface:
    """Read an LV surface from a file or a PyVista mesh and check it.

    A file is first checked for its size and for the counts its header
    declares (:func:`lvcore.safety.headers.check_mesh_header`), then parsed by
    VTK/meshio in a memory-limited child process (:func:`lvcore.safety.isolation.run_isolated`),
    so a crafted file that crashes the parser raises a :class:`GeometryError`
    naming it instead of killing the caller (or the app's server).

    Parameters
    ----------
    path_or_mesh : str, Path or pyvista.DataSet
    name : str
        "endo" or "epi", used in messages.
    units : {"mm", "cm", "m"}
        Units of the file's coordinates (converted to mm).

    Raises
    ------
    GeometryError
        Missing, empty or unreadable file; no surface cells; wrong units.
    """
    if isinstance(path_or_mesh, (str, Path)):
        from lvcore.safety import limits
        from lvcore.safety.headers import check_mesh_header
        from lvcore.safety.isolation import run_isolated

        what = "surface file" if name == "surface" else f"{name} surface file"
        path = limits.check_regular_file(path_or_mesh, limits.MAX_SURFACE_BYTES, what, GeometryError)
        check_mesh_header(path, what, GeometryError)
        return run_isolated(_read_surface, path, name, units, what=what, path=path, error=GeometryError)
    return _read_surface(path_or_mesh, name, units)


def _read_surface(path_or_mesh, name: str, units: str) -> LVSurface:
    """:func:`read_surface` in this process (for files: called in the isolated child)."""
    import pyvista as pv

    scale = {"mm": 1.0, "cm": 10.0, "m": 1000.0}.get(units)
    if scale is None:
        raise GeometryError(f"{name} surface: units '{units}' not understood; use mm, cm or m")
    source = "<mesh>"
    if isinstance(path_or_mesh, (str, Path)):
        from lvcore.safety import limits

        path = limits.check_regular_file(path_or_mesh, limits.MAX_SURFACE_BYTES, f"{name} surface file", GeometryError)
        source = str(path)
        mesh = None
        errors = []
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                mesh = pv.read(path)
        except (Exception, SystemExit) as err:
            errors.append(_reader_problem("VTK", err))
        if mesh is None or mesh.n_points == 0:
            try:
                import meshio

                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    m = meshio.read(path)
                mesh = pv.from_meshio(m)
            except (Exception, SystemExit) as err:
                errors.append(_reader_problem("meshio", err))
        if mesh is None or mesh.n_points == 0:
            errors = errors or ["no points found"]
            suffix = path.suffix.lower()
            if suffix in SURFACE_EXTENSIONS:
                what_to_do = (f"it is not a valid {suffix[1:].upper()} file: export the {name} surface again from "
                              "your segmentation tool (STL, VTK, PLY or OBJ, open at the base)")
            else:
                what_to_do = (f"'{suffix or '(no extension)'}' is not a surface format: save it as one of "
                              f"{', '.join(SURFACE_EXTENSIONS)}")
            raise GeometryError(f"cannot read {name} surface '{path}': {what_to_do} ({'; '.join(errors)})")
    else:
        mesh = path_or_mesh
    try:
        surf = mesh.extract_surface(algorithm="dataset_surface") if not isinstance(mesh, pv.PolyData) else mesh
    except TypeError:
        surf = mesh.extract_surface() if not isinstance(mesh, pv.PolyData) else mesh
    surf = surf.triangulate().clean()
    if surf.n_points == 0 or surf.n_cells == 0:
        raise GeometryError(f"{name} surface '{source}' has no surface cells (found {surf.n_points} points); "
                            "give a triangulated or polygonal surface mesh")
    faces = surf.faces.reshape(-1, 4)
    if not np.all(faces[:, 0] == 3):
        raise GeometryError(f"{name} surface '{source}' could not be triangulated")
    pts = np.asarray(surf.points, dtype=float) * scale
    if not np.all(np.isfinite(pts)):
        raise GeometryError(f"{name} surface '{source}' has NaN or inf coordinates")
    check_extent_is_mm(float(np.ptp(pts, axis=0).max()), f"{name} surface '{source}'",
                       "pass units='m' (CLI: --units m) or convert to mm",
                       "pass units='cm' (CLI: --units cm) or convert to mm", max_mm=500.0)
    edges = surf.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False,
                                       non_manifold_edges=False)
    boundary = np.asarray(edges.points, dtype=float) * scale if edges.n_points else np.zeros((0, 3))
    return LVSurface(name=name, points=pts, triangles=faces[:, 1:].astype(np.int64), boundary=boundary, source=source)


def _reader_problem(reader: str, err: BaseException) -> str:
    """What a reader's exception says, in words a user can act on (never a bare exit status or codec text)."""
    if isinstance(err, SystemExit):
        return f"{reader} gave up on its contents"
    if isinstance(err, UnicodeDecodeError):
        return f"{reader} found binary data where text was expected"
    text = " ".join(str(err).split())
    if not text or "produced no output" in text:
        return f"{reader} found no mesh in it"
    return f"{reader}: {text[:120]}"


def check_surface_pair(endo: LVSurface, epi: LVSurface) -> None:
    """Raise GeometryError if the pair cannot be an LV (closed endocardium, swapped)."""
    if len(endo.boundary) < 3:
        raise GeometryError(f"endocardial surface '{endo.source}' is closed; cut it at the base so it is open there "
                            "(its boundary loop defines the base plane)")
    size_endo = np.ptp(endo.points, axis=0).max()
    size_epi = np.ptp(epi.points, axis=0).max()
    if endo.area() > epi.area() and size_endo >= size_epi:
        raise GeometryError(f"the endocardial surface ('{endo.source}', area {endo.area():.0f} mm²) is larger than the "
                            f"epicardial one ('{epi.source}', {epi.area():.0f} mm²); they look swapped")
