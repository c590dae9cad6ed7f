"""Membrane Cauchy stress of the HO law (lvcore.mechanics.stress.ho_fibre_stress): stress-free reference, the
power identity against the law's strain energy, and closed forms of the fibre and sheet terms."""
import jax.numpy as jnp
import numpy as np
import pytest

from lvcore import units
from lvcore.mechanics.materials import HolzapfelOgden
from lvcore.mechanics.stress import ho_fibre_stress

THETA = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}


def _draws(n=5, seed=0):
    """(n,) draws of theta around THETA (a, af kPa; b, bf -)."""
    rng = np.random.default_rng(seed)
    return {k: v * rng.uniform(0.5, 2.0, n) for k, v in THETA.items()}


def test_unit_stretch_is_stress_free():
    s_ff, s_ss = ho_fibre_stress(_draws(), 1.0)
    assert s_ff.shape == s_ss.shape == (5,)
    np.testing.assert_allclose(s_ff, 0.0, atol=1e-13)
    np.testing.assert_allclose(s_ss, 0.0, atol=1e-13)


def test_shapes_broadcast():
    s_ff, s_ss = ho_fibre_stress(THETA, 1.1)
    assert s_ff.shape == s_ss.shape == ()
    assert ho_fibre_stress(THETA, np.array([1.0, 1.1, 1.2]))[0].shape == (3,)
    assert ho_fibre_stress(_draws(4), np.linspace(0.9, 1.2, 4))[0].shape == (4,)


def _energy(params, lam):
    """The simulator's HO strain energy (kPa) at F = diag(λ, λ^-1/2, λ^-1/2) in the frame (f0, s0, n0)."""
    law = HolzapfelOgden.from_params(params)
    F = jnp.diag(jnp.array([lam, lam ** -0.5, lam ** -0.5]))
    return float(law.strain_energy(F, jnp.eye(3)))


@pytest.mark.parametrize("lam", [0.8, 0.93, 1.04, 1.15, 1.3])
def test_power_identity_matches_strain_energy_finite_difference(lam):
    """dW/dλ = σ : D / λ̇ with D = diag(1, −1/2, −1/2) λ̇/λ, so dW/dλ = (σ_ff − (σ_ss + σ_nn)/2)/λ, σ_nn = 0."""
    draws = _draws(4, seed=1)
    draws = {k: np.append(v, THETA[k]) for k, v in draws.items()}
    s_ff, s_ss = ho_fibre_stress(draws, lam)
    h = 1e-5 * lam
    for i in range(len(s_ff)):
        params = {k: float(v[i]) for k, v in draws.items()}
        dW = (_energy(params, lam + h) - _energy(params, lam - h)) / (2 * h)
        assert (s_ff[i] - 0.5 * s_ss[i]) / lam == pytest.approx(dW, rel=1e-6)


def _closed_form_no_sheet(a, b, af, bf, lam):
    """σ_ff of W = a/(2b)(e^{b(I1−3)} − 1) + af/(2bf)(e^{bf(I4f−1)²} − 1)·[I4f > 1], σ_nn = 0 (then σ_ss = 0)."""
    i1, i4 = lam ** 2 + 2.0 / lam, lam ** 2
    W1 = 0.5 * a * np.exp(b * (i1 - 3.0))
    W4 = np.where(i4 > 1.0, af * (i4 - 1.0) * np.exp(bf * (i4 - 1.0) ** 2), 0.0)
    return 2.0 * W1 * (lam ** 2 - 1.0 / lam) + 2.0 * W4 * lam ** 2


def test_closed_form_of_isotropic_and_fibre_terms():
    d = _draws(6, seed=2)
    lam = np.array([0.8, 0.9, 0.97, 1.05, 1.15, 1.25])
    s_ff, s_ss = ho_fibre_stress(d, lam, fixed={"as": 0.0, "afs": 0.0})
    np.testing.assert_allclose(s_ff, _closed_form_no_sheet(d["a"], d["b"], d["af"], d["bf"], lam), rtol=1e-12)
    np.testing.assert_allclose(s_ss, 0.0, atol=1e-12)
    # in tension the sheet terms are off anyway (I4s = 1/λ < 1, I8fs = 0): the population values change
    # nothing
    t = lam > 1
    np.testing.assert_allclose(ho_fibre_stress(d, lam)[0][t], s_ff[t], rtol=1e-12)


def test_sheet_term_in_compression_loads_the_wall_normal():
    """λ < 1: the wall normal s0 is stretched (I4s = 1/λ > 1) and carries the sheet term; σ_nn(s0) = 0 gives
    σ_ff = 2 W1 (λ² − 1/λ) − 2 Ws/λ and the in-plane cross-fibre σ = −2 Ws/λ, Ws = a_s (I4s−1) e^{b_s (I4s−1)²}."""
    lam = np.array([0.8, 0.9, 0.95])
    s_ff, s_ss = ho_fibre_stress(THETA, lam)
    as_, bs = units.HO_FIXED["as"], units.HO_FIXED["bs"]
    Ws = as_ * (1 / lam - 1) * np.exp(bs * (1 / lam - 1) ** 2)
    no_sheet = _closed_form_no_sheet(*(THETA[k] for k in ("a", "b", "af", "bf")), lam)
    np.testing.assert_allclose(s_ff, no_sheet - 2 * Ws / lam, rtol=1e-12)
    np.testing.assert_allclose(s_ss, -2 * Ws / lam, rtol=1e-12)


@pytest.mark.parametrize("key", ["af", "bf"])
def test_fibre_stress_increases_with_af_and_bf(key):
    values = np.array([0.5, 1.0, 2.0, 4.0]) * THETA[key]
    theta = {**THETA, key: values}
    for lam in (1.05, 1.2):
        s_ff, _ = ho_fibre_stress(theta, lam)
        assert np.all(np.diff(s_ff) > 0)


def test_refuses_bad_input():
    with pytest.raises(ValueError, match="missing \\['bf'\\]"):
        ho_fibre_stress({k: THETA[k] for k in ("a", "b", "af")}, 1.1)
    with pytest.raises(ValueError, match="fixed="):
        ho_fibre_stress({**THETA, "as": 1.0}, 1.1)
    with pytest.raises(ValueError, match="fixed may set only"):
        ho_fibre_stress(THETA, 1.1, fixed={"a": 1.0})
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="stretch"):
            ho_fibre_stress(THETA, bad)
