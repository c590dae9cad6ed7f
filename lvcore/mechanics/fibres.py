"""Fibre, sheet and sheet-normal directions at quadrature points.

Rule-based LV fibres
--------------------
At each quadrature point the local wall frame is built from the reference
isoparametric map of the LV mesh (local coordinates: ``xi_a`` around,
``xi_b`` through the wall, ``xi_c`` base to apex):

* ``e_c`` (circumferential): unit ``dX/dxi_a``, i.e. the direction of
  increasing ``phi``: counter-clockwise seen from the base (from +z);
* ``e_t`` (transmural): the unit wall normal ``e_c x dX/dxi_c`` oriented from
  the endocardium to the epicardium;
* ``e_l`` (longitudinal): ``e_t x e_c`` flipped if needed so that it points
  from the apex towards the base.

The helix angle varies linearly with the transmural coordinate ``t``
(0 endo, 1 epi): ``alpha(t) = alpha_endo + t (alpha_epi − alpha_endo)`` and

    f0 = cos(alpha) e_c + sin(alpha) e_l,   s0 = e_t,   n0 = f0 x s0.

So alpha = 0 is circumferential, alpha = +90° longitudinal pointing
basewards; with the defaults (−60°, +90°) endocardial fibres run from the
base downwards in the counter-clockwise direction.

Constant fibres (the box)
-------------------------
``f0`` is the given direction, ``s0`` the coordinate axis least aligned with it
made orthogonal by Gram–Schmidt, ``n0 = f0 x s0``.
"""
from __future__ import annotations

import numpy as np

from lvcore.geometry.template import lagrange_q2_shape


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def lv_wall_frame(nodes: np.ndarray, elements: np.ndarray, xi: np.ndarray):
    """Circumferential, longitudinal and transmural unit vectors at points ``xi``.

    Parameters
    ----------
    nodes : (n_nodes, 3) reference positions (mm) of an LV mesh.
    elements : (n_el, 27) connectivity in the template's local order.
    xi : (n_q, 3) reference points (circ, trans, long) in [-1, 1]³.

    Returns
    -------
    e_c, e_l, e_t : each (n_el, n_q, 3).
    """
    _, dN = lagrange_q2_shape(xi, derivatives=True)
    X = nodes[elements]
    d = np.einsum("eai,qaj->eqji", X, dN, optimize=True)  # d[..., j, :] = dX/dxi_j
    e_c = _unit(d[..., 0, :])
    e_t = _unit(np.cross(e_c, d[..., 2, :]))
    flip = np.sum(e_t * d[..., 1, :], axis=-1, keepdims=True) < 0
    e_t = np.where(flip, -e_t, e_t)
    e_l = _unit(np.cross(e_t, e_c))
    flip = np.sum(e_l * d[..., 2, :], axis=-1, keepdims=True) > 0  # d_c points towards the apex
    e_l = np.where(flip, -e_l, e_l)
    return e_c, e_l, e_t


def rule_based_frames(nodes, elements, xi, transmural_t, alpha_endo_deg, alpha_epi_deg):
    """Rule-based fibre frames (rows f0, s0, n0) at quadrature points of an LV mesh.

    Parameters
    ----------
    transmural_t : (n_el, n_q) transmural coordinate t (0 endo, 1 epi) of each point.
    alpha_endo_deg, alpha_epi_deg : helix angles (degrees) at endo and epi.

    Returns
    -------
    frames : (n_el, n_q, 3, 3); also ``e_c`` (n_el, n_q, 3).
    """
    e_c, e_l, e_t = lv_wall_frame(nodes, elements, xi)
    alpha = np.deg2rad(alpha_endo_deg + transmural_t * (alpha_epi_deg - alpha_endo_deg))[..., None]
    f0 = np.cos(alpha) * e_c + np.sin(alpha) * e_l
    s0 = e_t
    n0 = np.cross(f0, s0)
    return np.stack([f0, s0, n0], axis=-2), e_c


def constant_frame(direction) -> np.ndarray:
    """Orthonormal frame (rows f0, s0, n0) with f0 along ``direction``."""
    f = np.asarray(direction, dtype=float)
    n = np.linalg.norm(f)
    if not np.isfinite(n) or n == 0:
        raise ValueError(f"fibre direction must be a non-zero vector, got {direction}")
    f = f / n
    axis = np.eye(3)[int(np.argmin(np.abs(f)))]
    s = axis - (axis @ f) * f
    s = s / np.linalg.norm(s)
    return np.stack([f, s, np.cross(f, s)])
