"""Sparse solves of the tangent (lvcore.mechanics.linear)."""
import numpy as np
import pytest
import scipy.sparse as sp

from lvcore.mechanics import linear


def _spd_plus_shift(n=60, shift=0.0, seed=0):
    """A sparse symmetric banded matrix; ``shift`` > its smallest eigenvalue makes it indefinite."""
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=0.1, random_state=rng) + sp.eye(n)
    A = (B @ B.T).tocsr() + sp.eye(n)
    return (A - shift * sp.eye(n)).tocsr()


@pytest.mark.parametrize("shift", [0.0, 2.5])
def test_symmetric_solve_definite_and_indefinite(shift):
    A = _spd_plus_shift(shift=shift)
    eig = np.linalg.eigvalsh(A.toarray())
    assert (eig.min() < 0) == (shift > 0)  # the shifted matrix really is indefinite
    b = np.arange(A.shape[0], dtype=float)
    f = linear.factorize(A, symmetric=True, cache={})  # the fastest backend here
    np.testing.assert_allclose(A @ f.solve(b), b, rtol=0, atol=1e-9 * np.abs(b).max())
    if "cholmod" in linear.available_backends():
        cache = {}
        f = linear.factorize(A, backend="cholmod", symmetric=True, cache=cache)
        x = f.solve(b)
        np.testing.assert_allclose(A @ x, b, rtol=0, atol=1e-9 * np.abs(b).max())
        assert f.backend == "cholmod"  # LDLT, no SuperLU fallback on the indefinite matrix
        # a definite matrix gets the process's mode; an indefinite one the simplicial LDLT (LLT rejects it)
        assert f.factorisation == (linear.cholmod_mode() if shift == 0 else "simplicial")
        assert {"supernodal": "cholmod_ll", "simplicial": "cholmod_ldl"}[f.factorisation] in cache
        # a later factorisation of the same pattern does not change this one
        linear.factorize(A + sp.eye(A.shape[0]), backend="cholmod", symmetric=True, cache=cache)
        np.testing.assert_allclose(f.solve(b), x, rtol=1e-12)


needs_pardiso = pytest.mark.skipif("pardiso" not in linear.available_backends(),
                                   reason="PARDISO (py-mkl-pardiso) not installed: no wheel for this platform")


@needs_pardiso
def test_pardiso_factors_stay_valid_and_share_one_analysis_per_pattern():
    A = _spd_plus_shift(n=200, seed=3)
    b = np.linspace(-1.0, 1.0, A.shape[0])
    ref = linear.factorize(A, backend="superlu", symmetric=True).solve(b)
    cache = {}
    f = linear.factorize(sp.triu(A).tocsr(), backend="pardiso", symmetric=True, cache=cache, triangle=True)
    assert (f.backend, f.factorisation) == ("pardiso", "supernodal")
    x = f.solve(b)
    np.testing.assert_allclose(x, ref, rtol=1e-10, atol=1e-12)
    # a second live factorisation of the same pattern takes a second solver: the first one's factor is kept
    A2 = (A + 3.0 * sp.eye(A.shape[0])).tocsr()
    g = linear.factorize(sp.triu(A2).tocsr(), backend="pardiso", symmetric=True, cache=cache, triangle=True)
    np.testing.assert_allclose(A2 @ g.solve(b), b, atol=1e-10)
    np.testing.assert_array_equal(f.solve(b), x)
    assert cache["pardiso"] == []  # both solvers in use
    solver = g._pardiso
    del g  # dropped: its solver goes back to the pool, analysed, and is taken by the next factorisation
    assert cache["pardiso"] == [solver]
    h = linear.factorize(sp.triu(A).tocsr(), backend="pardiso", symmetric=True, cache=cache, triangle=True)
    assert h._pardiso is solver
    np.testing.assert_array_equal(h.solve(b), x)  # the same analysis and values: the same bits
    # 2-D right-hand sides (the sensitivities' dR columns), also non-contiguous ones
    B = np.asfortranarray(np.stack([b, 2.0 * b, -b], axis=1))
    np.testing.assert_allclose(h.solve(B), np.stack([x, 2.0 * x, -x], axis=1), rtol=1e-12, atol=1e-14)


@needs_pardiso
def test_pardiso_factors_an_indefinite_matrix_with_ldlt_or_refuses_it(monkeypatch):
    A = _spd_plus_shift(shift=2.5)
    b = np.arange(A.shape[0], dtype=float)
    cache = {}
    f = linear.factorize(sp.triu(A).tocsr(), backend="pardiso", symmetric=True, cache=cache, triangle=True)
    # the LLT refused it (a negative pivot): PARDISO's indefinite LDLT, a solver of its own pool
    assert (f.backend, f.factorisation) == ("pardiso", "indefinite")
    assert f._pardiso.mtype == linear._pardiso().MTYPE_REAL_SYM_INDEF and cache["pardiso_indefinite"] == []
    x = f.solve(b)
    assert f.factorisation == "indefinite"  # its backward error passed the check: no SuperLU
    np.testing.assert_allclose(A @ x, b, atol=1e-9 * np.abs(b).max())
    np.testing.assert_allclose(x, linear.factorize(A, backend="superlu", symmetric=True).solve(b), rtol=1e-10)
    B = np.stack([b, -2.0 * b], axis=1)  # 2-D right-hand sides, checked as one block
    np.testing.assert_allclose(f.solve(B), np.stack([x, -2.0 * x], axis=1), rtol=1e-12)
    monkeypatch.setenv(linear.PARDISO_INDEFINITE_ENV, "0")  # switched off: SuperLU, as before
    assert linear.factorize(sp.triu(A).tocsr(), backend="pardiso", symmetric=True, cache=cache,
                            triangle=True).backend == "superlu"
    monkeypatch.delenv(linear.PARDISO_INDEFINITE_ENV)
    with pytest.raises(linear.NotPositiveDefinite, match="not positive definite"):
        linear.factorize(sp.triu(A).tocsr(), backend="pardiso", symmetric=True, cache=cache, triangle=True,
                         require_definite=True)
    # the failed factorisations left the pool's analysis usable: a definite matrix of the pattern after them
    D = _spd_plus_shift()
    g = linear.factorize(sp.triu(D).tocsr(), backend="pardiso", symmetric=True, cache=cache, triangle=True)
    assert g.backend == "pardiso" and len(cache["pardiso"]) == 0
    np.testing.assert_allclose(D @ g.solve(b), b, atol=1e-9 * np.abs(b).max())
    # a non-positive diagonal entry (or one not stored) cannot be definite: refused before PARDISO
    Z = sp.csr_matrix(np.array([[0.0, 1.0], [1.0, 2.0]]))
    with pytest.raises(linear.NotPositiveDefinite):
        linear.factorize(Z, backend="pardiso", symmetric=True, require_definite=True)
    np.testing.assert_allclose(linear.factorize(Z, backend="pardiso", symmetric=True).solve(np.array([1.0, 4.0])),
                               [2.0, 1.0], rtol=1e-12)


@needs_pardiso
def test_pardiso_ldlt_with_a_large_backward_error_falls_back_to_superlu(monkeypatch):
    A = _spd_plus_shift(shift=2.5, seed=1)
    b = np.linspace(1.0, 2.0, A.shape[0])
    ref = linear.factorize(A, backend="superlu", symmetric=True).solve(b)
    monkeypatch.setattr(linear, "BACKWARD_ERROR_TOL", 0.0)  # no solve in floating point passes this
    f = linear.factorize(sp.triu(A).tocsr(), backend="pardiso", symmetric=True, cache={}, triangle=True)
    assert f.factorisation == "indefinite"
    np.testing.assert_allclose(f.solve(b), ref, rtol=1e-12)
    assert (f.backend, f.factorisation, f._pardiso) == ("superlu", "", None)  # factorised again, with SuperLU
    np.testing.assert_allclose(A @ f.solve(b), b, atol=1e-9)


def test_backends_without_pardiso(monkeypatch):
    monkeypatch.setattr(linear, "_PARDISO", [None])  # as on a platform without its wheel
    assert "pardiso" not in linear.available_backends()
    assert linear.available_backends()[-1] == "superlu"
    monkeypatch.setenv(linear.BACKEND_ENV, "pardiso")
    with pytest.raises(ValueError, match="py-mkl-pardiso"):
        linear.default_backend()
    monkeypatch.setenv(linear.BACKEND_ENV, "superlu")
    assert linear.default_backend() == "superlu"


@pytest.mark.skipif("cholmod" not in linear.available_backends(), reason="CHOLMOD (scikit-sparse) not installed")
@pytest.mark.parametrize("mode", ["supernodal", "simplicial"])
def test_require_definite_refuses_an_indefinite_matrix_in_either_mode(monkeypatch, mode):
    monkeypatch.setenv(linear.CHOLMOD_MODE_ENV, mode)
    b = np.ones(60)
    with pytest.raises(linear.NotPositiveDefinite, match="not positive definite"):
        linear.factorize(_spd_plus_shift(shift=2.5), backend="cholmod", symmetric=True, cache={},
                         require_definite=True)
    A = _spd_plus_shift()  # definite: factorised as usual
    f = linear.factorize(A, backend="cholmod", symmetric=True, cache={}, require_definite=True)
    assert f.factorisation == mode
    np.testing.assert_allclose(A @ f.solve(b), b, atol=1e-9)


def test_require_definite_is_ignored_by_superlu():
    A = _spd_plus_shift(shift=2.5)
    f = linear.factorize(A, backend="superlu", symmetric=True, require_definite=True)  # cannot tell: factorises
    b = np.ones(A.shape[0])
    np.testing.assert_allclose(A @ f.solve(b), b, atol=1e-9)


def test_unstable_ldl_falls_back_to_pivoting():
    # [[0, 1], [1, 0]] has a zero leading pivot: LDLT without pivoting cannot factor it
    A = sp.csr_matrix(np.array([[1e-30, 1.0, 0.0], [1.0, 1e-30, 0.0], [0.0, 0.0, 2.0]]))
    b = np.array([1.0, 2.0, 4.0])
    for backend in linear.available_backends():
        f = linear.factorize(A, backend=backend, symmetric=True)
        np.testing.assert_allclose(f.solve(b), [2.0, 1.0, 2.0], rtol=1e-12)
        # pivoting: SuperLU's, or PARDISO's Bunch-Kaufman 2x2 pivot (CHOLMOD's LDLT has none: SuperLU)
        assert (f.backend, f.factorisation) in (("superlu", ""), ("pardiso", "indefinite"))


def test_nonsymmetric_uses_superlu():
    A = sp.csr_matrix(np.array([[2.0, 1.0], [0.0, 3.0]]))
    f = linear.factorize(A, symmetric=False)
    assert f.backend == "superlu"
    np.testing.assert_allclose(f.solve(np.array([3.0, 3.0])), [1.0, 1.0])


@pytest.mark.skipif("cholmod" not in linear.available_backends(), reason="CHOLMOD (scikit-sparse) not installed")
@pytest.mark.parametrize("shift", [0.0, 2.5])
def test_supernodal_and_simplicial_agree(monkeypatch, shift):
    A = _spd_plus_shift(n=200, shift=shift, seed=3)
    b = np.linspace(-1.0, 1.0, A.shape[0])
    x = {}
    for mode in ("supernodal", "simplicial"):
        monkeypatch.setenv(linear.CHOLMOD_MODE_ENV, mode)
        f = linear.factorize(A, backend="cholmod", symmetric=True, cache={})
        assert f.backend == "cholmod"
        assert f.factorisation == (mode if shift == 0 else "simplicial")
        x[mode] = f.solve(b)
        np.testing.assert_allclose(A @ x[mode], b, rtol=0, atol=1e-10)
    np.testing.assert_allclose(x["supernodal"], x["simplicial"], rtol=1e-9, atol=1e-12)
    monkeypatch.setenv(linear.CHOLMOD_MODE_ENV, "fastest")
    with pytest.raises(ValueError, match="supernodal"):
        linear.cholmod_mode()


def _banded_spd(n=300, width=12, seed=0):
    """A symmetric positive definite matrix with a full band of half-width ``width``."""
    rng = np.random.default_rng(seed)
    diags = [rng.uniform(-1.0, 0.0, n - k) for k in range(1, width + 1)]
    A = sp.diags(diags, list(range(1, width + 1)), shape=(n, n))
    A = A + A.T
    return (A + sp.diags(np.asarray(abs(A).sum(axis=1)).ravel() + 1.0)).tocsr()


@pytest.mark.skipif("cholmod" not in linear.available_backends(), reason="CHOLMOD (scikit-sparse) not installed")
def test_supernodal_ordering_keeps_a_banded_numbering_and_reorders_a_scrambled_one(monkeypatch):
    banded = _banded_spd()
    # a band has no fill inside it: the numbering is kept
    assert linear.supernodal_ordering(sp.csc_matrix(banded)) == "natural"
    # the same matrix with its rows and columns scrambled: the natural factor fills in (far beyond 2x AMD's)
    perm = np.random.default_rng(1).permutation(banded.shape[0])
    scrambled = banded[perm][:, perm].tocsr()
    assert linear._factor_entries(sp.csc_matrix(scrambled), "natural") > \
        2 * linear._factor_entries(sp.csc_matrix(scrambled), "default")
    assert linear.supernodal_ordering(sp.csc_matrix(scrambled)) == "default"
    # both give the same solution as SuperLU, through the factorisation the solver uses
    monkeypatch.setenv(linear.CHOLMOD_MODE_ENV, "supernodal")
    b = np.linspace(-1.0, 1.0, banded.shape[0])
    for A in (banded, scrambled):
        f = linear.factorize(A, backend="cholmod", symmetric=True, cache={})
        assert f.factorisation == "supernodal"
        ref = linear.factorize(A, backend="superlu", symmetric=True).solve(b)
        np.testing.assert_allclose(f.solve(b), ref, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("backend", linear.available_backends())
@pytest.mark.parametrize("shift", [0.0, 2.5])
def test_upper_triangle_solves_like_the_whole_matrix(backend, shift):
    # definite (LLT), indefinite (LDLT with its backward-error check on the whole matrix) and SuperLU
    A = _spd_plus_shift(shift=shift)
    b = np.arange(A.shape[0], dtype=float)
    x = linear.factorize(A, backend=backend, symmetric=True, cache={}).solve(b)
    f = linear.factorize(sp.triu(A).tocsr(), backend=backend, symmetric=True, cache={}, triangle=True)
    np.testing.assert_allclose(f.solve(b), x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(A @ f.solve(b), b, atol=1e-9 * np.abs(b).max())


def test_upper_triangle_falls_back_to_pivoting_on_the_whole_matrix():
    A = sp.csr_matrix(np.array([[1e-30, 1.0, 0.0], [1.0, 1e-30, 0.0], [0.0, 0.0, 2.0]]))
    for backend in linear.TRIANGLE_BACKENDS:
        if backend in linear.available_backends():
            f = linear.factorize(sp.triu(A).tocsr(), backend=backend, symmetric=True, triangle=True)
            np.testing.assert_allclose(f.solve(np.array([1.0, 2.0, 4.0])), [2.0, 1.0, 2.0], rtol=1e-12)
            assert (f.backend, f.factorisation) in (("superlu", ""), ("pardiso", "indefinite"))


def test_upper_triangle_needs_a_symmetric_csr_matrix():
    A = _spd_plus_shift()
    with pytest.raises(ValueError, match="upper triangle of a symmetric matrix"):
        linear.factorize(sp.triu(A).tocsc(), symmetric=True, triangle=True)
    with pytest.raises(ValueError, match="upper triangle of a symmetric matrix"):
        linear.factorize(sp.triu(A).tocsr(), symmetric=False, triangle=True)
