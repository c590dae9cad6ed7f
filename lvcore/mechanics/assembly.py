"""Sparse assembly into a fixed pattern with Dirichlet dofs eliminated.

The pattern (CSR over the free dofs) and the map from every element/face
matrix entry to its CSR slot are computed once per mesh topology and
boundary condition (NumPy); each assembly is then one sparse product with the
0/1 scatter matrix of :meth:`SparsityPattern.scatter`.

A symmetric matrix can be assembled as its upper triangle only (``triangle=True``):
the local matrices then contribute their upper triangles (``np.triu_indices``,
row-major), each entry to the slot of its global pair in upper orientation. That
is what CHOLMOD reads of a symmetric matrix (the CSR upper triangle is the CSC
lower one), from half the entries.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp


def block_dofs(conn: np.ndarray) -> np.ndarray:
    """(n_blocks, n_local) node connectivity -> (n_blocks, 3 n_local) dof numbers (node-major)."""
    return (3 * conn[:, :, None] + np.arange(3)).reshape(conn.shape[0], -1)


@dataclass(frozen=True, eq=False)
class SparsityPattern:
    """CSR pattern over the free dofs and the scatter map of local matrix entries.

    Attributes
    ----------
    n_dofs, free : total dofs and the sorted free dof numbers.
    indptr, indices : CSR structure (free x free).
    keep : indices into the concatenated, raveled local matrices of the entries
        that land on free rows and columns (with ``triangle``: their raveled upper triangles).
    dest : CSR slot of each kept entry.
    cache : scratch space for solvers (e.g. a reusable symbolic factorisation).
    """

    n_dofs: int
    free: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    keep: np.ndarray
    dest: np.ndarray
    #: Only the upper triangle (row <= column) of a symmetric matrix is stored.
    triangle: bool = False
    #: Multiplicity of each kept entry in the sum (None: all 1). With ``triangle``, an off-diagonal
    #: local entry landing on a diagonal slot (a node repeated in an element, e.g. a collapsed
    #: apex) stands for itself and its transpose: 2.
    weights: np.ndarray | None = None
    cache: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def n_free(self) -> int:
        return int(self.free.size)

    @property
    def nnz(self) -> int:
        return int(self.indices.size)

    def scatter(self, start: int, stop: int) -> sp.csr_matrix:
        """The (nnz, stop - start) 0/1 matrix that sums the concatenated, raveled local matrix entries
        ``start:stop`` into their CSR slots (``scatter(a, b) @ values[a:b]``; built once, kept in :attr:`cache`)."""
        key = ("scatter", int(start), int(stop))
        S = self.cache.get(key)
        if S is None:
            sel = (self.keep >= start) & (self.keep < stop)
            w = np.ones(int(sel.sum())) if self.weights is None else self.weights[sel]
            S = sp.csr_matrix((w, (self.dest[sel], self.keep[sel] - start)),
                              shape=(self.nnz, stop - start))
            self.cache[key] = S
        return S

    def matrix(self, data) -> sp.csr_matrix:
        """The free-dof CSR matrix with slot values ``data``."""
        n = self.n_free
        return sp.csr_matrix((np.asarray(data), self.indices, self.indptr), shape=(n, n))


def upper_triangle(M):
    """The raveled upper triangles of square matrices (..., m, m), in the order ``triangle`` patterns expect
    (``np.triu_indices``, row-major); NumPy or JAX arrays."""
    i, j = np.triu_indices(M.shape[-1])
    return M[..., i, j]


def build_pattern(n_dofs: int, fixed: np.ndarray, blocks: list[np.ndarray], triangle: bool = False) -> SparsityPattern:
    """Pattern of the stiffness assembled from dof ``blocks`` (each (n_b, m_b)).

    ``triangle``: the upper triangle of a symmetric stiffness, from the blocks' raveled upper
    triangles (see the module docstring).
    """
    free_mask = np.ones(n_dofs, bool)
    free_mask[np.asarray(fixed, dtype=np.int64)] = False
    free = np.flatnonzero(free_mask)
    g2f = -np.ones(n_dofs, np.int64)
    g2f[free] = np.arange(free.size)
    rows, cols, off = [], [], []
    for d in blocks:
        m = d.shape[1]
        if triangle:
            i, j = np.triu_indices(m)
            rows.append(d[:, i].ravel())
            cols.append(d[:, j].ravel())
            off.append(np.broadcast_to(i != j, (d.shape[0], i.size)).ravel())
        else:
            rows.append(np.repeat(d, m, axis=1).ravel())
            cols.append(np.tile(d, (1, m)).ravel())
    r = g2f[np.concatenate(rows)]
    c = g2f[np.concatenate(cols)]
    if triangle:
        r, c = np.minimum(r, c), np.maximum(r, c)
    keep = np.flatnonzero((r >= 0) & (c >= 0))
    key = r[keep] * free.size + c[keep]
    uniq, dest = np.unique(key, return_inverse=True)
    ur = uniq // free.size
    indptr = np.zeros(free.size + 1, np.int64)
    np.cumsum(np.bincount(ur, minlength=free.size), out=indptr[1:])
    weights = None
    if triangle:
        weights = np.where((r[keep] == c[keep]) & np.concatenate(off)[keep], 2.0, 1.0)
    return SparsityPattern(n_dofs, free, indptr, (uniq % free.size).astype(np.int32), keep, dest.astype(np.int64),
                           triangle, weights)
