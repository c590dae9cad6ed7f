"""Sparse assembly: the element kernels' six node blocks give the same matrix as the dense element matrices."""
import numpy as np
import pytest

from lvcore.mechanics.assembly import (NODE_BLOCK_PAIRS, block_dofs, build_pattern, local_entries,
                                       node_blocks_matrix, upper_triangle)


def _symmetric_blocks(rng, n_el, n):
    """Random symmetric (3n, 3n) element matrices and their node blocks (6, n, n)."""
    M = rng.normal(size=(n_el, 3 * n, 3 * n))
    M = M + M.transpose(0, 2, 1)
    K4 = M.reshape(n_el, n, 3, n, 3)
    blocks = np.stack([K4[:, :, i, :, k] for i, k in NODE_BLOCK_PAIRS], axis=1)  # (n_el, 6, n, n)
    return M, blocks


def _assemble(pattern, values):
    return pattern.matrix(pattern.scatter(0, values.size) @ values.ravel()).toarray()


@pytest.mark.parametrize("triangle", [False, True])
def test_node_blocks_assemble_like_the_dense_matrices(triangle):
    """Two 8-node elements sharing a face, one with a repeated node (a collapsed edge, as at the LV apex:
    off-diagonal local entries on a diagonal slot), and fixed dofs."""
    rng = np.random.default_rng(3)
    conn = np.array([[0, 1, 2, 3, 4, 5, 6, 7], [4, 5, 6, 7, 8, 9, 10, 10]])
    dofs = block_dofs(conn)
    fixed = np.array([0, 1, 2, 31])
    M, blocks = _symmetric_blocks(rng, 2, 8)
    np.testing.assert_array_equal(node_blocks_matrix(blocks[1]), M[1])
    dense = build_pattern(33, fixed, [dofs], triangle)
    tiled = build_pattern(33, fixed, [(dofs, "node_blocks")], triangle)
    K_dense = _assemble(dense, upper_triangle(M) if triangle else M)
    K_tiled = _assemble(tiled, blocks)
    assert np.abs(K_dense).max() > 1.0
    np.testing.assert_allclose(K_tiled, K_dense, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(tiled.indices, dense.indices)
    if triangle:  # the upper triangle of the whole matrix
        full = _assemble(build_pattern(33, fixed, [(dofs, "node_blocks")], False), blocks)
        np.testing.assert_allclose(K_tiled, np.triu(full), rtol=0, atol=1e-12)


def test_local_entries_cover_each_entry_or_pair_once():
    for triangle in (False, True):
        src, row, col, size = local_entries(12, "node_blocks", triangle)
        assert size == 6 * 16 and src.max() < size
        pairs = set(zip(np.minimum(row, col), np.maximum(row, col))) if triangle else set(zip(row, col))
        assert len(pairs) == row.size == (12 * 13 // 2 if triangle else 144)
    with pytest.raises(ValueError, match="layout"):
        local_entries(10, "node_blocks")
