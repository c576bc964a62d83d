"""Sanity checks that a mesh is usable by the finite element assembly."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from contactfem.case.crossings import first_crossing_among, self_crossing
from contactfem.errors import MeshError
from contactfem.mesh.core import Mesh
from contactfem.mesh.refine import (
    _decode,
    _single_codes,
    _sorted_edge_codes,
    _undirected_keys,
)

__all__ = ["boundary_loops", "check_body", "check_mesh", "DEGENERATE_RATIO"]

#: A triangle whose area is at most this times its longest edge squared is degenerate
#: (an equilateral triangle has ratio sqrt(3)/4 = 0.43).
DEGENERATE_RATIO = 1e-10
#: Two boundary nodes closer than this fraction of the boundary edges at them are taken for
#: nodes meant to be one (a CAD import's interface, merged to a tolerance it did not meet):
#: the mesh is cut between them, and no P1 element could resolve so narrow a slit anyway.
NEAR_NODES = 1e-6
#: Relative distance from its circle that a node of a curved edge may have.
CURVE_TOLERANCE = 1e-9


def _check_arrays(mesh: Mesh) -> None:
    """Shapes, dtypes and index ranges of every array of ``mesh``."""
    points = np.asarray(mesh.points)
    tri = np.asarray(mesh.triangles)
    edges = np.asarray(mesh.boundary_edges)
    if points.ndim != 2 or points.shape[1] != 2 or not np.issubdtype(points.dtype, np.floating):
        raise MeshError(f"points must be a float (n, 2) array, got {points.dtype} {points.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
    if bad.size:
        raise MeshError(f"point {bad[0]} has a non-finite coordinate {points[bad[0]].tolist()}")
    if tri.ndim != 2 or tri.shape[1] != 3 or not np.issubdtype(tri.dtype, np.integer):
        raise MeshError(f"triangles must be an integer (n, 3) array, got {tri.dtype} {tri.shape}")
    if len(tri) == 0:
        raise MeshError("the mesh has no triangles")
    if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
        raise MeshError(f"boundary_edges must be an integer (n, 2) array, got {edges.dtype} {edges.shape}")
    for name, index in (("triangles", tri), ("boundary_edges", edges)):
        out = np.flatnonzero(np.any((index < 0) | (index >= len(points)), axis=1))
        if out.size:
            raise MeshError(
                f"{name} row {out[0]} has a node index out of range 0..{len(points) - 1}: "
                f"{index[out[0]].tolist()}"
            )
    n_e = len(edges)
    parts = np.asarray(mesh.edge_parts)
    curves = np.asarray(mesh.edge_curves)
    for name, values, low, high in (
        ("edge_parts", parts, 0, len(mesh.part_names)),
        ("edge_curves", curves, -1, len(mesh.curves)),
    ):
        if values.shape != (n_e,) or not np.issubdtype(values.dtype, np.integer):
            raise MeshError(f"{name} must be an integer ({n_e},) array, got {values.dtype} {values.shape}")
        out = np.flatnonzero((values < low) | (values >= high))
        if out.size:
            raise MeshError(f"{name}[{out[0]}] = {values[out[0]]} is outside {low}..{high - 1}")


def _check_triangles(mesh: Mesh) -> None:
    """Orientation, size and use of every node."""
    # Coordinate by coordinate over contiguous (n, 3) corner arrays: plain elementwise
    # arithmetic on them is several times faster than einsum over (n, 3, 2) corners.
    x, y = (np.ascontiguousarray(mesh.points[:, k])[mesh.triangles] for k in range(2))
    e1x, e1y = x[:, 1] - x[:, 0], y[:, 1] - y[:, 0]
    e2x, e2y = x[:, 2] - x[:, 0], y[:, 2] - y[:, 0]
    e3x, e3y = x[:, 2] - x[:, 1], y[:, 2] - y[:, 1]
    areas = 0.5 * (e1x * e2y - e1y * e2x)
    flipped = np.flatnonzero(areas < 0)
    if flipped.size:
        t = flipped[0]
        raise MeshError(
            f"triangle {t} is clockwise (signed area {areas[t]:.3g}); triangles must be counter-clockwise"
        )
    longest2 = np.maximum(np.maximum(e1x * e1x + e1y * e1y, e2x * e2x + e2y * e2y), e3x * e3x + e3y * e3y)
    # Relative to the longest edge squared so the test does not depend on the units.
    tiny = np.flatnonzero(areas <= DEGENERATE_RATIO * longest2)
    if tiny.size:
        t = tiny[0]
        raise MeshError(
            f"triangle {t} is degenerate (area {areas[t]:.3g}, longest edge {np.sqrt(longest2[t]):.3g})"
        )
    used = np.zeros(mesh.n_points, dtype=bool)
    used[mesh.triangles.reshape(-1)] = True
    unused = np.flatnonzero(~used)
    if unused.size:
        raise MeshError(f"point {unused[0]} belongs to no triangle ({unused.size} unused points)")


def _check_edges(mesh: Mesh) -> None:
    """Conformity of the triangulation and agreement of boundary_edges with its boundary."""
    n = mesh.n_points
    codes = _sorted_edge_codes(mesh.triangles, n)
    # Two counter-clockwise triangles on either side of an edge traverse it in
    # opposite directions: the same code twice means overlapping triangles, and an
    # edge key three times a non-manifold edge.
    same = np.flatnonzero(codes[1:] == codes[:-1])
    if same.size:
        a, b = _decode(codes[same[:1]], n)[0]
        raise MeshError(
            f"edge ({a}, {b}) is used in the same direction by two triangles (overlapping triangles)"
        )
    keys = codes >> 1
    triple = np.flatnonzero(keys[2:] == keys[:-2])
    if triple.size:
        a, b = _decode(codes[triple[:1]], n)[0]
        raise MeshError(f"edge ({min(a, b)}, {max(a, b)}) is shared by more than two triangles")

    actual = _single_codes(codes)
    listed = mesh.boundary_edges
    listed_codes = 2 * _undirected_keys(listed, n) + (listed[:, 0] > listed[:, 1])
    sorted_listed = np.sort(listed_codes)
    if np.array_equal(sorted_listed, actual):
        return
    twice = np.flatnonzero(sorted_listed[1:] == sorted_listed[:-1])
    if twice.size:
        edge = _decode(sorted_listed[twice[:1]], n)[0].tolist()
        raise MeshError(f"boundary edge {edge} is listed more than once")
    extra = np.flatnonzero(~np.isin(listed_codes, actual))
    if extra.size:
        raise MeshError(
            f"boundary_edges[{extra[0]}] = {listed[extra[0]].tolist()} is not a boundary edge of the "
            "triangulation oriented with the body on its left"
        )
    missing = actual[~np.isin(actual, sorted_listed)]
    raise MeshError(
        f"boundary edge {_decode(missing[:1], n)[0].tolist()} of the triangulation has no part "
        f"({missing.size} such edges)"
    )


def _check_curves(mesh: Mesh) -> None:
    """Nodes of curved edges lie on their circle."""
    for index, circle in enumerate(mesh.curves):
        nodes = np.unique(mesh.boundary_edges[mesh.edge_curves == index])
        if nodes.size == 0:
            continue
        distance = np.linalg.norm(mesh.points[nodes] - np.asarray(circle.center), axis=1)
        off = np.flatnonzero(np.abs(distance - circle.radius) > CURVE_TOLERANCE * circle.radius)
        if off.size:
            raise MeshError(
                f"node {nodes[off[0]]} of a curved edge is at distance {distance[off[0]]:.12g} from "
                f"the centre of its circle of radius {circle.radius:.12g}"
            )


def check_mesh(mesh: Mesh) -> None:
    """Raise MeshError unless ``mesh`` is a valid conforming counter-clockwise triangulation.

    Checks, in this order: array shapes and finite coordinates; node, part and curve
    indices in range; every triangle counter-clockwise and not degenerate
    (area > ``DEGENERATE_RATIO`` * longest edge**2); every node used; no edge used
    twice in one direction or by more than two triangles; ``boundary_edges`` equal,
    edge for edge and orientation included, to the boundary of the triangulation;
    nodes of curved edges on their circle.

    Parameters
    ----------
    mesh : Mesh

    Raises
    ------
    MeshError
        Naming the first offending triangle, edge or node.
    """
    _check_arrays(mesh)
    _check_triangles(mesh)
    _check_edges(mesh)
    _check_curves(mesh)


def _at(point: np.ndarray) -> str:
    return f"({point[0]:.6g}, {point[1]:.6g})"


def boundary_loops(mesh: Mesh) -> list[np.ndarray]:
    """The closed loops of ``mesh``'s boundary, each as its node sequence with the body on
    the left (the outer loop counter-clockwise, holes clockwise), loop by loop in the order
    of their first edge.

    Each boundary edge is followed by the one leaving its end node; the loops are the
    cycles of that successor map, ranked by pointer jumping (O(m log m) for m boundary
    edges, no walk in Python).

    Raises
    ------
    MeshError
        If a node starts two boundary edges: the boundary touches itself there.
    """
    edges = np.asarray(mesh.boundary_edges, dtype=np.int64)
    m = len(edges)
    if m == 0:
        return []
    start, end = edges[:, 0], edges[:, 1]
    leaving = np.bincount(start, minlength=mesh.n_points)
    pinched = np.flatnonzero(leaving > 1)
    if pinched.size:
        raise MeshError(f"the boundary touches itself at node {pinched[0]} {_at(mesh.points[pinched[0]])}: "
                        "parts of the body meet at a single point")
    edge_from = np.full(mesh.n_points, -1, dtype=np.int64)
    edge_from[start] = np.arange(m)
    successor = edge_from[end]  # a closed boundary: every end node starts an edge
    count, label = connected_components(sp.csr_matrix((np.ones(m), (np.arange(m), successor)), shape=(m, m)),
                                        connection="weak")
    head = np.full(count, m, dtype=np.int64)
    np.minimum.at(head, label, np.arange(m))
    # Cut each cycle before its head, then rank every edge by its distance to the cut.
    last = head[label][successor] == successor
    following = np.where(last, np.arange(m), successor)
    distance = np.where(last, 0, 1)
    while True:
        jumped = following[following]
        distance = distance + distance[following]
        if np.array_equal(jumped, following):
            break
        following = jumped
    order = np.lexsort((-distance, head[label]))
    sizes = np.bincount(label, minlength=count)[np.argsort(head)]
    return np.split(start[order], np.cumsum(sizes)[:-1])


def check_body(mesh: Mesh) -> None:
    """Raise MeshError unless the triangulation ``mesh`` (already valid, :func:`check_mesh`)
    covers each point of the plane at most once and is cut nowhere: its boundary is simple
    closed loops that neither cross nor touch, and no piece (triangles joined through
    edges) lies inside another's material. Separate pieces are allowed (two punches, each
    held by its own supports, :mod:`contactfem.discretize.supports`).

    A conforming mesh can still be one no one drew: surfaces meshed apart and not merged
    (coincident nodes on either side of their interface, which then carries no force), a
    slit of such nodes, pieces that overlap or meet at a point. Each solves, but not as the
    body drawn. Sweeps over the boundary: O(m log m) for m boundary edges, and for pieces
    whose bounding box lies in another's, a ray test of one point against its edges.
    """
    points = mesh.points
    loops = boundary_loops(mesh)
    pieces, piece = connected_components(_edge_adjacency(mesh), directed=False)
    close = _nearly_coincident(points, loops)
    if close is not None:
        a, b = close
        apart = float(np.hypot(*(points[a] - points[b])))
        where = (f"nodes {a} and {b} coincide at {_at(points[a])} on the boundary" if apart == 0.0 else
                 f"nodes {a} and {b} on the boundary are {apart:.3g} apart at {_at(points[a])}, less than "
                 f"{NEAR_NODES:g} of the edges there")
        if pieces > 1:
            raise MeshError(f"{where}: the mesh is {pieces} pieces that share no edge, so surfaces meshed apart "
                            "were not merged and no force crosses between them; merge them (Gmsh: Coherence Mesh)")
        raise MeshError(f"{where}: the mesh is cut there (unmerged nodes, a slit) and no force crosses the cut; "
                        "merge them (Gmsh: Coherence Mesh)")
    outlines = [points[loop] for loop in loops]
    for outline in outlines:
        crossing = self_crossing(outline)
        if crossing is not None:
            raise MeshError(f"the boundary crosses itself near {_at(outline[crossing[1]])}: triangles overlap")
    found = first_crossing_among(outlines)
    if found is not None:
        raise MeshError(f"two boundary loops meet near {_at(found[0])}: triangles overlap or touch")
    if pieces > 1:
        node_piece = np.empty(mesh.n_points, dtype=np.int64)
        node_piece[mesh.triangles.ravel()] = np.repeat(piece, 3)
        inside = _piece_inside_another(points, loops, node_piece[[loop[0] for loop in loops]], pieces)
        if inside is not None:
            raise MeshError(f"a piece of the mesh, at {_at(inside)}, lies inside another piece's triangles: "
                            "they overlap")


def _nearly_coincident(points: np.ndarray, loops: list[np.ndarray]) -> tuple[int, int] | None:
    """Two boundary nodes closer than :data:`NEAR_NODES` of the shorter boundary edges at
    either (their own, so neighbours along a loop never count), or None; a KD-tree of the
    boundary nodes, O(m log m)."""
    nodes = np.concatenate(loops)
    before = np.concatenate([np.roll(loop, 1) for loop in loops])
    after = np.concatenate([np.roll(loop, -1) for loop in loops])
    edge = np.minimum(np.hypot(*(points[nodes] - points[before]).T), np.hypot(*(points[nodes] - points[after]).T))
    # Pairs within the bound for the longest edge, then each pair against its own edges:
    # one pair query costs less than a k-nearest query of every node.
    pairs = cKDTree(points[nodes]).query_pairs(NEAR_NODES * float(edge.max()), output_type="ndarray")
    if not len(pairs):
        return None
    i, j = pairs[:, 0], pairs[:, 1]
    distance = np.hypot(*(points[nodes[i]] - points[nodes[j]]).T)
    near = np.flatnonzero(distance < NEAR_NODES * np.minimum(edge[i], edge[j]))
    if not near.size:
        return None
    first = near[np.argmin(distance[near])]
    return tuple(sorted((int(nodes[i[first]]), int(nodes[j[first]]))))


def _piece_inside_another(points: np.ndarray, loops: list[np.ndarray], loop_piece: np.ndarray,
                          pieces: int) -> np.ndarray | None:
    """A point of a piece inside another piece's material, or None. With no boundaries
    crossing, a piece is inside another's material exactly when one of its points is: a
    ray from it crosses that piece's boundary an odd number of times. Only pieces whose
    bounding box lies in the other's are tested, all of them at once for each other piece."""
    starts = np.concatenate(loops)
    ends = np.concatenate([np.roll(loop, -1) for loop in loops])
    edge_piece = np.repeat(loop_piece, [len(loop) for loop in loops])
    low = np.full((pieces, 2), np.inf)
    high = np.full((pieces, 2), -np.inf)
    for k in range(2):
        np.minimum.at(low[:, k], edge_piece, points[starts, k])
        np.maximum.at(high[:, k], edge_piece, points[starts, k])
    probe = np.empty(pieces, dtype=np.int64)
    probe[loop_piece] = [loop[0] for loop in loops]  # any boundary node of the piece
    for outer in range(pieces):
        inner = np.flatnonzero(np.all((low >= low[outer]) & (high <= high[outer]), axis=1))
        inner = inner[inner != outer]
        if not inner.size:
            continue
        mine = edge_piece == outer
        a, b = points[starts[mine]], points[ends[mine]]
        # Blocks of probes by edges, a few million pairs at a time.
        for block in np.array_split(inner, max(1, inner.size * len(a) // 4_000_000)):
            x, y = points[probe[block], 0][:, None], points[probe[block], 1][:, None]
            straddle = (a[:, 1] > y) != (b[:, 1] > y)
            with np.errstate(divide="ignore", invalid="ignore"):
                crossing_x = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
            odd = np.flatnonzero(np.count_nonzero(straddle & (crossing_x > x), axis=1) % 2)
            if odd.size:
                return points[probe[block[odd[0]]]].copy()
    return None


def _edge_adjacency(mesh: Mesh) -> sp.csr_matrix:
    """Triangles joined through an edge, as a symmetric sparse graph."""
    sides = mesh.topology.edge_triangles
    shared = sides[(sides[:, 0] >= 0) & (sides[:, 1] >= 0)]
    n = mesh.n_triangles
    return sp.csr_matrix((np.ones(len(shared)), (shared[:, 0], shared[:, 1])), shape=(n, n))
