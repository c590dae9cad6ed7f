"""Conventions of the fibre helix and the LV twist, and two measurements that pin them.

lvcore's rule-based fibres (:mod:`lvcore.mechanics.fibres`) are
``f0 = cos α e_c + sin α e_l`` with ``e_c`` counter-clockwise seen from the
base and ``e_l`` pointing from the apex to the base. A fibre whose tangent
turns counter-clockwise (seen from the base) while it climbs towards the
base is a right-handed helix, so in lvcore **α > 0 is a right-handed helix
and α < 0 a left-handed one**. The defaults (α_endo, α_epi) = (−60°, +60°)
or (−60°, +90°) therefore make the subendocardium a *left-handed* helix.

The anatomical convention (Streeter; e.g. Harrington et al. 2005, Am J
Physiol Heart Circ Physiol 288:H1324: +42° at the endocardium, −41° at the
epicardium) measures the helix angle from the circumferential direction
counter-clockwise as seen from the epicardium with the base up; there the
subendocardium is a right-handed helix and the subepicardium a left-handed
one. The Land et al. 2015 benchmark's fibres (+90° endo to −90° epi, with
``f = n(dx/du) sin α + n(dx/dv) cos α``) and the fibre field of the real LV
of Dalton et al. 2022 (+59° median at the endocardial layer, −58° at the
epicardial one, measured with :func:`helix_handedness`) follow it. So an
lvcore angle pair equals the anatomical pair with both signs flipped: the
anatomical (+60°, −60°) is lvcore's (−60°, +60°) mirrored, i.e. lvcore's
defaults simulate the mirror image of the anatomical fibre architecture.

Twist (:func:`apex_twist_deg`): the rotation of the apical part of the wall
relative to the basal part about the long axis, in degrees, **positive
counter-clockwise as seen from the apex** (the echocardiographic
convention). Passive inflation of a wall with a uniform right-handed helix
(α > 0 in lvcore) twists the apex clockwise seen from the apex (negative):
the inflation stretches the wall in the circumferential and longitudinal
directions, and the wall shears (E_cl with the sign of −sin α cos α) to
lower the fibre strain ``E_ff = cos²α E_cc + sin²α E_ll + 2 sin α cos α E_cl``;
with u_c = r φ(z), E_cl < 0 means φ falls towards the base, i.e. the apex
turns counter-clockwise seen from the base, clockwise seen from the apex.
``tests/test_mechanics_twist_sign.py`` checks this sign on the FE simulator.
"""
from __future__ import annotations

import numpy as np

#: Share of the long axis at each end whose nodes make the apical and basal bands of :func:`apex_twist_deg`.
BAND_FRACTION = 0.25


def helix_handedness(fibres, points, axis=(0.0, 0.0, 1.0), centre=None) -> np.ndarray:
    """+1 where a fibre direction winds as a right-handed helix about the long axis, −1 left-handed, 0 neither.

    Parameters
    ----------
    fibres : array_like, shape (..., 3)
        Fibre directions (any length, either sign: a direction, not a vector).
    points : array_like, shape (..., 3)
        Where they are (mm).
    axis : array_like, shape (3,)
        The long axis direction (either sign: handedness does not depend on it).
    centre : array_like, shape (3,), optional
        A point on the axis (default the mean of ``points``).

    Returns
    -------
    ndarray
        ``sign((f·e_θ)(f·a))`` with ``e_θ = a × r̂``: the sign of the product of the circumferential and axial
        components (flipping ``f`` or ``a`` leaves it unchanged).
    """
    f = np.asarray(fibres, dtype=float)
    x = np.asarray(points, dtype=float)
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    c = x.reshape(-1, 3).mean(0) if centre is None else np.asarray(centre, dtype=float)
    r = x - c
    r = r - (r @ a)[..., None] * a
    r = r / np.maximum(np.linalg.norm(r, axis=-1, keepdims=True), 1e-12)
    e_theta = np.cross(a, r)
    return np.sign(np.sum(f * e_theta, axis=-1) * (f @ a))


def _band_rotation(x0, x1, axis) -> float:
    """The rotation (radians, right-handed about ``axis``) that best maps points ``x0`` onto ``x1`` about their
    centroids, projected on the plane normal to ``axis`` (least squares: atan2(Σ r0 × r1, Σ r0 · r1), so
    points near the axis weigh little)."""
    r0 = x0 - x0.mean(0)
    r1 = x1 - x1.mean(0)
    r0 = r0 - np.outer(r0 @ axis, axis)
    r1 = r1 - np.outer(r1 @ axis, axis)
    return float(np.arctan2(np.sum(np.cross(r0, r1) @ axis), np.sum(r0 * r1)))


def apex_twist_deg(reference_nodes, displacement, *, axis=(0.0, 0.0, 1.0), fraction: float = BAND_FRACTION) -> float:
    """Apex twist of a deformed LV (degrees), positive counter-clockwise as seen from the apex.

    Parameters
    ----------
    reference_nodes : array_like, shape (n, 3)
        Reference node positions (mm); the long axis runs along ``axis``, from the apex to the base (lvcore's
        meshes: +z, base at the top).
    displacement : array_like, shape (n, 3)
        Node displacements (mm).
    axis : array_like, shape (3,)
        Unit direction from the apex to the base.
    fraction : float
        The apical and basal bands are the nodes within this share of the long-axis extent of each end.

    Returns
    -------
    float
        Mean rotation of the apical band minus that of the basal band (each about its own centroid, so rigid
        translations cancel), seen from the apex.
    """
    x0 = np.asarray(reference_nodes, dtype=float)
    x1 = x0 + np.asarray(displacement, dtype=float)
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    h = x0 @ a
    lo, hi = h.min(), h.max()
    if not hi > lo or not 0 < fraction <= 0.5:
        raise ValueError(f"need an extent along the axis and 0 < fraction <= 0.5, got extent {hi - lo:g}, "
                         f"fraction {fraction:g}")
    apical = h <= lo + fraction * (hi - lo)
    basal = h >= hi - fraction * (hi - lo)
    rot_about_axis = _band_rotation(x0[apical], x1[apical], a) - _band_rotation(x0[basal], x1[basal], a)
    return float(-np.degrees(rot_about_axis))  # seen from the apex: looking along +axis, counter-clockwise is −


__all__ = ["helix_handedness", "apex_twist_deg", "BAND_FRACTION"]
