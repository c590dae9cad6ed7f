"""Element kernels of the mixed Q2/P1-discontinuous hexahedron (pressure condensed).

Each element carries, besides its 27 nodes, four pressure coefficients ``p_e``
of the element-wise linear field ``p(ξ) = P(ξ) · p_e`` with ``P = {1, ξ, η, ζ}``
(a discontinuous P1 pressure, condensed out of the global system). The
nearly incompressible problem is the saddle point of

    Π(u, p) = ∫ W(F) dV + ∫ p (J − 1) dV − ∫ p² / (2κ) dV − (external work)

so the element residuals are

* ``r_u[a,i] = Σ_q w_q (∂W/∂F + p_q cof F)_{iJ} ∂N_a/∂X_J`` (internal force, mN);
* ``r_p[m] = Σ_q w_q P_{qm} (J_q − 1) − (M p_e)_m / κ`` (mm³),

with ``w_q`` the weight times the reference Jacobian and ``M = Σ_q w_q P_q P_qᵀ``.
Eliminating ``p_e`` leaves the penalty energy ``κ/2 ∫ (Π J − 1)²`` with
``Π J`` the L² projection of J onto P1 (locking free). Newton is applied to
the mixed equations (its convergence does not degrade with κ); the
pressure increment is condensed per element:

    dp = κ M⁻¹ (r_p + D du),  D_{m,ai} = Σ_q w_q P_{qm} (cof F_q)_{iJ} ∂N_a/∂X_J,
    (K_uu + κ Dᵀ M⁻¹ D) du = −(r_u + κ Dᵀ M⁻¹ r_p),

with ``K_uu = Σ_q w_q ∇Nᵀ (∂²W/∂F² + p_q ∂²J/∂F²) ∇N``. The pointwise stress
and 9x9 tangent come from the model (:meth:`~lvcore.mechanics.materials.ConstitutiveModel.first_piola_tangent`:
in closed form for the laws of :mod:`lvcore.mechanics.materials`, else automatic differentiation of the
energy density in F), followed by this explicit chain rule.

The kernels work in the element's reference coordinates ξ: the shape-function
gradients ``∂N_a/∂ξ_K`` at the points are the same for every element, and
each element brings its inverse Jacobians ``Jinv_KJ = ∂ξ_K/∂X_J`` (q, 3, 3),
so ``∂N_a/∂X_J = ∂N_a/∂ξ_K Jinv_KJ`` is never formed: point tensors are
mapped to ξ (``F = (x_eᵀ ∂N/∂ξ) Jinv``, stresses ``P Jinvᵀ``, tangents
``Jinv A Jinvᵀ`` on both gradient slots, built so by the law from mapped 3×3
factors) and contracted with the shared gradients. Each element then reads
3.5× less data than with stored physical gradients (n_el, q, 27, 3); the
residual kernel runs 0.72–0.76× the time (default LV, in-process A/B on the
2-core machine), the tangent kernel 0.80× with the law's mapped factors instead
of pulling the 3⁴ tensor back (BENCHMARKS.md row 41).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp

from lvcore.mechanics.assembly import NODE_BLOCK_PAIRS
from lvcore.mechanics.kinematics import cofactor, det3, matmul3


def deformation_gradients(x_e, Jinv, dNdxi):
    """F at the points, (q, 3, 3): ``F_iJ = (Σ_a x_ai ∂N_a/∂ξ_K) Jinv_KJ``.

    Parameters
    ----------
    x_e : (27, 3) current node positions (mm); Jinv : (q, 3, 3) (1/mm); dNdxi : (q, 27, 3) (-).
    """
    return matmul3(jnp.einsum("ai,qaK->qiK", x_e, dNdxi), Jinv)


def nodal_sum(T, Jinv, dNdxi):
    """``Σ_q T_qiJ ∂N_a/∂X_J`` as (27, 3) (a, i) for point tensors ``T`` (q, 3, 3) (weights included)."""
    return jnp.einsum("qiK,qaK->ai", matmul3(T, Jinv.swapaxes(1, 2)), dNdxi)


def element_residual(x_e, p_e, Jinv, wdet, frames, Minv, P, dNdxi, model, energy: bool = True):
    """Element residuals of the mixed form.

    Parameters
    ----------
    x_e : (27, 3) current node positions (mm); p_e : (4,) pressure coefficients (kPa).
    Jinv : (q, 3, 3) inverse Jacobians ``∂ξ_K/∂X_J`` (1/mm) at the points.
    wdet : (q,) (mm³); frames : (q, 3, 3) rows f0, s0, n0.
    Minv : (4, 4) inverse P1 mass matrix; P : (q, 4) P1 basis at the points.
    dNdxi : (q, 27, 3) shape-function gradients in reference coordinates (the same for every element).
    model : :class:`lvcore.mechanics.materials.ConstitutiveModel` (law and bulk penalty κ, kPa).
    energy : also integrate the strain energy (False: 0; Newton does not need it, ~10 % of the kernel).

    Returns
    -------
    r_u : (27, 3) internal forces (mN); r_p : (4,) constraint residual (mm³);
    min_J : smallest pointwise J; energy : ∫ W dV (kPa mm³).
    """
    kappa = model.kappa
    F = deformation_gradients(x_e, Jinv, dNdxi)
    J = det3(F)
    pq = P @ p_e
    Pst = jax.vmap(model.first_piola)(F, frames, pq)
    r_u = nodal_sum(wdet[:, None, None] * Pst, Jinv, dNdxi)
    r_p = P.T @ (wdet * (J - 1.0)) - jnp.linalg.solve(Minv, p_e) / kappa
    if not energy:
        return r_u, r_p, jnp.min(J), jnp.zeros(())
    w = jax.vmap(model.material.strain_energy)(F, frames)
    return r_u, r_p, jnp.min(J), jnp.sum(wdet * w)


def material_stiffness(wG, A, dNdX):
    """``K[a,i,b,k] = Σ_q Σ_JL wG[q,a,J] A[q,i,J,k,L] dNdX[q,b,L]`` as its six node blocks (6, 27, 27).

    The pointwise tangent of a hyperelastic law is symmetric (``A[iJkL] = A[kLiJ]``),
    so the (27, 27) node blocks of components (k, i) are the transposes of those of
    (i, k): only the six with i <= k are contracted (two thirds of the products) and
    returned as they are, block ``n`` for the pair ``NODE_BLOCK_PAIRS[n]`` (the layout
    ``"node_blocks"`` of :mod:`lvcore.mechanics.assembly`, whose scatter map puts each entry
    in its slot or slots): interleaving them into the (81, 81) matrix and taking its upper
    triangle in XLA took longer than the contraction itself (default LV, 36 elements:
    6.5 against 4.7 ms on the 2-core CPU machine).
    The gradient slots J, L may be physical or reference coordinates (with A mapped to match).

    Parameters
    ----------
    wG : (q, 27, 3) weighted shape gradients ``w_q ∂N_a/∂X_J`` (mm²).
    A : (q, 3, 3, 3, 3) symmetric pointwise tangent ``∂P_iJ/∂F_kL`` (kPa).
    dNdX : (q, 27, 3) shape gradients (1/mm).
    """
    q, n = dNdX.shape[:2]
    Au = jnp.stack([A[:, i, :, k, :] for i, k in NODE_BLOCK_PAIRS])  # (6, q, J, L)
    # the sum over J (3 terms) as broadcast products, which XLA fuses: its dot with a contraction of 3
    # ran slower (default LV tangent kernel 0.84–0.88× the time with the sum; as kinematics.matmul3)
    wt = wG.transpose(1, 0, 2)  # (a, q, J)
    T = sum(wt[None, :, :, J, None] * Au[:, None, :, J, :] for J in range(3))  # (6, a, q, L)
    # laid out (6, a, q, L), the sum over (q, L) is one plain matrix product (0.90–0.94× the time of
    # an einsum over (6, q, a, L))
    return (T.reshape(6 * n, q * 3) @ dNdX.transpose(0, 2, 1).reshape(q * 3, n)).reshape(6, n, n)


def element_tangent(x_e, p_e, Jinv, wdet, frames, Minv, P, dNdxi, model):
    """Condensed element system (arguments as :func:`element_residual`).

    The pointwise tangent comes from the model with both gradient slots in reference coordinates,
    ``A'_iKkM = Σ_JL Jinv_KJ A_iJkL Jinv_ML`` (``first_piola_tangent(..., G=Jinv)``: the closed-form
    laws map the 3×3 factors of their outer products, not the 3⁴ tensor; kernel 0.80× the time at the
    default LV), and is contracted with the shared ``∂N/∂ξ``.

    Returns
    -------
    rhs : (81,) condensed residual ``r_u + κ Dᵀ M⁻¹ r_p``;
    Kb : (6, 27, 27) condensed tangent as its six node blocks (``"node_blocks"`` layout, see
    :func:`material_stiffness`; the matrix: :func:`lvcore.mechanics.assembly.node_blocks_matrix`);
    D : (4, 81); r_p : (4,).
    """
    kappa = model.kappa
    F = deformation_gradients(x_e, Jinv, dNdxi)
    J = det3(F)
    pq = P @ p_e
    # the pointwise tangent with its gradient slots in ξ (q, i, K, k, M), built so by the law
    Pst, A_ref = jax.vmap(model.first_piola_tangent)(F, frames, pq, Jinv)
    r_u = nodal_sum(wdet[:, None, None] * Pst, Jinv, dNdxi).reshape(81)
    r_p = P.T @ (wdet * (J - 1.0)) - jnp.linalg.solve(Minv, p_e) / kappa
    Kb = material_stiffness(wdet[:, None, None] * dNdxi, A_ref, dNdxi)
    cof = matmul3(cofactor(F), Jinv.swapaxes(1, 2))  # (q, i, K)
    D = jnp.einsum("q,qm,qiK,qaK->mai", wdet, P, cof, dNdxi).reshape(4, 81)
    KMD = kappa * (Minv @ D)
    # the condensation term Dᵀ κ M⁻¹ D, in the same node blocks: block (i, k) is Σ_m D[m, a, i] KMD[m, b, k]
    rows, cols = ([c[j] for c in NODE_BLOCK_PAIRS] for j in (0, 1))
    Kb = Kb + jnp.einsum("map,mbp->pab", D.reshape(4, 27, 3)[:, :, rows], KMD.reshape(4, 27, 3)[:, :, cols])
    rhs = r_u + KMD.T @ r_p
    return rhs, Kb, D, r_p
