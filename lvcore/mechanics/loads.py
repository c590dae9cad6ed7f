"""Pressure loads on quadratic surface quads (pure jax.numpy functions).

Cavity pressure as a potential
------------------------------
For the LV the endocardial pressure ``p`` is the potential ``−p V_cavity(x)``
with the cavity volume computed exactly from the deformed endocardium closed
by the base plane ``z = base_z`` (divergence theorem with the field
``(0, 0, z − base_z)``, as in :func:`lvcore.geometry.measures.cavity_volume`;
exact while the base stays planar, true for clamped and sliding bases). Its
gradient is the follower pressure load and its Hessian the (symmetric) load
stiffness.

Follower pressure on an open face
---------------------------------
For a box face the virtual work ``δW = −∫ p n · δx da`` (``n`` the outward
deformed normal) is not a potential; :func:`follower_force` gives the
consistent nodal forces and its linearisation is taken by autodiff.

Faces are (9, 3) node arrays with local order ``a + 3 b`` oriented so that
``dx/da x dx/db`` points out of the solid (into the cavity for the endocardium).
"""
from __future__ import annotations

import jax.numpy as jnp

from lvcore.mechanics.quadrature import gauss_quad, quad9_shape

_XI, _W = gauss_quad(4)
_N, _DA, _DB = quad9_shape(_XI)


def _tangents(x_f):
    N, da, db = jnp.asarray(_N), jnp.asarray(_DA), jnp.asarray(_DB)
    return N @ x_f, da @ x_f, db @ x_f


def face_cavity_volume(x_f, base_z):
    """Contribution of one endocardial quad to the cavity volume (mm³)."""
    x, ta, tb = _tangents(x_f)
    nz = ta[:, 0] * tb[:, 1] - ta[:, 1] * tb[:, 0]
    return -jnp.sum((x[:, 2] - base_z) * nz * jnp.asarray(_W))


def cavity_volume(x, faces, base_z):
    """Cavity volume (mm³) of current nodes ``x`` (n, 3) with endocardial ``faces`` (f, 9)."""
    xf = x[faces]
    return jnp.sum(jnp.vectorize(face_cavity_volume, signature="(9,3),()->()")(xf, base_z))


def follower_force(x_f, pressure):
    """Nodal forces (9, 3) of a pressure acting against the outward normal of one quad."""
    _, ta, tb = _tangents(x_f)
    n_da = jnp.cross(ta, tb) * jnp.asarray(_W)[:, None]
    return -pressure * jnp.asarray(_N).T @ n_da
