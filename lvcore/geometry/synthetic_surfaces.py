"""SYNTHETIC endo/epi surface pairs with the bases real segmentation pipelines write.

Each case is a pair of truncated ellipsoidal surfaces (an
:class:`~lvcore.geometry.analytic.TruncatedEllipsoidLV`) whose open base is
what atlas meshes and surface-based segmentation tools produce, placed in
"scanner" coordinates by a seeded rigid pose:

``flat``
    both surfaces cut by the plane ``z = base_z`` (the classic input);
``joined``
    both ellipsoids cut at ``z = base_z``, then continued by a conical *lip*
    of height :data:`LIP_HEIGHT_MM` that joins them at one shared base ring:
    the wall thins to zero at the ring, as in a population atlas;
``partial_join``
    both walls continued :data:`LIP_HEIGHT_MM` straight up, except over
    :data:`PARTIAL_JOIN_DEG` (90°) where they lean together and meet (the
    wall vanishes over a quarter of the ring, as next to an outflow tract);
``oblique``
    both cut by a plane tilted by :data:`OBLIQUE_DEG` (20°) about the y axis
    through ``(0, 0, base_z)``;
``uneven``
    both cut at the height ``base_z + u(φ)``, ``u`` a seeded Fourier series
    (orders 2–4; order 1 would only tilt it) scaled to ``max |u| = UNEVEN_MM`` (±3 mm);
``notch``
    cut at ``base_z`` except a notch of depth :data:`NOTCH_DEPTH_MM` and
    width :data:`NOTCH_WIDTH_DEG` (cosine flanks) where the outflow tract
    leaves the LV;
``deep_notch``
    the same notch reaching :data:`DEEP_NOTCH_DEPTH_MM` down the wall;
``outflow_hole``
    a flat base plus a separate opening through both walls just below it
    (:data:`HOLE_DEG` wide, from 3 to :data:`HOLE_DEPTH_MM` below the base):
    an outflow tract segmented as its own opening, a second boundary loop.

Every surface is a (φ, ψ) grid (``ψ`` the polar angle from the apex) that
ends exactly on its base curve, with one apex vertex. The exact cavity of the
part kept below any plane that lies below the whole base is the closed form
:func:`~lvcore.geometry.analytic.ellipsoid_volume_below_plane` of the
endocardial ellipsoid (:meth:`SyntheticSurfacePair.exact_cavity_below_ml`).
Everything here is SYNTHETIC; ``scripts/synthetic_surfaces.py`` writes the
cases to disk. All lengths in mm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV, ellipsoid_volume_below_plane

#: The ellipsoid pair of every case (mm): endo (26, 23, 70), epi (35, 32, 80), base 10 mm above the centre.
SURFACE_LV = TruncatedEllipsoidLV(EllipsoidSurface(26.0, 70.0, ry=23.0), EllipsoidSurface(35.0, 80.0, ry=32.0), 10.0)
#: Height of the lip joining the walls in the ``joined`` case (mm).
LIP_HEIGHT_MM = 4.0
#: Tilt of the ``oblique`` base plane (deg).
OBLIQUE_DEG = 20.0
#: Largest height deviation of the ``uneven`` base (mm).
UNEVEN_MM = 3.0
#: Depth and width of the outflow notch (mm, deg), and of the deep one (mm).
NOTCH_DEPTH_MM = 8.0
NOTCH_WIDTH_DEG = 60.0
DEEP_NOTCH_DEPTH_MM = 35.0
#: Width (deg) and lowest depth below the base (mm) of the separate outflow opening.
HOLE_DEG = 30.0
HOLE_DEPTH_MM = 10.0
#: Arc (deg) over which the walls meet in the ``partial_join`` case.
PARTIAL_JOIN_DEG = 90.0
#: The cases :func:`synthetic_surface_pair` makes.
CASES = ("flat", "joined", "partial_join", "oblique", "uneven", "notch", "deep_notch", "outflow_hole")


@dataclass(frozen=True)
class SyntheticSurfacePair:
    """A SYNTHETIC endo/epi pair in scanner coordinates (mm).

    Attributes
    ----------
    case : str
        One of :data:`CASES`.
    endo_points, epi_points : (n, 3) arrays
        Vertices, scanner coordinates (mm).
    endo_triangles, epi_triangles : (m, 3) int arrays
    lv : TruncatedEllipsoidLV
        The ellipsoids, in their own frame (apex on −z).
    rotation, shift : arrays
        The pose: ``x_scanner = rotation @ x + shift``.
    endo_ring, epi_ring : int arrays
        Vertex indices of each surface's base ring, in φ order.
    description : str
    """

    case: str
    endo_points: np.ndarray
    endo_triangles: np.ndarray
    epi_points: np.ndarray
    epi_triangles: np.ndarray
    lv: TruncatedEllipsoidLV
    rotation: np.ndarray
    shift: np.ndarray
    endo_ring: np.ndarray
    epi_ring: np.ndarray
    description: str = ""

    def to_local(self, x) -> np.ndarray:
        """Scanner coordinates -> the ellipsoids' frame (mm)."""
        return (np.asarray(x, float) - self.shift) @ self.rotation

    def exact_cavity_below_ml(self, point, normal) -> float:
        """Closed-form cavity (mL) of the endocardial ellipsoid behind a plane given in scanner coordinates.

        ``normal`` points away from the kept part (towards the base). Exact
        for the kept part when the plane lies below the whole base curve.
        """
        p = self.to_local(point)
        n = np.asarray(normal, float) @ self.rotation
        e = self.lv.endo
        return ellipsoid_volume_below_plane(e.rs, e.ry if e.ry is not None else e.rs, e.rl, p, n) / 1000.0

    def closed_wall(self) -> tuple[np.ndarray, np.ndarray]:
        """The myocardium's closed boundary: endo + epi (+ a base band between their rings unless they share one).

        Returns points (n, 3) and triangles (m, 3), scanner coordinates (mm).
        """
        ne = len(self.endo_points)
        pts = np.vstack([self.endo_points, self.epi_points])
        re, rp = self.endo_ring, self.epi_ring + ne
        tris = [self.endo_triangles[:, ::-1], self.epi_triangles + ne]
        if np.allclose(self.endo_points[self.endo_ring], self.epi_points[self.epi_ring]):
            remap = np.arange(len(pts))
            remap[rp] = re
            tris = [remap[t] for t in tris]
        else:
            re1, rp1 = np.roll(re, -1), np.roll(rp, -1)
            tris.append(np.vstack([np.stack([re, rp, rp1], 1), np.stack([re, rp1, re1], 1)]))
        tri = np.vstack(tris)
        used, inv = np.unique(tri, return_inverse=True)
        return pts[used], inv.reshape(-1, 3)

    def tet_mesh(self, size_mm: float = 4.0):
        """A tetrahedral mesh of the wall (gmsh, from :meth:`closed_wall`), as a ``meshio.Mesh`` (mm)."""
        import meshio

        from lvcore.geometry.meshing import gmsh_cells, gmsh_model

        pts, tri = self.closed_wall()
        with gmsh_model("wall") as gmsh:
            s = gmsh.model.addDiscreteEntity(2)
            gmsh.model.mesh.addNodes(2, s, np.arange(1, len(pts) + 1), pts.ravel())
            gmsh.model.mesh.addElementsByType(s, 2, [], (tri + 1).ravel())
            loop = gmsh.model.geo.addSurfaceLoop([s])
            gmsh.model.geo.addVolume([loop])
            gmsh.model.geo.synchronize()
            gmsh.option.setNumber("Mesh.MeshSizeMax", float(size_mm))
            gmsh.option.setNumber("General.NumThreads", 1)
            gmsh.model.mesh.generate(3)
            tags, coords, _ = gmsh.model.mesh.getNodes()
            _, enodes = gmsh.model.mesh.getElementsByType(4)
        xyz, cells = gmsh_cells(tags, coords, enodes, 4)
        return meshio.Mesh(xyz, [("tetra", cells)])

    def polydata(self, which: str):
        """The endo or epi surface as a ``pyvista.PolyData``."""
        import pyvista as pv

        pts, tri = (self.endo_points, self.endo_triangles) if which == "endo" else (self.epi_points, self.epi_triangles)
        return pv.PolyData(pts, np.hstack([np.full((len(tri), 1), 3), tri]).ravel())

    def save(self, folder, fmt: str = "vtk") -> tuple:
        """Write ``SYNTHETIC_<case>_endo.<fmt>`` and ``..._epi.<fmt>`` (any format PyVista writes)."""
        from pathlib import Path

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        out = []
        for which in ("endo", "epi"):
            p = folder / f"SYNTHETIC_{self.case}_{which}.{fmt}"
            self.polydata(which).save(p)
            out.append(p)
        return tuple(out)


def _first_root(f, n_phi: int, hi: float = np.pi - 1e-3, n_grid: int = 400) -> np.ndarray:
    """Per φ column, the smallest ψ in (0, hi) with f(ψ) = 0 (f < 0 near the apex)."""
    from scipy.optimize import brentq

    psi = np.linspace(1e-6, hi, n_grid)
    vals = f(psi[:, None], np.arange(n_phi)[None, :])  # (n_grid, n_phi)
    out = np.empty(n_phi)
    for j in range(n_phi):
        k = np.nonzero((vals[:-1, j] < 0) & (vals[1:, j] >= 0))[0]
        if k.size == 0:
            raise ValueError("the base curve does not cut this ellipsoid")
        a = int(k[0])
        out[j] = brentq(lambda s: float(f(np.array([[s]]), np.array([[j]]))[0, 0]), psi[a], psi[a + 1], xtol=1e-13)
    return out


def _grid_surface(surf: EllipsoidSurface, phi, psi_top, n_psi: int, extra_rows=()):
    """Triangulated (φ, ψ) grid from the apex to ``psi_top(φ)``, then ``extra_rows`` (each (n_phi, 3))."""
    n_phi = len(phi)
    frac = np.linspace(0.0, 1.0, n_psi + 1)[1:]
    P = np.broadcast_to(phi[:, None], (n_phi, n_psi))
    S = psi_top[:, None] * frac[None, :]
    rows = surf.point(P, S)  # (n_phi, n_psi, 3)
    if extra_rows:
        rows = np.concatenate([rows, np.stack(extra_rows, axis=1)], axis=1)
    n_rows = rows.shape[1]
    pts = np.vstack([[[0.0, 0.0, -surf.rl]], rows.reshape(-1, 3)])
    idx = 1 + np.arange(n_phi * n_rows).reshape(n_phi, n_rows)
    i1 = np.roll(idx, -1, 0)
    tris = np.vstack([np.stack([idx[:, :-1], idx[:, 1:], i1[:, 1:]], -1).reshape(-1, 3),
                      np.stack([idx[:, :-1], i1[:, 1:], i1[:, :-1]], -1).reshape(-1, 3),
                      np.stack([np.zeros(n_phi, int), idx[:, 0], i1[:, 0]], -1)])
    return pts, tris.astype(np.int64)


def random_pose(rng) -> tuple[np.ndarray, np.ndarray]:
    """A random rotation (det +1) and a shift of 50-250 mm: scanner coordinates."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q, rng.uniform(-250.0, 250.0, 3)


def synthetic_surface_pair(case: str, seed: int = 0, n_phi: int = 96, n_psi: int = 48,
                           lv: TruncatedEllipsoidLV = SURFACE_LV, pose: bool = True) -> SyntheticSurfacePair:
    """Make one SYNTHETIC case (see the module docstring).

    Parameters
    ----------
    case : str
        One of :data:`CASES`.
    seed : int
        Seeds the pose and the ``uneven`` base.
    n_phi, n_psi : int
        Grid size (circumferential, apex to base).
    lv : TruncatedEllipsoidLV
    pose : bool
        Place the pair in random scanner coordinates (else the ellipsoids' frame).
    """
    if case not in CASES:
        raise ValueError(f"unknown case {case!r}; one of {CASES}")
    rng = np.random.default_rng(seed)
    rotation, shift = random_pose(rng) if pose else (np.eye(3), np.zeros(3))
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    zb = lv.base_z
    if case == "uneven":
        k = np.arange(2, 5)  # order 1 would only tilt the plane
        a, b = rng.normal(size=3) / k, rng.normal(size=3) / k
        u = (a[None, :] * np.cos(k[None, :] * phi[:, None]) + b[None, :] * np.sin(k[None, :] * phi[:, None])).sum(1)
        u = UNEVEN_MM * u / np.abs(u).max()
    else:
        u = np.zeros(n_phi)
    if case in ("notch", "deep_notch"):
        depth = NOTCH_DEPTH_MM if case == "notch" else DEEP_NOTCH_DEPTH_MM
        half, ramp = np.radians(NOTCH_WIDTH_DEG) / 2, np.radians(15.0)
        d = np.abs(np.angle(np.exp(1j * (phi - np.pi / 3))))  # notch centred at φ = 60°
        w = np.where(d < half - ramp, 1.0, np.where(d < half, 0.5 * (1 + np.cos(np.pi * (d - half + ramp) / ramp)), 0.0))
        u = -depth * w
    tilt = np.radians(OBLIQUE_DEG) if case == "oblique" else 0.0
    nrm = np.array([np.sin(tilt), 0.0, np.cos(tilt)])

    def top(surf):
        def f(psi, j):
            ph, ps = np.broadcast_arrays(phi[j], psi)
            x = surf.point(ph, ps)
            if case == "oblique":
                return (x - np.array([0.0, 0.0, zb])) @ nrm
            return x[..., 2] - (zb + u[j])
        return _first_root(f, n_phi)

    tops = {"endo": top(lv.endo), "epi": top(lv.epi)}
    extra = {"endo": (), "epi": ()}
    if case in ("joined", "partial_join"):
        x_endo = lv.endo.point(phi, tops["endo"])
        x_epi = lv.epi.point(phi, tops["epi"])
        up = np.array([0.0, 0.0, LIP_HEIGHT_MM])
        shared = 0.5 * (x_endo + x_epi) + up
        # joined: everywhere; partial_join: over PARTIAL_JOIN_DEG (cosine flanks), elsewhere straight up
        if case == "joined":
            w = np.ones(n_phi)
        else:
            d = np.abs(np.angle(np.exp(1j * (phi - np.pi / 3))))
            half, ramp = np.radians(PARTIAL_JOIN_DEG) / 2, np.radians(15.0)
            w = np.where(d < half - ramp, 1.0, np.where(d < half, 0.5 * (1 + np.cos(np.pi * (d - half + ramp) / ramp)),
                                                          0.0))
        n_lip = 6
        for name, x0 in (("endo", x_endo), ("epi", x_epi)):
            top_ring = w[:, None] * shared + (1 - w[:, None]) * (x0 + up)
            extra[name] = tuple(x0 + (top_ring - x0) * (i / n_lip) for i in range(1, n_lip + 1))
    pe, te = _grid_surface(lv.endo, phi, tops["endo"], n_psi, extra["endo"])
    pp, tp = _grid_surface(lv.epi, phi, tops["epi"], n_psi, extra["epi"])
    desc = {
        "flat": "both walls cut by one flat base plane",
        "joined": f"walls joined by a {LIP_HEIGHT_MM:g} mm lip at one shared base ring (wall thickness 0 at the ring)",
        "oblique": f"base plane tilted {OBLIQUE_DEG:g}° from the short axis",
        "uneven": f"uneven base, ±{UNEVEN_MM:g} mm about its plane",
        "notch": f"outflow notch {NOTCH_DEPTH_MM:g} mm deep, {NOTCH_WIDTH_DEG:g}° wide",
        "deep_notch": f"outflow notch {DEEP_NOTCH_DEPTH_MM:g} mm deep, {NOTCH_WIDTH_DEG:g}° wide",
        "partial_join": f"walls rising {LIP_HEIGHT_MM:g} mm above the base, joined at the ring over "
                        f"{PARTIAL_JOIN_DEG:g}° (wall thickness 0 there)",
        "outflow_hole": f"flat base and a separate outflow opening {HOLE_DEG:g}° wide, 3-{HOLE_DEPTH_MM:g} mm below it",
    }[case]
    rings = {k: 1 + np.arange(n_phi) * ((len(p) - 1) // n_phi) + (len(p) - 1) // n_phi - 1
             for k, p in (("endo", pe), ("epi", pp))}
    if case == "outflow_hole":
        def punch(p, t):
            c = p[t].mean(axis=1)
            dphi = np.abs(np.angle(np.exp(1j * (np.arctan2(c[:, 1], c[:, 0]) - np.pi / 3))))
            cut = (dphi < np.radians(HOLE_DEG) / 2) & (c[:, 2] < zb - 3.0) & (c[:, 2] > zb - HOLE_DEPTH_MM)
            return t[~cut]
        te, tp = punch(pe, te), punch(pp, tp)
    return SyntheticSurfacePair(case=case, endo_points=pe @ rotation.T + shift, endo_triangles=te,
                                epi_points=pp @ rotation.T + shift, epi_triangles=tp, lv=lv, rotation=rotation,
                                shift=shift, endo_ring=rings["endo"], epi_ring=rings["epi"],
                                description=f"SYNTHETIC {desc}")


__all__ = ["SyntheticSurfacePair", "synthetic_surface_pair", "random_pose", "CASES", "SURFACE_LV"]
