"""The pieces of a distributed refined mesh, built for P = 1..4 ranks in one process (no MPI):
their union is the serially refined mesh (the same coordinates bit for bit, up to a
permutation of the nodes; the same triangles row for row; the same boundary rows with their
parts), shared nodes and edges carry the same ids on every piece, and the PETSc numbers the
ranks agree on are a bijection onto 0..n−1 with each rank's owned nodes one contiguous range.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactfem.case import load_case
from contactfem.discretize import build_mesh
from contactfem.distributed_mesh import coarse_partition, mesh_piece, petsc_numbers_of_pieces
from contactfem.errors import MeshError
from contactfem.mesh.refine import refine_uniform

CASES = Path(__file__).resolve().parent.parent / "cases"
#: A structured square, a graded quarter disk with a curved rim (midpoints projected onto
#: the circle) and a plate with a hole.
MESHES = ("square", "hertz_quarter", "hole")
REFINEMENTS = 2


@pytest.fixture(scope="module", params=MESHES)
def meshes(request):
    coarse = build_mesh(load_case(CASES / f"{request.param}.yaml"), refine=0)
    return coarse, refine_uniform(coarse, REFINEMENTS)


def _union(pieces, fine):
    """The nodes of all pieces by global id (checking that pieces agree on shared ids), and
    the map from global id to the serial mesh's node (by coordinates, which must match)."""
    n_points = int(pieces[0].global_counts[0])
    points = np.full((n_points, 2), np.nan)
    for piece in pieces:
        seen = ~np.isnan(points[piece.node_ids, 0])
        np.testing.assert_array_equal(points[piece.node_ids][seen], piece.points[seen])
        points[piece.node_ids] = piece.points
    assert n_points == fine.n_points and not np.isnan(points).any()
    mine, serial = np.lexsort(points.T[::-1]), np.lexsort(fine.points.T[::-1])
    np.testing.assert_array_equal(points[mine], fine.points[serial])  # bit for bit
    to_serial = np.empty(n_points, dtype=np.int64)
    to_serial[mine] = serial
    return to_serial


@pytest.mark.parametrize("ranks", [1, 2, 3, 4])
def test_the_pieces_make_up_the_serially_refined_mesh(meshes, ranks):
    coarse, fine = meshes
    pieces = [mesh_piece(coarse, REFINEMENTS, ranks, rank) for rank in range(ranks)]
    to_serial = _union(pieces, fine)
    triangles = np.full_like(fine.triangles, -1)
    boundary = np.full_like(fine.boundary_edges, -1)
    parts = np.full_like(fine.edge_parts, -1)
    curves = np.full_like(fine.edge_curves, -2)
    for piece in pieces:
        assert not (triangles[piece.triangle_ids] >= 0).any()  # each triangle on one piece
        triangles[piece.triangle_ids] = to_serial[piece.node_ids[piece.triangles]]
        boundary[piece.boundary_ids] = to_serial[piece.node_ids[piece.boundary_edges]]
        parts[piece.boundary_ids], curves[piece.boundary_ids] = piece.edge_parts, piece.edge_curves
    np.testing.assert_array_equal(triangles, fine.triangles)
    np.testing.assert_array_equal(boundary, fine.boundary_edges)
    np.testing.assert_array_equal(parts, fine.edge_parts)
    np.testing.assert_array_equal(curves, fine.edge_curves)
    assert sum(len(piece.triangles) for piece in pieces) == fine.n_triangles


@pytest.mark.parametrize("ranks", [2, 4])
def test_edges_ids_and_owners_agree_between_pieces(meshes, ranks):
    """Every side of every triangle is the local edge the piece says, global edge ids are a
    bijection onto the serial mesh's edges, and a shared node's owner is the lowest rank
    holding it."""
    coarse, fine = meshes
    pieces = [mesh_piece(coarse, REFINEMENTS, ranks, rank) for rank in range(ranks)]
    to_serial = _union(pieces, fine)
    n_edges = int(pieces[0].global_counts[1])
    assert n_edges == fine.topology.n_edges
    ends = np.full((n_edges, 2), -1)
    lowest = np.full(int(pieces[0].global_counts[0]), ranks)
    for piece in pieces:
        ids = piece.node_ids[piece.edges]
        assert (ids[:, 0] < ids[:, 1]).all()
        sides = piece.edges[piece.triangle_edges]  # (t, 3, 2)
        for k in range(3):
            np.testing.assert_array_equal(np.sort(sides[:, k], axis=1),
                                          np.sort(piece.triangles[:, [k, (k + 1) % 3]], axis=1))
        seen = ends[piece.edge_ids, 0] >= 0
        np.testing.assert_array_equal(ends[piece.edge_ids][seen], ids[seen])
        ends[piece.edge_ids] = ids
        np.minimum.at(lowest, piece.node_ids, piece.rank)
    serial_edges = np.sort(to_serial[ends], axis=1)
    assert len(np.unique(serial_edges, axis=0)) == n_edges
    np.testing.assert_array_equal(fine.topology.edge_index(serial_edges[:, 0], serial_edges[:, 1]) >= 0, True)
    for piece in pieces:
        np.testing.assert_array_equal(piece.node_owner, lowest[piece.node_ids])


@pytest.mark.parametrize("ranks", [1, 2, 3, 4])
def test_petsc_numbers_are_one_numbering_with_contiguous_ranges(meshes, ranks):
    coarse, fine = meshes
    pieces = [mesh_piece(coarse, REFINEMENTS, ranks, rank) for rank in range(ranks)]
    numbers = petsc_numbers_of_pieces(pieces)
    whole = np.full(fine.n_points, -1)
    first = 0
    for piece, piece_numbers in zip(pieces, numbers):
        seen = whole[piece.node_ids] >= 0
        np.testing.assert_array_equal(whole[piece.node_ids][seen], piece_numbers[seen])
        whole[piece.node_ids] = piece_numbers
        owned = np.sort(piece_numbers[piece.owned])
        np.testing.assert_array_equal(owned, first + np.arange(len(owned)))
        first += len(owned)
    np.testing.assert_array_equal(np.sort(whole), np.arange(fine.n_points))


def test_pieces_are_balanced_slabs():
    """The square's 2 048 coarse triangles split 4 ways: 512 each, so 4**R times that after R
    refinements, and each piece holds about a quarter of the nodes plus one cut line."""
    coarse = build_mesh(load_case(CASES / "square.yaml"), refine=0)
    owner = coarse_partition(coarse, 4)
    assert np.bincount(owner).tolist() == [512] * 4
    pieces = [mesh_piece(coarse, REFINEMENTS, 4, rank) for rank in range(4)]
    assert [len(piece.triangles) for piece in pieces] == [512 * 4**REFINEMENTS] * 4
    side = 32 * 2**REFINEMENTS + 1  # nodes along a side of the fine square
    assert max(piece.n_points for piece in pieces) <= side * (side - 1) // 4 + 2 * side


def test_more_ranks_than_coarse_triangles_are_refused():
    coarse = build_mesh(load_case(CASES / "square.yaml"), refine=0)
    with pytest.raises(MeshError, match="fewer than the 4096 ranks"):
        coarse_partition(coarse, 4096)
