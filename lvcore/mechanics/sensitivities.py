"""Adjoint (implicit-function) sensitivities of the outputs to material parameters.

At a converged state the mixed equations hold: ``r_u(u, p, θ) = 0``,
``r_p(u, p) = 0``; ``r_p`` does not depend on θ. Differentiating and
condensing the pressure gives ``K du/dθ = −∂r_u/∂θ`` with ``K`` the condensed
tangent (one factorisation serves all parameters); output derivatives follow
as ``dy/dθ = ∂y/∂u · du/dθ`` by forward-mode autodiff of the output function.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lvcore.mechanics.linear import factorize


def output_sensitivities(system, u_free, p, output_fn, param_names, which) -> dict:
    """d outputs / d params.

    Parameters
    ----------
    system : DiscreteSystem at its converged state ``(u_free, p)`` (full load).
    output_fn : jax function of the full displacement vector -> (n_out,) outputs.
    param_names : names of the law's parameters, in its ``keys`` (vector) order.
    which : names to differentiate with respect to.

    Returns
    -------
    dict name -> (n_out,) array.
    """
    _, K, _, _ = system.tangent(u_free, p, 1.0)
    dR = system.residual_param_jacobian(u_free, p, 1.0)
    idx = [list(param_names).index(n) for n in which]
    du = -factorize(K, symmetric=system.potential, cache=system.pattern.cache).solve(np.ascontiguousarray(dR[:, idx]))
    if du.ndim == 1:
        du = du[:, None]
    u_full = jnp.asarray(system.full(u_free))
    out = {}
    for k, name in enumerate(which):
        tang = jnp.asarray(system.full(du[:, k]))
        _, dy = jax.jvp(output_fn, (u_full,), (tang,))
        out[name] = np.asarray(dy)
    return out
