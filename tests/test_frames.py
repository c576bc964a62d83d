"""The kernel's rotated system: QᵀKQ built in K's own 2x2 node blocks equals the product."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import shipped_case

from contactfem.discretize.frames import _frames, _rotated_in_blocks
from contactfem.methods import get_method
from contactfem.solve import prepare


def _rotation(n_dof: int, nodes: np.ndarray, frames: np.ndarray) -> sp.csr_matrix:
    """Q: identity but the 2x2 blocks ``frames`` of ``nodes``."""
    rows = np.concatenate([2 * nodes, 2 * nodes, 2 * nodes + 1, 2 * nodes + 1])
    cols = np.concatenate([2 * nodes, 2 * nodes + 1, 2 * nodes, 2 * nodes + 1])
    values = np.concatenate([frames[:, 0, 0], frames[:, 0, 1], frames[:, 1, 0], frames[:, 1, 1]])
    rest = np.setdiff1d(np.arange(n_dof), np.concatenate([2 * nodes, 2 * nodes + 1]))
    return sp.csr_matrix((np.concatenate([values, np.ones(len(rest))]),
                          (np.concatenate([rows, rest]), np.concatenate([cols, rest]))), shape=(n_dof, n_dof))


@pytest.mark.parametrize("name", ["square", "hertz", "hertz_quarter", "punch", "flat_punch", "hole", "rough"])
def test_block_rotation_of_every_shipped_case_is_the_product(name):
    """On each shipped case's mesh, rotating K's blocks in place gives QᵀKQ to round-off
    (1e-14 of K's largest entry), in K's pattern, K itself untouched."""
    problem = prepare(shipped_case(name))
    stiffness = problem.stiffness
    before = stiffness.data.copy()
    supported = np.zeros(stiffness.shape[0], dtype=bool)
    supported[problem.dirichlet_dofs] = True
    frames = _frames(problem, supported)
    blocks = np.stack([frames.a, frames.b], axis=2)
    rotated = _rotated_in_blocks(stiffness, frames.nodes, blocks)
    assert rotated is not None
    q = _rotation(stiffness.shape[0], frames.nodes, blocks)
    expected = (q.T @ stiffness @ q).toarray() if stiffness.shape[0] < 6000 else None
    if expected is None:  # compare entry by entry on the stored pattern
        product = (q.T @ stiffness @ q).tocsr()
        expected_entries = np.asarray(product[np.repeat(np.arange(stiffness.shape[0]), np.diff(stiffness.indptr)),
                                              stiffness.indices]).ravel()
        assert product.count_nonzero() <= stiffness.nnz
        assert np.abs(rotated.data - expected_entries).max() <= 1e-14 * np.abs(stiffness.data).max()
    else:
        assert np.abs(rotated.toarray() - expected).max() <= 1e-14 * np.abs(stiffness.data).max()
    np.testing.assert_array_equal(stiffness.data, before)
    assert rotated.nnz == stiffness.nnz


def test_random_frames_rotate_as_the_product():
    """Arbitrary (not orthogonal) 2x2 frames on a random subset of nodes: still QᵀKQ."""
    problem = prepare(shipped_case("hole"))
    stiffness = problem.stiffness
    rng = np.random.default_rng(11)
    n_nodes = stiffness.shape[0] // 2
    nodes = np.sort(rng.choice(n_nodes, n_nodes // 3, replace=False))
    frames = rng.normal(size=(len(nodes), 2, 2))
    rotated = _rotated_in_blocks(stiffness, nodes, frames)
    q = _rotation(stiffness.shape[0], nodes, frames)
    expected = (q.T @ stiffness @ q).toarray()
    assert np.abs(rotated.toarray() - expected).max() <= 1e-13 * np.abs(expected).max()


def test_a_matrix_not_in_node_blocks_takes_the_product_path():
    """Rows whose columns are not in pairs 2j, 2j+1 (or whose two rows of a node differ) are
    not rotated in place: None, and the product path serves."""
    matrix = sp.csr_matrix(np.array([[2.0, 0, 1, 0], [0, 2, 0, 0], [1, 0, 2, 0], [0, 0, 0, 2]]))
    assert _rotated_in_blocks(matrix, np.array([0]), np.eye(2)[None]) is None
    odd = sp.csr_matrix(np.diag([1.0, 2.0, 3.0]))
    assert _rotated_in_blocks(odd, np.array([0]), np.eye(2)[None]) is None


@pytest.mark.parametrize("name", ["hertz_platen", "hertz_quarter", "rough"])
def test_the_kernel_stiffness_is_rotation_transposed_times_k_times_rotation(name):
    """Whichever path builds it (a platen's Q is not block-diagonal: its nodes follow the
    first node's advance), the kernel's stiffness is RᵀKR with R the system's own map from
    rotated unknowns to mesh displacements, to round-off."""
    problem = prepare(shipped_case(name))
    reduced = problem.contact_system(get_method("positive"))
    expected = (reduced.rotation.T @ problem.stiffness @ reduced.rotation).tocsr()
    difference = abs(reduced.system.stiffness - expected)
    assert difference.max() <= 1e-14 * np.abs(problem.stiffness.data).max()
