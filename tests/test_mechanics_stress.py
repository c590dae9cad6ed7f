"""Strip-biaxial Cauchy stress of the HO law (lvcore.mechanics.stress.ho_fibre_stress), F = diag(λ, 1/λ, 1) in
(f0, s0, n0) with σ(s0, s0) = 0: stress-free reference, power identities against the law's strain energy,
closed forms of the isotropic, fibre and sheet terms, and the sign and monotonicity of the cross-fibre stress."""
import jax.numpy as jnp
import numpy as np
import pytest

from lvcore.domain import conditions
from lvcore.mechanics.materials import HolzapfelOgden
from lvcore.mechanics.stress import ho_fibre_stress

THETA = dict(conditions.THETA_TILDE)  # a, af kPa; b, bf -


def _draws(n=5, seed=0):
    """(n,) draws of theta around THETA (a, af kPa; b, bf -)."""
    rng = np.random.default_rng(seed)
    return {k: v * rng.uniform(0.5, 2.0, n) for k, v in THETA.items()}


def test_unit_stretch_is_stress_free():
    for fixed in (None, {"as": 0.0, "afs": 0.0}):
        s_ff, s_nn = ho_fibre_stress(_draws(), 1.0, fixed=fixed)
        assert s_ff.shape == s_nn.shape == (5,)
        np.testing.assert_allclose(s_ff, 0.0, atol=1e-13)
        np.testing.assert_allclose(s_nn, 0.0, atol=1e-13)


def test_shapes_broadcast():
    s_ff, s_nn = ho_fibre_stress(THETA, 1.1)
    assert s_ff.shape == s_nn.shape == ()
    assert ho_fibre_stress(THETA, np.array([1.0, 1.1, 1.2]))[0].shape == (3,)
    assert ho_fibre_stress(_draws(4), np.linspace(0.9, 1.2, 4))[1].shape == (4,)


def _energy(params, lam, mu=1.0):
    """The simulator's HO strain energy (kPa) at F = diag(λ, 1/(λμ), μ) in the frame (f0, s0, n0) (μ = 1: the
    strip-biaxial path)."""
    law = HolzapfelOgden.from_params(params)
    F = jnp.diag(jnp.array([lam, 1.0 / (lam * mu), mu]))
    return float(law.strain_energy(F, jnp.eye(3)))


def _draws_and_population(seed):
    d = _draws(4, seed=seed)
    return {k: np.append(v, THETA[k]) for k, v in d.items()}


@pytest.mark.parametrize("lam", [0.8, 0.93, 1.04, 1.15, 1.3])
def test_power_identity_along_the_fibre_matches_strain_energy(lam):
    """dW/dλ = σ : D / λ̇ with D = diag(1, −1, 0) λ̇/λ, so dW/dλ = (σ_ff − σ_ss)/λ = σ_ff/λ (σ_ss = 0)."""
    draws = _draws_and_population(seed=1)
    s_ff, _ = ho_fibre_stress(draws, lam)
    h = 1e-5 * lam
    for i in range(len(s_ff)):
        params = {k: float(v[i]) for k, v in draws.items()}
        dW = (_energy(params, lam + h) - _energy(params, lam - h)) / (2 * h)
        assert s_ff[i] / lam == pytest.approx(dW, rel=1e-6)


@pytest.mark.parametrize("lam", [0.8, 0.93, 1.04, 1.15, 1.3])
def test_power_identity_across_the_fibre_matches_strain_energy(lam):
    """Stretching n0 by μ from the strip state (F = diag(λ, 1/(λμ), μ)): D = diag(0, −1, 1) μ̇/μ, so at μ = 1
    ∂W/∂μ = σ_nn − σ_ss = σ_nn, the returned cross-fibre stress."""
    draws = _draws_and_population(seed=3)
    _, s_nn = ho_fibre_stress(draws, lam)
    h = 1e-5
    for i in range(len(s_nn)):
        params = {k: float(v[i]) for k, v in draws.items()}
        dW = (_energy(params, lam, 1.0 + h) - _energy(params, lam, 1.0 - h)) / (2 * h)
        assert s_nn[i] == pytest.approx(dW, rel=1e-6)


def _closed_form_no_sheet(a, b, af, bf, lam):
    """(σ_ff, σ_nn) of W = a/(2b)(e^{b(I1−3)} − 1) + af/(2bf)(e^{bf(I4f−1)²} − 1)·[I4f > 1] at
    F = diag(λ, 1/λ, 1), σ_ss = 0: I1 = λ² + 1/λ² + 1, I4f = λ²."""
    i1, i4 = lam ** 2 + 1.0 / lam ** 2 + 1.0, lam ** 2
    W1 = 0.5 * a * np.exp(b * (i1 - 3.0))
    W4 = np.where(i4 > 1.0, af * (i4 - 1.0) * np.exp(bf * (i4 - 1.0) ** 2), 0.0)
    return 2.0 * W1 * (lam ** 2 - 1.0 / lam ** 2) + 2.0 * W4 * lam ** 2, 2.0 * W1 * (1.0 - 1.0 / lam ** 2)


def test_closed_form_of_isotropic_and_fibre_terms():
    d = _draws(6, seed=2)
    lam = np.array([0.8, 0.9, 0.97, 1.05, 1.15, 1.25])
    s_ff, s_nn = ho_fibre_stress(d, lam, fixed={"as": 0.0, "afs": 0.0})
    c_ff, c_nn = _closed_form_no_sheet(d["a"], d["b"], d["af"], d["bf"], lam)
    np.testing.assert_allclose(s_ff, c_ff, rtol=1e-12)
    np.testing.assert_allclose(s_nn, c_nn, rtol=1e-12)
    # in tension the sheet terms are off anyway (I4s = 1/λ² < 1, I8fs = 0): the population values change nothing
    t = lam > 1
    p_ff, p_nn = ho_fibre_stress({k: v[t] for k, v in d.items()}, lam[t])
    np.testing.assert_allclose(p_ff, c_ff[t], rtol=1e-12)
    np.testing.assert_allclose(p_nn, c_nn[t], rtol=1e-12)


def test_closed_form_at_population_values_by_hand():
    """λ = 1.1 at the population theta (a = 0.6, b = 1.3, af = 1, bf = 3.6), worked by hand."""
    lam = 1.1
    i1 = 1.21 + 1.0 / 1.21 + 1.0
    W1 = 0.3 * np.exp(1.3 * (i1 - 3.0))
    W4 = 1.0 * 0.21 * np.exp(3.6 * 0.21 ** 2)
    s_ff, s_nn = ho_fibre_stress(THETA, lam)
    assert float(s_ff) == pytest.approx(2 * W1 * (1.21 - 1 / 1.21) + 2 * W4 * 1.21, rel=1e-12)
    assert float(s_nn) == pytest.approx(2 * W1 * (1 - 1 / 1.21), rel=1e-12)


def test_sheet_term_in_compression_loads_the_wall_normal():
    """λ < 1: the wall normal s0 is stretched (I4s = 1/λ² > 1) and carries the sheet term; σ(s0, s0) = 0 takes
    2 Ws/λ² off both in-plane stresses, Ws = a_s (I4s−1) e^{b_s (I4s−1)²}; I8fs = 0 leaves a_fs out."""
    lam = np.array([0.8, 0.9, 0.95])
    s_ff, s_nn = ho_fibre_stress(THETA, lam)
    as_, bs = conditions.HO_FIXED["as"], conditions.HO_FIXED["bs"]
    i4s = 1.0 / lam ** 2
    Ws = as_ * (i4s - 1.0) * np.exp(bs * (i4s - 1.0) ** 2)
    c_ff, c_nn = _closed_form_no_sheet(*(THETA[k] for k in ("a", "b", "af", "bf")), lam)
    np.testing.assert_allclose(s_ff, c_ff - 2 * Ws / lam ** 2, rtol=1e-12)
    np.testing.assert_allclose(s_nn, c_nn - 2 * Ws / lam ** 2, rtol=1e-12)
    assert np.all(s_ff < 0) and np.all(s_nn < 0)


def test_cross_fibre_stress_is_positive_in_tension_and_below_the_fibre_stress():
    d = _draws(8, seed=4)
    for lam in (1.02, 1.1, 1.25):
        s_ff, s_nn = ho_fibre_stress(d, lam)
        assert np.all(s_nn > 0)
        assert np.all(s_nn < s_ff)  # σ_ff − σ_nn = 2 W₁ (λ² − 1) + 2 W₄ λ² > 0


@pytest.mark.parametrize("key", ["a", "b"])
def test_cross_fibre_stress_increases_with_a_and_b(key):
    values = np.array([0.5, 1.0, 2.0, 4.0]) * THETA[key]
    theta = {**THETA, key: values}
    for lam in (1.05, 1.2):
        _, s_nn = ho_fibre_stress(theta, lam)
        assert np.all(np.diff(s_nn) > 0)


@pytest.mark.parametrize("key", ["af", "bf"])
def test_fibre_stress_increases_with_af_and_bf_and_cross_fibre_stress_does_not_see_them(key):
    values = np.array([0.5, 1.0, 2.0, 4.0]) * THETA[key]
    theta = {**THETA, key: values}
    for lam in (1.05, 1.2):
        s_ff, s_nn = ho_fibre_stress(theta, lam)
        assert np.all(np.diff(s_ff) > 0)
        np.testing.assert_allclose(s_nn, s_nn[0], rtol=1e-13)


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
