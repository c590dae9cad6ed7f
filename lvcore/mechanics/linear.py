"""Sparse direct solves of the tangent.

* Symmetric tangents (pressure potential on the LV): CHOLMOD (scikit-sparse,
  optional) with the symbolic analysis done once per sparsity pattern and
  reused; an indefinite tangent (possible away from equilibrium) or a missing
  CHOLMOD falls back to SciPy's SuperLU with a symmetric ordering.
* Non-symmetric tangents (follower pressure on an open face): SuperLU with
  partial pivoting.

Install CHOLMOD with ``apt-get install -y libsuitesparse-dev`` and
``pip install scikit-sparse==0.4.16``; without it everything still works, slower.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # optional, faster
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, analyze as _cholmod_analyze
except Exception:  # pragma: no cover - depends on the environment
    _cholmod_analyze = None
    CholmodNotPositiveDefiniteError = Exception

def available_backends() -> tuple[str, ...]:
    """Names of the usable backends, fastest first."""
    return (("cholmod",) if _cholmod_analyze is not None else ()) + ("superlu",)


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
        self.backend = backend or available_backends()[0]
        self._lu = None
        self._chol = None
        A = _as_csc(K, symmetric)
        if self.backend == "cholmod" and _cholmod_analyze is not None and symmetric:
            try:
                f = cache.get("cholmod") if cache is not None else None
                if f is None:
                    f = _cholmod_analyze(A)
                    if cache is not None:
                        cache["cholmod"] = f
                f.cholesky_inplace(A)
                self._chol = f
                return
            except CholmodNotPositiveDefiniteError:
                pass
        self.backend = "superlu"
        if symmetric:
            self._lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01,
                                 options={"SymmetricMode": True})
        else:
            self._lu = spla.splu(A)

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._chol is not None:
            return self._chol(b)
        return self._lu.solve(b)


def factorize(K, backend: str | None = None, symmetric: bool = True, cache: dict | None = None) -> Factorization:
    """Factorise ``K`` with the fastest available backend (``symmetric=False``: SuperLU, partial pivoting)."""
    return Factorization(K, backend, symmetric, cache)
