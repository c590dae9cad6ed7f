"""The base of an endo/epi surface pair as segmentation pipelines write it: rings, plane, axis and the cut.

Real surfaces end in a base that is rarely one flat plane with a wall of
finite thickness: atlas meshes join the endocardium and epicardium at one
shared ring (the wall thins to zero there), the mitral annulus is oblique
and uneven, and the outflow tract leaves an opening. This module finds the
base from the data and decides where to cut both surfaces so that the part
kept is a complete LV wall below one plane orthogonal to the long axis.

Method (all lengths mm, scanner coordinates)
--------------------------------------------
1. **Rings.** The boundary loops of each surface (edges of exactly one
   triangle, chained in order). The longest loop of a surface is its base
   ring; any other loop is an extra opening (an outflow tract), or a hole
   when shorter than :data:`HOLE_FRACTION` of the base ring (a mesh defect:
   bridged by the fit, it does not move the cut).
2. **Base plane.** Least-squares plane of the endocardial base ring
   (:func:`~lvcore.geometry.contours.plane_fit`); its *unevenness* is the
   peak-to-peak distance of the ring from that plane.
3. **Long axis.** From the ring centroid ``c`` (mean of the endocardial ring
   points) to the apex. The apex is found by fixed-point iteration: starting
   along the base-plane normal, the epicardial point furthest along
   ``−axis`` from ``c`` is the apex, the axis is re-aimed at it, until it
   moves by less than :data:`AXIS_TOL_DEG`. The *base level* is the plane
   orthogonal to the axis through ``c``; the *obliquity* is the angle between
   the base plane's normal and the axis.
4. **Wall thickness.** Distance of every endocardial vertex to the
   epicardial surface. ``T`` is its median between 20 % and 60 % of the
   base-apex length below the base level; the thickness *at the ring* is the
   10th percentile over the endocardial ring points (so a wall that vanishes
   over a tenth of the ring, as at an outflow tract, counts). When it is below
   :data:`MEET_FRACTION` ``× T`` the walls meet (or thin to zero) at the base.
5. **The cut**, a plane orthogonal to the axis at depth ``d`` below the base
   level (``d`` = ``base_cut_mm`` when given). By default ``d`` is the largest of

   * the depth of the lowest ring point of either surface (every ring
     point, including extra openings, must lie above the cut, so the kept
     wall is complete all round); depths within :data:`RING_TOL_MM` count
     as flat (``d = 0``, the base level itself, as for a flat base);
   * where the walls meet: the first depth, scanning down in 0.5 mm steps,
     at which the 10th percentile of the wall thickness in a band of
     ``max(2 mm, 2 × median edge)`` below it reaches :data:`USABLE_FRACTION` ``× T``.

   A default cut deeper than :data:`MAX_CUT_FRACTION` of the base-apex
   length is refused with the cause (a deep opening, a wall that never
   reaches a usable thickness) and what to do.
6. **Volumes (from the input surface).** The cavity closed at its rings (a
   fan from each loop's centroid; divergence theorem) and the cavity below
   the cut (the endocardium clipped by the cut plane, divergence theorem with
   the field ``((x − p)·a) a``, which vanishes on the plane, so no cap is
   needed); their difference is the cavity removed by the cut.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lvcore.exceptions import GeometryError
from lvcore.geometry.contours import plane_fit

#: Ring points this close below the base level (mm) do not move the cut (a flat base).
RING_TOL_MM = 0.5
#: The walls "meet" at the base when the ring's wall thickness is below this fraction of the typical one.
MEET_FRACTION = 0.5
#: The default cut lies where the wall first reaches this fraction of the typical thickness.
USABLE_FRACTION = 0.8
#: A default cut deeper than this fraction of the base-apex length is refused.
MAX_CUT_FRACTION = 0.25
#: Extra boundary loops shorter than this fraction of the base ring's perimeter are holes: bridged, not cut below.
HOLE_FRACTION = 0.1
#: Convergence of the apex/axis iteration (deg).
AXIS_TOL_DEG = 0.5
#: A mesh or endocardium enclosing less than this fraction of its largest extent cubed (mm³) has no volume (refused).
ZERO_VOLUME_FRACTION = 1e-9


@dataclass(frozen=True)
class BaseRing:
    """One boundary loop of a surface (mm, scanner coordinates).

    Attributes
    ----------
    surface : str
        "endo" or "epi".
    points : (k, 3) array
        The loop's points in order.
    centroid, normal : (3,) arrays
        Its least-squares plane.
    unevenness_mm : float
        Peak-to-peak distance of the points from that plane (mm).
    perimeter_mm : float
    is_base : bool
        The longest loop of its surface (the base ring); others are extra openings.
    depth_mm : float
        Depth of its lowest point below the base level, along the long axis (mm; set by :func:`analyse_base`).
    """

    surface: str
    points: np.ndarray
    centroid: np.ndarray
    normal: np.ndarray
    unevenness_mm: float
    perimeter_mm: float
    is_base: bool = True
    depth_mm: float = 0.0

    def summary(self) -> dict:
        return {"surface": self.surface, "base_ring": self.is_base, "n_points": int(len(self.points)),
                "centroid": _r(self.centroid), "normal": _r(self.normal, 4),
                "unevenness_mm": round(self.unevenness_mm, 3), "perimeter_mm": round(self.perimeter_mm, 2),
                "lowest_point_depth_mm": round(self.depth_mm, 3)}


@dataclass(frozen=True)
class BaseCut:
    """Where the base of a segmentation is, and where it was cut (mm, mL; scanner coordinates).

    Attributes
    ----------
    rings : tuple of BaseRing
        Every boundary loop of both surfaces.
    plane_origin, plane_normal : (3,) arrays
        Least-squares plane of the endocardial base ring (normal towards the base).
    unevenness_mm : float
        Peak-to-peak distance of the endocardial base ring from that plane.
    obliquity_deg : float
        Angle between the base plane's normal and the long axis.
    apex : (3,) array
        Epicardial apex.
    axis : (3,) array
        Unit long axis, apex -> base.
    ring_centroid : (3,) array
        Centroid of the endocardial ring points; the base level passes through it.
    ring_depth_mm : float
        Depth of the lowest ring point (any loop, either surface) below the base level.
    wall_at_ring_mm, wall_typical_mm : float
        Wall thickness at the endocardial ring (10th percentile over its points) and typical (median, 20-60 %
        of the length).
    walls_meet : bool
        The ring's wall is thinner than ``MEET_FRACTION × wall_typical_mm``.
    cut_depth_mm : float
        Depth of the cut plane below the base level (along the axis).
    cut_origin, cut_normal : (3,) arrays
        The cut plane: the point on the axis and the normal (= axis).
    rule : str
        How the depth was chosen: "flat base", "below the ring", "wall thickness" or "base_cut_mm".
    wall_at_cut_mm : float
        10th percentile of the wall thickness just below the cut.
    cavity_full_ml, cavity_kept_ml, cavity_removed_ml : float
        Input cavity closed at its rings, below the cut, and their difference.
    length_mm : float
        Base level to apex, along the axis.
    messages : tuple of str
        What was found and done, in words (also given as warnings when the cut removed something).
    """

    rings: tuple
    plane_origin: np.ndarray
    plane_normal: np.ndarray
    unevenness_mm: float
    obliquity_deg: float
    apex: np.ndarray
    axis: np.ndarray
    ring_centroid: np.ndarray
    ring_depth_mm: float
    wall_at_ring_mm: float
    wall_typical_mm: float
    walls_meet: bool
    cut_depth_mm: float
    cut_origin: np.ndarray
    cut_normal: np.ndarray
    rule: str
    wall_at_cut_mm: float
    cavity_full_ml: float
    cavity_kept_ml: float
    cavity_removed_ml: float
    length_mm: float
    messages: tuple = field(default=())

    def summary(self) -> dict:
        """JSON-ready summary."""
        return {
            "base_plane": {"origin": _r(self.plane_origin), "normal": _r(self.plane_normal, 4),
                           "unevenness_mm": round(self.unevenness_mm, 3),
                           "obliquity_deg": round(self.obliquity_deg, 2)},
            "long_axis": {"apex": _r(self.apex), "direction": _r(self.axis, 4),
                          "ring_centroid": _r(self.ring_centroid), "length_mm": round(self.length_mm, 2)},
            "rings": [r.summary() for r in self.rings],
            "wall_at_ring_mm": round(self.wall_at_ring_mm, 3),
            "wall_typical_mm": round(self.wall_typical_mm, 3),
            "walls_meet": bool(self.walls_meet),
            "cut": {"depth_mm": round(self.cut_depth_mm, 3), "rule": self.rule, "origin": _r(self.cut_origin),
                    "normal": _r(self.cut_normal, 4), "wall_at_cut_mm": round(self.wall_at_cut_mm, 3)},
            "cavity_full_ml": round(self.cavity_full_ml, 3),
            "cavity_kept_ml": round(self.cavity_kept_ml, 3),
            "cavity_removed_ml": round(self.cavity_removed_ml, 3),
            "messages": list(self.messages),
        }

    def describe(self) -> str:
        """One line for the CLI."""
        return (f"base plane through {_fmt(self.plane_origin)} normal {_fmt(self.plane_normal, 3)} "
                f"(uneven {self.unevenness_mm:.1f} mm, {self.obliquity_deg:.1f}° to the long axis); "
                f"cut {self.cut_depth_mm:.1f} mm below the ring centre ({self.rule}), wall there "
                f"{self.wall_at_cut_mm:.1f} mm; cavity removed {self.cavity_removed_ml:.2f} mL of "
                f"{self.cavity_full_ml:.1f} mL")


def _r(v, nd: int = 3) -> list:
    return [round(float(x), nd) for x in np.asarray(v).ravel()]


def _fmt(v, nd: int = 1) -> str:
    return "(" + ", ".join(f"{float(x):.{nd}f}" for x in v) + ")"


# ----------------------------------------------------------------------------- loops
def _edge_once(e: np.ndarray) -> np.ndarray:
    """Mask of the (directed) edges whose undirected edge occurs exactly once."""
    lo, hi = np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1])
    code = lo.astype(np.int64) * (int(hi.max()) + 1) + hi
    _, inv, cnt = np.unique(code, return_inverse=True, return_counts=True)
    return cnt[inv] == 1


def boundary_loops(triangles) -> list[np.ndarray]:
    """Ordered vertex loops of the open boundary of a triangle mesh.

    A boundary edge belongs to exactly one triangle; loops follow the edges
    in their triangles' orientation. Chains that cannot be closed (a
    non-manifold boundary) are returned as they are.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    if len(tri) == 0:
        return []
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    b = e[_edge_once(e)]
    nxt: dict[int, list[int]] = {}
    for a, c in b:
        nxt.setdefault(int(a), []).append(int(c))
    loops, used = [], set()
    for start in list(nxt):
        for first in list(nxt[start]):
            if (start, first) in used:
                continue
            loop, a, c = [start], start, first
            used.add((a, c))
            while c != start and len(loop) <= len(b):
                loop.append(c)
                options = [d for d in nxt.get(c, []) if (c, d) not in used]
                if not options:
                    break
                a, c = c, options[0]
                used.add((a, c))
            loops.append(np.asarray(loop, dtype=np.int64))
    return loops


def _ring(surface: str, pts: np.ndarray, is_base: bool) -> BaseRing:
    c, n, _ = plane_fit(pts) if len(pts) >= 3 else (pts.mean(axis=0), np.array([0.0, 0.0, 1.0]), 0.0)
    d = (pts - c) @ n
    per = float(np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]), axis=0), axis=1).sum())
    return BaseRing(surface=surface, points=pts, centroid=c, normal=n, unevenness_mm=float(np.ptp(d)),
                    perimeter_mm=per, is_base=is_base)


def surface_rings(surface) -> list[BaseRing]:
    """The boundary loops of an :class:`~lvcore.geometry.surfaces.LVSurface`, longest (the base ring) first."""
    loops = [lp for lp in boundary_loops(surface.triangles) if len(lp) >= 3]
    rings = [_ring(surface.name, surface.points[lp], False) for lp in loops]
    rings.sort(key=lambda r: -r.perimeter_mm)
    if rings:
        rings[0] = _replace(rings[0], is_base=True)
    return rings


def _replace(obj, **kw):
    from dataclasses import replace

    return replace(obj, **kw)


# ----------------------------------------------------------------------------- volumes
def _oriented(points, triangles) -> np.ndarray:
    """Triangles reoriented consistently (VTK's polygon consistency), as (m, 3) indices."""
    import pyvista as pv

    poly = pv.PolyData(np.asarray(points, float), np.hstack([np.full((len(triangles), 1), 3), triangles]).ravel())
    out = poly.compute_normals(cell_normals=True, point_normals=False, consistent_normals=True,
                               auto_orient_normals=False, split_vertices=False, non_manifold_traversal=False)
    faces = np.asarray(out.faces).reshape(-1, 4)[:, 1:]
    if out.n_points != len(points) or len(faces) != len(triangles):
        return np.asarray(triangles)
    return faces


def closed_volume(points, triangles) -> float:
    """Volume (mm³) enclosed by a surface after closing each boundary loop by a fan from its centroid."""
    pts = np.asarray(points, float)
    tri = _oriented(pts, np.asarray(triangles, np.int64))
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    bnd = e[_edge_once(e)]
    origin = pts.mean(axis=0)
    loop_of = np.full(len(pts), -1)
    centres = []
    for k, lp in enumerate(boundary_loops(tri)):
        loop_of[lp] = k
        centres.append(pts[lp].mean(axis=0))
    x = pts[tri] - origin
    v = np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum()
    if centres and len(bnd):
        k = loop_of[bnd[:, 0]]
        ok = k >= 0
        cx = np.stack([np.asarray(centres)[k[ok]], pts[bnd[ok, 1]], pts[bnd[ok, 0]]], axis=1) - origin
        v += np.einsum("ij,ij->i", cx[:, 0], np.cross(cx[:, 1], cx[:, 2])).sum()
    return float(abs(v) / 6.0)


def volume_below_plane(points, triangles, origin, axis) -> float:
    """Volume (mm³) enclosed by the part of a surface with ``(x − origin)·axis ≤ 0`` and the plane.

    Triangles crossing the plane are clipped exactly. The divergence theorem
    with ``F = ((x − origin)·axis) axis`` (``div F = 1``, ``F·axis = 0`` on
    the plane) needs no cap; exact when the kept part is closed by the plane.
    """
    pts = np.asarray(points, float)
    tri = _oriented(pts, np.asarray(triangles, np.int64))
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    h = (pts - np.asarray(origin, float)) @ a
    hv = h[tri]
    total = 0.0
    below = np.all(hv <= 0, axis=1)

    def flux(x):  # x: (k, 3, 3) triangles
        cr = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])  # 2 A N
        c = x.mean(axis=1)
        return float(np.sum(((c - origin) @ a) * (cr @ a)) / 2.0)

    total += flux(pts[tri[below]])
    cross = np.nonzero(~below & np.any(hv < 0, axis=1))[0]
    pieces = []
    for t in cross:
        poly = []
        for k in range(3):
            i, j = tri[t, k], tri[t, (k + 1) % 3]
            if h[i] <= 0:
                poly.append(pts[i])
            if (h[i] < 0) != (h[j] < 0) and h[i] != h[j]:
                s = h[i] / (h[i] - h[j])
                poly.append(pts[i] + s * (pts[j] - pts[i]))
        for k in range(1, len(poly) - 1):
            pieces.append((poly[0], poly[k], poly[k + 1]))
    if pieces:
        total += flux(np.asarray(pieces))
    return float(abs(total))


# ----------------------------------------------------------------------------- thickness
def wall_thickness(endo_points, epi) -> np.ndarray:
    """Distance (mm) of each endocardial point to the epicardial surface (an LVSurface)."""
    import pyvista as pv

    poly = pv.PolyData(epi.points, np.hstack([np.full((len(epi.triangles), 1), 3), epi.triangles]).ravel())
    pts = np.asarray(endo_points, float)
    if len(pts) == 0:
        return np.zeros(0)
    _, closest = poly.find_closest_cell(pts, return_closest_point=True)
    return np.linalg.norm(pts - closest, axis=1)


def _median_edge(surface) -> float:
    t = surface.triangles
    x = surface.points
    return float(np.median(np.linalg.norm(x[t[:, 1]] - x[t[:, 0]], axis=1)))


# ----------------------------------------------------------------------------- analysis
def find_axis(ring_centroid, normal, epi_points, tol_deg: float = AXIS_TOL_DEG, max_iter: int = 20):
    """Apex and unit axis (apex -> base) by the fixed-point iteration of the module docstring."""
    c = np.asarray(ring_centroid, float)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    proj = (epi_points - c) @ n
    if abs(proj.min()) < abs(proj.max()):
        n = -n  # the bulk of the epicardium lies on the -normal side
    a = n
    apex = epi_points[np.argmin((epi_points - c) @ a)]
    for _ in range(max_iter):
        v = c - apex
        if np.linalg.norm(v) < 10.0:
            raise GeometryError("cannot find the apex: the surfaces extend less than 10 mm from the base opening")
        a_new = v / np.linalg.norm(v)
        moved = np.degrees(np.arccos(np.clip(a_new @ a, -1.0, 1.0)))
        a = a_new
        if moved < tol_deg:
            break
        apex = epi_points[np.argmin((epi_points - c) @ a)]
    return apex, a


def analyse_base(endo, epi, base_cut_mm: float | None = None) -> BaseCut:
    """Find the base rings, plane and long axis of a surface pair and choose the cut (module docstring).

    Parameters
    ----------
    endo, epi : LVSurface
        Scanner coordinates (mm).
    base_cut_mm : float, optional
        Depth of the cut below the base level (the plane through the
        endocardial ring centroid orthogonal to the long axis), mm. Default:
        the rule of the module docstring.

    Raises
    ------
    GeometryError
        No base opening, an endocardium that encloses no volume (below
        :data:`ZERO_VOLUME_FRACTION` of its largest extent cubed, mm³), a
        ``base_cut_mm`` above part of a ring or where the walls meet, or a
        default cut that would remove too much (the message names the cause
        and what to do).
    """
    if base_cut_mm is not None and not (np.isfinite(base_cut_mm) and base_cut_mm >= 0):
        raise GeometryError(f"base_cut_mm (--base-cut) = {base_cut_mm}: give a distance >= 0 mm below the base ring")
    endo_rings, epi_rings = surface_rings(endo), surface_rings(epi)
    base, full = _open_base(endo, endo_rings)
    c = base.points.mean(axis=0)
    apex, a = find_axis(c, base.normal, epi.sample())
    n_plane = base.normal if base.normal @ a > 0 else -base.normal
    obliq = float(np.degrees(np.arccos(np.clip(n_plane @ a, -1.0, 1.0))))
    length = float((c - apex) @ a)
    rings = [_replace(r, depth_mm=float(np.max(-(r.points - c) @ a)), normal=r.normal * np.sign(r.normal @ a or 1.0))
             for r in endo_rings + epi_rings]
    # small holes (defects of the mesh) are bridged by the fit and do not move the cut
    hole_max = HOLE_FRACTION * base.perimeter_mm
    holes = [r for r in rings if not r.is_base and r.perimeter_mm < hole_max]
    rings_cut = [r for r in rings if r.is_base or r.perimeter_mm >= hole_max]
    ring_depth = max(0.0, max(r.depth_mm for r in rings_cut))
    wall = _wall_profile(endo, epi, base, c, a, length)
    deepest = max(rings_cut, key=lambda r: (round(r.depth_mm, 1), r.surface == "endo", r.is_base))
    kind = "endocardium" if deepest.surface == "endo" else "epicardium"
    max_cut = MAX_CUT_FRACTION * length
    rule_depth = _rule_depth(wall, ring_depth, max_cut) if wall.meet else 0.0
    if base_cut_mm is not None:
        depth, rule = _given_cut(float(base_cut_mm), wall, ring_depth, rule_depth, deepest, kind)
    else:
        depth, rule = _default_cut(wall, ring_depth, rule_depth, max_cut)
    origin = c - depth * a
    kept = volume_below_plane(endo.points, endo.triangles, origin, a) / 1000.0
    removed = full - kept
    if base_cut_mm is None and depth > max_cut:
        what = ("base ring" if deepest.is_base else f"extra opening (perimeter {deepest.perimeter_mm:.0f} mm)")
        raise GeometryError(
            f"the {kind}'s {what} reaches {ring_depth:.1f} mm below the base ring's centre (an opening for the "
            f"outflow tract, a notch in the wall, or a strongly oblique base; unevenness "
            f"{deepest.unevenness_mm:.1f} mm): "
            f"cutting below it would remove {removed:.1f} mL ({100 * removed / full:.0f} %) of the cavity. "
            f"Close the opening in the segmentation (cap the outflow tract at the valve plane), or accept the cut "
            f"with --base-cut {np.ceil(ring_depth * 10) / 10:g} (base_cut_mm=)")
    msgs = _messages(wall, obliq, base, holes, [r for r in rings_cut if not r.is_base], depth, rule, removed, full)
    return BaseCut(rings=tuple(rings), plane_origin=base.centroid, plane_normal=n_plane,
                   unevenness_mm=base.unevenness_mm, obliquity_deg=obliq, apex=apex, axis=a, ring_centroid=c,
                   ring_depth_mm=ring_depth, wall_at_ring_mm=wall.at_ring, wall_typical_mm=wall.typical,
                   walls_meet=bool(wall.meet), cut_depth_mm=float(depth), cut_origin=origin, cut_normal=a, rule=rule,
                   wall_at_cut_mm=wall.below(max(depth, 0.0)), cavity_full_ml=full, cavity_kept_ml=kept,
                   cavity_removed_ml=removed, length_mm=length, messages=tuple(msgs))


def _open_base(endo, endo_rings: list[BaseRing]) -> tuple[BaseRing, float]:
    """The endocardium's base ring and its cavity volume closed there (mL); refused when it has no base opening
    or encloses no volume."""
    if not endo_rings:
        raise GeometryError(f"endocardial surface '{endo.source}' is closed; cut it at the base so it is open there "
                            "(its boundary loop defines the base plane)")
    base = endo_rings[0]
    if np.linalg.norm(np.ptp(base.points, axis=0)) < 5.0:
        raise GeometryError(f"the endocardial surface '{endo.source}' has only a tiny opening; it must be open at "
                            "the base")
    full = closed_volume(endo.points, endo.triangles) / 1000.0
    extent = float(np.ptp(endo.points, axis=0).max())
    if not full * 1000.0 > ZERO_VOLUME_FRACTION * extent ** 3:
        raise GeometryError(f"the endocardial surface '{endo.source}' encloses no volume ({full:.3g} mL once closed "
                            "at its base opening): the mesh has no cavity volume; check that the file holds an LV "
                            "whose endocardium is a 3-D cup, not a flattened or collapsed one")
    return base, full


@dataclass(frozen=True)
class _WallProfile:
    """Wall thickness at the endocardial nodes by depth below the base level (mm).

    Attributes
    ----------
    h, thick : ndarray
        Depth of each endocardial node below the ring centre along the axis, and the wall thickness there (mm).
    typical, at_ring : float
        Median thickness over 20–60 % of the length, and the 10th percentile at the base ring (mm).
    band : float
        Depth band over which :meth:`below` takes its percentile (mm).
    """

    h: np.ndarray
    thick: np.ndarray
    typical: float
    at_ring: float
    band: float

    @property
    def meet(self) -> bool:
        """Whether the endocardium and epicardium (nearly) meet at the base ring."""
        return self.at_ring < MEET_FRACTION * self.typical

    @property
    def meet_text(self) -> str:
        return (f"the endocardium and epicardium meet at the base (wall thickness {self.at_ring:.1f} mm at the ring)"
                if self.at_ring < 0.5 else
                f"the wall thins to {self.at_ring:.1f} mm at the base ring (typical {self.typical:.1f} mm)")

    def below(self, d: float) -> float:
        """10th-percentile wall thickness in the band ``d`` to ``d + band`` mm below the ring (NaN: too few nodes)."""
        sel = (self.h >= d) & (self.h <= d + self.band)
        return float(np.percentile(self.thick[sel], 10)) if sel.sum() >= 8 else float("nan")


def _wall_profile(endo, epi, base: BaseRing, c: np.ndarray, a: np.ndarray, length: float) -> _WallProfile:
    h = -(endo.points - c) @ a
    thick = wall_thickness(endo.points, epi)
    mid = (h > 0.2 * length) & (h < 0.6 * length)
    t_typ = float(np.median(thick[mid])) if mid.sum() >= 10 else float(np.median(thick))
    t_ring = float(np.percentile(wall_thickness(base.points, epi), 10))
    return _WallProfile(h, thick, t_typ, t_ring, max(2.0, 2.0 * _median_edge(endo)))


def _rule_depth(wall: _WallProfile, ring_depth: float, max_cut: float) -> float:
    """The first depth (0.5 mm steps from the ring's) where the wall reaches :data:`USABLE_FRACTION` of its
    typical thickness; NaN when it does not above the deepest cut allowed."""
    d = ring_depth
    while d <= max(max_cut, ring_depth) + 1e-9:
        w = wall.below(d)
        if np.isfinite(w) and w >= USABLE_FRACTION * wall.typical:
            return d
        d += 0.5
    return float("nan")


def _given_cut(depth: float, wall: _WallProfile, ring_depth: float, rule_depth: float, deepest: BaseRing,
               kind: str) -> tuple[float, str]:
    """``base_cut_mm`` as given, refused above part of a ring or where the wall is too thin."""
    if depth < ring_depth - RING_TOL_MM:
        raise GeometryError(
            f"base_cut_mm (--base-cut) = {depth:g} mm lies above part of the base: the {kind}'s "
            f"{'base ring' if deepest.is_base else 'extra opening'} reaches {ring_depth:.1f} mm below the ring "
            f"centre; give at least {np.ceil(ring_depth * 10) / 10:g} mm so the wall below the cut is complete")
    if wall.meet:
        w = wall.below(max(depth, 0.0))
        if not (np.isfinite(w) and w >= MEET_FRACTION * wall.typical):
            hint = (f"use at least {rule_depth:.1f} mm (where the wall first reaches "
                    f"{USABLE_FRACTION * wall.typical:.1f} mm) or leave it out" if np.isfinite(rule_depth)
                    else "cut lower")
            raise GeometryError(f"{wall.meet_text}; a cut {depth:g} mm below the ring leaves a wall only "
                                f"{0.0 if not np.isfinite(w) else w:.1f} mm thick there: {hint}")
    return depth, "base_cut_mm"


def _default_cut(wall: _WallProfile, ring_depth: float, rule_depth: float, max_cut: float) -> tuple[float, str]:
    """The default cut's depth (mm) and the rule that set it (module docstring)."""
    if wall.meet and not np.isfinite(rule_depth):
        raise GeometryError(
            f"{wall.meet_text}, and the wall stays thinner than {USABLE_FRACTION * wall.typical:.1f} mm "
            f"({USABLE_FRACTION:.0%} of its typical {wall.typical:.1f} mm) down to {max_cut:.0f} mm below the ring; "
            "check that the surfaces are the endocardium and epicardium of one LV, or give the cut with "
            "--base-cut MM (base_cut_mm=)")
    flat_depth = ring_depth if ring_depth > RING_TOL_MM else 0.0
    depth = max(flat_depth, rule_depth)
    rule = ("wall thickness" if wall.meet and rule_depth >= flat_depth and rule_depth > 0
            else "below the ring" if flat_depth > 0 else "flat base")
    return depth, rule


def _messages(wall: _WallProfile, obliq: float, base: BaseRing, holes: list, extra: list, depth: float, rule: str,
              removed: float, full: float) -> list[str]:
    """The notes of :attr:`BaseCut.messages`: thin wall, oblique or uneven base, holes, extra openings, the cut."""
    msgs = []
    if wall.meet:
        msgs.append(wall.meet_text)
    if obliq > 5.0:
        msgs.append(f"the base plane is oblique ({obliq:.1f}° to the long axis)")
    if base.unevenness_mm > 2 * RING_TOL_MM:
        msgs.append(f"the endocardial base ring is uneven ({base.unevenness_mm:.1f} mm peak to peak about its plane)")
    if holes:
        msgs.append(f"{len(holes)} small hole(s) in the surfaces (perimeter up to "
                    f"{max(r.perimeter_mm for r in holes):.1f} mm) bridged by the fit; fill them for a clean surface")
    if extra:
        msgs.append(f"{len(extra)} extra opening(s) besides the base rings (outflow tract or holes), the deepest "
                    f"{max(r.depth_mm for r in extra):.1f} mm below the ring centre")
    if depth > 0:
        msgs.append(f"cut both surfaces {depth:.1f} mm below the base ring's centre ({rule}); "
                    f"{removed:.2f} mL of the {full:.1f} mL cavity removed")
    return msgs


__all__ = ["BaseRing", "BaseCut", "boundary_loops", "surface_rings", "closed_volume", "volume_below_plane",
           "wall_thickness", "find_axis", "analyse_base", "RING_TOL_MM", "MEET_FRACTION", "USABLE_FRACTION",
           "MAX_CUT_FRACTION", "HOLE_FRACTION", "ZERO_VOLUME_FRACTION"]
