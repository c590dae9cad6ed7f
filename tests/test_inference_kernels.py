"""Polar GP kernel: PD/PSD on the strain grid, symmetry, periodicity, compact support."""
import numpy as np
import pytest

from lvcore.inference import kernels


def _hyper(c, tau, lam=1.0, s1=1.0, s2=1.0):
    return {"sigma1_sq": s1, "sigma2_sq": s2, "c": c, "tau": tau, "lam": lam}


def test_grid_matches_region_order():
    x = kernels.strain_grid()
    assert x.shape == (24, 2)
    for r in range(24):
        level, sector = divmod(r, 6)
        assert x[r, 0] == pytest.approx(sector * np.pi / 3)
        assert x[r, 1] == level


def test_wendland_at_zero_and_support():
    t = np.linspace(0, np.pi, 200)
    for c in (0.3, 1.0, np.pi):
        w = np.asarray(kernels.wendland_polar(t, c, 5.0))
        assert w[0] == pytest.approx(1.0)
        assert np.all(w[t >= c] == 0.0)
        assert np.all(w[t < c] > 0.0)
        assert np.all(np.diff(w) <= 1e-15)  # non-increasing


def test_geodesic_distance_periodic_and_bounded():
    g = np.linspace(0, 2 * np.pi, 13)
    d = np.asarray(kernels.geodesic_distance(g[:, None], g[None, :]))
    assert np.all(d >= 0) and np.all(d <= np.pi + 1e-12)
    d2 = np.asarray(kernels.geodesic_distance(g[:, None] + 2 * np.pi, g[None, :]))
    np.testing.assert_allclose(d, d2, atol=1e-7)
    assert float(kernels.geodesic_distance(0.1, 2 * np.pi - 0.1)) == pytest.approx(0.2)


@pytest.mark.parametrize("c", np.linspace(0.05, np.pi, 12))
@pytest.mark.parametrize("tau", [4.0, 5.5, 7.0, 10.0])
def test_polar_gram_positive_definite(c, tau):
    """The 6x6 Wendland Gram over the sectors is PD for c in (0, pi], tau in [4, 10]."""
    g = np.arange(6) * np.pi / 3
    d = np.asarray(kernels.geodesic_distance(g[:, None], g[None, :]))
    w = np.asarray(kernels.wendland_polar(d, c, tau))
    np.testing.assert_allclose(w, w.T)
    assert np.linalg.eigvalsh(w).min() > 1e-10


@pytest.mark.parametrize("c", [0.2, 1.0, 2.0, np.pi])
@pytest.mark.parametrize("tau", [4.0, 10.0])
@pytest.mark.parametrize("lam", [0.2, 1.0, 3.0])
def test_full_gram_psd_rank_and_nugget(c, tau, lam):
    """Additive kernel on the grid: symmetric, PSD of rank 9; + nugget it is PD and Cholesky works."""
    k0 = np.asarray(kernels.gram(_hyper(c, tau, lam), nugget=0.0))
    np.testing.assert_allclose(k0, k0.T, atol=1e-14)
    ev = np.linalg.eigvalsh(k0)
    assert ev.min() > -1e-10 * ev.max()
    assert np.sum(ev > 1e-9 * ev.max()) == 9
    nug = 1e-8
    k = np.asarray(kernels.gram(_hyper(c, tau, lam, s1=1e-3, s2=1e-3), nugget=nug))
    assert np.linalg.eigvalsh(k).min() > 0.5 * nug
    chol = np.asarray(kernels.gram_cholesky(_hyper(c, tau, lam, s1=1e-3, s2=1e-3), nugget=nug))
    np.testing.assert_allclose(chol @ chol.T, k, atol=1e-14)


def test_gram_periodic_in_gamma():
    x = kernels.strain_grid()
    shifted = x.copy()
    shifted[:, 0] += 2 * np.pi
    h = _hyper(1.3, 6.0, 0.7)
    k1 = np.asarray(kernels.polar_kernel(x, x, sigma1_sq=1.0, sigma2_sq=0.5, c=1.3, tau=6.0, lengthscale=0.7))
    k2 = np.asarray(kernels.polar_kernel(shifted, x, sigma1_sq=1.0, sigma2_sq=0.5, c=1.3, tau=6.0, lengthscale=0.7))
    np.testing.assert_allclose(k1, k2, atol=1e-12)
    np.testing.assert_allclose(np.asarray(kernels.gram(h, nugget=0.0)).diagonal(), 2.0)


def test_kernel_values_by_hand():
    # regions 0 (sector 0, level 0) and 7 (sector 1, level 1): d = pi/3, dz = 1
    c, tau, lam = 2.0, 4.0, 0.8
    k = np.asarray(kernels.gram(_hyper(c, tau, lam, s1=0.3, s2=0.2), nugget=0.0))
    t = np.pi / 3 / c
    expected = 0.3 * (1 + tau * t) * (1 - t) ** tau + 0.2 * np.exp(-0.5 / lam**2)
    assert k[0, 7] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("c", [0.2, 1.0, 2.0, np.pi])
@pytest.mark.parametrize("tau", [4.0, 10.0])
@pytest.mark.parametrize("lam", [0.5, 1.0, 2.0])
def test_product_kernel_is_full_rank_where_the_additive_one_has_rank_9(c, tau, lam):
    """The product (sector × level) kernel's Gram on the 6 × 4 grid is the Kronecker product of the level and
    sector Grams (exactly, by hand), hence of full rank 24; the additive kernel's has rank 9 at the same
    hyperparameters, so it cannot represent a sector × level interaction."""
    h = _hyper(c, tau, lam, s1=2.0)
    k = np.asarray(kernels.gram(h, nugget=0.0, kind="product"))
    gam = np.arange(6) * np.pi / 3
    d = np.arccos(np.clip(np.cos(gam[:, None] - gam[None, :]), -1, 1))
    r = d / c
    w = (1 + tau * r) * np.clip(1 - r, 0, None) ** tau
    z = np.arange(4.0)
    kz = np.exp(-0.5 * ((z[:, None] - z[None, :]) / lam) ** 2)
    np.testing.assert_allclose(k, 2.0 * np.kron(kz, w), rtol=1e-12, atol=1e-14)  # region r = 6 * level + sector
    ev = np.linalg.eigvalsh(k)
    assert ev.min() > 0 and np.linalg.matrix_rank(k, tol=1e-12 * ev.max()) == 24
    k_add = np.asarray(kernels.gram(h, nugget=0.0))
    assert np.linalg.matrix_rank(k_add, tol=1e-9 * np.abs(np.linalg.eigvalsh(k_add)).max()) == 9
    # a sector × level interaction (zero row and column means) lies in the product kernel's span only
    u = np.outer([1.0, -1.0, 1.0, -1.0], np.cos(2 * gam)).ravel()
    for kk, inside in ((k, True), (k_add, False)):
        coef, *_ = np.linalg.lstsq(kk, u, rcond=1e-12)
        assert (np.linalg.norm(kk @ coef - u) < 1e-6 * np.linalg.norm(u)) == inside
    with pytest.raises(ValueError, match="kernel kind"):
        kernels.gram(h, kind="sum")
