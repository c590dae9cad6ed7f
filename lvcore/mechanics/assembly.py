"""Sparse assembly into a fixed pattern with Dirichlet dofs eliminated.

The pattern (CSR over the free dofs) and the map from every element/face
matrix entry to its CSR slot are computed once per mesh topology and
boundary condition (NumPy); each assembly is then one sparse product with the
0/1 scatter matrix of :meth:`SparsityPattern.scatter`.
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
        that land on free rows and columns.
    dest : CSR slot of each kept entry.
    cache : scratch space for solvers (e.g. a reusable symbolic factorisation).
    """

    n_dofs: int
    free: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    keep: np.ndarray
    dest: np.ndarray
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
            S = sp.csr_matrix((np.ones(int(sel.sum())), (self.dest[sel], self.keep[sel] - start)),
                              shape=(self.nnz, stop - start))
            self.cache[key] = S
        return S

    def matrix(self, data) -> sp.csr_matrix:
        """The free-dof CSR matrix with slot values ``data``."""
        n = self.n_free
        return sp.csr_matrix((np.asarray(data), self.indices, self.indptr), shape=(n, n))


def build_pattern(n_dofs: int, fixed: np.ndarray, blocks: list[np.ndarray]) -> SparsityPattern:
    """Pattern of the stiffness assembled from dof ``blocks`` (each (n_b, m_b))."""
    free_mask = np.ones(n_dofs, bool)
    free_mask[np.asarray(fixed, dtype=np.int64)] = False
    free = np.flatnonzero(free_mask)
    g2f = -np.ones(n_dofs, np.int64)
    g2f[free] = np.arange(free.size)
    rows, cols = [], []
    for d in blocks:
        m = d.shape[1]
        rows.append(np.repeat(d, m, axis=1).ravel())
        cols.append(np.tile(d, (1, m)).ravel())
    r = g2f[np.concatenate(rows)]
    c = g2f[np.concatenate(cols)]
    keep = np.flatnonzero((r >= 0) & (c >= 0))
    key = r[keep] * free.size + c[keep]
    uniq, dest = np.unique(key, return_inverse=True)
    ur = uniq // free.size
    indptr = np.zeros(free.size + 1, np.int64)
    np.cumsum(np.bincount(ur, minlength=free.size), out=indptr[1:])
    return SparsityPattern(n_dofs, free, indptr, (uniq % free.size).astype(np.int32), keep, dest.astype(np.int64))
