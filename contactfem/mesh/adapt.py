"""Local refinement by newest-vertex bisection (NVB) and Dörfler marking.

Convention: the refinement edge of triangle (v0, v1, v2) is (v0, v1), and v2 is its
newest vertex. :func:`label_longest_edge` rotates every triangle of an initial mesh
(cyclically, so it stays counter-clockwise) to make its longest edge the refinement edge;
:func:`bisect` then keeps the convention: triangle (v0, v1, v2) with m the midpoint of
(v0, v1) is split into (v2, v0, m) and (v1, v2, m), whose refinement edges (v2, v0) and
(v1, v2) are edges of the parent opposite the new vertex m.

Conformity by closure: the edges to split are the refinement edges of the marked
triangles, extended until every triangle that has a split edge also has its refinement
edge split (a fixed point, reached in a few vectorised sweeps). Every triangle whose
refinement edge is split is bisected; a child whose refinement edge (an edge of its
parent) is split is bisected again in the next sweep, so after at most two sweeps no
split edge is left with a hanging node. NVB meshes of one labelled initial mesh fall into
at most four similarity classes per initial triangle, so angles stay bounded away from 0
and π (checked by :func:`min_angle`). Boundary edges that are split keep their part and
curve; midpoints of curved edges go onto their circle, as in uniform refinement.
"""

from __future__ import annotations

import numpy as np

from contactfem.errors import MeshError
from contactfem.mesh.core import Mesh
from contactfem.mesh.quality import check_mesh

__all__ = ["bisect", "bisect_uniform", "dorfler_mark", "label_longest_edge", "min_angle"]


def label_longest_edge(mesh: Mesh) -> Mesh:
    """The same mesh with each triangle rotated so that its longest edge is (v0, v1)."""
    tri = mesh.triangles
    p = mesh.points[tri]
    # Edge k runs from vertex k to vertex k+1; rotate so the longest one starts at position 0.
    lengths = np.linalg.norm(np.roll(p, -1, axis=1) - p, axis=2)
    start = np.argmax(lengths, axis=1)
    order = (start[:, None] + np.arange(3)) % 3
    rotated = np.take_along_axis(tri, order, axis=1)
    return Mesh(points=mesh.points, triangles=rotated, boundary_edges=mesh.boundary_edges,
                edge_parts=mesh.edge_parts, part_names=mesh.part_names,
                edge_curves=mesh.edge_curves, curves=mesh.curves)


def dorfler_mark(indicators_squared: np.ndarray, theta: float) -> np.ndarray:
    """Bulk (Dörfler) marking: a smallest set M with Σ_M η_T² ≥ θ Σ η_T² (bool mask).

    Ties at the threshold are all marked, so equal indicators are treated alike.
    """
    if not 0.0 < theta <= 1.0:
        raise ValueError(f"theta must be in (0, 1], got {theta!r}")
    values = np.asarray(indicators_squared, dtype=float)
    total = values.sum()
    if total <= 0.0:
        return np.zeros(len(values), dtype=bool)
    ordered = np.sort(values)[::-1]
    count = int(np.searchsorted(np.cumsum(ordered), theta * total * (1 - 1e-12))) + 1
    threshold = ordered[min(count, len(values)) - 1]
    return values >= threshold


def bisect(mesh: Mesh, marked: np.ndarray, *, check: bool = True) -> Mesh:
    """Refine the ``marked`` triangles (bool mask or indices) by NVB with conforming closure.

    The old nodes keep their indices (new midpoints are numbered after them); the mesh
    must follow the refinement-edge convention of this module (see
    :func:`label_longest_edge`). With ``check`` the result goes through
    :func:`~contactfem.mesh.check_mesh` (conformity, orientation, boundary parts).
    """
    n_points = mesh.n_points
    tri = mesh.triangles.astype(np.int64)
    n_tri = len(tri)
    marked = np.asarray(marked)
    if marked.dtype == bool:
        if marked.shape != (n_tri,):
            raise MeshError(f"marked must have one entry per triangle ({n_tri}), got {marked.shape}")
        marked = np.flatnonzero(marked)
    if marked.size == 0:
        return mesh
    topology = mesh.topology
    edge_of = topology.half_edge_edge.reshape(n_tri, 3)  # (t, k): edge k = (v_k, v_{k+1})
    refinement = edge_of[:, 0]
    split = np.zeros(topology.n_edges, dtype=bool)
    split[refinement[marked]] = True
    while True:
        needs = split[edge_of].any(axis=1) & ~split[refinement]
        if not needs.any():
            break
        split[refinement[needs]] = True

    # The midpoint of the split edge e is node n_points + midpoint[e], in edge order.
    midpoint = np.cumsum(split) - 1
    split_edges = topology.edges[split]
    points = np.concatenate(
        [mesh.points, 0.5 * (mesh.points[split_edges[:, 0]] + mesh.points[split_edges[:, 1]])]
    )

    # Boundary edges: split ones become (a, m), (m, b) keeping part and curve.
    bedges = mesh.boundary_edges.astype(np.int64)
    bedge = topology.edge_index(bedges[:, 0], bedges[:, 1])
    cut = (bedge >= 0) & split[bedge]
    mid = n_points + midpoint[bedge[cut]]
    halves = np.stack([np.stack([bedges[cut, 0], mid], axis=1), np.stack([mid, bedges[cut, 1]], axis=1)],
                      axis=1).reshape(-1, 2)
    new_bedges = np.concatenate([bedges[~cut], halves])
    new_parts = np.concatenate([mesh.edge_parts[~cut], np.repeat(mesh.edge_parts[cut], 2)])
    new_curves = np.concatenate([mesh.edge_curves[~cut], np.repeat(mesh.edge_curves[cut], 2)])
    for index, circle in enumerate(mesh.curves):
        nodes = mid[mesh.edge_curves[cut] == index]
        if nodes.size:
            points[nodes] = circle.project(points[nodes])

    # Sweeps of bisection: a triangle whose refinement edge is split is halved. The
    # refinement edge of a child is an edge of its parent, or has a new node and is then
    # no edge of the old topology (edge_index gives -1).
    for _ in range(64):
        edge = topology.edge_index(tri[:, 0], tri[:, 1])
        hit = (edge >= 0) & split[edge]
        if not hit.any():
            break
        parent = tri[hit]
        m = n_points + midpoint[edge[hit]]
        v0, v1, v2 = parent[:, 0], parent[:, 1], parent[:, 2]
        children = np.concatenate([np.stack([v2, v0, m], axis=1), np.stack([v1, v2, m], axis=1)])
        tri = np.concatenate([tri[~hit], children])
    else:  # pragma: no cover - the closure makes two sweeps enough
        raise MeshError("newest-vertex bisection did not terminate")

    refined = Mesh(points=points, triangles=tri, boundary_edges=new_bedges, edge_parts=new_parts,
                   part_names=mesh.part_names, edge_curves=new_curves, curves=mesh.curves)
    if check:
        check_mesh(refined)
    return refined


def bisect_uniform(mesh: Mesh, times: int = 1, *, check: bool = True) -> Mesh:
    """Bisect every triangle ``times`` times (two times: 4× the triangles, like one red step)."""
    for _ in range(int(times)):
        mesh = bisect(mesh, np.ones(mesh.n_triangles, dtype=bool), check=check)
    return mesh


def min_angle(mesh: Mesh) -> float:
    """The smallest interior angle of the mesh, in degrees."""
    p = mesh.points[mesh.triangles]
    smallest = np.inf
    for k in range(3):
        u = p[:, (k + 1) % 3] - p[:, k]
        v = p[:, (k + 2) % 3] - p[:, k]
        cosine = np.einsum("ij,ij->i", u, v) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        smallest = min(smallest, float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))).min()))
    return smallest
