"""Segmentation contour stacks: the JSON schema, reading and validation.

A contour stack is what an operator produces from a cardiac-MRI scan at one
phase (early diastole here): closed endocardial and epicardial contours on
parallel short-axis (SA) slices, optionally open long-axis (LA) contours, all as
3-D points in scanner coordinates. Schema (``"schema": "lvcore.contours/1"``)::

    {
      "schema": "lvcore.contours/1",
      "units": "mm",                      # "mm" (default), "cm" or "m"
      "patient": "P01", "operator": "op1",
      "synthetic": true,                  # optional; true for generated data
      "slices": [                         # short-axis slices, any order
        {"position": 0.0,                 # optional slice location (units)
         "endo": [[x, y, z], ...],        # closed contour, >= 8 points; may be
                                          #   null/omitted on apical slices
         "epi":  [[x, y, z], ...]},       # closed contour, >= 8 points
        ...],
      "long_axis": [                      # optional open contours
        {"name": "4CH", "endo": [[x, y, z], ...], "epi": [[x, y, z], ...]}],
      "landmarks": {"septum": [x, y, z]}  # optional: sets the phi = 0 direction
    }

A closed contour may repeat its first point at the end. See ``docs/geometry.md``.

Validation (:func:`validate_contours`) raises :class:`GeometryError` naming
what to fix for: empty or non-JSON files, missing fields, fewer than
:data:`MIN_SLICES` slices, contours with too few points, open or
self-intersecting SA contours, swapped endo/epi, an endocardium that leaves the
epicardium, and coordinates whose size betrays metres or centimetres. It
warns (:class:`GeometryWarning`) about non-parallel slices or slice positions
that disagree with the points.
"""
from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lvcore.safety import limits
from lvcore.exceptions import GeometryError

SCHEMA = "lvcore.contours/1"
#: Fewest short-axis slices a stack needs.
MIN_SLICES = 4
#: Fewest points per contour.
MIN_POINTS = 8
_UNIT_TO_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}


class GeometryWarning(UserWarning):
    """A segmentation is usable but something about it looks wrong."""


@dataclass(frozen=True)
class ContourSlice:
    """One short-axis slice: closed contours (mm, scanner coordinates)."""

    epi: np.ndarray
    endo: np.ndarray | None = None
    position: float | None = None


@dataclass(frozen=True)
class LongAxisContour:
    """One long-axis view: open contours from base over the apex to base (mm)."""

    name: str
    endo: np.ndarray | None = None
    epi: np.ndarray | None = None


@dataclass(frozen=True)
class ContourStack:
    """A validated segmentation of one LV by one operator (mm).

    ``slices`` are sorted from base to apex by :func:`validate_contours`.
    """

    slices: tuple[ContourSlice, ...]
    long_axis: tuple[LongAxisContour, ...] = ()
    patient: str = ""
    operator: str = ""
    synthetic: bool = False
    septum: np.ndarray | None = None
    source: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        """Short human-readable label, flagged SYNTHETIC when generated."""
        name = " / ".join(v for v in (self.patient, self.operator) if v) or (self.source or "contours")
        return ("SYNTHETIC " if self.synthetic else "") + name

    def endo_points(self, long_axis: bool = True) -> np.ndarray:
        """All endocardial points (n, 3) in mm."""
        pts = [s.endo for s in self.slices if s.endo is not None]
        if long_axis:
            pts += [c.endo for c in self.long_axis if c.endo is not None]
        return np.concatenate(pts, axis=0)

    def epi_points(self, long_axis: bool = True) -> np.ndarray:
        """All epicardial points (n, 3) in mm."""
        pts = [s.epi for s in self.slices]
        if long_axis:
            pts += [c.epi for c in self.long_axis if c.epi is not None]
        return np.concatenate(pts, axis=0)

    def to_dict(self, decimals: int = 3) -> dict:
        """The JSON form of this stack (mm)."""
        r = lambda a: None if a is None else np.round(np.asarray(a, float), decimals).tolist()  # noqa: E731
        d = {
            "schema": SCHEMA,
            "units": "mm",
            "patient": self.patient,
            "operator": self.operator,
            "synthetic": bool(self.synthetic),
            "slices": [
                {**({"position": float(s.position)} if s.position is not None else {}), "endo": r(s.endo), "epi": r(s.epi)}
                for s in self.slices
            ],
        }
        if self.long_axis:
            d["long_axis"] = [{"name": c.name, "endo": r(c.endo), "epi": r(c.epi)} for c in self.long_axis]
        if self.septum is not None:
            d["landmarks"] = {"septum": r(self.septum)}
        if self.extra:
            d["extra"] = self.extra
        return d

    def save(self, path) -> Path:
        """Write this stack as JSON (mm)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), separators=(",", ":")))
        return path


# ----------------------------------------------------------------------------- reading
def read_contours(path) -> ContourStack:
    """Read and validate a contour-stack JSON file (see the module docstring).

    Raises
    ------
    GeometryError
        With a message naming the problem and what to fix.
    """
    path = Path(path)
    text = limits.read_text_file(path, limits.MAX_CONTOUR_BYTES, "contour file", GeometryError)
    if not text.strip():
        raise GeometryError(f"contour file '{path}' is empty; export the segmentation as JSON (schema {SCHEMA})")
    data = limits.loads_json(text, f"contour file '{path}' (expected schema {SCHEMA})", GeometryError)
    return contours_from_dict(data, source=str(path))


def contours_from_dict(data, source: str = "<dict>") -> ContourStack:
    """Build and validate a :class:`ContourStack` from its JSON form."""
    where = f"contours {source}"
    if not isinstance(data, dict):
        raise GeometryError(f"{where}: top level must be a JSON object with 'slices', got {type(data).__name__}")
    schema = data.get("schema", SCHEMA)
    if schema != SCHEMA:
        raise GeometryError(f"{where}: unknown schema {_short(schema)}, expected '{SCHEMA}'")
    units = data.get("units", "mm")
    if not isinstance(units, str) or units not in _UNIT_TO_MM:
        raise GeometryError(f"{where}: units {_short(units)} not understood; use one of {sorted(_UNIT_TO_MM)}")
    scale = _UNIT_TO_MM[units]
    slices_in = data.get("slices")
    if not isinstance(slices_in, list) or not slices_in:
        raise GeometryError(f"{where}: 'slices' must be a non-empty list of short-axis slices "
                            "({'endo': [[x,y,z],...], 'epi': [[x,y,z],...]})")
    la_in = data.get("long_axis") or []
    if not isinstance(la_in, list):
        raise GeometryError(f"{where}: 'long_axis' must be a list of long-axis views "
                            f"({{'name': ..., 'endo': [[x,y,z],...], 'epi': [[x,y,z],...]}}), got {type(la_in).__name__}")
    if len(slices_in) + len(la_in) > limits.MAX_CONTOUR_SLICES:
        raise GeometryError(f"{where}: {len(slices_in)} slices and {len(la_in)} long-axis views are more than the "
                            f"limit of {limits.MAX_CONTOUR_SLICES} (lvcore.safety.limits.MAX_CONTOUR_SLICES)")
    total = 0
    for i, s in enumerate(list(slices_in) + list(la_in)):
        if isinstance(s, dict):
            for key in ("endo", "epi"):
                if isinstance(s.get(key), list):
                    total += len(s[key])
    if total > limits.MAX_CONTOUR_POINTS:
        raise GeometryError(f"{where}: {total:,} contour points in all is more than the limit of "
                            f"{limits.MAX_CONTOUR_POINTS:,} (lvcore.safety.limits.MAX_CONTOUR_POINTS); resample the contours")
    for key in ("patient", "operator"):
        if data.get(key) is not None and not isinstance(data[key], (str, int, float)):
            raise GeometryError(f"{where}: '{key}' must be a string, got {type(data[key]).__name__}")
    if not isinstance(data.get("synthetic", False), (bool, int)):
        raise GeometryError(f"{where}: 'synthetic' must be true or false, got {_short(data.get('synthetic'))}")
    if not isinstance(data.get("extra") or {}, dict):
        raise GeometryError(f"{where}: 'extra' must be an object, got {type(data.get('extra')).__name__}")
    slices = []
    for i, s in enumerate(slices_in):
        if not isinstance(s, dict):
            raise GeometryError(f"{where}: slice {i} must be an object with 'endo' and 'epi'")
        if s.get("epi") is None:
            raise GeometryError(f"{where}: slice {i} has no 'epi' contour (every short-axis slice needs one)")
        epi = _points(s["epi"], f"{where}: slice {i} epi", scale)
        endo = None if s.get("endo") is None else _points(s["endo"], f"{where}: slice {i} endo", scale)
        pos = s.get("position")
        if pos is not None and (isinstance(pos, bool) or not isinstance(pos, (int, float))
                                or not np.isfinite(float(pos))):
            raise GeometryError(f"{where}: slice {i} 'position' must be a finite number, got {_short(pos)}")
        slices.append(ContourSlice(epi=epi, endo=endo, position=None if pos is None else float(pos) * scale))
    la = []
    for i, c in enumerate(la_in):
        if not isinstance(c, dict):
            raise GeometryError(f"{where}: long_axis[{i}] must be an object with 'endo' and/or 'epi'")
        endo = None if c.get("endo") is None else _points(c["endo"], f"{where}: long_axis[{i}] endo", scale)
        epi = None if c.get("epi") is None else _points(c["epi"], f"{where}: long_axis[{i}] epi", scale)
        if endo is None and epi is None:
            raise GeometryError(f"{where}: long_axis[{i}] has neither 'endo' nor 'epi' points")
        name = c.get("name", f"LA{i + 1}")
        if not isinstance(name, (str, int)) or isinstance(name, bool):
            raise GeometryError(f"{where}: long_axis[{i}] 'name' must be a string, got {_short(name)}")
        la.append(LongAxisContour(name=str(name)[:64], endo=endo, epi=epi))
    septum = None
    lm = data.get("landmarks") or {}
    if not isinstance(lm, dict):
        raise GeometryError(f"{where}: 'landmarks' must be an object such as {{\"septum\": [x, y, z]}}, "
                            f"got {type(lm).__name__}")
    if "septum" in lm and lm["septum"] is not None:
        sep = lm["septum"]
        if (not isinstance(sep, list) or len(sep) != 3
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in sep)):
            raise GeometryError(f"{where}: landmarks.septum must be one point [x, y, z], got {_short(sep)}")
        septum = np.asarray(sep, dtype=float) * scale
        if not np.all(np.isfinite(septum)):
            raise GeometryError(f"{where}: landmarks.septum must be one point [x, y, z] of finite numbers")
    stack = ContourStack(
        slices=tuple(slices),
        long_axis=tuple(la),
        patient=str(data.get("patient", "")),
        operator=str(data.get("operator", "")),
        synthetic=bool(data.get("synthetic", False)),
        septum=septum,
        source=source,
        extra=dict(data.get("extra", {}) or {}),
    )
    return validate_contours(stack, declared_units=units)


def _short(value, n: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= n else text[: n - 3] + "..."


def _points(value, where: str, scale: float) -> np.ndarray:
    if not isinstance(value, (list, tuple, np.ndarray)):
        raise GeometryError(f"{where}: points must be a list of [x, y, z] numbers, got {type(value).__name__}")
    if len(value) > limits.MAX_POINTS_PER_CONTOUR:
        raise GeometryError(f"{where}: {len(value):,} points is more than the limit of "
                            f"{limits.MAX_POINTS_PER_CONTOUR:,} per contour (lvcore.safety.limits.MAX_POINTS_PER_CONTOUR); "
                            "resample the contour")
    if not isinstance(value, np.ndarray) and any(
            not isinstance(p, (list, tuple)) or any(isinstance(v, (bool, str)) or v is None for v in p)
            for p in value):
        raise GeometryError(f"{where}: points must be a list of [x, y, z] numbers")
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise GeometryError(f"{where}: points must be a list of [x, y, z] numbers") from None
    if a.ndim != 2 or a.shape[1] != 3:
        raise GeometryError(f"{where}: points must be a list of [x, y, z] triples, got array of shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise GeometryError(f"{where}: points contain NaN or inf")
    if len(a) > 1 and np.allclose(a[0], a[-1]):
        a = a[:-1]  # a repeated closing point
    if len(a) < MIN_POINTS:
        raise GeometryError(f"{where}: {len(a)} points; a contour needs at least {MIN_POINTS}")
    return a * scale


# ----------------------------------------------------------------------------- geometry helpers
def plane_fit(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares plane of points: (centroid, unit normal, rms out-of-plane distance)."""
    c = points.mean(axis=0)
    _, sv, vt = np.linalg.svd(points - c, full_matrices=False)
    return c, vt[2], float(sv[2] / np.sqrt(len(points)))


def in_plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane orthogonal to ``normal``."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = ref - normal * (ref @ normal)
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


def polygon_area(xy: np.ndarray) -> float:
    """Signed area of a closed 2-D polygon (shoelace)."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


#: Most edge pairs (or point-edge pairs) handled in one vectorised block: bounds the memory of
#: :func:`self_intersections` and :func:`_inside` to about 100 MB whatever the contour size.
_BLOCK_PAIRS = 1_000_000


def self_intersections(xy: np.ndarray) -> int:
    """Number of crossing pairs of non-adjacent edges of a closed 2-D polygon.

    Edges are sorted by their smallest x; only pairs whose x-ranges overlap
    (a sweep) and whose bounding boxes overlap get the orientation tests,
    done in blocks of at most ``_BLOCK_PAIRS`` pairs, so memory stays bounded
    (no n x n arrays) and a typical contour costs about O(n log n).
    """
    p = np.asarray(xy, dtype=float)
    n = len(p)
    if n < 4:
        return 0
    q = np.roll(p, -1, axis=0)
    lo, hi = np.minimum(p, q), np.maximum(p, q)
    order = np.argsort(lo[:, 0], kind="stable")
    lo_x_sorted = lo[order, 0]
    # for edge order[k], candidates are order[k+1 : end[k]] (x-ranges overlap)
    end = np.searchsorted(lo_x_sorted, hi[order, 0], side="right")
    counts = np.maximum(end - np.arange(n) - 1, 0)
    count = 0
    k0 = 0
    while k0 < n:
        # a block of sweep positions whose candidate pairs fit in _BLOCK_PAIRS
        csum = np.cumsum(counts[k0:])
        k1 = k0 + max(1, int(np.searchsorted(csum, _BLOCK_PAIRS, side="right")))
        ks = np.arange(k0, k1)
        reps = counts[ks]
        if reps.sum():
            a_pos = np.repeat(ks, reps)
            starts = np.repeat(ks + 1 - np.concatenate([[0], np.cumsum(reps)[:-1]]), reps)
            b_pos = starts + np.arange(reps.sum())
            i, j = order[a_pos], order[b_pos]
            i, j = np.minimum(i, j), np.maximum(i, j)
            keep = (j - i >= 2) & ~((i == 0) & (j == n - 1))  # adjacent edges share a vertex
            keep &= (lo[i, 1] <= hi[j, 1]) & (lo[j, 1] <= hi[i, 1])
            i, j = i[keep], j[keep]
            if i.size:
                count += _crossings(p[i], q[i] - p[i], p[j], q[j] - p[j])
        k0 = k1
    return count


def _crossings(pi, di, pj, dj) -> int:
    """Number of proper crossings of segment pairs (pi, pi + di) and (pj, pj + dj)."""
    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    o1 = cross(di, pj - pi)
    o2 = cross(di, pj + dj - pi)
    o3 = cross(dj, pi - pj)
    o4 = cross(dj, pi + di - pj)
    return int(np.count_nonzero((o1 * o2 < 0) & (o3 * o4 < 0)))


def _inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test (2-D), in blocks of bounded memory."""
    x1, y1 = poly[:, 0][None, :], poly[:, 1][None, :]
    x2, y2 = np.roll(poly[:, 0], -1)[None, :], np.roll(poly[:, 1], -1)[None, :]
    out = np.zeros(len(pts), dtype=bool)
    step = max(1, _BLOCK_PAIRS // max(1, len(poly)))
    for k in range(0, len(pts), step):
        x, y = pts[k:k + step, 0][:, None], pts[k:k + step, 1][:, None]
        cond = (y1 > y) != (y2 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xint = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        out[k:k + step] = np.count_nonzero(cond & (x < xint), axis=1) % 2 == 1
    return out


# ----------------------------------------------------------------------------- validation
def validate_contours(stack: ContourStack, declared_units: str = "mm") -> ContourStack:
    """Check a stack and return it with slices sorted from base to apex.

    Raises :class:`GeometryError` for unusable stacks, warns
    (:class:`GeometryWarning`) for suspicious ones. See the module docstring.
    """
    where = f"contours {stack.source or stack.label}"
    n = len(stack.slices)
    if n < MIN_SLICES:
        raise GeometryError(f"{where}: {n} short-axis slices; at least {MIN_SLICES} from base to apex are needed "
                            "to fit an LV (add the missing slices)")
    # slice planes
    normals, centroids = [], []
    for i, s in enumerate(stack.slices):
        c, nrm, rms = plane_fit(s.epi)
        normals.append(nrm)
        centroids.append(c)
    normals = np.array(normals)
    ref = normals[0]
    normals *= np.sign(normals @ ref)[:, None]
    normal = normals.mean(axis=0)
    normal /= np.linalg.norm(normal)
    tilt = np.degrees(np.arccos(np.clip(normals @ normal, -1, 1)))
    if tilt.max() > 10.0:
        warnings.warn(f"{where}: short-axis slices are not parallel (up to {tilt.max():.0f}° from the mean plane); "
                      "check that only short-axis contours are listed under 'slices'", GeometryWarning, stacklevel=3)
    u, v = in_plane_basis(normal)

    def xy(pts):
        return np.stack([pts @ u, pts @ v], axis=1)

    # units by size: an adult LV epicardium has a radius of about 15-45 mm
    radii = []
    for s in stack.slices:
        e = xy(s.epi)
        radii.append(np.sqrt(abs(polygon_area(e)) / np.pi))
    rmax = float(np.max(radii))
    scale = _UNIT_TO_MM[declared_units]
    if rmax < 0.1:
        raise GeometryError(f"{where}: the largest epicardial contour has an equivalent radius of {rmax / scale:.3g} "
                            f"{declared_units}; the coordinates look like metres. Set \"units\": \"m\" "
                            "or convert the points to mm")
    if rmax < 8.0:
        raise GeometryError(f"{where}: the largest epicardial contour has an equivalent radius of {rmax / scale:.3g} "
                            f"{declared_units}; the coordinates look like centimetres. Set \"units\": \"cm\" "
                            "or convert the points to mm")
    if rmax > 150.0:
        raise GeometryError(f"{where}: the largest epicardial contour has an equivalent radius of {rmax:.0f} mm, "
                            "far larger than an LV; check the units (mm expected) and that the points are contours")
    # per-slice checks
    swapped = []
    outside = {}  # slice -> fraction of its endocardium outside the epicardium (checked once the base is known)
    for i, s in enumerate(stack.slices):
        for name, pts in (("epi", s.epi), ("endo", s.endo)):
            if pts is None:
                continue
            p2 = xy(pts)
            seg = np.linalg.norm(np.diff(np.vstack([p2, p2[:1]]), axis=0), axis=1)
            med = float(np.median(seg))
            c2 = p2.mean(axis=0)
            ang = np.sort(np.arctan2(p2[:, 1] - c2[1], p2[:, 0] - c2[0]))
            ang_gap = float(np.max(np.diff(np.append(ang, ang[0] + 2 * np.pi))))
            closing = seg[-1]
            if closing > max(5.0 * med, 3.0) or ang_gap > np.pi / 2:
                raise GeometryError(f"{where}: slice {i} {name} contour is open (gap of {closing:.1f} mm between its last "
                                    f"and first point, median spacing {med:.1f} mm); short-axis contours must go "
                                    "all the way round")
            k = self_intersections(p2)
            if k:
                raise GeometryError(f"{where}: slice {i} {name} contour crosses itself ({k} crossing(s)); "
                                    "redraw it as a simple closed curve")
        if s.endo is not None:
            a_endo = abs(polygon_area(xy(s.endo)))
            a_epi = abs(polygon_area(xy(s.epi)))
            if a_endo >= a_epi:
                swapped.append(i)
                continue
            out = ~_inside(xy(s.epi), xy(s.endo))
            if out.mean() > 0.05:
                outside[i] = float(out.mean())
    if swapped:
        if len(swapped) >= n // 2:
            raise GeometryError(f"{where}: endocardial and epicardial contours look swapped (endo encloses the larger "
                                f"area in slices {swapped}); swap the 'endo' and 'epi' fields")
        raise GeometryError(f"{where}: in slices {swapped} the endocardial contour encloses more area than the "
                            "epicardial one; they look swapped there")
    if all(s.endo is None for s in stack.slices):
        raise GeometryError(f"{where}: no slice has an endocardial contour")
    # order base -> apex: base is the end with the larger epicardial area
    pos = np.array(centroids) @ normal
    order = np.argsort(pos)
    areas = np.array(radii)[order]
    k = max(1, n // 3)
    if areas[:k].mean() < areas[-k:].mean():
        order = order[::-1]
    given = np.array([np.nan if s.position is None else s.position for s in stack.slices])
    if np.all(np.isfinite(given)):
        gap = np.abs(np.abs(np.diff(np.sort(given))).sum() - np.abs(np.diff(np.sort(pos))).sum())
        if gap > 0.2 * max(np.ptp(pos), 1.0):
            warnings.warn(f"{where}: slice 'position' values span {np.ptp(given):.1f} mm but the contours' planes span "
                          f"{np.ptp(pos):.1f} mm; the positions are ignored (the points are used)", GeometryWarning,
                          stacklevel=3)
    for i, frac in outside.items():
        if i != order[0]:  # the basal slice may include the outflow tract: base_of_stack() judges it
            raise GeometryError(f"{where}: slice {i}: {100 * frac:.0f}% of the endocardial contour lies outside "
                                "the epicardial contour; fix the contours of that slice")
    slices = tuple(stack.slices[i] for i in order)
    if slices[0].endo is None:
        raise GeometryError(f"{where}: the basal slice has no endocardial contour; the base must show the cavity")
    return ContourStack(slices=slices, long_axis=stack.long_axis, patient=stack.patient, operator=stack.operator,
                        synthetic=stack.synthetic, septum=stack.septum, source=stack.source, extra=stack.extra)


def slice_normal(stack: ContourStack) -> np.ndarray:
    """Mean unit normal of the short-axis slices, pointing from the apex towards the base."""
    normals = np.array([plane_fit(s.epi)[1] for s in stack.slices])
    normals *= np.sign(normals @ normals[0])[:, None]
    n = normals.mean(axis=0)
    n /= np.linalg.norm(n)
    c0 = stack.slices[0].epi.mean(axis=0)
    c1 = stack.slices[-1].epi.mean(axis=0)
    if (c0 - c1) @ n < 0:
        n = -n
    return n


# ----------------------------------------------------------------------------- the base of a stack
#: A basal slice whose wall is thinner than this fraction of the typical wall over part of its circumference ...
OUTFLOW_THIN_FRACTION = 0.5
#: ... over at least this fraction of its endocardial contour includes the outflow tract.
OUTFLOW_MIN_ARC = 0.05
#: At most this many basal slices are dropped by default.
MAX_DROPPED_SLICES = 2


@dataclass(frozen=True)
class ContourBase:
    """The base of a contour stack and where it was cut (mm, mL; scanner coordinates).

    Attributes
    ----------
    plane_origin, plane_normal : (3,) arrays
        Least-squares plane of the most basal slice as given (normal apex -> base).
    unevenness_mm : float
        Peak-to-peak distance of that slice's points from its plane.
    wall_at_ring_mm, wall_typical_mm : float
        Thinnest wall of the most basal slice as given, and the median wall of the middle slices.
    walls_meet : bool
        The most basal slice as given has no wall over part of its circumference.
    dropped : tuple of str
        One line per basal slice dropped, with the reason.
    cut_depth_mm : float
        Distance from the given basal slice to the basal slice kept.
    rule : str
        "basal slice" (nothing dropped), "outflow tract", "wall thickness" (walls meet) or "base_cut_mm".
    cavity_removed_ml : float
        Cavity between the dropped slices and the new basal slice (frustum rule on the endocardial areas).
    messages : tuple of str
    """

    plane_origin: np.ndarray
    plane_normal: np.ndarray
    unevenness_mm: float
    wall_at_ring_mm: float
    wall_typical_mm: float
    walls_meet: bool
    dropped: tuple
    cut_depth_mm: float
    rule: str
    cavity_removed_ml: float
    messages: tuple = ()

    def summary(self) -> dict:
        r = lambda v, nd=3: [round(float(x), nd) for x in v]  # noqa: E731
        return {"base_plane": {"origin": r(self.plane_origin), "normal": r(self.plane_normal, 4),
                               "unevenness_mm": round(self.unevenness_mm, 3)},
                "wall_at_ring_mm": round(self.wall_at_ring_mm, 3), "wall_typical_mm": round(self.wall_typical_mm, 3),
                "walls_meet": bool(self.walls_meet),
                "cut": {"depth_mm": round(self.cut_depth_mm, 3), "rule": self.rule, "dropped_slices": list(self.dropped)},
                "cavity_removed_ml": round(self.cavity_removed_ml, 3), "messages": list(self.messages)}

    def describe(self) -> str:
        return (f"basal slice plane through ({', '.join(f'{v:.1f}' for v in self.plane_origin)}) normal "
                f"({', '.join(f'{v:.3f}' for v in self.plane_normal)}); cut {self.cut_depth_mm:.1f} mm below it "
                f"({self.rule}; {len(self.dropped)} slice(s) dropped); cavity removed {self.cavity_removed_ml:.2f} mL")


def _slice_wall(s: ContourSlice, u, v) -> np.ndarray:
    """Wall thickness (mm) at each endocardial point of a slice: distance to the epicardial polyline,
    0 where the point lies outside the epicardium."""
    e = np.stack([s.endo @ u, s.endo @ v], axis=1)
    p = np.stack([s.epi @ u, s.epi @ v], axis=1)
    a, b = p, np.roll(p, -1, axis=0)
    d = b - a
    t = np.clip(np.einsum("mkd,kd->mk", e[:, None, :] - a[None], d) / np.maximum((d * d).sum(1), 1e-300), 0, 1)
    dist = np.linalg.norm(e[:, None, :] - (a[None] + t[..., None] * d[None]), axis=2).min(axis=1)
    return np.where(_inside(p, e), dist, 0.0)


def base_of_stack(stack: ContourStack, base_cut_mm: float | None = None) -> tuple[ContourStack, ContourBase]:
    """Find the base of a validated stack; drop basal slices that include the outflow tract.

    A basal slice whose wall (distance from the endocardial to the epicardial
    contour) is thinner than :data:`OUTFLOW_THIN_FRACTION` of the typical
    wall (median over the middle third of the slices) over at least
    :data:`OUTFLOW_MIN_ARC` of its circumference cuts through the outflow
    tract: it is dropped and the next slice becomes the base (at most
    :data:`MAX_DROPPED_SLICES`). ``base_cut_mm`` instead drops every slice
    less than that distance (mm, less 0.5 mm) below the given basal slice.

    Returns
    -------
    (ContourStack, ContourBase)
        The stack from the new basal slice down, and the report.

    Raises
    ------
    GeometryError
        Too few slices left, or a ``base_cut_mm`` that keeps a slice through the outflow tract.
    """
    where = f"contours {stack.source or stack.label}"
    if base_cut_mm is not None and not (np.isfinite(base_cut_mm) and base_cut_mm >= 0):
        raise GeometryError(f"base_cut_mm (--base-cut) = {base_cut_mm}: give a distance >= 0 mm below the basal slice")
    n = slice_normal(stack)
    u, v = in_plane_basis(n)
    c0, n0, _ = plane_fit(np.concatenate([stack.slices[0].epi, stack.slices[0].endo]))
    n0 = n0 if n0 @ n > 0 else -n0
    uneven = float(np.ptp((np.concatenate([stack.slices[0].epi, stack.slices[0].endo]) - c0) @ n0))
    walls = [(_slice_wall(s, u, v) if s.endo is not None else None) for s in stack.slices]
    k = len(stack.slices)
    middle = [w for w in walls[k // 3: max(k // 3 + 1, 2 * k // 3)] if w is not None] or [w for w in walls if w is not None]
    t_typ = float(np.median(np.concatenate(middle)))
    depth = [float((s.epi.mean(axis=0) - stack.slices[0].epi.mean(axis=0)) @ -n) for s in stack.slices]

    def outflow(i) -> str:
        w = walls[i]
        if w is None:
            return ""
        thin = w < OUTFLOW_THIN_FRACTION * t_typ
        if thin.mean() < OUTFLOW_MIN_ARC:
            return ""
        where_ = f"slice {i} (at the base{'' if i == 0 else f', {depth[i]:.1f} mm down'})"
        if thin.mean() > 0.5:
            return (f"{where_}: the endocardium and epicardium meet there (wall thickness {np.median(w):.1f} mm over "
                    f"{360 * thin.mean():.0f}° of it, typical {t_typ:.1f} mm)")
        return (f"{where_} has no wall over {360 * thin.mean():.0f}° of its circumference (wall thickness "
                f"{w.min():.1f} mm there, typical {t_typ:.1f} mm): it includes the outflow tract")

    reasons = []
    if base_cut_mm is None:
        first = 0
        while first < min(MAX_DROPPED_SLICES, k) and outflow(first):
            reasons.append(outflow(first) + "; dropped")
            first += 1
        if first == MAX_DROPPED_SLICES and first < k and outflow(first):
            raise GeometryError(f"{where}: the {first + 1} most basal slices all include the outflow tract "
                                f"({outflow(first)}); remove the slices above the mitral valve plane, or give the cut "
                                "with --base-cut MM (base_cut_mm=)")
        rule = ("basal slice" if not first else "outflow tract" if all("outflow" in r for r in reasons)
                else "wall thickness")
    else:
        first = next((i for i in range(k) if depth[i] >= base_cut_mm - 0.5), k)
        if first < k and outflow(first):
            raise GeometryError(f"{where}: {outflow(first)}; --base-cut {base_cut_mm:g} keeps it as the basal slice: "
                                f"use at least {depth[first + 1] if first + 1 < k else depth[first]:.1f} mm or leave "
                                "--base-cut out")
        reasons = [f"slice {i} is {depth[i]:.1f} mm below the basal slice, less than --base-cut {base_cut_mm:g}; "
                   "dropped" for i in range(first)]
        rule = "base_cut_mm" if first else "basal slice"
    if k - first < MIN_SLICES:
        raise GeometryError(f"{where}: dropping {first} basal slice(s) leaves {k - first}; at least {MIN_SLICES} are "
                            f"needed ({'; '.join(reasons)})")
    removed = 0.0
    area = [abs(polygon_area(np.stack([s.endo @ u, s.endo @ v], 1))) if s.endo is not None else 0.0
            for s in stack.slices]
    for i in range(first):
        h = depth[i + 1] - depth[i]
        removed += h / 3.0 * (area[i] + area[i + 1] + np.sqrt(area[i] * area[i + 1]))
    msgs = list(reasons)
    if first:
        msgs.append(f"the base plane moved to slice {first}, {depth[first]:.1f} mm below the given basal slice; about "
                    f"{removed / 1000:.1f} mL of cavity removed (frustum rule)")
    new = ContourStack(slices=stack.slices[first:], long_axis=stack.long_axis, patient=stack.patient,
                       operator=stack.operator, synthetic=stack.synthetic, septum=stack.septum, source=stack.source,
                       extra=stack.extra)
    w0 = walls[0]
    return new, ContourBase(plane_origin=c0, plane_normal=n0, unevenness_mm=uneven,
                            wall_at_ring_mm=float(w0.min()) if w0 is not None else float("nan"),
                            wall_typical_mm=t_typ, walls_meet=bool(outflow(0)), dropped=tuple(reasons),
                            cut_depth_mm=float(depth[first]), rule=rule, cavity_removed_ml=removed / 1000.0,
                            messages=tuple(msgs))
