"""Gauss quadrature and Q2 (27-node) reference-element data.

Local node ``a + 3 b + 9 c`` of a hexahedron sits at reference coordinates
``(a - 1, b - 1, c - 1)`` (see :func:`lvcore.geometry.template.lagrange_q2_shape`).
The volumetric constraint uses the element-wise linear space
``{1, xi, eta, zeta}`` (the discontinuous P1 pressure space of the Q2/P1
mixed element); :func:`p1_basis` evaluates it.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from lvcore.geometry.template import lagrange_q2_shape


@lru_cache(maxsize=8)
def gauss_hex(order: int = 3):
    """Tensor Gauss–Legendre rule on [-1, 1]³.

    Returns
    -------
    xi : (order³, 3) points; w : (order³,) weights (sum 8).
    """
    return gauss_hex_points(order, order)


@lru_cache(maxsize=16)
def gauss_hex_points(order: int = 3, transmural: int | None = None):
    """Tensor Gauss rule with ``order`` points along ξ and ζ and ``transmural`` along η.

    η (the second reference coordinate) runs through the wall of an LV
    element (see :mod:`lvcore.geometry.template`). ``transmural=None`` or
    equal to ``order`` is :func:`gauss_hex`.
    """
    g, w = np.polynomial.legendre.leggauss(order)
    gt, wt = np.polynomial.legendre.leggauss(order if transmural is None else transmural)
    a, b, c = np.meshgrid(g, gt, g, indexing="ij")
    wa, wb, wc = np.meshgrid(w, wt, w, indexing="ij")
    return np.stack([a.ravel(), b.ravel(), c.ravel()], axis=1), (wa * wb * wc).ravel()


@lru_cache(maxsize=8)
def gauss_quad(order: int = 4):
    """Tensor Gauss–Legendre rule on [-1, 1]²: points (order², 2), weights (order²,)."""
    g, w = np.polynomial.legendre.leggauss(order)
    a, b = np.meshgrid(g, g, indexing="ij")
    return np.stack([a.ravel(), b.ravel()], axis=1), np.outer(w, w).ravel()


def quad9_shape(xi: np.ndarray):
    """9-node quadratic quad basis (local node ``a + 3 b`` at ``(a-1, b-1)``).

    Returns N (n, 9), dN/da (n, 9), dN/db (n, 9) at points ``xi`` (n, 2).
    """
    def basis(x):
        return (np.stack([0.5 * x * (x - 1), 1 - x * x, 0.5 * x * (x + 1)], -1),
                np.stack([x - 0.5, -2 * x, x + 0.5], -1))

    na, da = basis(xi[:, 0])
    nb, db = basis(xi[:, 1])
    q = np.arange(9)
    a, b = q % 3, q // 3
    return na[:, a] * nb[:, b], da[:, a] * nb[:, b], na[:, a] * db[:, b]


def p1_basis(xi: np.ndarray) -> np.ndarray:
    """Element-wise linear basis {1, xi, eta, zeta} at points ``xi`` (n, 3) -> (n, 4)."""
    xi = np.atleast_2d(xi)
    return np.concatenate([np.ones((xi.shape[0], 1)), xi], axis=1)


def reference_jacobians(nodes: np.ndarray, elements: np.ndarray, order: int = 3, points=None):
    """Reference shape gradients, inverse Jacobians and integration weights of the elements.

    Parameters
    ----------
    nodes : (n_nodes, 3) reference positions (mm).
    elements : (n_el, 27) connectivity.
    order : Gauss points per direction.
    points : optional (xi (q, 3), w (q,)) rule used instead of the Gauss rule.

    Returns
    -------
    dNdxi : (n_q, 27, 3) shape-function gradients in reference coordinates (-), the same for every element.
    Jinv : (n_el, n_q, 3, 3) inverse Jacobians ``Jinv[e, q, K, J] = ∂ξ_K/∂X_J`` (1/mm), so
        ``∂N_a/∂X_J = Σ_K ∂N_a/∂ξ_K Jinv_KJ``.
    wdet : (n_el, n_q) quadrature weight times det(dX/dxi) (mm³).
    """
    xi, w = gauss_hex(order) if points is None else points
    _, dN = lagrange_q2_shape(xi, derivatives=True)  # (q, 27, 3)
    X = nodes[elements]  # (e, 27, 3)
    Jm = np.einsum("eai,qaj->eqij", X, dN, optimize=True)  # dX_i/dxi_j
    return dN, np.linalg.inv(Jm), w[None, :] * np.linalg.det(Jm)


def reference_gradients(nodes: np.ndarray, elements: np.ndarray, order: int = 3, points=None):
    """Shape-function gradients and integration weights in the reference configuration.

    Parameters as :func:`reference_jacobians`.

    Returns
    -------
    dNdX : (n_el, n_q, 27, 3) gradients (1/mm).
    wdet : (n_el, n_q) quadrature weight times det(dX/dxi) (mm³).
    detJ : (n_el, n_q) det(dX/dxi), for checking element validity.
    """
    xi, w = gauss_hex(order) if points is None else points
    dN, inv, wdet = reference_jacobians(nodes, elements, points=(xi, w))
    dNdX = np.matmul(dN[None], inv)  # sum_j dN[q, a, j] inv[e, q, j, i]; 3x faster than the plain einsum
    return dNdX, wdet, wdet / w[None, :]
