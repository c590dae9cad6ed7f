"""LV geometry from a volumetric mesh (tetrahedra or hexahedra, any format meshio reads).

A user's pipeline usually ends in a volumetric LV mesh (ABAQUS ``.inp``, gmsh
``.msh``, VTU, XDMF, ...) rather than separate endo/epi surfaces. This module
splits such a mesh into the surfaces :func:`lvcore.geometry.fitting.fit_surfaces`
needs, then fits the template.

Method
------
1. **Boundary.** Every element face (tetrahedron: 4 triangles; hexahedron: 6
   quadrilaterals, each split into 2 triangles; quadratic elements use their
   corner nodes) that belongs to exactly one element is a boundary face; it is
   oriented outwards (away from its element's centroid).
2. **Base.** The base is the largest *planar* patch of the boundary: for up to
   :data:`N_CANDIDATES` candidate faces, the area of boundary faces whose
   normal lies within :data:`PLANE_ANGLE_DEG` of the candidate's and whose
   centroid lies within :data:`PLANE_TOL_FRACTION` of the mesh size of its
   plane is summed; the best candidate's plane is refitted (area-weighted)
   and its faces form the basal cap. Its outward normal is the long axis,
   pointing from the apex to the base; the cap must be roughly orthogonal to
   the mesh's principal (longest) axis, else a warning is given.
2b. **A base that is not one flat patch** (walls that meet at a shared
   ring, an oblique-and-uneven or notched cap): when removing the largest
   planar patch does not leave two pieces, the boundary is split at its
   sharp edges instead: faces are joined across an edge when their normals
   differ by less than :data:`FEATURE_DEG`; the two largest smooth pieces
   are the endocardium (the one enclosing the smaller volume once its
   openings are closed) and the epicardium, the rest is the base. The base
   itself is then found and cut by :mod:`lvcore.geometry.base_plane` in the
   surface fit (step 4).
3. **Endo vs epi.** Without the cap the boundary falls into exactly two
   connected pieces. Each piece, closed by the base plane, encloses a volume
   ``V = |Σ_f ((c_f − p_0)·n_b)(n_b·N_f) A_f|`` (divergence theorem with the
   field ``((x − p_0)·n_b) n_b``, exact for flat faces); the smaller is the
   endocardium, and its ``V`` is the mesh's own cavity volume.
4. **Fit.** The two pieces (open at the base) go to
   :func:`~lvcore.geometry.fitting.fit_surfaces`, which builds the frame,
   fits the template and measures the residual.

All lengths in mm (``units`` converts cm or m on reading).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lvcore.exceptions import GeometryError
from lvcore.geometry.base_plane import ZERO_VOLUME_FRACTION
from lvcore.geometry.io import check_extent_is_mm, read_meshio_file
from lvcore.geometry.surfaces import LVSurface

#: Unit -> mm factor.
UNIT_SCALE = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
#: Normals within this angle (deg) of the candidate's count as coplanar.
PLANE_ANGLE_DEG = 5.0
#: Centroids within this fraction of the mesh's largest extent of the plane count as on it.
PLANE_TOL_FRACTION = 0.01
#: Number of candidate faces tried for the basal plane.
N_CANDIDATES = 400
#: Largest angle (deg) between the base normal and the principal axis before a warning.
AXIS_WARN_DEG = 30.0
#: Boundary faces whose normals differ by more than this (deg) are not joined when the base is not flat.
FEATURE_DEG = 60.0

# Corner faces of a tetrahedron and a hexahedron (VTK/meshio node order).
_TET_FACES = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
_HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
#: meshio cell types accepted, with their number of corner nodes.
VOLUME_CELL_TYPES = {"tetra": 4, "tetra10": 4, "hexahedron": 8, "hexahedron20": 8, "hexahedron24": 8,
                     "hexahedron27": 8}
_SURFACE_CELL_TYPES = ("triangle", "triangle6", "quad", "quad8", "quad9", "polygon")


@dataclass(frozen=True)
class LVBoundary:
    """The boundary of a volumetric LV mesh, split into endocardium, epicardium and base (mm).

    Attributes
    ----------
    endo, epi : LVSurface
        Open at the base, outward-oriented triangles (scanner coordinates, mm).
    base_origin : (3,) array
        Area-weighted centroid of the basal cap (mm).
    base_normal : (3,) array
        Unit outward normal of the basal cap (points from the apex to the base).
    base_flatness_mm : float
        RMS distance of the cap's face centroids from its plane (mm).
    n_tets, n_hexes : int
        Volume elements read.
    n_faces : dict
        Boundary triangles per piece: ``{"endo": .., "epi": .., "base": ..}``.
    cavity_volume_ml : float
        Volume enclosed by the endocardial piece and the base plane (mL), from
        the mesh itself.
    wall_volume_ml : float
        Volume of the mesh's elements (mL).
    source : str
    warnings : tuple of str
    """

    endo: LVSurface
    epi: LVSurface
    base_origin: np.ndarray
    base_normal: np.ndarray
    base_flatness_mm: float
    n_tets: int
    n_hexes: int
    n_faces: dict
    cavity_volume_ml: float
    wall_volume_ml: float
    source: str = ""
    warnings: tuple = field(default=())

    def summary(self) -> dict:
        return {
            "source": self.source,
            "n_tets": self.n_tets,
            "n_hexes": self.n_hexes,
            "boundary_triangles": dict(self.n_faces),
            "base_normal": [float(v) for v in self.base_normal],
            "base_flatness_mm": self.base_flatness_mm,
            "mesh_cavity_volume_ml": self.cavity_volume_ml,
            "mesh_wall_volume_ml": self.wall_volume_ml,
            "warnings": list(self.warnings),
        }


@dataclass(frozen=True)
class VolumeMeshFit:
    """A template fitted to a volumetric mesh: the fit and the extracted boundary."""

    fit: object  # lvcore.geometry.fitting.FitResult
    boundary: LVBoundary

    def summary(self) -> dict:
        s = self.fit.summary()
        s["warnings"] = list(self.boundary.warnings) + list(s.get("warnings", []))
        s["mesh"] = self.boundary.summary()
        s["cavity_volume_change_pct"] = 100.0 * (self.fit.cavity_volume_ml - self.mesh_cavity_ml) / self.mesh_cavity_ml
        s["mesh_cavity_below_cut_ml"] = self.mesh_cavity_ml
        return s

    @property
    def mesh_cavity_ml(self) -> float:
        """The mesh's own cavity (mL) over the part the fit kept: below the base cut when the base was cut."""
        base = getattr(self.fit, "base", None)
        if base is not None and base.cut_depth_mm > 0:
            return float(base.cavity_kept_ml)
        return float(self.boundary.cavity_volume_ml)


# ----------------------------------------------------------------------------- reading
def read_volume_cells(path_or_mesh, units: str = "mm"):
    """Points (mm) and volume cells of a mesh file or a ``meshio.Mesh``.

    Returns
    -------
    points : (n, 3) float array (mm)
    tets : (n_t, 4) int array, corner nodes
    hexes : (n_h, 8) int array, corner nodes
    source : str
    """
    import meshio

    scale = UNIT_SCALE.get(units)
    if scale is None:
        raise GeometryError(f"volume mesh: units '{units}' not understood; use mm, cm or m")
    if isinstance(path_or_mesh, meshio.Mesh):
        mesh, source = path_or_mesh, "<mesh>"
    else:
        from lvcore.safety import limits

        path = Path(path_or_mesh)
        source = str(path)
        if not path.exists():
            raise GeometryError(f"volume mesh '{path}' does not exist")
        mesh = read_meshio_file(path, "volume mesh", limits.MAX_SURFACE_BYTES,
                                "give a format meshio reads (.inp, .msh, .vtu, .vtk, .xdmf, .med, ...)")
    pts = np.asarray(mesh.points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3) or len(pts) == 0:
        raise GeometryError(f"volume mesh '{source}' has no 3-D points")
    if pts.shape[1] == 2:
        raise GeometryError(f"volume mesh '{source}' is two-dimensional; an LV mesh needs 3-D points")
    pts = pts * scale
    tets, hexes, others = [], [], set()
    for block in mesh.cells:
        if block.type in VOLUME_CELL_TYPES:
            corners = np.asarray(block.data, dtype=np.int64)[:, :VOLUME_CELL_TYPES[block.type]]
            (tets if VOLUME_CELL_TYPES[block.type] == 4 else hexes).append(corners)
        elif block.type not in _SURFACE_CELL_TYPES and block.type not in ("line", "line3", "vertex"):
            others.add(block.type)
    if not tets and not hexes:
        found = sorted({b.type for b in mesh.cells})
        hint = ("it holds surface cells only: pass the endocardial and epicardial surfaces with --endo/--epi"
                if set(found) & set(_SURFACE_CELL_TYPES) else "export the mesh with tetrahedra or hexahedra")
        raise GeometryError(f"volume mesh '{source}' has no tetrahedra or hexahedra (cell types {found or 'none'}); "
                            f"{hint}")
    if others:
        raise GeometryError(f"volume mesh '{source}' mixes unsupported volume cells {sorted(others)} with "
                            "tetrahedra/hexahedra; convert it to tetrahedra or hexahedra only")
    tets = np.concatenate(tets) if tets else np.zeros((0, 4), np.int64)
    hexes = np.concatenate(hexes) if hexes else np.zeros((0, 8), np.int64)
    n = len(pts)
    for name, c in (("tetrahedra", tets), ("hexahedra", hexes)):
        if c.size and (c.min() < 0 or c.max() >= n):
            raise GeometryError(f"volume mesh '{source}': {name} reference points outside the point list")
    used = np.unique(np.concatenate([tets.ravel(), hexes.ravel()]))
    if not np.all(np.isfinite(pts[used])):
        raise GeometryError(f"volume mesh '{source}' has NaN or inf coordinates")
    check_extent_is_mm(float(np.ptp(pts[used], axis=0).max()), f"volume mesh '{source}'",
                       "pass units='m' (CLI: --units m) or convert to mm",
                       "pass units='cm' (CLI: --units cm) or convert to mm", max_mm=500.0)
    return pts, tets, hexes, source


# ----------------------------------------------------------------------------- boundary
def boundary_triangles(points, tets, hexes) -> tuple[np.ndarray, float]:
    """Outward-oriented boundary triangles of a tet/hex mesh, and the mesh volume (mm³).

    A face is on the boundary when no other element shares it (faces are
    matched by their sorted corner nodes). Orientation: the face normal points
    away from its element's centroid.
    """
    points = np.asarray(points, float)
    faces, centroids, volume = [], [], 0.0
    if len(tets):
        f = tets[:, _TET_FACES]  # (t, 4, 3)
        faces.append(f.reshape(-1, 3))
        centroids.append(np.repeat(points[tets].mean(axis=1), 4, axis=0))
        x = points[tets]
        volume += float(np.abs(np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]),
                                         x[:, 3] - x[:, 0])).sum() / 6.0)
    quads, qcent = None, None
    if len(hexes):
        quads = hexes[:, _HEX_FACES].reshape(-1, 4)
        qcent = np.repeat(points[hexes].mean(axis=1), 6, axis=0)
        # hexahedron volume: 6 tetrahedra about the diagonal 0-6
        x = points[hexes]
        for a, b, c in ((1, 2, 6), (2, 3, 6), (3, 7, 6), (7, 4, 6), (4, 5, 6), (5, 1, 6)):
            volume += float(np.abs(np.einsum("ij,ij->i", np.cross(x[:, a] - x[:, 0], x[:, b] - x[:, 0]),
                                             x[:, c] - x[:, 0])).sum() / 6.0)
    tris_out = []
    if faces:
        tri = np.concatenate(faces)
        cen = np.concatenate(centroids)
        key = np.sort(tri, axis=1)
        _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        keep = cnt[inv.ravel()] == 1
        tris_out.append((tri[keep], cen[keep]))
    if quads is not None:
        key = np.sort(quads, axis=1)
        _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        keep = cnt[inv.ravel()] == 1
        q, c = quads[keep], qcent[keep]
        tris_out.append((np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]]), np.concatenate([c, c])))
    tri = np.concatenate([t for t, _ in tris_out])
    cen = np.concatenate([c for _, c in tris_out])
    x = points[tri]
    nrm = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    flip = np.einsum("ij,ij->i", nrm, x.mean(axis=1) - cen) < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    return tri, volume


def _triangle_geometry(points, tri):
    x = points[tri]
    cr = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    area = 0.5 * np.linalg.norm(cr, axis=1)
    normal = cr / np.maximum(2.0 * area, 1e-300)[:, None]
    return x.mean(axis=1), normal, area


def find_base_cap(points, tri, angle_deg: float = PLANE_ANGLE_DEG, tol_fraction: float = PLANE_TOL_FRACTION,
                  n_candidates: int = N_CANDIDATES) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The largest planar patch of a boundary (see the module docstring).

    Returns
    -------
    mask : (m,) bool, the cap's triangles
    origin : (3,) area-weighted cap centroid (mm)
    normal : (3,) unit outward normal of the cap
    flatness : RMS distance of the cap's centroids from its plane (mm)
    """
    cen, nrm, area = _triangle_geometry(points, tri)
    tol = tol_fraction * float(np.ptp(points[np.unique(tri)], axis=0).max())
    cos_a = np.cos(np.radians(angle_deg))
    rng = np.random.default_rng(0)
    cand = np.arange(len(tri)) if len(tri) <= n_candidates else \
        rng.choice(len(tri), size=n_candidates, replace=False, p=area / area.sum())
    best, best_area = None, -1.0
    for start in range(0, len(cand), 100):
        c = cand[start:start + 100]
        same_dir = nrm[c] @ nrm.T > cos_a  # (k, m)
        dist = np.abs(np.einsum("kd,kmd->km", nrm[c], cen[None, :, :] - cen[c][:, None, :]))
        score = ((same_dir & (dist < tol)) * area[None, :]).sum(axis=1)
        k = int(np.argmax(score))
        if score[k] > best_area:
            best, best_area = int(c[k]), float(score[k])
    mask = (nrm @ nrm[best] > cos_a) & (np.abs((cen - cen[best]) @ nrm[best]) < tol)
    for _ in range(2):  # refit the plane to the selected faces, then reselect
        w = area[mask]
        normal = (nrm[mask] * w[:, None]).sum(axis=0)
        normal /= np.linalg.norm(normal)
        origin = (cen[mask] * w[:, None]).sum(axis=0) / w.sum()
        mask = (nrm @ normal > cos_a) & (np.abs((cen - origin) @ normal) < tol)
    w = area[mask]
    origin = (cen[mask] * w[:, None]).sum(axis=0) / w.sum()
    flat = float(np.sqrt(np.average(((cen[mask] - origin) @ normal) ** 2, weights=w)))
    return mask, origin, normal, flat


def _components(tri: np.ndarray, n_points: int) -> np.ndarray:
    """Connected component label of each triangle (sharing a vertex connects)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_points, n_points))
    _, lab = connected_components(g, directed=False)
    return lab[tri[:, 0]]


def _open_boundary_points(points, tri) -> np.ndarray:
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    u, cnt = np.unique(e, axis=0, return_counts=True)
    idx = np.unique(u[cnt == 1].ravel())
    return points[idx]


def _enclosed_volume(points, tri, origin, normal) -> float:
    """Volume (mm³) enclosed by an open surface and the base plane (origin, normal)."""
    cen, nrm, area = _triangle_geometry(points, tri)
    return float(abs(np.sum(((cen - origin) @ normal) * (nrm @ normal) * area)))


def _surface(points, tri, name, source) -> LVSurface:
    used, inv = np.unique(tri, return_inverse=True)
    return LVSurface(name=name, points=points[used], triangles=inv.reshape(-1, 3).astype(np.int64),
                     boundary=_open_boundary_points(points[used], inv.reshape(-1, 3)), source=source)


def extract_lv_boundary(path_or_mesh, units: str = "mm") -> LVBoundary:
    """Split a volumetric LV mesh into endocardium, epicardium and basal cap.

    Parameters
    ----------
    path_or_mesh : str, Path or meshio.Mesh
        Tetrahedra and/or hexahedra (quadratic ones use their corners).
    units : {"mm", "cm", "m"}
        Units of the file's coordinates.

    Raises
    ------
    GeometryError
        Unreadable file, no volume cells, cells of zero total volume (below
        :data:`~lvcore.geometry.base_plane.ZERO_VOLUME_FRACTION` of the
        largest extent cubed, mm³), no planar base, or a boundary that does
        not split into exactly two surfaces once the base is removed.
    """
    points, tets, hexes, source = read_volume_cells(path_or_mesh, units)
    tri, wall_mm3 = boundary_triangles(points, tets, hexes)
    used = np.unique(np.concatenate([tets.ravel(), hexes.ravel()]))
    if not wall_mm3 > ZERO_VOLUME_FRACTION * float(np.ptp(points[used], axis=0).max()) ** 3:
        cells = " and ".join(f"{n} {name}" for n, name in ((len(tets), "tetrahedra"), (len(hexes), "hexahedra")) if n)
        raise GeometryError(f"volume mesh '{source}' has no volume: its {cells} all have zero volume "
                            f"(together {wall_mm3:.3g} mm³), so it has no wall and no cavity to fit; export the "
                            "LV wall as 3-D cells (not flattened or collapsed ones)")
    try:
        parts = _split_flat_cap(points, tri, source)
    except GeometryError as flat_err:
        try:
            parts = _split_by_features(points, tri, source)
        except GeometryError as feat_err:
            raise GeometryError(f"{flat_err}. Nor does it split at sharp edges into an endocardium and an "
                                f"epicardium that meet at the base or join a base cap ({feat_err})") from None
    t_endo, t_epi, n_base, origin, normal, flat, v_endo, warn = parts
    endo = _surface(points, t_endo, "endo", f"{source} (endocardium)")
    epi = _surface(points, t_epi, "epi", f"{source} (epicardium)")
    return LVBoundary(endo=endo, epi=epi, base_origin=origin, base_normal=normal, base_flatness_mm=flat,
                      n_tets=int(len(tets)), n_hexes=int(len(hexes)),
                      n_faces={"endo": int(len(t_endo)), "epi": int(len(t_epi)), "base": int(n_base)},
                      cavity_volume_ml=v_endo / 1000.0, wall_volume_ml=wall_mm3 / 1000.0, source=source,
                      warnings=tuple(warn))


def _split_flat_cap(points, tri, source):
    """Endo/epi triangles by removing the largest planar patch (module docstring, steps 2-3)."""
    warn = []
    mask, origin, normal, flat = find_base_cap(points, tri)
    cen, _, area = _triangle_geometry(points, tri)
    cap_frac = float(area[mask].sum() / area.sum())
    rest = tri[~mask]
    lab = _components(rest, len(points))
    labels, counts = np.unique(lab, return_counts=True)
    if len(labels) != 2:
        sizes = ", ".join(str(c) for c in sorted(counts, reverse=True)[:5])
        raise GeometryError(
            f"volume mesh '{source}': removing its largest planar patch (the base candidate, {100 * cap_frac:.1f} % of "
            f"the boundary area) leaves {len(labels)} surface pieces ({sizes} triangles), not 2 (endo and epi), so "
            "its base is not one flat cap")
    # outward cap normal: make it point away from the apex (the far side of the mesh)
    used = np.unique(tri)
    h = (points[used] - origin) @ normal
    if h.max() > -h.min():
        # most of the mesh lies on the +normal side: the "cap" normal points into the LV -> not the base
        raise GeometryError(f"volume mesh '{source}': no flat base found: its largest flat patch is not at an end of "
                            "the LV (the mesh extends on both sides of it)")
    # principal axis check
    p = points[used] - points[used].mean(axis=0)
    _, _, vt = np.linalg.svd(p, full_matrices=False)
    ang = float(np.degrees(np.arccos(min(1.0, abs(vt[0] @ normal)))))
    if ang > AXIS_WARN_DEG:
        warn.append(f"the base plane's normal is {ang:.0f}° off the mesh's longest axis; check that the flat cap "
                    "found is the base")
    pieces = []
    for lb in labels:
        t = rest[lab == lb]
        pieces.append((t, _enclosed_volume(points, t, origin, normal)))
    pieces.sort(key=lambda x: x[1])
    (t_endo, v_endo), (t_epi, _) = pieces
    if len(_open_boundary_points(points, t_endo)) < 3 or len(_open_boundary_points(points, t_epi)) < 3:
        raise GeometryError(f"volume mesh '{source}' has no flat base joining its inner and outer surfaces (one of "
                            "them is closed)")
    if flat > 0.02 * float(np.ptp(points[used], axis=0).max()):
        warn.append(f"the base cap is not flat (rms {flat:.2f} mm off its plane)")
    return t_endo, t_epi, int(mask.sum()), origin, normal, flat, v_endo, warn


def _split_by_features(points, tri, source, feature_deg: float = FEATURE_DEG):
    """Endo/epi triangles of a boundary whose base is not one flat patch (module docstring, step 2b)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from lvcore.geometry.base_plane import closed_volume

    cen, nrm, area = _triangle_geometry(points, tri)
    ok = area > 1e-12 * area.max()
    tri, cen, nrm, area = tri[ok], cen[ok], nrm[ok], area[ok]
    m = len(tri)
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(m), 3)
    _, inv, cnt = np.unique(e, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    order = np.argsort(inv, kind="stable")
    shared = cnt[inv[order]] == 2
    o = order[shared]
    a, b = owner[o[0::2]], owner[o[1::2]]
    smooth = np.einsum("ij,ij->i", nrm[a], nrm[b]) > np.cos(np.radians(feature_deg))
    g = coo_matrix((np.ones(int(smooth.sum())), (a[smooth], b[smooth])), shape=(m, m))
    n_comp, lab = connected_components(g, directed=False)
    comp_area = np.bincount(lab, weights=area, minlength=n_comp)
    big = np.argsort(comp_area)[::-1][:2]
    if n_comp < 2 or comp_area[big].sum() < 0.75 * area.sum():
        raise GeometryError(f"its sharp edges (> {feature_deg:g}°) split it into {n_comp} pieces, the two largest only "
                            f"{100 * comp_area[big].sum() / area.sum():.0f} % of its area")
    pieces = []
    for c in big:
        t = tri[lab == c]
        if len(_open_boundary_points(points, t)) < 3:
            raise GeometryError("one of its two largest smooth pieces is closed: the LV is not open at the base")
        pieces.append((t, closed_volume(points, t)))
    pieces.sort(key=lambda x: x[1])
    (t_endo, v_endo), (t_epi, _) = pieces
    base_mask = ~np.isin(lab, big)
    ring = _open_boundary_points(points, t_endo)
    from lvcore.geometry.contours import plane_fit

    if base_mask.any():
        bp = points[np.unique(tri[base_mask])]
        origin, normal, flat = plane_fit(bp)
    else:
        origin, normal, flat = plane_fit(ring)
    used = np.unique(tri)
    if (points[used].mean(axis=0) - origin) @ normal > 0:
        normal = -normal
    rest = (f"a base of {int(base_mask.sum())} triangles" if base_mask.any()
            else "no base cap (the walls meet at the base)")
    warn = [f"the base is not one flat cap: the boundary was split at its sharp edges into endocardium, epicardium "
            f"and {rest}"]
    return t_endo, t_epi, int(base_mask.sum()), origin, normal, float(flat), v_endo, warn


def fit_volume_mesh(path_or_mesh, units: str = "mm", base_z: float | None = None, septum=None,
                    base_cut_mm: float | None = None, **fit_kwargs) -> VolumeMeshFit:
    """Fit the LV template to a volumetric mesh (see the module docstring).

    Parameters
    ----------
    path_or_mesh : str, Path or meshio.Mesh
    units : {"mm", "cm", "m"}
    base_z : float, optional
        Base-plane height of the fitted template (mm; default that of
        :func:`~lvcore.geometry.fitting.fit_surfaces`).
    septum : (3,) array, optional
        A point on the septum (file coordinates, in ``units``) fixing phi = 0.
    base_cut_mm : float, optional
        Depth of the base cut below the endocardial base ring's centre (mm); default the rule of
        :mod:`lvcore.geometry.base_plane` (no cut for a flat base).
    **fit_kwargs
        Passed to :func:`~lvcore.geometry.fitting.fit_surfaces` (``template``, ``degree``, ``smoothing``).

    Returns
    -------
    VolumeMeshFit
        ``.fit`` (nodes, residuals, fitted cavity volume) and ``.boundary``
        (the extracted surfaces and the mesh's own cavity volume).
    """
    from lvcore.geometry.fitting import fit_surfaces

    b = extract_lv_boundary(path_or_mesh, units)
    kw = dict(fit_kwargs)
    if base_z is not None:
        kw["base_z"] = base_z
    if septum is not None:
        septum = np.asarray(septum, float) * UNIT_SCALE[units]
    fit = fit_surfaces(b.endo, b.epi, septum=septum, base_cut_mm=base_cut_mm, **kw)
    return VolumeMeshFit(fit=fit, boundary=b)


__all__ = ["LVBoundary", "VolumeMeshFit", "read_volume_cells", "boundary_triangles", "find_base_cap",
           "extract_lv_boundary", "fit_volume_mesh", "VOLUME_CELL_TYPES"]
