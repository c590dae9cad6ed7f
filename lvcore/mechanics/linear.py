"""Sparse direct solves of the (symmetric, possibly indefinite) tangent.

Uses CHOLMOD (scikit-sparse) when it is installed and the matrix is positive
definite, falling back to SciPy's SuperLU with a symmetric ordering, which
also handles indefinite tangents away from equilibrium.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # optional, faster
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky as _cholmod
except Exception:  # pragma: no cover - depends on the environment
    _cholmod = None
    CholmodNotPositiveDefiniteError = Exception


def available_backends() -> tuple[str, ...]:
    """Names of the usable backends, fastest first."""
    return (("cholmod",) if _cholmod is not None else ()) + ("superlu",)


class Factorization:
    """A factorised matrix; call :meth:`solve` (1-D or 2-D right-hand sides)."""

    def __init__(self, K: sp.csr_matrix, backend: str | None = None, symmetric: bool = True):
        self.backend = backend or available_backends()[0]
        self._lu = None
        self._chol = None
        if self.backend == "cholmod" and _cholmod is not None and symmetric:
            try:
                self._chol = _cholmod(sp.csc_matrix(K))
                return
            except CholmodNotPositiveDefiniteError:
                self.backend = "superlu"
        self.backend = "superlu"
        if symmetric:
            self._lu = spla.splu(sp.csc_matrix(K), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01,
                                 options={"SymmetricMode": True})
        else:
            self._lu = spla.splu(sp.csc_matrix(K))

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._chol is not None:
            return self._chol(b)
        return self._lu.solve(b)


def factorize(K: sp.csr_matrix, backend: str | None = None, symmetric: bool = True) -> Factorization:
    """Factorise ``K`` with the fastest available backend (``symmetric=False``: SuperLU, partial pivoting)."""
    return Factorization(K, backend, symmetric)
