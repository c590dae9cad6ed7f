"""The fourth-order tensor forms of the closed-form tangents (lvcore.mechanics.tensor_forms), against index
notation (numpy.einsum), the general pull-back and central differences."""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lvcore.execution.jax_cache import enable_x64
from lvcore.mechanics import tensor_forms as tf
from lvcore.mechanics.kinematics import cofactor

enable_x64()


@pytest.fixture()
def mats():
    rng = np.random.default_rng(7)
    F = np.eye(3) + 0.2 * rng.standard_normal((3, 3))
    X, Y, B, G = (rng.standard_normal((3, 3)) for _ in range(4))
    return F, X, Y, B, G


def test_products_match_index_notation(mats):
    _, X, Y, B, _ = mats
    np.testing.assert_allclose(tf.outer(X, Y), np.einsum("iJ,kL->iJkL", X, Y), rtol=0, atol=1e-14)
    np.testing.assert_allclose(tf.box(X, Y), np.einsum("iL,kJ->iJkL", X, Y), rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(tf.delta_ik(jnp.asarray(B))), np.einsum("ik,JL->iJkL", np.eye(3), B),
                               rtol=0, atol=1e-14)
    assert not np.allclose(tf.outer(X, Y), tf.box(X, Y))  # the two products differ: the checks can fail


def test_slot_maps_equal_the_general_pull_back(mats):
    """``A'_iKkM = G_KJ A_iJkL G_ML`` by the factor-by-factor maps and by :func:`pull_back` itself."""
    _, X, Y, B, G = mats
    G = jnp.asarray(G)
    expect = np.einsum("KJ,iJkL,ML->iKkM", G, tf.outer(X, Y), G)
    np.testing.assert_allclose(np.asarray(tf.pull_back(jnp.asarray(tf.outer(X, Y)), G)), expect, rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_allclose(np.asarray(tf.outer(tf.slot(X, G), tf.slot(Y, G))), expect, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(tf.box(tf.slot(X, G), tf.slot(Y, G))),
                               np.einsum("KJ,iJkL,ML->iKkM", G, tf.box(X, Y), G), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(tf.delta_ik(tf.slots(jnp.asarray(B), G))),
                               np.einsum("KJ,iJkL,ML->iKkM", G, np.asarray(tf.delta_ik(jnp.asarray(B))), G),
                               rtol=1e-12, atol=1e-12)
    assert tf.slot(X, None) is X and tf.slots(B, None) is B


def test_cofactor_derivative_matches_central_differences(mats):
    F = mats[0]
    dcof = (F.reshape(9) @ tf.COF_DERIVATIVE).reshape(3, 3, 3, 3)
    h = 1e-6
    fd = np.zeros((3, 3, 3, 3))
    for k in range(3):
        for L in range(3):
            E = np.zeros((3, 3))
            E[k, L] = h
            fd[:, :, k, L] = (np.asarray(cofactor(jnp.asarray(F + E))) - np.asarray(cofactor(jnp.asarray(F - E)))) / (2 * h)
    np.testing.assert_allclose(dcof, fd, rtol=0, atol=1e-8)


def test_isochoric_split_of_a_neo_hookean_energy_equals_autodiff(mats):
    """``Ŵ(C̄) = mu/2 (tr C̄ − 3)``: ``S̄ = mu I``, ``ℂ̄ = 0``; the split gives ``2 ∂W/∂C`` and ``4 ∂²W/∂C∂C``."""
    F = jnp.asarray(mats[0])
    C = F.T @ F
    mu = 1.7

    def energy(C):
        return 0.5 * mu * (jnp.linalg.det(C) ** (-1.0 / 3.0) * jnp.trace(C) - 3.0)

    def energy_sym(C):  # W of the symmetric part, so autodiff gives the symmetric derivatives
        return energy(0.5 * (C + C.T))

    S, CC = tf.isochoric_split(C, mu * jnp.eye(3), jnp.zeros((3, 3, 3, 3)))
    np.testing.assert_allclose(np.asarray(S), 2 * np.asarray(jax.grad(energy_sym)(C)), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(CC), 4 * np.asarray(jax.hessian(energy_sym)(C)), rtol=1e-9, atol=1e-10)
    S_only, none = tf.isochoric_split(C, mu * jnp.eye(3), None)
    assert none is None
    np.testing.assert_allclose(np.asarray(S_only), np.asarray(S), rtol=0, atol=0)
