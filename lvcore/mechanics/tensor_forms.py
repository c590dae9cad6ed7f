"""Fourth-order tensor forms of the closed-form material tangents (:mod:`lvcore.mechanics.materials`).

The outer products ``X ⊗ Y`` and ``X ⊠ Y`` and the form ``δ_ik B_JL`` a tangent is built from; the same forms with
their gradient slots mapped to an element's reference coordinates (:func:`slot`, :func:`slots`), the general
pull-back of a tangent (:func:`pull_back`); the derivative of the cofactor (:data:`COF_DERIVATIVE`); and the
isochoric split of a stress and its elasticity tensor (:func:`isochoric_split`). Index convention: ``F_iJ``
(spatial ``i``, reference ``J``); stresses in kPa.
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from lvcore.mechanics.kinematics import cofactor, det3

#: Levi-Civita symbol: ``∂²J/∂F_iJ ∂F_kL = ε_ikm ε_JLN F_mN`` (the second derivative of a determinant).
LEVI_CIVITA = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    LEVI_CIVITA[_i, _j, _k], LEVI_CIVITA[_i, _k, _j] = 1.0, -1.0

#: ``∂(cof F)_iJ/∂F_kL = ε_ikm ε_JLN F_mN`` as a (9, 81) matrix acting on ``F`` raveled (``mN`` -> ``iJkL``).
COF_DERIVATIVE = np.einsum("ikm,JLN->mNiJkL", LEVI_CIVITA, LEVI_CIVITA).reshape(9, 81)


def outer(X, Y):
    """``(X ⊗ Y)_iJkL = X_iJ Y_kL`` of two 3×3 arrays."""
    return X[:, :, None, None] * Y[None, None, :, :]


def box(X, Y):
    """``(X ⊠ Y)_iJkL = X_iL Y_kJ`` of two 3×3 arrays."""
    return X[:, None, None, :] * Y.T[None, :, :, None]


def delta_ik(S):
    """``δ_ik S_JL`` (3, 3, 3, 3)."""
    return jnp.eye(3)[:, None, :, None] * S[None, :, None, :]


# Pointwise tangents with their gradient slots in other coordinates. The element kernels contract a
# tangent with shape-function gradients in the element's reference coordinates ξ, so they want
# ``A'_iKkM = G_KJ A_iJkL G_ML`` with ``G = ∂ξ/∂X`` (the inverse Jacobian at the point). A tangent built
# from the forms ``X ⊗ Y``, ``X ⊠ Y`` and ``δ_ik B_JL`` maps factor by factor: ``X ⊗ Y -> (X Gᵀ) ⊗ (Y Gᵀ)``,
# ``X ⊠ Y -> (X Gᵀ) ⊠ (Y Gᵀ)``, ``δ_ik B -> δ_ik (G B Gᵀ)``: a few 3×3 products instead of the 3⁴ pull-back
# (the default LV tangent kernel 0.80× the time).

def slot(X, G):
    """``X_iJ G_KJ`` (i, K): a gradient slot of an outer-product factor mapped by ``G`` (None: ``X``)."""
    return X if G is None else X @ G.T


def slots(B, G):
    """``G B Gᵀ``: both gradient slots of the ``B`` in ``δ_ik B_JL`` mapped by ``G`` (None: ``B``)."""
    return B if G is None else G @ B @ G.T


def pull_back(A, G):
    """``A'_iKkM = G_KJ A_iJkL G_ML``: both gradient slots of a pointwise tangent (3, 3, 3, 3) mapped by
    ``G`` (3, 3), e.g. ``∂ξ/∂X`` to the element's reference coordinates; None: ``A``. The general way, for
    tangents not built from outer products (automatic derivatives, :meth:`lvcore.mechanics.materials.MaterialLaw.piola_tangent`).
    """
    if G is None:
        return A
    # sums over J and L as broadcast products (XLA fuses them; faster than its dot for these sizes)
    A1 = sum(G[None, :, J, None, None] * A[:, J, None, :, :] for J in range(3))  # (i, K, k, L)
    return sum(A1[..., L, None] * G[None, None, None, :, L] for L in range(3))  # (i, K, k, M)


def isochoric_split(C, Sbar, CCbar):
    """Stress and elasticity tensor of ``W(C) = Ŵ(C̄)``, ``C̄ = I3^{-1/3} C`` (``I3 = det C``), from
    ``S̄ = 2 ∂Ŵ/∂C̄`` and ``ℂ̄ = 4 ∂²Ŵ/∂C̄∂C̄`` (Holzapfel 2000, eqs. 6.88 and 6.168)::

        S = I3^{-1/3} Dev S̄,  Dev X = X − (X : C)/3 C⁻¹,
        ℂ = ℙ : (I3^{-2/3} ℂ̄) : ℙᵀ + 2/3 (I3^{-1/3} S̄ : C) ℙ̃ − 2/3 (C⁻¹ ⊗ S + S ⊗ C⁻¹),

    with ``ℙ = 𝕀 − C⁻¹ ⊗ C / 3`` and ``ℙ̃ = C⁻¹ ⊙ C⁻¹ − C⁻¹ ⊗ C⁻¹ / 3``. ``CCbar`` None: stress only.
    """
    i3 = det3(C)
    Cinv = cofactor(C) / i3  # C symmetric: cof C = det C · C⁻¹
    j23 = i3 ** (-1.0 / 3.0)
    S = j23 * (Sbar - (jnp.sum(Sbar * C) / 3.0) * Cinv)
    if CCbar is None:
        return S, None
    Y = (j23 * j23) * CCbar
    Y = Y - jnp.einsum("IJ,KL->IJKL", Cinv, jnp.einsum("AB,ABKL->KL", C, Y)) / 3.0
    Y = Y - jnp.einsum("IJ,KL->IJKL", jnp.einsum("IJAB,AB->IJ", Y, C), Cinv) / 3.0
    CsC = 0.5 * (jnp.einsum("IK,JL->IJKL", Cinv, Cinv) + jnp.einsum("IL,JK->IJKL", Cinv, Cinv))
    Pt = CsC - jnp.einsum("IJ,KL->IJKL", Cinv, Cinv) / 3.0
    CC = (Y + (2.0 / 3.0) * j23 * jnp.sum(Sbar * C) * Pt
          - (2.0 / 3.0) * (jnp.einsum("IJ,KL->IJKL", Cinv, S) + jnp.einsum("IJ,KL->IJKL", S, Cinv)))
    return S, CC


__all__ = ["LEVI_CIVITA", "COF_DERIVATIVE", "outer", "box", "delta_ik", "slot", "slots", "pull_back", "isochoric_split"]
