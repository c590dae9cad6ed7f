"""Cauchy stress of the Holzapfel–Ogden law in a planar strip-biaxial state: ``ho_fibre_stress``.

A derived quantity of calibrated stiffness draws: the fibre and in-plane
cross-fibre stresses of the simulator's own Holzapfel–Ogden law
(:class:`lvcore.mechanics.materials.HolzapfelOgden`, the closed-form stress
the finite elements use, with its tension-only fibre and sheet terms) at a
given fibre stretch, with the in-plane cross-fibre direction held at stretch 1
(the strip-biaxial state of myocardial biaxial testing).
"""
from __future__ import annotations

from typing import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from lvcore.domain import conditions
from lvcore.mechanics.kinematics import right_cauchy_green
from lvcore.mechanics.materials import HolzapfelOgden

#: The calibrated parameters, in :attr:`HolzapfelOgden.keys` order.
THETA_KEYS = ("a", "b", "af", "bf")
#: The other parameters of the law at the simulator's population values (Gao et al. 2017; no dispersion).
FIXED_DEFAULTS = {**conditions.HO_FIXED, "kappa": 0.0}

#: Rows f0, s0, n0 of the fibre frame in the stress state's own coordinates: fibre e1, sheet (wall normal) e2.
_FRAME = np.eye(3)


@jax.jit
def _membrane_stress(params, lam):
    """(σ_ff, σ_nn) (kPa) for parameter rows ``params`` (m, 9) (law keys order) and stretches ``lam`` (m,)."""
    def one(v, stretch):
        law = HolzapfelOgden.from_vector(v)
        F = jnp.diag(jnp.stack([stretch, 1.0 / stretch, jnp.ones_like(stretch)]))  # strip biaxial, J = 1
        S, _ = law.pk2_tangent(right_cauchy_green(F), _FRAME, with_tangent=False)
        tau = F @ S @ F.T  # J = 1: the Cauchy stress less the hydrostatic pressure
        return tau[0, 0] - tau[1, 1], tau[2, 2] - tau[1, 1]  # the pressure makes σ along s0 (the wall normal) 0

    return jax.vmap(one)(params, lam)


def ho_fibre_stress(theta: Mapping[str, object], stretch, *, fixed: Mapping[str, float] | None = None):
    """Fibre and in-plane cross-fibre Cauchy stress (kPa) of the HO law in planar strip-biaxial extension.

    The deformation, in the simulator's fibre frame (f0 fibre, s0 sheet = the wall normal, transmural as in
    :mod:`lvcore.mechanics.fibres`, n0 = f0 × s0 the in-plane cross-fibre direction)::

        F = diag(λ, 1/λ, 1)      (f0, s0, n0 components; J = 1)

    the fibre stretched to λ, the in-plane cross-fibre direction n0 held at stretch 1 (as the clamped cross-fibre
    axis of a strip-biaxial test of myocardium) and the wall normal s0 contracting to 1/λ (incompressible). The
    hydrostatic pressure is fixed by a traction-free wall normal, ``σ(s0, s0) = 0``; the Cauchy stress is
    ``σ = F S Fᵀ − p I`` with ``S = 2 ∂W/∂C`` the simulator's closed-form stress
    (:meth:`HolzapfelOgden.pk2_tangent`: isotropic term in Ī1 (= I1 here), fibre term only in tension,
    E_f > 0, sheet term only for I4s > 1, fibre-sheet term in I8fs = 0 here). With
    ``W = a/(2b)(e^{b(I1−3)} − 1) + a_f/(2b_f)(e^{b_f(I4f−1)²} − 1)·[I4f > 1] + …`` (κ = 0), for λ ≥ 1
    (``I1 = λ² + 1/λ² + 1``, ``I4f = λ²``; the sheet term is off since ``I4s = 1/λ² ≤ 1``, the fibre-sheet
    term is zero)::

        σ_ff = 2 W₁ (λ² − 1/λ²) + 2 W₄ λ²,      σ_nn = 2 W₁ (1 − 1/λ²),
        W₁ = (a/2) e^{b(I1−3)},                 W₄ = a_f (λ² − 1) e^{b_f (λ² − 1)²},

    so the cross-fibre stress is positive for λ > 1 and depends on a, b only. For λ < 1 the fibre term is off
    and the stretched wall normal (I4s = 1/λ² > 1) carries the sheet term
    ``W_s = a_s (I4s − 1) e^{b_s (I4s − 1)²}``, which the pressure takes over: both stresses gain ``−2 W_s/λ²``.
    Along this path ``D = diag(1, −1, 0) λ̇/λ``, so ``dW/dλ = (σ_ff − σ_ss)/λ = σ_ff/λ``.

    Parameters
    ----------
    theta : mapping with exactly the keys ``"a", "b", "af", "bf"``
        Stiffnesses a, a_f (kPa) and exponents b, b_f (-); floats or arrays (e.g. (n,) posterior draws).
    stretch : float or array
        Fibre stretch λ > 0 (-), e.g. :func:`lvcore.mechanics.fibre_stretch.mean_fibre_stretch`; broadcast
        against the theta arrays.
    fixed : mapping, optional
        Overrides of the other parameters ``"as", "bs", "afs", "bfs"`` (kPa, -, kPa, -) and ``"kappa"`` (fibre
        dispersion, -); default the simulator's population values :data:`lvcore.domain.conditions.HO_FIXED`, κ = 0.

    Returns
    -------
    sigma_ff, sigma_nn : arrays of the inputs' broadcast shape (0-d for scalars), kPa
        The fibre stress σ(f0, f0) and the in-plane cross-fibre stress σ(n0, n0) (the second in-plane
        direction of the wall, held at stretch 1; the simulator's sheet direction s0 is the traction-free
        wall normal).

    Raises
    ------
    ValueError
        Missing or unknown keys in ``theta`` or ``fixed``, or a stretch that is not finite and > 0.
    """
    theta = dict(theta)
    missing = [k for k in THETA_KEYS if k not in theta]
    unknown = sorted(set(theta) - set(THETA_KEYS))
    if missing or unknown:
        hint = " (pass the population parameters as fixed=)" if set(unknown) & set(FIXED_DEFAULTS) else ""
        raise ValueError(f"theta needs exactly the keys {list(THETA_KEYS)}; missing {missing}, unknown {unknown}{hint}")
    fx = dict(FIXED_DEFAULTS)
    if fixed is not None:
        bad = sorted(set(fixed) - set(FIXED_DEFAULTS))
        if bad:
            raise ValueError(f"fixed may set only {list(FIXED_DEFAULTS)}, got {bad}")
        fx.update(fixed)
    values = [np.asarray(theta[k], dtype=np.float64) for k in THETA_KEYS]
    values += [np.asarray(fx[k], dtype=np.float64) for k in HolzapfelOgden.keys[len(THETA_KEYS):]]
    lam = np.asarray(stretch, dtype=np.float64)
    if not np.all(np.isfinite(lam) & (lam > 0)):
        raise ValueError(f"stretch must be finite and > 0, got {stretch!r}")
    *values, lam = np.broadcast_arrays(*values, lam)
    shape = lam.shape
    params = np.stack([v.ravel() for v in values], axis=1)
    s_ff, s_nn = _membrane_stress(params, lam.ravel())
    return np.asarray(s_ff).reshape(shape), np.asarray(s_nn).reshape(shape)


__all__ = ["ho_fibre_stress", "THETA_KEYS", "FIXED_DEFAULTS"]
