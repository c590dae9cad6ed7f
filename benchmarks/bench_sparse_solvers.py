"""Sparse symmetric solvers side by side on the simulator's own tangents.

Usage::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
        python benchmarks/bench_sparse_solvers.py [--repeats 7] [--cases default land2]

Solves the default LV (8 mmHg) and Land 2015 problem 2 (6 × (4,2,2,4) × 1, 5 Gauss points, the row-42
mesh) once, recording every tangent the Newton solver factorises (the upper triangle, CSR, as the
symmetric path assembles it) with the right-hand side of its first solve. Then, per backend found in
this environment, each tangent is factorised and solved ``--repeats`` times, the backends taking turns
within each repeat (so a drift of the shared machine's load hits all alike); the symbolic analysis is
done once per sparsity pattern beforehand, as in the simulator. Prints per case and backend the median
(over repeats) of the summed factor + solve wall time over all tangents, the CPU time per tangent
(what a loaded shared machine distorts least), and the largest
relative difference of the solutions from SuperLU's (‖x − x_SuperLU‖∞ / ‖x_SuperLU‖∞).

Backends (each skipped if its package is missing):

* ``superlu``: SciPy's SuperLU as the simulator's fallback uses it (symmetric mode, MMD on AᵀA+A).
* ``cholmod-sksparse``: scikit-sparse's CHOLMOD (the apt build: libsuitesparse-dev + scikit-sparse
  0.4.16), supernodal LLᵀ with the simulator's ordering rule, system BLAS.
* ``cholmod-cvxopt``: CVXOPT's bundled CHOLMOD (its PyPI wheel carries SuiteSparse and OpenBLAS),
  supernodal LLᵀ, CHOLMOD's default ordering. Not in the same process as ``cholmod-sksparse`` (two
  CHOLMOD builds in one process crash): run it alone with ``--backends superlu cholmod-cvxopt``.
* ``pardiso``: oneMKL PARDISO through py-mkl-pardiso (MKL linked into the wheel), symmetric
  positive definite type, symbolic reused (numeric refactorisation only).
* ``cholespy``: cholespy (bundled CHOLMOD, reference BLAS); it analyses and factorises together.
* ``qdldl``: QDLDL (LDLᵀ without pivoting, no BLAS), ``update`` reuses the symbolic analysis.
* ``mumps``: MUMPS through python-mumps (symmetric), analysis once, numeric factorisation per tangent
  (the only python-mumps wheel on PyPI for Python 3.11, 0.0.2, is built against NumPy 1 and fails to load).

Then (``--whole N``, default 4) whole solves of each case, the simulator's backend switched by
``$LVCORE_SPARSE_SOLVER`` between the solves (backends taking turns, each solve a new case: the
per-process cache of prepared cases cleared), median wall and CPU seconds of this process per solve:
CPU time is what a loaded shared machine distorts least.

The default solve, the campaign and Land problem 2 end to end are also measured by ``bench_simulator.py``,
``bench_campaign.py`` and ``land2015.py``, which state the backend the simulator used
(:func:`lvcore.mechanics.linear.default_backend`).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402


def record(case) -> list[tuple[sp.csr_matrix, np.ndarray]]:
    """(upper-triangle CSR tangent, first right-hand side) of every factorisation in one solve of ``case``."""
    from lvcore.mechanics import newton
    from lvcore.mechanics import simulate as sim

    out, orig = [], newton.factorize

    class _Rec:
        def __init__(self, fac, K, triangle):
            self._fac, self._K, self._tri, self._done = fac, K, triangle, False

        def solve(self, b):
            if not self._done:
                K = self._K if self._tri else sp.triu(self._K, format="csr")
                out.append((sp.csr_matrix(K, copy=True), np.array(b, copy=True)))
                self._done = True
            return self._fac.solve(b)

    def factorize(K, *a, **kw):
        return _Rec(orig(K, *a, **kw), K.copy(), kw.get("triangle", False))

    newton.factorize = factorize
    try:
        sim.simulate(case)
    finally:
        newton.factorize = orig
    return out


def _definite(U):
    """A positive definite (diagonally dominant) matrix with ``U``'s upper-triangle pattern, for symbolic analyses."""
    B = sp.csr_matrix((-np.ones_like(U.data), U.indices, U.indptr), shape=U.shape)
    d = np.asarray(abs(B).sum(axis=1)).ravel() + np.asarray(abs(B).sum(axis=0)).ravel() + 1.0
    B = B.tolil()
    B.setdiag(d)
    return B.tocsr()


def _full_csc(U):
    """The whole symmetric matrix (CSC) from its upper triangle (CSR)."""
    return (U + U.T - sp.diags(U.diagonal())).tocsc()


# Each backend: prepare(U) -> state (symbolic analysis, once per pattern); run(state, U, b) -> x.

def _superlu():
    def run(_, U, b):
        return spla.splu(_full_csc(U), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01,
                         options={"SymmetricMode": True}).solve(b)
    return (lambda U: None), run


def _cholmod_sksparse():
    from sksparse.cholmod import analyze  # noqa: F401

    from lvcore.mechanics import linear

    def prepare(U):  # CSR upper read as CSC: the lower triangle
        return linear._analysis(sp.csc_matrix(_definite(U).T), "supernodal", None)

    def run(f, U, b):
        L = sp.csc_matrix((U.data, U.indices, U.indptr), shape=U.shape)
        return f.cholesky(L)(b)
    return prepare, run


def _cholmod_cvxopt():
    from cvxopt import cholmod, matrix, spmatrix

    def _lower(U):
        n = U.shape[0]
        cols = np.repeat(np.arange(n), np.diff(U.indptr))  # CSR upper rows = CSC lower columns
        return spmatrix(matrix(U.data), matrix(U.indices.astype(np.int64)), matrix(cols.astype(np.int64)),
                        U.shape), cols

    def prepare(U):
        A, _ = _lower(U)
        cholmod.options["supernodal"] = 2
        return cholmod.symbolic(A)

    def run(F, U, b):
        A, _ = _lower(U)
        cholmod.options["supernodal"] = 2
        cholmod.numeric(A, F)
        x = matrix(b)
        cholmod.solve(F, x)
        return np.asarray(x).ravel()
    return prepare, run


def _pardiso():
    import pymklpardiso as pm

    def prepare(U):
        return pm.PardisoSolver(_definite(U), pm.MTYPE_REAL_SYM_POSDEF)

    def run(s, U, b):
        s.refactor(U.data)
        return s.solve(b)
    return prepare, run


def _cholespy():
    from cholespy import CholeskySolverD, MatrixType

    def run(_, U, b):
        L = sp.csc_matrix((U.data, U.indices, U.indptr), shape=U.shape)
        s = CholeskySolverD(U.shape[0], L.indptr.astype(np.int32), L.indices.astype(np.int32), L.data,
                            MatrixType.CSC)
        x = np.zeros_like(b)
        s.solve(b, x)
        return x
    return (lambda U: None), run


def _qdldl():
    import qdldl

    def prepare(U):
        return qdldl.Solver(_definite(U).tocsc(), upper=True)  # the upper triangle as CSC

    def run(s, U, b):
        s.update(U.tocsc(), upper=True)
        return s.solve(b)
    return prepare, run


def _mumps():
    import mumps

    def prepare(U):
        ctx = mumps.Context()
        ctx.set_matrix(sp.coo_matrix(U), symmetric=True)
        ctx.analyze()
        return ctx

    def run(ctx, U, b):
        ctx.set_matrix(sp.coo_matrix(U), symmetric=True)
        ctx.factor(reuse_analysis=True)
        return ctx.solve(b)
    return prepare, run


BACKENDS = {"superlu": _superlu, "cholmod-sksparse": _cholmod_sksparse, "cholmod-cvxopt": _cholmod_cvxopt,
            "pardiso": _pardiso, "cholespy": _cholespy, "qdldl": _qdldl, "mumps": _mumps}
#: Run by default (cvxopt's CHOLMOD cannot share a process with scikit-sparse's; mumps has no usable wheel).
DEFAULT_BACKENDS = ("superlu", "cholmod-sksparse", "pardiso", "cholespy", "qdldl")


def _load() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True).stdout.split("load average:")[1].strip()
    except Exception:  # pragma: no cover
        return "?"


def compare(tangents, names, repeats):
    """{backend: (median wall s of all tangents, median CPU ms per tangent, max relative difference from SuperLU,
    tangents sent to SuperLU)}."""
    ready = {}
    for name in names:
        try:
            prepare, run = BACKENDS[name]()
        except ImportError as exc:
            print(f"  {name}: not installed ({exc})", file=sys.stderr)
            continue
        states = [prepare(U) for U, _ in tangents[:1]]  # one sparsity pattern per case
        ready[name] = (states[0], run)
    ref = [BACKENDS["superlu"]()[1](None, U, b) for U, b in tangents]
    totals = {n: [] for n in ready}
    cpus = {n: [] for n in ready}
    diffs = {n: 0.0 for n in ready}
    fallbacks = {n: 0 for n in ready}
    for _ in range(repeats):
        for name, (state, run) in ready.items():
            t0, c0 = time.perf_counter(), time.process_time()
            xs = []
            for U, b in tangents:
                try:
                    xs.append(run(state, U, b))
                except Exception:  # not positive definite: the simulator's fallback, SuperLU (timed too)
                    fallbacks[name] += 1
                    xs.append(BACKENDS["superlu"]()[1](None, U, b))
            totals[name].append(time.perf_counter() - t0)
            cpus[name].append(time.process_time() - c0)
            for x, r in zip(xs, ref):
                diffs[name] = max(diffs[name], float(np.max(np.abs(np.asarray(x).ravel() - r)) / np.max(np.abs(r))))
    return {n: (statistics.median(t), 1e3 * statistics.median(cpus[n]) / len(tangents), diffs[n],
                fallbacks[n] // repeats) for n, t in totals.items()}


def whole_solves(case, names, repeats):
    """{backend: (median wall s, median CPU s)} of whole solves of ``case``, backends taking turns."""
    from lvcore.mechanics import linear
    from lvcore.mechanics import simulate as sim

    names = [n for n in names if n in linear.available_backends()]
    sim.simulate(case)  # compile
    wall, cpu = {n: [] for n in names}, {n: [] for n in names}
    old = os.environ.get(linear.BACKEND_ENV)
    try:
        for _ in range(repeats):
            for n in names:
                os.environ[linear.BACKEND_ENV] = n
                sim._PREPARED.clear()
                c0, w0 = time.process_time(), time.perf_counter()
                sim.simulate(case)
                wall[n].append(time.perf_counter() - w0)
                cpu[n].append(time.process_time() - c0)
    finally:
        os.environ.pop(linear.BACKEND_ENV, None)
        if old is not None:
            os.environ[linear.BACKEND_ENV] = old
    return {n: (statistics.median(wall[n]), statistics.median(cpu[n])) for n in names}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=7, help="timed rounds per backend (default: 7)")
    ap.add_argument("--cases", nargs="+", default=["default", "land2"], choices=["default", "land2"],
                    help="which problems' tangents (default: default land2)")
    ap.add_argument("--backends", nargs="+", default=list(DEFAULT_BACKENDS), choices=list(BACKENDS),
                    help=f"backends to compare, each skipped if not installed (default: {' '.join(DEFAULT_BACKENDS)})")
    ap.add_argument("--whole", type=int, default=4,
                    help="whole solves per backend, the simulator's backends taking turns (default: 4; 0: none)")
    args = ap.parse_args(argv)
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.linear import default_backend
    from lvcore.mechanics.verification import problem2_case

    cases = {"default": lambda: Case.default_lv(), "land2": lambda: Case.from_dict(problem2_case("6,4+2+2+4,1,5"))}
    print(f"simulator's own backend while recording: {default_backend()}; python {sys.version.split()[0]}")
    print("| case | dofs | tangents | backend | of which to SuperLU (indefinite) | factor + solve, all tangents "
          "(wall ms, median) | per tangent (CPU ms, median) | max rel. diff from SuperLU | load before |")
    print("|---|---|---|---|---|---|---|---|---|")
    for cname in args.cases:
        tangents = record(cases[cname]())
        load = _load()
        res = compare(tangents, args.backends, args.repeats)
        for name, (tot, per, diff, fb) in sorted(res.items(), key=lambda kv: kv[1][0]):
            print(f"| {cname} | {tangents[0][0].shape[0]} | {len(tangents)} | {name} | {fb} | {1e3 * tot:.1f} "
                  f"| {per:.2f} | {diff:.1e} | {load} |", flush=True)
    if args.whole:
        print("\n| case | simulator backend | whole solve, wall s (median) | whole solve, CPU s (median) | load before |")
        print("|---|---|---|---|---|")
        for cname in args.cases:
            load = _load()
            for name, (w, c) in whole_solves(cases[cname](), ("pardiso", "cholmod", "superlu"), args.whole).items():
                print(f"| {cname} | {name} | {w:.3f} | {c:.3f} | {load} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
