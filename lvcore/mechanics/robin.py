"""A linear Robin (spring) boundary on a surface: the pericardium as springs on the LV epicardium.

As fenicsx-pulse's ``RobinBC`` on the epicardium, the surface carries the
energy

    Π_s(u) = k/2 ∫_Γ₀ |P u|² dA,   P = N ⊗ N ("normal") or I ("full"),

on the *reference* surface Γ₀ with its outward unit normal N, k in kPa/mm
(force per reference area per displacement). The traction on Γ₀ is
``−k P u`` and the energy is quadratic in u, so the stiffness is a constant
matrix per face,

    K_f[(a,i),(b,j)] = k Σ_q w_q |dX/da × dX/db|_q N_a(q) N_b(q) P_ij(q),

computed once (NumPy; 4×4 Gauss points on the 9-node quad) and added to the
tangent; the residual gets ``K_f u_f``. It is symmetric, so the LV problem
with the cavity-pressure potential stays symmetric. ``k = 0`` adds nothing.
Units: mm, kPa; forces mN.
"""
from __future__ import annotations

import numpy as np

from lvcore.mechanics.quadrature import gauss_quad, quad9_shape

#: Directions the spring acts in.
DIRECTIONS = ("normal", "full")


def face_stiffness(X_f: np.ndarray, k: float, direction: str = "normal") -> np.ndarray:
    """Spring stiffness of reference quads.

    Parameters
    ----------
    X_f : (m, 9, 3) reference node positions (mm) of quadratic quads, local order ``a + 3 b``.
    k : spring stiffness (kPa/mm), >= 0.
    direction : "normal" or "full".

    Returns
    -------
    (m, 27, 27) stiffness (mN/mm), rows and columns node-major (``3 node + component``).
    """
    if direction not in DIRECTIONS:
        raise ValueError(f"spring direction must be one of {DIRECTIONS}, got {direction!r}")
    X_f = np.asarray(X_f, dtype=np.float64)
    xi, w = gauss_quad(4)
    N, dA, dB = quad9_shape(xi)  # (q, 9) each
    ta = np.einsum("qa,mai->mqi", dA, X_f)
    tb = np.einsum("qa,mai->mqi", dB, X_f)
    n = np.cross(ta, tb)
    area = np.linalg.norm(n, axis=-1)  # (m, q)
    if direction == "normal":
        unit = n / area[..., None]
        P = np.einsum("mqi,mqj->mqij", unit, unit)
    else:
        P = np.broadcast_to(np.eye(3), area.shape + (3, 3))
    K = float(k) * np.einsum("mq,qa,qb,mqij->maibj", area * w, N, N, P)
    return K.reshape(X_f.shape[0], 27, 27)


def spring_energy(u_f: np.ndarray, K_f: np.ndarray) -> float:
    """Π_s = ½ Σ_f u_fᵀ K_f u_f (kPa mm³) for face displacements ``u_f`` (m, 9, 3)."""
    v = np.asarray(u_f).reshape(K_f.shape[0], 27)
    return 0.5 * float(np.einsum("mi,mij,mj->", v, K_f, v))


__all__ = ["DIRECTIONS", "face_stiffness", "spring_energy"]
