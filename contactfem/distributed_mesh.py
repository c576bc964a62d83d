"""Each rank's piece of a uniformly refined mesh, built without the whole fine mesh on any rank.

Every rank holds the coarse mesh (small, and deterministic: the same on every rank), splits
its triangles into contiguous blocks along the longer side of the body (one block per rank),
and refines only its own block. Global ids need no message:

- coarse nodes, edges and triangles keep their coarse indices (edges as the coarse
  :class:`~contactfem.mesh.topology.Topology` numbers them);
- at each refinement, with N nodes, E edges and T triangles before it, the midpoint of edge e
  is node N + e; the halves of edge e are edges 2e (at its lower-id end) and 2e + 1; the three
  edges inside triangle t are 2E + 3t + k (k = 0: m01–m12, 1: m12–m20, 2: m20–m01); the
  children of triangle t are 4t .. 4t + 3 in :func:`contactfem.mesh.refine.refine_uniform`'s
  order, and the halves of boundary row k are rows 2k, 2k + 1.

So ranks that share an edge name its midpoint alike, triangle ids and boundary rows are the
rows of the serially refined mesh, and node ids differ from the serial ones only by a
permutation of each level's new nodes (the coordinates are computed by the same operations,
so they agree bit for bit).

Each node is owned by the lowest rank touching it, found from its coarse ancestor (a coarse
node or edge touches the ranks of the coarse triangles around it; a node inside a coarse
triangle only that triangle's rank). :func:`petsc_numbers` numbers the owned nodes of each
rank in one contiguous range (an exclusive scan of the owned counts) and fetches the numbers
of the other nodes of the piece from their owners (one all-to-all of ids, one of numbers).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from contactfem.errors import MeshError
from contactfem.mesh.core import Circle, Mesh, coordinate_span

__all__ = ["MeshPiece", "coarse_partition", "mesh_piece", "petsc_numbers", "petsc_numbers_of_pieces"]


@dataclass(frozen=True, eq=False)
class MeshPiece:
    """One rank's triangles of the refined mesh, in local numbering, with their global ids.

    Attributes
    ----------
    rank, ranks : int
        This piece's rank and the number of pieces.
    points : (n, 2) float64
        The piece's nodes.
    node_ids : (n,) int64
        Each node's global id (see the module docstring).
    node_owner : (n,) int64
        The lowest rank whose piece holds the node.
    triangles : (t, 3) int64
        Local node indices, counter-clockwise.
    triangle_ids : (t,) int64
        Row of each triangle in the serially refined mesh.
    edges : (e, 2) int64
        The piece's edges, local node indices, the node of lower global id first.
    edge_ids : (e,) int64
        Global edge ids.
    edge_owner : (e,) int64
        The lowest rank whose piece holds the edge.
    triangle_edges : (t, 3) int64
        Local edge of each triangle side k (from its node k to node k + 1).
    boundary_edges : (b, 2) int64
        The piece's boundary edges of the body (local node indices, body on the left),
        ordered by ``boundary_ids``.
    boundary_ids : (b,) int64
        Row of each boundary edge in the serially refined mesh.
    boundary_edge_local : (b,) int64
        Local edge of each boundary edge.
    edge_parts, edge_curves : (b,) int64
        Part and circle (−1: straight) of each boundary edge.
    part_names : tuple of str
    curves : tuple of Circle
    global_counts : (3,) int64
        Nodes, edges and triangles of the whole refined mesh.
    major : int
        The coarse mesh's longer side (0: x, 1: y): the pieces are slabs across it, and each
        rank numbers its owned nodes along it (see :func:`petsc_numbers`).
    """

    rank: int
    ranks: int
    points: np.ndarray
    node_ids: np.ndarray
    node_owner: np.ndarray
    triangles: np.ndarray
    triangle_ids: np.ndarray
    edges: np.ndarray
    edge_ids: np.ndarray
    edge_owner: np.ndarray
    triangle_edges: np.ndarray
    boundary_edges: np.ndarray
    boundary_ids: np.ndarray
    boundary_edge_local: np.ndarray
    edge_parts: np.ndarray
    edge_curves: np.ndarray
    part_names: tuple[str, ...]
    curves: tuple[Circle, ...]
    global_counts: np.ndarray
    major: int = 0

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def owned(self) -> np.ndarray:
        """Local indices of the nodes this rank owns, increasing."""
        return np.flatnonzero(self.node_owner == self.rank)

    def as_mesh(self) -> Mesh:
        """The piece as a :class:`Mesh` of its own (its boundary rows being the body's boundary
        edges it holds, not the cut to the other pieces): for element-wise work on the piece."""
        return Mesh(points=self.points, triangles=self.triangles, boundary_edges=self.boundary_edges,
                    edge_parts=self.edge_parts, part_names=self.part_names, edge_curves=self.edge_curves,
                    curves=self.curves)


def coarse_partition(coarse: Mesh, ranks: int) -> np.ndarray:
    """The rank of each coarse triangle (t,): contiguous blocks of equal counts (±1) along the
    triangles' centroids sorted by the longer side of the bounding box (ties by the other
    coordinate), so that each block is a slab and its cut to the next is one line.

    Raises
    ------
    MeshError
        If there are fewer coarse triangles than ranks.
    """
    n_triangles = coarse.n_triangles
    if n_triangles < ranks:
        raise MeshError(f"the coarse mesh has {n_triangles} triangles, fewer than the {ranks} ranks to share them")
    centroids = coarse.points[coarse.triangles].mean(axis=1)
    major = _major_axis(coarse.points)
    order = np.lexsort((np.arange(n_triangles), centroids[:, 1 - major], centroids[:, major]))
    bounds = (n_triangles * np.arange(ranks + 1, dtype=np.int64)) // ranks
    owner = np.empty(n_triangles, dtype=np.int64)
    owner[order] = np.repeat(np.arange(ranks, dtype=np.int64), np.diff(bounds))
    return owner


def _major_axis(points: np.ndarray) -> int:
    """0 if the points span at least as far along x as along y, else 1."""
    extent = coordinate_span(points)
    return 0 if extent[0] >= extent[1] else 1


def mesh_piece(coarse: Mesh, times: int, ranks: int, rank: int) -> MeshPiece:
    """Rank ``rank``'s piece of ``refine_uniform(coarse, times)`` split ``ranks`` ways.

    Parameters
    ----------
    coarse : Mesh
        The coarse mesh, the same on every rank.
    times : int
        Refinements.
    ranks, rank : int
        Number of pieces and which one to build.

    Returns
    -------
    MeshPiece
        O(n / ranks) arrays: no rank holds the whole refined mesh.
    """
    piece = _coarse_piece(coarse, coarse_partition(coarse, ranks), ranks, rank)
    for _ in range(int(times)):
        piece = _refine_piece(piece)
    return piece


def _coarse_piece(coarse: Mesh, triangle_rank: np.ndarray, ranks: int, rank: int) -> MeshPiece:
    """The coarse triangles of ``rank`` with their nodes and edges, ids the coarse indices."""
    topology = coarse.topology
    n_triangles = coarse.n_triangles
    half_edge = np.asarray(topology.half_edge_edge, dtype=np.int64).reshape(n_triangles, 3)
    edges_all = np.asarray(topology.edges, dtype=np.int64)
    # The lowest rank around each coarse node and edge.
    node_owner_all = np.full(coarse.n_points, ranks, dtype=np.int64)
    np.minimum.at(node_owner_all, coarse.triangles.ravel(), np.repeat(triangle_rank, 3))
    edge_owner_all = np.full(len(edges_all), ranks, dtype=np.int64)
    np.minimum.at(edge_owner_all, half_edge.ravel(), np.repeat(triangle_rank, 3))

    mine = np.flatnonzero(triangle_rank == rank)
    node_ids = np.unique(coarse.triangles[mine])
    edge_ids = np.unique(half_edge[mine])
    triangles = np.searchsorted(node_ids, coarse.triangles[mine])
    boundary_rows = np.flatnonzero(triangle_rank[coarse.boundary_edge_triangles] == rank)
    bedges = coarse.boundary_edges[boundary_rows]
    bedge_global = topology.edge_index(bedges[:, 0], bedges[:, 1]).astype(np.int64)
    return MeshPiece(
        rank=rank, ranks=ranks, points=coarse.points[node_ids], node_ids=node_ids,
        node_owner=node_owner_all[node_ids], triangles=triangles, triangle_ids=mine.astype(np.int64),
        edges=np.searchsorted(node_ids, edges_all[edge_ids]), edge_ids=edge_ids,
        edge_owner=edge_owner_all[edge_ids], triangle_edges=np.searchsorted(edge_ids, half_edge[mine]),
        boundary_edges=np.searchsorted(node_ids, bedges), boundary_ids=boundary_rows.astype(np.int64),
        boundary_edge_local=np.searchsorted(edge_ids, bedge_global),
        edge_parts=coarse.edge_parts[boundary_rows], edge_curves=coarse.edge_curves[boundary_rows],
        part_names=coarse.part_names, curves=coarse.curves,
        global_counts=np.array([coarse.n_points, len(edges_all), n_triangles], dtype=np.int64),
        major=_major_axis(coarse.points))


def _refine_piece(piece: MeshPiece) -> MeshPiece:
    """One red refinement of the piece, global ids by the formulas of the module docstring."""
    n_nodes, n_edges, n_triangles = (int(count) for count in piece.global_counts)
    n, e, t = piece.n_points, len(piece.edges), len(piece.triangles)
    ends = piece.edges
    # As refine_uniform computes them, so that the coordinates agree bit for bit.
    points = np.concatenate([piece.points, 0.5 * (piece.points[ends[:, 0]] + piece.points[ends[:, 1]])])
    for index, circle in enumerate(piece.curves):
        nodes = n + piece.boundary_edge_local[piece.edge_curves == index]
        if nodes.size:
            points[nodes] = circle.project(points[nodes])

    def half(edge: np.ndarray, node: np.ndarray) -> np.ndarray:
        """Local index of the half of local ``edge`` that ends at local ``node``."""
        return 2 * edge + (ends[edge, 0] != node)

    middles = np.arange(e, dtype=np.int64)
    halves = np.stack([np.stack([ends[:, 0], n + middles], axis=1),
                       np.stack([ends[:, 1], n + middles], axis=1)], axis=1).reshape(-1, 2)
    tri, sides = piece.triangles, piece.triangle_edges
    mid = n + sides  # m01, m12, m20
    inner = np.stack([mid, mid[:, [1, 2, 0]]], axis=2)  # (t, 3, 2): k = 0 m01-m12, 1 m12-m20, 2 m20-m01
    inner_ids = 2 * n_edges + 3 * piece.triangle_ids[:, None] + np.arange(3)
    node_ids = np.concatenate([piece.node_ids, n_nodes + piece.edge_ids])
    swap = node_ids[inner[:, :, 0]] > node_ids[inner[:, :, 1]]
    inner[swap] = inner[swap][:, ::-1]
    edges = np.concatenate([halves, inner.reshape(-1, 2)])
    edge_ids = np.concatenate([(2 * piece.edge_ids[:, None] + np.arange(2)).ravel(), inner_ids.ravel()])
    edge_owner = np.concatenate([np.repeat(piece.edge_owner, 2), np.full(3 * t, piece.rank, dtype=np.int64)])

    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    m01, m12, m20 = mid[:, 0], mid[:, 1], mid[:, 2]
    triangles = np.stack([np.stack([v0, m01, m20], axis=1), np.stack([v1, m12, m01], axis=1),
                          np.stack([v2, m20, m12], axis=1), np.stack([m01, m12, m20], axis=1)], axis=1).reshape(-1, 3)
    i0, i1, i2 = (2 * e + 3 * np.arange(t, dtype=np.int64) + k for k in range(3))
    s01, s12, s20 = sides[:, 0], sides[:, 1], sides[:, 2]
    triangle_edges = np.stack([
        np.stack([half(s01, v0), i2, half(s20, v0)], axis=1),
        np.stack([half(s12, v1), i0, half(s01, v1)], axis=1),
        np.stack([half(s20, v2), i1, half(s12, v2)], axis=1),
        np.stack([i0, i1, i2], axis=1)], axis=1).reshape(-1, 3)

    bedges, blocal = piece.boundary_edges, piece.boundary_edge_local
    bmid = n + blocal
    boundary_edges = np.stack([np.stack([bedges[:, 0], bmid], axis=1), np.stack([bmid, bedges[:, 1]], axis=1)],
                              axis=1).reshape(-1, 2)
    boundary_edge_local = np.stack([half(blocal, bedges[:, 0]), half(blocal, bedges[:, 1])], axis=1).ravel()
    return replace(
        piece, points=points, node_ids=node_ids, node_owner=np.concatenate([piece.node_owner, piece.edge_owner]),
        triangles=triangles, triangle_ids=(4 * piece.triangle_ids[:, None] + np.arange(4)).ravel(),
        edges=edges, edge_ids=edge_ids, edge_owner=edge_owner, triangle_edges=triangle_edges,
        boundary_edges=boundary_edges, boundary_ids=(2 * piece.boundary_ids[:, None] + np.arange(2)).ravel(),
        boundary_edge_local=boundary_edge_local, edge_parts=np.repeat(piece.edge_parts, 2),
        edge_curves=np.repeat(piece.edge_curves, 2),
        global_counts=np.array([n_nodes + n_edges, 2 * n_edges + 3 * n_triangles, 4 * n_triangles], dtype=np.int64))


def _owned_numbers(piece: MeshPiece, offset: int) -> tuple[np.ndarray, np.ndarray]:
    """The owned nodes' global ids, sorted, and their PETSc node numbers: ``offset`` + their
    rank along the longer side (ties by the other coordinate), as the replicated mesh's
    :func:`contactfem.distributed_assembly.node_order` numbers them. MUMPS's ordering (PORD)
    depends on the numbering it is given: numbered by global id, the square at 2.1M unknowns
    had 5 % more factor entries."""
    owned = piece.owned
    points = piece.points[owned]
    along = np.lexsort((points[:, 1 - piece.major], points[:, piece.major]))
    numbers = np.empty(len(owned), dtype=np.int64)
    numbers[along] = offset + np.arange(len(owned), dtype=np.int64)
    ids = piece.node_ids[owned]
    by_id = np.argsort(ids)
    return ids[by_id], numbers[by_id]


def _requests(piece: MeshPiece) -> list[np.ndarray]:
    """Per rank, the ids of this piece's nodes it owns (others than this rank's, sorted)."""
    return [np.sort(piece.node_ids[piece.node_owner == other]) if other != piece.rank
            else np.empty(0, dtype=np.int64) for other in range(piece.ranks)]


def _answer(ids: np.ndarray, numbers: np.ndarray, asked: np.ndarray) -> np.ndarray:
    """Numbers of the ``asked`` ids among the owned (sorted) ``ids``."""
    where = np.searchsorted(ids, asked)
    if len(asked) and not np.array_equal(ids[np.minimum(where, len(ids) - 1)], asked):
        raise MeshError("a node asked of its owner is not among its owned nodes")
    return numbers[where]


def _assemble_numbers(piece: MeshPiece, ids: np.ndarray, numbers: np.ndarray,
                      received: list[np.ndarray]) -> np.ndarray:
    """Each local node's PETSc number, from its own numbers and those received per owner."""
    result = np.empty(piece.n_points, dtype=np.int64)
    owned = piece.owned
    result[owned] = _answer(ids, numbers, piece.node_ids[owned])
    for other, values in enumerate(received):
        if other == piece.rank:
            continue
        local = np.flatnonzero(piece.node_owner == other)
        order = np.argsort(piece.node_ids[local], kind="stable")
        result[local[order]] = values
    return result


def petsc_numbers(piece: MeshPiece, mpi) -> tuple[np.ndarray, int, int]:
    """Each local node's PETSc node number, and this rank's owned range [first, last) of node
    numbers: owned nodes are numbered contiguously by rank, the others' numbers fetched from
    their owners. Collective over ``mpi`` (an mpi4py communicator of ``piece.ranks`` ranks)."""
    from mpi4py import MPI

    count = len(piece.owned)
    offset = mpi.exscan(count, op=MPI.SUM)
    offset = int(offset) if piece.rank else 0  # undefined on rank 0
    ids, numbers = _owned_numbers(piece, offset)
    asked = mpi.alltoall(_requests(piece))
    answers = mpi.alltoall([_answer(ids, numbers, request) if other != piece.rank else np.empty(0, dtype=np.int64)
                            for other, request in enumerate(asked)])
    return _assemble_numbers(piece, ids, numbers, answers), offset, offset + count


def petsc_numbers_of_pieces(pieces: list[MeshPiece]) -> list[np.ndarray]:
    """:func:`petsc_numbers` of all the pieces in one process (the messages passed by hand):
    what the ranks compute together, for checking the numbering without MPI."""
    offsets = np.concatenate([[0], np.cumsum([len(piece.owned) for piece in pieces])])
    owned = [_owned_numbers(piece, int(offsets[piece.rank])) for piece in pieces]
    requests = [_requests(piece) for piece in pieces]
    return [_assemble_numbers(piece, *owned[piece.rank],
                              [_answer(*owned[other], requests[piece.rank][other]) if other != piece.rank
                               else np.empty(0, dtype=np.int64) for other in range(len(pieces))])
            for piece in pieces]
