"""Kinematics: deformation gradient, invariants and strains (jax.numpy, pure).

Conventions: ``F[i, J] = d x_i / d X_J``; ``C = F^T F``; Green strain
``E = (C - I) / 2``. Fibre frames are stored as rows ``(f0, s0, n0)`` of an
orthonormal 3x3 matrix in the reference configuration.
"""
from __future__ import annotations

import jax.numpy as jnp


def matmul3(X, Y):
    """``X @ Y`` for 3×3 matrices (..., 3, 3), as three broadcast products.

    XLA fuses them with their neighbours; its dot for 3×3 operands (batched over the points) ran
    slower on the CPU (the element residual kernel ~0.75× the time). Where the product feeds many
    consumers (the outer products of a pointwise tangent) XLA may recompute it in each: the default LV
    tangent kernel took 1.6× the time with it inside the Holzapfel–Ogden tangent, so the laws keep ``@``.
    """
    return X[..., :, 0, None] * Y[..., None, 0, :] + X[..., :, 1, None] * Y[..., None, 1, :] \
        + X[..., :, 2, None] * Y[..., None, 2, :]


def det3(F):
    """Determinant of (..., 3, 3)."""
    return (
        F[..., 0, 0] * (F[..., 1, 1] * F[..., 2, 2] - F[..., 1, 2] * F[..., 2, 1])
        - F[..., 0, 1] * (F[..., 1, 0] * F[..., 2, 2] - F[..., 1, 2] * F[..., 2, 0])
        + F[..., 0, 2] * (F[..., 1, 0] * F[..., 2, 1] - F[..., 1, 1] * F[..., 2, 0])
    )


def cofactor(F):
    """Cofactor ``dJ/dF = J F^{-T}`` of (..., 3, 3), computed without inversion."""
    c0, c1, c2 = F[..., :, 0], F[..., :, 1], F[..., :, 2]
    return jnp.stack([jnp.cross(c1, c2), jnp.cross(c2, c0), jnp.cross(c0, c1)], axis=-1)


def right_cauchy_green(F):
    """C = F^T F."""
    return jnp.einsum("...kI,...kJ->...IJ", F, F)


def green_strain(F):
    """E = (F^T F - I) / 2."""
    return 0.5 * (right_cauchy_green(F) - jnp.eye(3))


def isochoric_i1(F):
    """First invariant of the isochoric part: J^{-2/3} tr(C)."""
    J = det3(F)
    return jnp.sum(F * F, axis=(-2, -1)) * J ** (-2.0 / 3.0)


def circumferential_green_strain(F, c):
    """Glasgow convention, end diastole as reference: ``(1/λ² − 1)/2`` with ``λ = |F c|``."""
    lam2 = jnp.sum(jnp.einsum("...iJ,...J->...i", F, c) ** 2, axis=-1)
    return 0.5 * (1.0 / lam2 - 1.0)
