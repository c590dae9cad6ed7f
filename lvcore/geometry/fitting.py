"""Fit the fixed-topology template to a segmentation (contour stack or surfaces).

Method
------
1. **Frame.** The long axis runs from the base centroid (centroid of the
   basal endocardial contour, or of the endocardial surface's open boundary)
   to the apex (the epicardial point furthest from the base, from long-axis
   contours or the surface; without long-axis contours the mean short-axis
   slice normal is used). It becomes −z; the base plane, orthogonal to it
   through the base centroid, becomes ``z = base_z``. The +x axis (phi = 0)
   points from the axis towards the ``septum`` landmark if one is given,
   otherwise along the scanner x axis projected onto the base plane.
2. **Radial functions.** About a centre ``O = (0, 0, base_z − κ L)`` on the
   axis (``L`` the base-to-epicardial-apex length, ``κ`` = :data:`CENTRE_FRACTION`),
   each surface is star-shaped: ``x = O + R(θ, φ) d(θ, φ)`` with
   ``d = (sin θ cos φ, sin θ sin φ, −cos θ)`` (θ = 0 at the apex). ``R`` is
   fitted to the points by Tikhonov-regularised least squares on real
   spherical harmonics up to :data:`DEFAULT_DEGREE` (penalty ``λ (l(l+1))²``),
   which smooths the contours, bridges the gaps between slices and closes the
   apical cap. ``L`` (hence ``O``) is re-estimated from the fitted epicardium
   and the fit repeated, so the parametrisation is intrinsic to the shape.
3. **Nodes.** Template node ``(φ, s, t)``: on each surface the point at polar
   angle ``θ = (1 − s) θ_b(φ)``, where ``θ_b(φ)`` puts the base row exactly on
   the base plane; interior layers interpolate linearly between endocardium
   (t = 0) and epicardium (t = 1), as in :mod:`lvcore.geometry.analytic`.
4. **Residual.** Distance from every input point at or below the base plane
   to the fitted (isoparametric) template surface of its kind, computed
   against a fine triangulation of the template surface (mm).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from lvcore.exceptions import GeometryError
from lvcore.geometry.contours import ContourStack, GeometryWarning, plane_fit, read_contours, slice_normal
from lvcore.geometry.template import DEFAULT_TEMPLATE, LVTemplate

#: Default spherical-harmonic degree of the radial functions.
DEFAULT_DEGREE = 10
#: Default regularisation weight (relative; see :func:`fit_radial`).
DEFAULT_SMOOTHING = 1e-6
#: Centre of the radial parametrisation, as a fraction of the base-apex length below the base.
CENTRE_FRACTION = 0.4
#: Base plane height of fitted geometries (mm).
DEFAULT_BASE_Z = 0.0


@dataclass(frozen=True)
class LVFrame:
    """Rigid map from scanner coordinates to the template frame (mm).

    ``x_template = rotation @ (x - origin) + (0, 0, base_z)``; the rows of
    ``rotation`` are the template's x, y, z axes in scanner coordinates.
    """

    origin: np.ndarray
    rotation: np.ndarray
    base_z: float = DEFAULT_BASE_Z

    def to_template(self, x) -> np.ndarray:
        return (np.asarray(x, float) - self.origin) @ self.rotation.T + np.array([0.0, 0.0, self.base_z])

    def to_scanner(self, x) -> np.ndarray:
        return (np.asarray(x, float) - np.array([0.0, 0.0, self.base_z])) @ self.rotation + self.origin


@dataclass(frozen=True)
class FitResult:
    """A template fitted to a segmentation.

    Attributes
    ----------
    nodes : (n_nodes, 3) array
        Node positions on the template, in the template frame (mm).
    residual_mean_mm, residual_max_mm : float
        Mean and maximum distance of the input points (at or below the base
        plane) to the fitted surfaces (mm).
    residual_endo_mean_mm, residual_epi_mean_mm : float
        The mean split by surface (mm).
    n_points : int
        Input points used in the residual.
    n_above_base : int
        Input points above the base plane (not part of the truncated LV).
    cavity_volume_ml : float
        Cavity volume of the fitted geometry (mL).
    length_mm : float
        Base-plane-to-epicardial-apex length (mm).
    frame : LVFrame
        Scanner -> template transform.
    label : str
        What was fitted (patient / operator; SYNTHETIC if generated).
    warnings : tuple of str
    base : BaseCut or None
        Where the base was found and cut (:mod:`lvcore.geometry.base_plane`; surfaces and volume meshes),
        or a :class:`~lvcore.geometry.contours.ContourBase` (contour stacks): the base plane, the cut and
        the cavity volume it removed.
    """

    nodes: np.ndarray
    residual_mean_mm: float
    residual_max_mm: float
    residual_endo_mean_mm: float
    residual_epi_mean_mm: float
    n_points: int
    n_above_base: int
    cavity_volume_ml: float
    length_mm: float
    frame: LVFrame
    label: str = ""
    warnings: tuple = field(default=())
    base: object = None

    def summary(self) -> dict:
        """Plain-data summary (JSON-ready); ``"base"`` holds the base plane, the cut and the volume removed."""
        return {
            "label": self.label,
            "residual_mean_mm": self.residual_mean_mm,
            "residual_max_mm": self.residual_max_mm,
            "residual_endo_mean_mm": self.residual_endo_mean_mm,
            "residual_epi_mean_mm": self.residual_epi_mean_mm,
            "n_points": self.n_points,
            "n_above_base": self.n_above_base,
            "cavity_volume_ml": self.cavity_volume_ml,
            "length_mm": self.length_mm,
            "warnings": list(self.warnings),
            "base": None if self.base is None else self.base.summary(),
        }


def units_warnings(res, units: str = "mm", option: str = "--units") -> list[str]:
    """Warnings naming the units option when a fitted LV is larger than any real one (wrong units).

    The one home of this check: ``lvcore geometry fit`` (``--units``), ``lvcore calibrate --geometry MESH``
    (``--geometry-units``) and the app's uploads each pass the name of their own units option.

    Parameters
    ----------
    res : FitResult
        Anything with ``cavity_volume_ml`` (mL) and ``length_mm`` (mm).
    units : str
        The length units the file was read in (``"mm"``, ``"cm"``, ``"m"``).
    option : str
        The option (or control) that sets ``units``, named in the warning.

    Returns
    -------
    list of str
        One warning when the cavity exceeds :data:`lvcore.safety.limits.PLAUSIBLE_MAX_FITTED_CAVITY_ML` or the
        length exceeds :data:`lvcore.safety.limits.PLAUSIBLE_MAX_FITTED_LENGTH_MM`; empty otherwise.
    """
    from lvcore.safety import limits

    if not (res.cavity_volume_ml > limits.PLAUSIBLE_MAX_FITTED_CAVITY_ML
            or res.length_mm > limits.PLAUSIBLE_MAX_FITTED_LENGTH_MM):
        return []
    return [f"the fitted LV has a {res.cavity_volume_ml:,.0f} mL cavity and is {res.length_mm:.0f} mm long, "
            f"more than a real LV (> {limits.PLAUSIBLE_MAX_FITTED_CAVITY_ML:.0f} mL or "
            f"> {limits.PLAUSIBLE_MAX_FITTED_LENGTH_MM:.0f} mm): check {option} (read as {units}; a mm file "
            "read as cm is 1,000 times too large in volume)"]


# ----------------------------------------------------------------------------- spherical harmonics
def _sh_basis(theta, phi, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal real spherical harmonics (n, P) up to ``degree`` and their degrees l (P,).

    Column order: for l = 0..degree, m = 0 (cos), then m = 1..l as (cos m phi, sin m phi)
    pairs. Fully normalised associated Legendre functions by the standard
    three-term recurrences (equal, up to sign, to ``scipy.special.sph_harm_y``
    with the real parts scaled by sqrt 2, and about 5x faster).
    """
    theta = np.asarray(theta, float).ravel()
    phi = np.asarray(phi, float).ravel()
    x, s = np.cos(theta), np.sin(theta)
    P = {}
    pmm = np.full(x.shape, 1.0 / np.sqrt(4.0 * np.pi))
    for m in range(degree + 1):
        if m > 0:
            pmm = -np.sqrt((2 * m + 1) / (2.0 * m)) * s * pmm
        P[(m, m)] = pmm
        if m + 1 <= degree:
            P[(m + 1, m)] = np.sqrt(2 * m + 3) * x * pmm
        for l in range(m + 2, degree + 1):
            a = np.sqrt((4.0 * l * l - 1) / (l * l - m * m))
            b = np.sqrt(((l - 1.0) ** 2 - m * m) / (4.0 * (l - 1) ** 2 - 1))
            P[(l, m)] = a * (x * P[(l - 1, m)] - b * P[(l - 2, m)])
    cm = [np.cos(m * phi) for m in range(degree + 1)]
    sm = [np.sin(m * phi) for m in range(degree + 1)]
    cols, ls = [], []
    for l in range(degree + 1):
        for m in range(l + 1):
            if m == 0:
                cols.append(P[(l, 0)])
                ls.append(l)
            else:
                cols += [np.sqrt(2.0) * P[(l, m)] * cm[m], np.sqrt(2.0) * P[(l, m)] * sm[m]]
                ls += [l, l]
    return np.stack(cols, axis=-1), np.asarray(ls)


@dataclass(frozen=True)
class RadialSurface:
    """A star-shaped surface ``O + R(θ, φ) d(θ, φ)`` about ``O = (0, 0, z0)`` (mm)."""

    z0: float
    coef: np.ndarray
    degree: int

    def radius(self, theta, phi) -> np.ndarray:
        theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
        B, _ = _sh_basis(theta.ravel(), phi.ravel(), self.degree)
        return (B @ self.coef).reshape(theta.shape)

    def point(self, theta, phi) -> np.ndarray:
        theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
        r = self.radius(theta, phi)
        d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)], axis=-1)
        return np.array([0.0, 0.0, self.z0]) + r[..., None] * d

    def base_angle(self, phi, base_z: float, n_grid: int = 90) -> np.ndarray:
        """Polar angle θ_b(φ) where the surface meets the plane z = base_z (rad).

        The centre lies below the base plane, so θ_b > 90°: a grid search over
        [80°, 179°] then secant refinement.
        """
        phi = np.asarray(phi, float)
        th = np.linspace(np.radians(80.0), np.pi - 0.02, n_grid)
        TH, PH = np.meshgrid(th, phi, indexing="ij")
        z = self.z0 - self.radius(TH, PH) * np.cos(TH) - base_z  # (n_grid, n_phi)
        out = np.empty(phi.shape)
        for i in range(phi.size):
            idx = np.nonzero((z[:-1, i] < 0) & (z[1:, i] >= 0))[0]
            if idx.size == 0:
                raise GeometryError("the fitted surface does not reach the base plane; the segmentation is "
                                    "too short or the base slice is missing")
            a = idx[0]
            t0, t1, z0_, z1_ = th[a], th[a + 1], z[a, i], z[a + 1, i]
            out.flat[i] = t0 + (t1 - t0) * (-z0_) / (z1_ - z0_)
        # two secant refinements
        for _ in range(2):
            f = self.z0 - self.radius(out, phi) * np.cos(out) - base_z
            h = 1e-4
            f2 = self.z0 - self.radius(out + h, phi) * np.cos(out + h) - base_z
            step = f * h / np.where(np.abs(f2 - f) > 1e-14, f2 - f, 1e-14)
            out = out - np.clip(step, -0.05, 0.05)
        return out


def fit_radial(points, z0: float, degree: int = DEFAULT_DEGREE, smoothing: float = DEFAULT_SMOOTHING) -> RadialSurface:
    """Least-squares radial function of points (template frame, mm) about ``(0, 0, z0)``.

    Minimises ``Σ (|x_i - O| - R(θ_i, φ_i))² / n + smoothing · R0² Σ_lm (l(l+1))² c_lm²``
    where ``R0`` is the mean radius, so ``smoothing`` is scale-free.
    """
    p = np.asarray(points, float) - np.array([0.0, 0.0, z0])
    r = np.linalg.norm(p, axis=1)
    theta = np.arccos(np.clip(-p[:, 2] / np.maximum(r, 1e-12), -1.0, 1.0))
    phi = np.arctan2(p[:, 1], p[:, 0])
    B, ls = _sh_basis(theta, phi, degree)
    n = len(r)
    pen = smoothing * (ls * (ls + 1.0)) ** 2
    A = B.T @ B / n + np.diag(pen)
    coef = np.linalg.solve(A, B.T @ r / n)
    return RadialSurface(z0=float(z0), coef=coef, degree=degree)


# ----------------------------------------------------------------------------- core fit
def nodes_from_radial(endo: RadialSurface, epi: RadialSurface, base_z: float,
                      template: LVTemplate = DEFAULT_TEMPLATE) -> np.ndarray:
    """Template nodes from two radial surfaces (see the module docstring)."""
    pc = template.parametric_coords
    phi_u = 2 * np.pi * np.arange(template.nc) / template.nc
    tb_endo = endo.base_angle(phi_u, base_z)
    tb_epi = epi.base_angle(phi_u, base_z)
    i = template.grid_ijk[:, 0]
    phi, s, t = pc[:, 0], pc[:, 1], pc[:, 2]
    x_endo = endo.point((1.0 - s) * tb_endo[i], phi)
    x_epi = epi.point((1.0 - s) * tb_epi[i], phi)
    x = (1.0 - t)[:, None] * x_endo + t[:, None] * x_epi
    x[:, 2] = np.where(s == 0.0, base_z, x[:, 2])  # exactly planar base
    return x


def fit_point_clouds(endo_points, epi_points, base_z: float = DEFAULT_BASE_Z, template: LVTemplate = DEFAULT_TEMPLATE,
                     degree: int = DEFAULT_DEGREE, smoothing: float = DEFAULT_SMOOTHING, n_iter: int = 2):
    """Fit template nodes to endo/epi point clouds already in the template frame (mm).

    Returns
    -------
    nodes : (n_nodes, 3) array (mm)
    endo, epi : RadialSurface
    length : float
        Base-to-epicardial-apex length (mm).
    """
    endo_points = np.asarray(endo_points, float)
    epi_points = np.asarray(epi_points, float)
    length = float(base_z - epi_points[:, 2].min())
    if length <= 5.0:
        raise GeometryError(f"the epicardial points reach only {length:.1f} mm below the base plane; an LV needs its "
                            "slices from base towards the apex")
    for _ in range(max(1, n_iter)):
        z0 = base_z - CENTRE_FRACTION * length
        endo = fit_radial(endo_points, z0, degree, smoothing)
        epi = fit_radial(epi_points, z0, degree, smoothing)
        length = float(base_z - (z0 - epi.radius(0.0, 0.0)))
    nodes = nodes_from_radial(endo, epi, base_z, template)
    return nodes, endo, epi, length


def _surface_polydata(nodes, template: LVTemplate, t: float, n_phi: int = 96, n_s: int = 64):
    import pyvista as pv

    phi = np.linspace(0.0, 2 * np.pi, n_phi, endpoint=False)
    s = np.linspace(0.0, 1.0, n_s + 1)[:-1]
    P, S = np.meshgrid(phi, s, indexing="ij")
    pts = template.evaluate(nodes, P, S, np.full_like(P, t)).reshape(-1, 3)
    apex = template.evaluate(nodes, 0.0, 1.0, t).reshape(1, 3)
    pts = np.vstack([pts, apex])
    idx = np.arange(n_phi * n_s).reshape(n_phi, n_s)
    i1 = np.roll(idx, -1, axis=0)
    tris = [np.stack([idx[:, :-1], i1[:, :-1], i1[:, 1:]], -1).reshape(-1, 3),
            np.stack([idx[:, :-1], i1[:, 1:], idx[:, 1:]], -1).reshape(-1, 3),
            np.stack([idx[:, -1], i1[:, -1], np.full(n_phi, n_phi * n_s)], -1)]
    tris = np.vstack(tris)
    faces = np.hstack([np.full((len(tris), 1), 3), tris]).ravel()
    return pv.PolyData(pts, faces)


def surface_distances(nodes, points, which: str, template: LVTemplate = DEFAULT_TEMPLATE) -> np.ndarray:
    """Distance (mm) of points (template frame) to the template's endo or epi surface."""
    poly = _surface_polydata(nodes, template, 0.0 if which == "endo" else 1.0)
    points = np.asarray(points, float)
    if len(points) == 0:
        return np.zeros(0)
    _, closest = poly.find_closest_cell(points, return_closest_point=True)
    return np.linalg.norm(points - closest, axis=1)


def fitted_wall_thickness(nodes, template: LVTemplate = DEFAULT_TEMPLATE) -> np.ndarray:
    """Distance (mm) from each endocardial node to the epicardial node of the same (φ, s): (nl - 1, nc) rows."""
    i, j = np.meshgrid(np.arange(template.nc), np.arange(template.nl - 1), indexing="xy")
    a = nodes[template.node_index(i, j, 0)]
    b = nodes[template.node_index(i, j, template.nt - 1)]
    return np.linalg.norm(b - a, axis=-1)


def _inverted_message(nodes, template, label: str, base) -> str:
    """The last guard's message: where the inverted elements are and the thinnest fitted wall."""
    from lvcore.geometry.io import element_jacobian_determinants

    bad = np.nonzero(np.any(element_jacobian_determinants(nodes, template) <= 0, axis=1))[0]
    rows = template.element_grid[bad, 1]
    where = ", ".join(sorted({("base" if r < template.n_long / 3 else "mid-ventricle" if r < 2 * template.n_long / 3
                               else "apex") for r in rows}))
    w = fitted_wall_thickness(nodes, template)
    i, j = np.meshgrid(np.arange(template.nc), np.arange(template.nl - 1), indexing="xy")
    r_endo = np.hypot(*nodes[template.node_index(i, j, 0)][..., :2].transpose(2, 0, 1))
    r_epi = np.hypot(*nodes[template.node_index(i, j, template.nt - 1)][..., :2].transpose(2, 0, 1))
    n_out = int(np.sum(r_endo[1:] > r_epi[1:]))  # below the base row: endocardium further from the axis
    msg = (f"{label}: the fitted mesh has {bad.size} inverted elements (near the {where}; thinnest fitted wall "
           f"{w.min():.1f} mm" + (f"; the fitted endocardium lies outside the epicardium at {n_out} of "
                                  f"{r_endo[1:].size} node pairs" if n_out else "") + ")")
    if base is not None and getattr(base, "walls_meet", False):
        return (msg + f"; {base.messages[0] if base.messages else 'the walls meet at the base'}: cut lower with "
                "--base-cut MM (base_cut_mm=)")
    return (msg + "; the segmentation is too irregular for the template there: check that the endocardium lies "
            "inside the epicardium with a wall of finite thickness all round")


def _finish(nodes, endo_t, epi_t, frame: LVFrame, length: float, template, label: str, warn: list,
            base=None) -> FitResult:
    from lvcore.geometry.measures import cavity_volume

    tol = 0.5
    e_in = endo_t[endo_t[:, 2] <= frame.base_z + tol]
    p_in = epi_t[epi_t[:, 2] <= frame.base_z + tol]
    n_above = len(endo_t) + len(epi_t) - len(e_in) - len(p_in)
    de = surface_distances(nodes, e_in, "endo", template)
    dp = surface_distances(nodes, p_in, "epi", template)
    d = np.concatenate([de, dp])
    vol = float(cavity_volume(nodes, template, frame.base_z)) / 1000.0
    from lvcore.geometry.io import element_jacobian_determinants

    if np.any(element_jacobian_determinants(nodes, template) <= 0):  # the last guard
        raise GeometryError(_inverted_message(nodes, template, label, base))
    return FitResult(
        nodes=nodes,
        residual_mean_mm=float(d.mean()),
        residual_max_mm=float(d.max()),
        residual_endo_mean_mm=float(de.mean()) if de.size else float("nan"),
        residual_epi_mean_mm=float(dp.mean()) if dp.size else float("nan"),
        n_points=int(d.size),
        n_above_base=int(n_above),
        cavity_volume_ml=vol,
        length_mm=float(length),
        frame=frame,
        label=label,
        warnings=tuple(warn),
        base=base,
    )


#: Closest a septum landmark may lie to the long axis (mm); nearer, phi = 0 is undefined.
MIN_SEPTUM_AXIS_DISTANCE_MM = 1.0


def _x_axis(ez: np.ndarray, origin: np.ndarray, septum, where: str = "septum landmark") -> np.ndarray:
    """Unit x axis of the template frame (phi = 0): towards ``septum`` if given.

    Parameters
    ----------
    ez : (3,) array
        Unit long axis (apex -> base).
    origin : (3,) array
        A point on the long axis (mm).
    septum : (3,) array or None
        A point on the septal wall (mm, same coordinates as ``origin``).
    where : str
        What the septum point is and where it came from (the file), for the messages.
    """
    if septum is not None:
        s = np.asarray(septum, float).reshape(-1)
        if s.shape != (3,) or not np.all(np.isfinite(s)):
            raise GeometryError(f"{where} {np.array2string(s[:6], precision=3)} must be 3 finite "
                                "coordinates (a point on the septal wall)")
        v = s - origin
        v = v - ez * (v @ ez)
        if not np.linalg.norm(v) >= MIN_SEPTUM_AXIS_DISTANCE_MM:
            raise GeometryError(f"{where} {np.array2string(s, precision=2)} lies "
                                f"{np.linalg.norm(v):.2g} mm from the LV's long axis (less than "
                                f"{MIN_SEPTUM_AXIS_DISTANCE_MM:g} mm), so it cannot fix the circumferential direction "
                                "(phi = 0); give a point on the septal wall")
        return v / np.linalg.norm(v)
    for ref in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        v = ref - ez * (ref @ ez)
        if np.linalg.norm(v) > 0.3:
            return v / np.linalg.norm(v)
    raise AssertionError("unreachable")


def _frame(origin, ez, septum, base_z, where: str = "septum landmark") -> LVFrame:
    ez = ez / np.linalg.norm(ez)
    ex = _x_axis(ez, origin, septum, where)
    ey = np.cross(ez, ex)
    return LVFrame(origin=np.asarray(origin, float), rotation=np.stack([ex, ey, ez]), base_z=float(base_z))


def frame_from_contours(stack: ContourStack, base_z: float = DEFAULT_BASE_Z) -> tuple[LVFrame, list]:
    """The template frame of a contour stack (see the module docstring) and warnings."""
    warn = []
    n = slice_normal(stack)  # apex -> base
    origin = stack.slices[0].endo.mean(axis=0)
    ez = n
    la_pts = [c.epi if c.epi is not None else c.endo for c in stack.long_axis]
    if la_pts:
        pts = np.concatenate(la_pts)
        apex = pts[np.argmin(pts @ n)]
        axis = origin - apex
        if np.linalg.norm(axis) > 10.0:
            cand = axis / np.linalg.norm(axis)
            ang = np.degrees(np.arccos(np.clip(cand @ n, -1, 1)))
            if ang < 30.0:
                ez = cand
            else:
                warn.append(f"the long-axis apex is {ang:.0f}° off the short-axis slice normal; using the slice "
                            "normal as the long axis (check the long-axis contours)")
    where = (f"contour file '{stack.source}': landmarks.septum" if stack.source
             else f"{stack.label}: landmarks.septum")
    return _frame(origin, ez, stack.septum, base_z, where), warn


def fit_contours(stack, template: LVTemplate = DEFAULT_TEMPLATE, base_z: float = DEFAULT_BASE_Z,
                 degree: int = DEFAULT_DEGREE, smoothing: float = DEFAULT_SMOOTHING,
                 base_cut_mm: float | None = None) -> FitResult:
    """Fit the template to a contour stack (a :class:`ContourStack` or a JSON path).

    Basal slices that include the outflow tract (no wall over part of their
    circumference) are dropped first, or every slice less than
    ``base_cut_mm`` below the basal slice
    (:func:`~lvcore.geometry.contours.base_of_stack`); points more than
    0.5 mm above the new basal slice are then not fitted.

    Returns
    -------
    FitResult
        Nodes in the template frame (base plane ``z = base_z``, apex on −z, mm),
        the fit residual and ``base`` (a :class:`~lvcore.geometry.contours.ContourBase`).
    """
    from lvcore.geometry.contours import base_of_stack

    if not isinstance(stack, ContourStack):
        stack = read_contours(stack)
    full = stack
    stack, base = base_of_stack(stack, base_cut_mm)
    frame, warn = frame_from_contours(stack, base_z)
    warn = list(base.messages) + warn
    endo_t = frame.to_template(full.endo_points())
    epi_t = frame.to_template(full.epi_points())
    if len(stack.slices) < len(full.slices):
        ke, kp = endo_t[:, 2] <= base_z + 0.5, epi_t[:, 2] <= base_z + 0.5
    else:  # nothing dropped: every point is fitted, as always
        ke, kp = np.ones(len(endo_t), bool), np.ones(len(epi_t), bool)
    nodes, _, _, length = fit_point_clouds(endo_t[ke], epi_t[kp], base_z, template, degree, smoothing)
    res = _finish(nodes, endo_t, epi_t, frame, length, template, stack.label, warn, base=base)
    for w in warn:
        warnings.warn(f"{stack.label}: {w}", GeometryWarning, stacklevel=2)
    return res


def fit_surfaces(endo, epi, template: LVTemplate = DEFAULT_TEMPLATE, base_z: float = DEFAULT_BASE_Z,
                 units: str = "mm", septum=None, degree: int = DEFAULT_DEGREE,
                 smoothing: float = DEFAULT_SMOOTHING, base_cut_mm: float | None = None) -> FitResult:
    """Fit the template to endocardial and epicardial surface meshes.

    The base is found from the data (:func:`lvcore.geometry.base_plane.analyse_base`):
    the boundary rings of both surfaces, their least-squares plane, the long
    axis from the rings to the apex, and a cut plane orthogonal to the axis
    below every ring point and, where the walls meet at the base, where the
    wall first reaches a usable thickness. The template's base plane
    ``z = base_z`` is that cut; input points more than
    :data:`~lvcore.geometry.base_plane.RING_TOL_MM` above it are not fitted.

    Parameters
    ----------
    endo, epi : path, pyvista mesh or :class:`~lvcore.geometry.surfaces.LVSurface`
        Surfaces open at the base, in any position and orientation (scanner coordinates).
    units : {"mm", "cm", "m"}
    septum : (3,) array, optional
        A point on the septum (scanner coordinates) fixing phi = 0.
    base_cut_mm : float, optional
        Depth of the cut below the endocardial base ring's centre, along the
        long axis (mm); default the rule above.

    Returns
    -------
    FitResult
        With ``base`` (:class:`~lvcore.geometry.base_plane.BaseCut`): the base
        plane, the cut and the cavity volume it removed.
    """
    from lvcore.geometry.base_plane import RING_TOL_MM, analyse_base
    from lvcore.geometry.surfaces import LVSurface, check_surface_pair, read_surface

    endo_s = endo if isinstance(endo, LVSurface) else read_surface(endo, "endo", units)
    epi_s = epi if isinstance(epi, LVSurface) else read_surface(epi, "epi", units)
    check_surface_pair(endo_s, epi_s)
    base = analyse_base(endo_s, epi_s, base_cut_mm)
    frame = _frame(base.cut_origin, base.axis, septum, base_z,
                   f"surfaces '{endo_s.source}' + '{epi_s.source}': the septum point (--septum)")
    endo_t = frame.to_template(endo_s.sample())
    epi_t = frame.to_template(epi_s.sample())
    ke = endo_t[:, 2] <= base_z + RING_TOL_MM
    kp = epi_t[:, 2] <= base_z + RING_TOL_MM
    nodes, _, _, length = fit_point_clouds(endo_t[ke], epi_t[kp], base_z, template, degree, smoothing)
    label = f"surfaces {endo_s.source} + {epi_s.source}"
    return _finish(nodes, endo_t, epi_t, frame, length, template, label, list(base.messages), base=base)
