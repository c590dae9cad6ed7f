"""Sparse direct solves of the tangent.

* Symmetric tangents (pressure potential on the LV): CHOLMOD (scikit-sparse,
  optional) simplicial LDLᵀ with the symbolic analysis done once per sparsity
  pattern and reused. LDLᵀ also factors the indefinite tangents met away from
  equilibrium (negative entries in D), which an LLᵀ Cholesky rejects. It does
  not pivot, so every solve checks its normwise backward error
  ``‖Kx − b‖∞ / (‖K‖∞‖x‖∞ + ‖b‖∞)``; above :data:`BACKWARD_ERROR_TOL` (or
  without CHOLMOD) SciPy's SuperLU with a symmetric ordering and threshold
  pivoting is used instead.
* Non-symmetric tangents (follower pressure on an open face): SuperLU with
  partial pivoting.

Install CHOLMOD with ``apt-get install -y libsuitesparse-dev`` and
``pip install scikit-sparse==0.4.16``; without it everything still works, slower.
"""
from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # optional, faster
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, analyze as _cholmod_analyze
except Exception:  # pragma: no cover - depends on the environment
    _cholmod_analyze = None
    CholmodNotPositiveDefiniteError = Exception

#: Largest accepted normwise backward error of an LDLᵀ solve (a stable solve gives ~1e-16).
BACKWARD_ERROR_TOL = 1e-10


#: Environment variable naming the backend to use (``cholmod`` or ``superlu``), e.g. to compare them.
BACKEND_ENV = "LVCORE_SPARSE_SOLVER"


def available_backends() -> tuple[str, ...]:
    """Names of the usable backends, fastest first."""
    return (("cholmod",) if _cholmod_analyze is not None else ()) + ("superlu",)


def default_backend() -> str:
    """The backend used when none is named: ``$LVCORE_SPARSE_SOLVER`` if set, else the fastest available.

    Raises
    ------
    ValueError
        If the variable names a backend that is not available here.
    """
    want = os.environ.get(BACKEND_ENV, "").strip().lower()
    if not want:
        return available_backends()[0]
    if want not in available_backends():
        raise ValueError(f"{BACKEND_ENV}={want!r}: available sparse solvers here are {list(available_backends())}"
                         + (" (CHOLMOD needs scikit-sparse: pip install 'lvcore[fast]')" if want == "cholmod" else ""))
    return want


def _as_csc(K, symmetric):
    if symmetric and sp.isspmatrix_csr(K):
        # a symmetric CSR matrix read as CSC is the same matrix: no conversion
        return sp.csc_matrix((K.data, K.indices, K.indptr), shape=K.shape)
    return sp.csc_matrix(K)


class Factorization:
    """A factorised matrix; call :meth:`solve` (1-D or 2-D right-hand sides).

    Parameters
    ----------
    K : sparse matrix.
    backend : "cholmod" or "superlu" (default: the fastest available).
    symmetric : whether K is symmetric.
    cache : optional dict owned by K's sparsity pattern; with CHOLMOD the
        symbolic analysis is stored there and reused for matrices of that pattern.
    """

    def __init__(self, K, backend: str | None = None, symmetric: bool = True, cache: dict | None = None):
        self.backend = backend or default_backend()
        self._lu = None
        self._chol = None
        self._symmetric = symmetric
        self._A = A = _as_csc(K, symmetric)
        self.shape = A.shape
        if self.backend == "cholmod" and _cholmod_analyze is not None and symmetric:
            try:
                f = cache.get("cholmod_ldl") if cache is not None else None
                if f is None:
                    f = _cholmod_analyze(A, mode="simplicial")
                    if cache is not None:
                        cache["cholmod_ldl"] = f
                self._chol = f.cholesky(A)  # a copy: this factorisation stays valid after later ones
                self._norm_A = float(abs(A).sum(axis=0).max())  # = ‖A‖∞ for symmetric A
                return
            except CholmodNotPositiveDefiniteError:  # a zero pivot (singular leading block)
                pass
        self._superlu()

    def _superlu(self):
        self.backend = "superlu"
        self._chol = None
        if self._symmetric:
            self._lu = spla.splu(self._A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01,
                                 options={"SymmetricMode": True})
        else:
            self._lu = spla.splu(self._A)

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._chol is not None:
            x = self._chol(b)
            r = self._A @ x - b
            denom = self._norm_A * np.max(np.abs(x)) + np.max(np.abs(b))
            if np.all(np.isfinite(x)) and np.max(np.abs(r)) <= BACKWARD_ERROR_TOL * denom:
                return x
            self._superlu()  # unstable LDLᵀ (tiny pivot): factor again with pivoting
        return self._lu.solve(b)


def factorize(K, backend: str | None = None, symmetric: bool = True, cache: dict | None = None) -> Factorization:
    """Factorise ``K`` with the fastest available backend (``symmetric=False``: SuperLU, partial pivoting)."""
    return Factorization(K, backend, symmetric, cache)
