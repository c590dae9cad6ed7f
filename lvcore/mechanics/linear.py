"""Sparse direct solves of the tangent.

* Symmetric tangents (pressure potential on the LV), fastest available first:

  - oneMKL PARDISO (``py-mkl-pardiso``, a regular dependency on Linux x86_64 and Windows: MKL is linked
    into its wheel, no system package): supernodal LLᵀ of the upper triangle, the symbolic analysis done
    once per sparsity pattern (a small pool of analysed solvers kept in the pattern's cache, so every
    factorisation stays valid while later ones are made). A matrix that is not positive definite
    (the indefinite tangents met away from equilibrium) is refused by the LLᵀ (zero or negative
    pivot) and gets PARDISO's symmetric indefinite LDLᵀ (Bunch–Kaufman 1×1 and 2×2 pivots within
    its supernodes, small pivots perturbed, iterative refinement where they were; its own pool of
    analysed solvers); as pivoting is restricted, every solve checks its normwise backward error
    ``‖Kx − b‖∞ / (‖K‖∞‖x‖∞ + ‖b‖∞)`` and above :data:`BACKWARD_ERROR_TOL` SuperLU is used instead.
    On the default LV's indefinite tangents ≈ 4× less CPU than SuperLU (BENCHMARKS.md, start-up);
    ``$LVCORE_PARDISO_INDEFINITE=0`` sends them to SuperLU directly. On the default LV's definite
    tangents the LLᵀ takes 3–4× less CPU per factorisation than
    CHOLMOD supernodal with OpenBLAS (``benchmarks/bench_sparse_solvers.py``, BENCHMARKS.md).
  - CHOLMOD (scikit-sparse, optional: ``lvcore[fast]`` plus the system's SuiteSparse) with the symbolic
    analysis done once per sparsity pattern and reused. Where CHOLMOD is linked to an optimised BLAS
    (OpenBLAS, MKL, BLIS: :func:`cholmod_mode`), a supernodal LLᵀ first (its dense blocks go to BLAS:
    ~2× faster than simplicial at the default LV resolution); a matrix it rejects (not positive
    definite) and every matrix with the reference BLAS get the simplicial LDLᵀ, which factors
    indefinite matrices too (negative entries in D). LDLᵀ does not pivot, so every solve checks its
    normwise backward error ``‖Kx − b‖∞ / (‖K‖∞‖x‖∞ + ‖b‖∞)``; above :data:`BACKWARD_ERROR_TOL`
    SuperLU is used instead.
  - SciPy's SuperLU with a symmetric ordering and threshold pivoting: the fallback for indefinite
    matrices, and the only backend where neither of the above is installed.
* Non-symmetric tangents (follower pressure on an open face): SuperLU with
  partial pivoting.

``$LVCORE_SPARSE_SOLVER`` (``pardiso``, ``cholmod`` or ``superlu``) picks one, e.g. to compare them.
"""
from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import weakref

try:  # optional
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, analyze as _cholmod_analyze
except Exception:  # pragma: no cover - depends on the environment
    _cholmod_analyze = None
    CholmodNotPositiveDefiniteError = Exception

_PARDISO: list = []  # [module or None], imported on first use (a 70 MB library: not at import time)


def _pardiso():
    """The ``pymklpardiso`` module, or None where it is not installed (or does not load)."""
    if not _PARDISO:
        try:
            import pymklpardiso
        except Exception:  # pragma: no cover - depends on the environment (no wheel for this platform)
            pymklpardiso = None
        _PARDISO.append(pymklpardiso)
    return _PARDISO[0]

#: Largest accepted normwise backward error of an LDLᵀ solve (a stable solve gives ~1e-16).
BACKWARD_ERROR_TOL = 1e-10


#: Environment variable naming the backend to use (``pardiso``, ``cholmod`` or ``superlu``), e.g. to compare them.
BACKEND_ENV = "LVCORE_SPARSE_SOLVER"
#: Environment variable that sends indefinite symmetric matrices to SuperLU instead of PARDISO's indefinite LDLᵀ
#: (``0``/``off``), e.g. to compare them.
PARDISO_INDEFINITE_ENV = "LVCORE_PARDISO_INDEFINITE"
#: ``iparm`` of PARDISO's symmetric indefinite LDLᵀ (0-based): minimum-degree ordering (1: 0), pivots below
#: 1e-8 ‖K‖ perturbed (9: 8), Bunch–Kaufman 1×1 and 2×2 pivoting (20: 1); with ``iparm[0] = 1`` (the
#: wrapper's) unset entries are 0, not PARDISO's defaults, hence all three.
PARDISO_INDEFINITE_IPARM = {1: 0, 9: 8, 20: 1}
#: Environment variable forcing CHOLMOD's factorisation (``supernodal`` or ``simplicial``), e.g. to compare them.
CHOLMOD_MODE_ENV = "LVCORE_CHOLMOD_MODE"
#: Shared-library names of BLAS implementations fast enough for CHOLMOD's supernodal factorisation.
OPTIMISED_BLAS = ("openblas", "libmkl", "libblis")


def _blas_in_process() -> tuple[str, ...]:
    """The files of the system BLAS libraries mapped into this process (Linux ``/proc/self/maps``)."""
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh if "blas" in line.lower() and "/" in line}
    except OSError:  # not Linux: no way to tell, assume the reference BLAS
        return ()
    # numpy/scipy wheels carry their own OpenBLAS (site-packages/numpy.libs, scipy_openblas); CHOLMOD
    # links the system's libblas.so.3
    return tuple(sorted(p for p in paths if not any(k in p for k in ("site-packages", "dist-packages", ".libs"))))


_MODE: list[str] = []


def cholmod_mode() -> str:
    """``supernodal`` where CHOLMOD's BLAS is an optimised one (or ``$LVCORE_CHOLMOD_MODE`` says so), else ``simplicial``.

    Decided once per process, after scikit-sparse is imported (so its BLAS is mapped).
    With Debian's reference BLAS (``libblas3``) the supernodal factorisation is slower
    than the simplicial one; ``apt-get install libopenblas0-serial`` makes OpenBLAS the
    system BLAS (Debian alternatives) and CHOLMOD picks it up.
    """
    want = os.environ.get(CHOLMOD_MODE_ENV, "").strip().lower()
    if want in ("supernodal", "simplicial"):
        return want
    if want:
        raise ValueError(f"{CHOLMOD_MODE_ENV}={want!r}: use 'supernodal' or 'simplicial'")
    if not _MODE:
        fast = any(k in path.lower() for path in _blas_in_process() for k in OPTIMISED_BLAS)
        _MODE.append("supernodal" if fast else "simplicial")
    return _MODE[0]


def available_backends() -> tuple[str, ...]:
    """Names of the usable backends, fastest first."""
    return ((("pardiso",) if _pardiso() is not None else ()) + (("cholmod",) if _cholmod_analyze is not None else ())
            + ("superlu",))


#: Backends that read a symmetric matrix's upper triangle only (CSR): the tangent is assembled as that.
TRIANGLE_BACKENDS = ("pardiso", "cholmod")


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
                         + (" (CHOLMOD needs scikit-sparse: pip install 'lvcore[fast]')" if want == "cholmod" else "")
                         + (" (PARDISO needs py-mkl-pardiso, a wheel for Linux x86_64 and Windows only)"
                            if want == "pardiso" else ""))
    return want


#: The supernodal factorisation keeps the matrix's own (mesh) numbering instead of AMD's fill-reducing
#: ordering when its factor has at most this many times AMD's entries (see :func:`supernodal_ordering`).
NATURAL_FILL_RATIO = 2.0


def _factor_entries(A, ordering: str) -> int:
    """Entries of the supernodal Cholesky factor of ``A``'s sparsity pattern under ``ordering``.

    Factorises a diagonally dominant matrix of the same pattern (positive definite, whatever ``A``'s
    values), so the count depends on the pattern only.
    """
    B = A.copy().tocsc()
    B.data = np.full(B.data.shape, -1.0)
    # row plus column sums: diagonally dominant whether A holds the whole pattern or one triangle of it
    B = B + sp.diags(np.asarray(abs(B).sum(axis=1)).ravel() + np.asarray(abs(B).sum(axis=0)).ravel() + 1.0)
    return int(_cholmod_analyze(B, mode="supernodal", ordering_method=ordering).cholesky(B).L().nnz)


def supernodal_ordering(A) -> str:
    """Fill-reducing ordering of the supernodal LLᵀ of ``A``: ``"natural"`` or CHOLMOD's default (``"default"``).

    The node numbering of the LV template meshes is banded (rings of nodes, base to apex, at up to 6
    elements around); kept as it is, the factor has more entries than under AMD but wider supernodes,
    whose dense blocks BLAS factorises faster. Measured on the 2-core machine (AMD vs natural, ms per
    numeric factorisation, factor entries): default LV 10.5 vs 6.4 ms (1.51× the entries); ``fast`` 7.1
    vs 5.2 (1.62×); Land problem 2 at 6×(4,2,2,4)×1 25.9 vs 14.3 (1.43×); but ``coarse`` (12 around)
    14.0 vs 18.7 (2.72×) and ``accurate`` 163 vs 221 (2.15×). So the natural numbering is kept when its
    factor has at most :data:`NATURAL_FILL_RATIO` times AMD's entries: a rule on the pattern alone, so
    the choice (and the round-off of every solve) is the same on every machine.
    """
    natural, amd = _factor_entries(A, "natural"), _factor_entries(A, "default")
    return "natural" if natural <= NATURAL_FILL_RATIO * amd else "default"


def _analysis(A, mode: str, cache: dict | None):
    """CHOLMOD's symbolic analysis of ``A`` for ``mode``, kept in ``cache`` (one per sparsity pattern)."""
    key = "cholmod_ldl" if mode == "simplicial" else "cholmod_ll"
    f = cache.get(key) if cache is not None else None
    if f is None:
        ordering = supernodal_ordering(A) if mode == "supernodal" else "default"
        f = _cholmod_analyze(A, mode=mode, ordering_method=ordering)
        if cache is not None:
            cache[key] = f
    return f


def _definite_like(U):
    """A positive definite (diagonally dominant) matrix with the sparsity pattern of the upper triangle ``U`` (CSR)."""
    B = sp.csr_matrix((-np.ones_like(U.data), U.indices, U.indptr), shape=U.shape)
    B.setdiag(np.asarray(abs(B).sum(axis=1)).ravel() + np.asarray(abs(B).sum(axis=0)).ravel() + 1.0)
    return B


def _pardiso_solver(U, cache: dict | None, indefinite: bool = False):
    """A PARDISO solver analysed for ``U``'s pattern (upper triangle, CSR, sorted): an idle one of ``cache``'s pool.

    PARDISO keeps one factor per solver, so each :class:`Factorization` holds its own solver and gives it
    back to the pool when it is garbage collected; the symbolic analysis (minimum-degree ordering,
    ``iparm[1] = 0``: fewer operations than METIS at these sizes) is done when a solver is made,
    on a positive definite matrix of the pattern. ``indefinite``: a solver of the symmetric indefinite
    LDLᵀ (:data:`PARDISO_INDEFINITE_IPARM`), from a pool of its own.
    """
    name = "pardiso_indefinite" if indefinite else "pardiso"
    pool = cache.setdefault(name, []) if cache is not None else []
    try:
        return pool.pop(), pool
    except IndexError:
        pm = _pardiso()
        if indefinite:
            return pm.PardisoSolver(_definite_like(U), pm.MTYPE_REAL_SYM_INDEF, iparms=PARDISO_INDEFINITE_IPARM), pool
        return pm.PardisoSolver(_definite_like(U), pm.MTYPE_REAL_SYM_POSDEF, iparms={1: 0}), pool


def _pardiso_indefinite_on() -> bool:
    """Whether indefinite symmetric matrices go to PARDISO's LDLᵀ (else SuperLU): :data:`PARDISO_INDEFINITE_ENV`."""
    return os.environ.get(PARDISO_INDEFINITE_ENV, "").strip().lower() not in ("0", "off", "false", "no")


def _backward_stable(Ax, x, b, norm_A: float) -> bool:
    """Whether a solve ``x`` of ``Ax = b`` has a normwise backward error ``‖Ax − b‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞)`` of at
    most :data:`BACKWARD_ERROR_TOL` (``Ax``: the product, computed by the caller; ``norm_A`` = ‖A‖∞)."""
    if not np.all(np.isfinite(x)):
        return False
    return bool(np.max(np.abs(Ax - b)) <= BACKWARD_ERROR_TOL * (norm_A * np.max(np.abs(x)) + np.max(np.abs(b))))


def _upper_csr(K, triangle: bool):
    """The upper triangle of symmetric ``K`` as CSR with sorted column indices (what PARDISO reads)."""
    U = K if triangle else sp.triu(K, format="csr")
    if not U.has_sorted_indices:
        U = U.sorted_indices()
    return U


def _as_csc(K, symmetric):
    if symmetric and sp.isspmatrix_csr(K):
        # a symmetric CSR matrix read as CSC is the same matrix: no conversion
        return sp.csc_matrix((K.data, K.indices, K.indptr), shape=K.shape)
    return sp.csc_matrix(K)


class NotPositiveDefinite(ValueError):
    """A factorisation asked for a positive definite matrix (``require_definite``) and found it indefinite."""


class Factorization:
    """A factorised matrix; call :meth:`solve` (1-D or 2-D right-hand sides).

    Parameters
    ----------
    K : sparse matrix.
    backend : "pardiso", "cholmod" or "superlu" (default: the fastest available).
    symmetric : whether K is symmetric.
    cache : optional dict owned by K's sparsity pattern; with PARDISO (a pool of analysed
        solvers) and CHOLMOD the symbolic analysis is stored there and reused for matrices of that pattern.
    require_definite : with PARDISO or CHOLMOD, raise :class:`NotPositiveDefinite` for a symmetric
        matrix that is not positive definite instead of factorising it with LDLᵀ (or
        SuperLU): the caller has a better way on (Newton cuts the load step) and skips
        the slower indefinite factorisation. SuperLU cannot tell and factorises.
    triangle : K (CSR, symmetric) holds its upper triangle only
        (:meth:`lvcore.mechanics.system.DiscreteSystem.tangent` with ``triangle=True``): PARDISO and
        CHOLMOD read nothing else; the whole matrix is formed only where a solve needs it (the
        backward-error check of LDLᵀ, SuperLU).
    """

    def __init__(self, K, backend: str | None = None, symmetric: bool = True, cache: dict | None = None,
                 require_definite: bool = False, triangle: bool = False):
        if triangle and not (symmetric and sp.isspmatrix_csr(K)):
            raise ValueError("triangle=True takes the upper triangle of a symmetric matrix in CSR form")
        self.backend = backend or default_backend()
        self._lu = None
        self._chol = None
        self._pardiso = None
        self._symmetric = symmetric
        self._A = A = _as_csc(K, symmetric)  # a CSR upper triangle read as CSC: the lower one
        self._triangle = triangle
        self.shape = A.shape
        if self.backend == "pardiso" and symmetric and _pardiso() is not None:
            U = _upper_csr(K, triangle)
            # a positive definite matrix has a positive diagonal (also: every diagonal entry stored, as the
            # pool's analysis assumes); anything else is indefinite or singular
            definite = bool(np.all(U.diagonal() > 0))
            if definite:
                if self._pardiso_factor(U, cache, indefinite=False):
                    return
                definite = self._pardiso_error  # another failure than a pivot ≤ 0: SuperLU, whatever asked
            if not definite and require_definite:
                raise NotPositiveDefinite("the matrix is not positive definite (PARDISO Cholesky)")
            if not definite and _pardiso_indefinite_on() and np.all(U.indptr[:-1] < U.indptr[1:]) \
                    and np.array_equal(U.indices[U.indptr[:-1]], np.arange(U.shape[0])) \
                    and self._pardiso_factor(U, cache, indefinite=True):
                self._U = U  # its solves check their backward error on the whole matrix, U + Uᵀ − diag(U)
                return
        elif self.backend == "cholmod" and _cholmod_analyze is not None and symmetric:
            modes = ("supernodal", "simplicial") if cholmod_mode() == "supernodal" else ("simplicial",)
            for mode in modes:
                try:
                    self._chol = _analysis(A, mode, cache).cholesky(A)  # a copy: stays valid after later ones
                    self.factorisation = mode
                    if mode == "simplicial":  # LDLᵀ without pivoting: its solves check their backward error
                        if require_definite and not np.all(self._chol.D() > 0):
                            raise NotPositiveDefinite("the matrix is not positive definite (LDLᵀ)")
                        self._norm_A = float(abs(self._matrix()).sum(axis=0).max())  # = ‖A‖∞ for symmetric A
                    return
                except CholmodNotPositiveDefiniteError:
                    # supernodal LLᵀ: not positive definite (LDLᵀ next); simplicial LDLᵀ: a zero pivot
                    if require_definite:
                        raise NotPositiveDefinite(f"the matrix is not positive definite ({mode} Cholesky)") from None
                    continue
        self._superlu()

    #: Factorisation used: "supernodal" (PARDISO's or CHOLMOD's LLᵀ), "simplicial" (CHOLMOD's LDLᵀ),
    #: "indefinite" (PARDISO's LDLᵀ with Bunch–Kaufman pivoting) or "" (SuperLU).
    factorisation: str = ""
    _pardiso_error = False  # PARDISO failed for another reason than a pivot ≤ 0

    def _pardiso_factor(self, U, cache: dict | None, indefinite: bool) -> bool:
        """Factorise the upper triangle ``U`` with a pool's solver (LLᵀ, or ``indefinite`` LDLᵀ); False: it failed."""
        solver, pool = _pardiso_solver(U, cache, indefinite)
        try:
            solver.refactor(U.data)
        except RuntimeError as exc:  # "zero pivot": the LLᵀ met a pivot ≤ 0
            pool.append(solver)  # a failed numeric factorisation leaves the analysis usable
            self._pardiso_error = "pivot" not in str(exc)
            return False
        self._pardiso = solver
        self.factorisation = "indefinite" if indefinite else "supernodal"
        weakref.finalize(self, pool.append, solver)  # back to the pool when this one is dropped
        return True

    def _matrix(self):
        """The whole matrix (CSC), formed from its lower triangle on first use where only that was given."""
        if self._triangle:
            A = self._A
            self._A = (A + A.T - sp.diags(A.diagonal())).tocsc()
            self._triangle = False
        return self._A

    def _superlu(self):
        self.backend = "superlu"
        self.factorisation = ""
        self._chol = None
        self._pardiso = None
        if self._symmetric:
            self._lu = spla.splu(self._matrix(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01,
                                 options={"SymmetricMode": True})
        else:
            self._lu = spla.splu(self._A)

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._pardiso is not None:
            x = self._pardiso.solve(np.ascontiguousarray(b, dtype=np.float64))
            if self.factorisation == "supernodal":
                # LLᵀ of a positive definite matrix is backward stable (no pivoting needed): no check
                return x
            U = self._U
            if not hasattr(self, "_norm_A"):  # ‖A‖∞ of A = U + Uᵀ − diag(U): its row sums from U's rows and columns
                aU = abs(U)
                self._norm_A = float((np.asarray(aU.sum(axis=1)).ravel() + np.asarray(aU.sum(axis=0)).ravel()
                                      - np.abs(U.diagonal())).max())
            d = U.diagonal() if x.ndim == 1 else U.diagonal()[:, None]
            if _backward_stable(U @ x + U.T @ x - d * x, x, b, self._norm_A):
                return x
            self._superlu()  # restricted pivoting was not enough: factor again with SuperLU's
        elif self._chol is not None:
            x = self._chol(b)
            if self.factorisation == "supernodal":
                # LLᵀ of a positive definite matrix is backward stable (no pivoting needed): no check
                return x
            if _backward_stable(self._matrix() @ x, x, b, self._norm_A):
                return x
            self._superlu()  # unstable LDLᵀ (tiny pivot): factor again with pivoting
        return self._lu.solve(b)


def factorize(K, backend: str | None = None, symmetric: bool = True, cache: dict | None = None,
              require_definite: bool = False, triangle: bool = False) -> Factorization:
    """Factorise ``K`` with the fastest available backend (``symmetric=False``: SuperLU, partial pivoting).

    ``require_definite``, ``triangle``: see :class:`Factorization`.
    """
    return Factorization(K, backend, symmetric, cache, require_definite, triangle)
