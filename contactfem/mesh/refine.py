"""Uniform red refinement of triangle meshes and extraction of a triangulation's boundary."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from contactfem.errors import MeshError
from contactfem.mesh.core import Mesh
from contactfem.mesh.topology import Topology

__all__ = ["boundary_edges", "prolongation", "refine_uniform"]


def _half_edges(triangles: np.ndarray) -> np.ndarray:
    """Directed edges of every triangle, edge-major.

    Parameters
    ----------
    triangles : (n_triangles, 3) int
        Node indices, counter-clockwise.

    Returns
    -------
    (3 * n_triangles, 2) int64
        Rows ``k * n_triangles + t`` hold edge ``k`` of triangle ``t``: (v0, v1),
        (v1, v2), (v2, v0) for k = 0, 1, 2, each oriented as in its triangle.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    starts = tri.T.reshape(-1)
    ends = tri[:, [1, 2, 0]].T.reshape(-1)
    return np.stack([starts, ends], axis=1)


def _undirected_keys(edges: np.ndarray, n_points: int) -> np.ndarray:
    """One int64 key per edge that ignores orientation: ``min * n_points + max``.

    Parameters
    ----------
    edges : (n_edges, 2) int64
    n_points : int
        Any bound above the largest index; n_points**2 must fit in int64, which
        holds for every mesh that fits in memory.

    Returns
    -------
    (n_edges,) int64
    """
    lo = np.minimum(edges[:, 0], edges[:, 1])
    hi = np.maximum(edges[:, 0], edges[:, 1])
    return lo * np.int64(n_points) + hi


def _sorted_edge_codes(triangles: np.ndarray, n_points: int) -> np.ndarray:
    """Sorted codes ``2 * undirected key + (start > end)`` of all half-edges.

    One sort of these codes groups the half-edges of each edge together and still
    tells their directions, which is all that boundary extraction and conformity
    checks need (cheaper than np.unique with return_index, which argsorts).

    Parameters
    ----------
    triangles : (n_triangles, 3) int64
    n_points : int
        Bound above the largest node index.

    Returns
    -------
    (3 * n_triangles,) int64, sorted.
    """
    half = _half_edges(triangles)
    codes = 2 * _undirected_keys(half, n_points) + (half[:, 0] > half[:, 1])
    codes.sort()
    return codes


def _single_codes(codes: np.ndarray) -> np.ndarray:
    """The codes whose undirected edge occurs once in sorted ``codes``: boundary half-edges."""
    keys = codes >> 1
    differs = keys[1:] != keys[:-1]
    single = np.ones(len(codes), dtype=bool)
    single[1:] &= differs
    single[:-1] &= differs
    return codes[single]


def _decode(codes: np.ndarray, n_points: int) -> np.ndarray:
    """Directed edges (k, 2) int64 from half-edge codes."""
    keys = codes >> 1
    lo = keys // n_points
    hi = keys % n_points
    reverse = (codes & 1).astype(bool)
    return np.stack([np.where(reverse, hi, lo), np.where(reverse, lo, hi)], axis=1)


def boundary_edges(triangles: np.ndarray) -> np.ndarray:
    """The edges that belong to exactly one triangle, oriented as in that triangle.

    With counter-clockwise triangles the result has the body on the left of every
    edge: the outer boundary runs counter-clockwise and holes clockwise.

    Parameters
    ----------
    triangles : (n_triangles, 3) int
        Node indices, counter-clockwise.

    Returns
    -------
    (n_boundary_edges, 2) int64
        Sorted by the undirected key ``(min node, max node)``.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    if tri.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    n = int(tri.max()) + 1
    if np.any((tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2]) | (tri[:, 2] == tri[:, 0])):
        # No topology for such triangles, but files are read with this before
        # check_mesh, which then names the degenerate triangle.
        return _decode(_single_codes(_sorted_edge_codes(tri, n)), n)
    return oriented_boundary(Topology.from_triangles(tri, n))


def oriented_boundary(topology: Topology) -> np.ndarray:
    """:func:`boundary_edges` of a triangulation whose topology is built: its boundary
    edges oriented as in their triangle, sorted by undirected key."""
    edges = topology.edges[topology.boundary].astype(np.int64)
    flipped = topology.half_edge_flipped[topology.boundary_half_edges]
    edges[flipped] = edges[flipped][:, ::-1]
    return edges


def _refine_once(mesh: Mesh) -> Mesh:
    """One red refinement step; see :func:`refine_uniform`."""
    n_points = mesh.n_points
    n_tri = mesh.n_triangles
    if n_tri == 0:
        raise MeshError("cannot refine a mesh without triangles")
    tri = mesh.triangles
    topology = mesh.topology

    # New midpoint nodes are numbered after the old ones, in edge order, so the coarse
    # mesh's nodes keep their indices and the meshes are nested.
    edges = topology.edges
    midpoints = 0.5 * (mesh.points[edges[:, 0]] + mesh.points[edges[:, 1]])
    mid_of_half = n_points + topology.half_edge_edge.astype(np.int64).reshape(n_tri, 3)
    m01, m12, m20 = mid_of_half[:, 0], mid_of_half[:, 1], mid_of_half[:, 2]
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    # Children of triangle t are rows 4t..4t+3: the three corner triangles and the
    # middle one, all counter-clockwise like their parent.
    children = np.stack(
        [
            np.stack([v0, m01, m20], axis=1),
            np.stack([v1, m12, m01], axis=1),
            np.stack([v2, m20, m12], axis=1),
            np.stack([m01, m12, m20], axis=1),
        ],
        axis=1,
    ).reshape(-1, 3)

    # Each boundary edge (a, b) becomes (a, m), (m, b) at rows 2k, 2k+1, keeping
    # its part and curve.
    bedges = mesh.boundary_edges
    bedge = topology.edge_index(bedges[:, 0], bedges[:, 1])
    if np.any(bedge < 0):
        raise MeshError("cannot refine: a boundary edge is not an edge of any triangle")
    bmid = n_points + bedge
    new_bedges = np.stack(
        [np.stack([bedges[:, 0], bmid], axis=1), np.stack([bmid, bedges[:, 1]], axis=1)], axis=1
    ).reshape(-1, 2)
    new_parts = np.repeat(mesh.edge_parts, 2)
    new_curves = np.repeat(mesh.edge_curves, 2)

    points = np.concatenate([mesh.points, midpoints])
    # Midpoints of curved boundary edges go onto their circle, so refinement
    # converges to the true curved domain instead of the coarse polygon.
    for index, circle in enumerate(mesh.curves):
        nodes = bmid[mesh.edge_curves == index]
        if nodes.size:
            points[nodes] = circle.project(points[nodes])

    return Mesh(
        points=points,
        triangles=children,
        boundary_edges=new_bedges,
        edge_parts=new_parts,
        part_names=mesh.part_names,
        edge_curves=new_curves,
        curves=mesh.curves,
    )


def refine_uniform(mesh: Mesh, times: int = 1) -> Mesh:
    """Split every triangle into four by its edge midpoints, ``times`` times.

    Parameters
    ----------
    mesh : Mesh
        The coarse mesh.
    times : int, default 1
        Number of refinement steps; 0 returns ``mesh`` itself.

    Returns
    -------
    Mesh
        ``4**times`` times as many triangles. The old nodes keep their indices
        (nested meshes); the children of coarse triangle ``t`` after one step are
        triangles ``4t .. 4t+3``. Boundary edges are split in two (children of
        edge ``k`` are ``2k, 2k+1``) and keep their part and curve; new nodes on
        curved edges are projected onto their circle.

    Raises
    ------
    MeshError
        If ``times`` is negative or not an integer, or the mesh's boundary edges are
        not edges of its triangles.
    """
    if isinstance(times, bool) or not isinstance(times, (int, np.integer)) or times < 0:
        raise MeshError(f"refinement count must be a non-negative integer, got {times!r}")
    for _ in range(int(times)):
        mesh = _refine_once(mesh)
    return mesh


def prolongation(mesh: Mesh, times: int = 1) -> sp.csr_matrix:
    """Interpolation of P1 fields from ``mesh`` onto ``refine_uniform(mesh, times)``.

    Returns
    -------
    (n_fine_points, n_points) sparse
        Old nodes copy their value, each new node takes the mean of the two ends of the
        edge it splits: exact for the nested P1 spaces (a new node on a curved edge is
        moved onto its circle, where this is the interpolant at the chord's midpoint).
    """
    operator = sp.identity(mesh.n_points, format="csr")
    for _ in range(int(times)):
        n_points = mesh.n_points
        edges = mesh.topology.edges.astype(np.int64)
        n_edges = len(edges)
        new = n_points + np.arange(n_edges)
        rows = np.concatenate([np.arange(n_points), new, new])
        cols = np.concatenate([np.arange(n_points), edges[:, 0], edges[:, 1]])
        vals = np.concatenate([np.ones(n_points), np.full(2 * n_edges, 0.5)])
        step = sp.csr_matrix((vals, (rows, cols)), shape=(n_points + n_edges, n_points))
        operator = step @ operator
        mesh = _refine_once(mesh)
    return operator.tocsr()
