"""Sparse assembly into a fixed pattern with Dirichlet dofs eliminated.

The pattern (CSR over the free dofs) and the map from every element/face
matrix entry to its CSR slot are computed once per mesh topology and
boundary condition (NumPy); each assembly is then one sparse product with the
0/1 scatter matrix of :meth:`SparsityPattern.scatter`.

Local matrices come in one of two layouts (:func:`local_entries`):

* ``"dense"``: the (m, m) matrix raveled row-major (or, with ``triangle``, its raveled
  upper triangle, ``np.triu_indices``, row-major);
* ``"node_blocks"``: a symmetric matrix over ``m = 3n`` node-major dofs as the six
  (n, n) blocks of its component pairs ``(i, k)``, ``i <= k`` (:data:`NODE_BLOCK_PAIRS`;
  block ``n`` holds ``K[3a + i, 3b + k]`` at ``[n, a, b]``), raveled: what the element
  kernels return, so that no kernel interleaves components or picks a triangle. The
  scatter map does both: an entry of an off-diagonal block stands for two matrix
  entries (itself and its transpose), one of a diagonal block for one.

A symmetric matrix can be assembled as its upper triangle only (``triangle=True``):
each local entry then goes to the slot of its global pair in upper orientation, and
the entries of a local pair's lower half are dropped (or, ``"dense"``, never given). That
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
    keep : indices into the concatenated, raveled local matrix data (in their layouts, see
        :func:`local_entries`) of the entries that land on free rows and columns (a value may
        appear twice: a ``"node_blocks"`` entry and its transpose).
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


#: The component pairs ``(i, k)`` of the six blocks of the ``"node_blocks"`` layout, in order.
NODE_BLOCK_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def node_blocks_matrix(Kb):
    """The (3n, 3n) symmetric matrix (dofs node-major, ``3a + i``) of its six node blocks ``Kb`` (6, n, n).

    For checks and small dense uses (the solvers assemble the blocks sparsely).
    """
    Kb = np.asarray(Kb)
    block = {}
    for n, (i, k) in enumerate(NODE_BLOCK_PAIRS):
        block[k, i], block[i, k] = Kb[n].T, Kb[n]  # a diagonal block (i == k) as given, as assembled
    K = np.stack([np.stack([block[i, k] for k in range(3)], axis=-1) for i in range(3)], axis=1)  # (a, i, b, k)
    return K.reshape(3 * Kb.shape[-1], 3 * Kb.shape[-1])


def local_entries(m: int, layout: str = "dense", triangle: bool = False):
    """Where the raveled values of one local matrix of ``layout`` go in the (m, m) matrix.

    Returns
    -------
    source, row, col : int arrays of equal length
        Value ``source[t]`` of the raveled local data is the matrix entry ``(row[t], col[t])``. With
        ``triangle`` every unordered pair of local dofs appears once (a value standing for an entry
        and its transpose); else every entry once (a ``"node_blocks"`` value of an off-diagonal
        block twice: as itself and as its transpose).
    size : int
        The length of one local matrix's raveled data.
    """
    if layout == "dense":
        if triangle:
            row, col = np.triu_indices(m)
        else:
            row, col = np.repeat(np.arange(m), m), np.tile(np.arange(m), m)
        return np.arange(row.size), row, col, row.size
    if layout != "node_blocks" or m % 3:
        raise ValueError(f"unknown local matrix layout {layout!r} for {m} dofs")
    n = m // 3
    a, b = np.repeat(np.arange(n), n), np.tile(np.arange(n), n)
    source, row, col = [], [], []
    for blk, (i, k) in enumerate(NODE_BLOCK_PAIRS):
        src = blk * n * n + np.arange(n * n)
        r, c = 3 * a + i, 3 * b + k
        if i == k:
            keep = a <= b if triangle else np.ones(n * n, bool)  # (a, b) and (b, a) are one pair
            source.append(src[keep]), row.append(r[keep]), col.append(c[keep])
        else:
            source.append(src), row.append(r), col.append(c)
            if not triangle:  # the transposed block (k, i)
                source.append(src), row.append(c), col.append(r)
    return np.concatenate(source), np.concatenate(row), np.concatenate(col), len(NODE_BLOCK_PAIRS) * n * n


def build_pattern(n_dofs: int, fixed: np.ndarray, blocks: list, triangle: bool = False) -> SparsityPattern:
    """Pattern of the stiffness assembled from dof ``blocks``.

    Each block group is a dof array (n_b, m_b) of local matrices in the ``"dense"`` layout, or a
    pair ``(dofs, layout)`` (see :func:`local_entries`). ``triangle``: the upper triangle of a
    symmetric stiffness (see the module docstring).
    """
    free_mask = np.ones(n_dofs, bool)
    free_mask[np.asarray(fixed, dtype=np.int64)] = False
    free = np.flatnonzero(free_mask)
    g2f = -np.ones(n_dofs, np.int64)
    g2f[free] = np.arange(free.size)
    rows, cols, off, sources = [], [], [], []
    start = 0
    for group in blocks:
        d, layout = group if isinstance(group, tuple) else (group, "dense")
        src, i, j, size = local_entries(d.shape[1], layout, triangle)
        rows.append(d[:, i].ravel())
        cols.append(d[:, j].ravel())
        off.append(np.broadcast_to(i != j, (d.shape[0], i.size)).ravel())
        sources.append((start + size * np.arange(d.shape[0])[:, None] + src).ravel())
        start += size * d.shape[0]
    r = g2f[np.concatenate(rows)]
    c = g2f[np.concatenate(cols)]
    if triangle:
        r, c = np.minimum(r, c), np.maximum(r, c)
    kept = np.flatnonzero((r >= 0) & (c >= 0))
    keep = np.concatenate(sources)[kept]
    key = r[kept] * free.size + c[kept]
    uniq, dest = np.unique(key, return_inverse=True)
    ur = uniq // free.size
    indptr = np.zeros(free.size + 1, np.int64)
    np.cumsum(np.bincount(ur, minlength=free.size), out=indptr[1:])
    weights = None
    if triangle:
        weights = np.where((r[kept] == c[kept]) & np.concatenate(off)[kept], 2.0, 1.0)
    return SparsityPattern(n_dofs, free, indptr, (uniq % free.size).astype(np.int32), keep, dest.astype(np.int64),
                           triangle, weights)
