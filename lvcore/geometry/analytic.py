"""Analytic LV geometries: truncated ellipsoids and the default LV.

The truncated ellipsoid follows Land et al. (2015), problem 2: each surface is

    x = r_x sin(psi) cos(phi),  y = r_y sin(psi) sin(phi),  z = -r_l cos(psi),

with ``psi`` the polar angle measured from the apex (``psi = 0``) and the
surface cut by the base plane ``z = base_z``. Land's problem has
``r_x = r_y = r_s``. Transmurally, points at the same template parameters
``(phi, s)`` on the endocardium and epicardium are joined by straight lines.
All lengths in mm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lvcore.geometry.template import DEFAULT_TEMPLATE, LVTemplate


@dataclass(frozen=True)
class EllipsoidSurface:
    """One truncated ellipsoidal surface (mm). ``rs`` is used for both short radii
    unless ``ry`` is given (an elliptical cross-section)."""

    rs: float
    rl: float
    ry: float | None = None

    def polar_angle_at(self, z: float) -> float:
        """Polar angle from the apex (rad) where the surface meets the plane z."""
        c = -z / self.rl
        if not -1.0 < c < 1.0:
            raise ValueError(f"base plane z={z} mm does not cut an ellipsoid with r_l={self.rl} mm")
        return float(np.arccos(c))

    def point(self, phi, psi):
        ry = self.rs if self.ry is None else self.ry
        return np.stack(
            [self.rs * np.sin(psi) * np.cos(phi), ry * np.sin(psi) * np.sin(phi), -self.rl * np.cos(psi)],
            axis=-1,
        )


@dataclass(frozen=True)
class TruncatedEllipsoidLV:
    """A thick-walled truncated ellipsoid between two ellipsoidal surfaces (mm).

    Parameters
    ----------
    endo, epi : EllipsoidSurface
        The inner and outer surfaces.
    base_z : float
        Height of the base plane (mm); the apex is on the negative z axis.
    """

    endo: EllipsoidSurface
    epi: EllipsoidSurface
    base_z: float

    def position(self, phi, s, t):
        """Parametric map (phi [rad], s in [0,1] base->apex, t in [0,1] endo->epi) -> xyz (mm)."""
        phi, s, t = np.broadcast_arrays(np.asarray(phi, float), np.asarray(s, float), np.asarray(t, float))
        psi_endo = (1.0 - s) * self.endo.polar_angle_at(self.base_z)
        psi_epi = (1.0 - s) * self.epi.polar_angle_at(self.base_z)
        x_endo = self.endo.point(phi, psi_endo)
        x_epi = self.epi.point(phi, psi_epi)
        return (1.0 - t)[..., None] * x_endo + t[..., None] * x_epi

    def nodes(self, template: LVTemplate = DEFAULT_TEMPLATE) -> np.ndarray:
        """Node positions of this geometry on ``template`` (mm)."""
        return template.nodes_from_map(self.position)

    def cavity_volume_mm3(self) -> float:
        """Exact cavity volume of the truncated endocardial ellipsoid (mm³)."""
        ry = self.endo.rs if self.endo.ry is None else self.endo.ry
        rl, h = self.endo.rl, self.base_z
        return float(np.pi * self.endo.rs * ry * ((h + rl) - (h**3 + rl**3) / (3.0 * rl**2)))


#: Land et al. (2015) problem 2 geometry.
LAND_LV = TruncatedEllipsoidLV(EllipsoidSurface(7.0, 17.0), EllipsoidSurface(10.0, 20.0), 5.0)

#: The default LV: a mildly elliptical, tapered truncated ellipsoid of
#: physiological size (early-diastolic cavity about 85 mL, wall 9-10 mm,
#: base-to-apex 75 mm inside and 85 mm outside).
DEFAULT_LV = TruncatedEllipsoidLV(
    endo=EllipsoidSurface(rs=24.0, rl=65.0, ry=21.5),
    epi=EllipsoidSurface(rs=33.5, rl=75.0, ry=31.0),
    base_z=10.0,
)


def ellipsoid_volume_below_plane(rx: float, ry: float, rl: float, point, normal) -> float:
    """Exact volume of the part of an ellipsoid on the back side of a plane (mm³).

    The ellipsoid is ``x²/rx² + y²/ry² + z²/rl² ≤ 1`` (centre at the origin);
    the part kept is ``{x : (x − point)·normal ≤ 0}``. The map ``x = D u`` with
    ``D = diag(rx, ry, rl)`` takes the ellipsoid to the unit ball and planes
    to planes: the kept part becomes ``u·m ≤ δ`` with ``m = D n / |D n|`` and
    ``δ = point·n / |D n|``, whose volume is ``4π/3 − π (1 − δ)² (2 + δ) / 3``
    (the ball minus a spherical cap of height ``1 − δ``), times ``rx ry rl``.

    Parameters
    ----------
    rx, ry, rl : float
        Semi-axes (mm).
    point : (3,) array
        A point of the plane, in the ellipsoid's frame (mm).
    normal : (3,) array
        The plane's normal (need not be unit); the kept part is behind it.

    Returns
    -------
    float
        Volume (mm³).
    """
    n = np.asarray(normal, float)
    dn = np.array([rx, ry, rl], float) * n
    delta = float(np.asarray(point, float) @ n) / float(np.linalg.norm(dn))
    delta = min(1.0, max(-1.0, delta))
    return float(rx * ry * rl * (4.0 * np.pi / 3.0 - np.pi * (1.0 - delta) ** 2 * (2.0 + delta) / 3.0))
