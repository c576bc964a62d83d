"""Triangle's quality mesh of the discretised loops, and the Mesh read back from it."""

from __future__ import annotations

import math

import numpy as np
import triangle

from contactfem.errors import MeshCapError, MeshError
from contactfem.mesh.boundary_points import SizeField, _Boundary
from contactfem.mesh.core import Mesh
from contactfem.mesh.refine import _undirected_keys, oriented_boundary
from contactfem.mesh.topology import Topology

#: Triangle gives marker 1 to boundary edges on no input segment and 0 to interior
#: edges, so input segment s is given marker s + MARKER_OFFSET.
MARKER_OFFSET = 2
#: Relative mismatch between the meshed area and the area enclosed by the loops that
#: reveals crossing loops or a hole outside the domain.
AREA_TOLERANCE = 1e-9


def _closed_segments(n: int, offset: int = 0) -> np.ndarray:
    """Segments (n, 2) joining points offset..offset+n-1 into a closed chain."""
    idx = np.arange(n, dtype=np.int64) + offset
    return np.stack([idx, np.roll(idx, -1)], axis=1)


def _shoelace(points: np.ndarray) -> float:
    """Signed area of the closed polygon through ``points`` (n, 2)."""
    nxt = np.roll(points, -1, axis=0)
    return 0.5 * float(np.sum(points[:, 0] * nxt[:, 1] - points[:, 1] * nxt[:, 0]))


def _interior_point(points: np.ndarray, which: str) -> np.ndarray:
    """A point strictly inside the closed polygon through ``points`` (n, 2).

    The centroid of the largest triangle of the polygon's own constrained
    triangulation is inside whatever the polygon's shape (the centroid of the
    vertices is not, for non-convex holes).
    """
    pslg = {"vertices": points, "segments": _closed_segments(len(points))}
    result = triangle.triangulate(pslg, "pQ")
    tri = result.get("triangles")
    if tri is None or len(tri) == 0:
        raise MeshError(f"cannot find a point inside {which}; is it a simple closed curve?")
    corners = result["vertices"][tri]
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return corners[np.argmax(area)].mean(axis=0)


def _area_switch(area: float) -> str:
    """Fixed-point text of the area bound with enough digits to be nonzero.

    Triangle parses the number after ``a`` up to the first character that is not a
    digit or '.', so ``a2.4e-06`` would read as area 2.4 followed by the ``e`` switch.
    """
    digits = max(12, 6 - math.floor(math.log10(area)))
    return f"{area:.{digits}f}"


#: A size-field refinement stops once every triangle is at most this many times the area
#: of the equilateral triangle of edge h(centroid) (an edge at most 1.22 times h): the size
#: at a new triangle's centroid is not the size its parent was refined to, and chasing it
#: exactly would take many more rounds for a hardly different mesh.
SIZE_AREA_SLACK = 1.5
#: Triangle meets a uniform area bound exactly (``a``): a triangle larger than this many
#: times it is one refinement left undone (only the bound's printed digits differ).
AREA_BOUND_SLACK = 1.0 + 1e-6


def _triangle_areas(result: dict) -> tuple[np.ndarray, np.ndarray]:
    """The areas of Triangle's triangles (t,) and their centroids (t, 2)."""
    corners = np.asarray(result["vertices"])[np.asarray(result["triangles"])]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]), corners.mean(axis=1)


def _equilateral_area(h: np.ndarray | float) -> np.ndarray | float:
    """The area of the equilateral triangle of edge ``h``."""
    return np.sqrt(3) / 4 * np.square(h)


def _steiner_switch(max_points: int | None, n_vertices: int) -> str:
    """Triangle's S switch: no more Steiner points than take the mesh to ``max_points`` nodes."""
    return "" if max_points is None else f"S{max(int(max_points) - n_vertices, 0)}"


def _refine_to_size(result: dict, holes: np.ndarray | None, size: SizeField, min_angle: float,
                    rounds: int = 12, max_points: int | None = None) -> dict:
    """Refine Triangle's mesh until every triangle is at most :data:`SIZE_AREA_SLACK` times the
    equilateral one of edge h(centroid); Triangle's ``r`` switch keeps segments and their
    markers. Each round adds no more points than take the mesh to ``max_points`` nodes."""
    for _ in range(rounds):
        area, centroid = _triangle_areas(result)
        target = _equilateral_area(size(centroid))
        if np.all(area <= SIZE_AREA_SLACK * target):
            break
        n_vertices = len(result["vertices"])
        if max_points is not None and n_vertices >= max_points:
            break  # the cap is reached: what is left undone is refused by _refuse_capped
        refine = {key: result[key] for key in ("vertices", "triangles", "segments", "segment_markers")}
        refine["triangle_max_area"] = target[:, None]
        if holes is not None:
            refine["holes"] = holes
        switches = f"rpq{float(min_angle):.6f}aQ{_steiner_switch(max_points, n_vertices)}"
        result = triangle.triangulate(refine, switches)
    return result


def _largest_over_size(result: dict, max_area: float, size: SizeField | None) -> tuple[float, float]:
    """How far Triangle's triangles are from the size asked for: the largest ratio of a
    triangle's area to its bound (``max_area``, or :data:`SIZE_AREA_SLACK` times the
    equilateral triangle of edge h(centroid)), and the largest triangle's edge over the edge
    asked for there (the side of the equilateral triangle of the same area)."""
    area, centroid = _triangle_areas(result)
    if size is None:
        asked = np.full(len(area), max_area)
        bound = AREA_BOUND_SLACK * asked
    else:
        asked = np.minimum(_equilateral_area(size(centroid)), max_area)
        bound = SIZE_AREA_SLACK * asked
    worst = int(np.argmax(area / bound))
    return float(area[worst] / bound[worst]), float(np.sqrt(np.max(area / asked)))


def _loop_label(index: int) -> str:
    """'the outer loop' or 'hole 2', for messages."""
    return "the outer loop" if index == 0 else f"hole {index - 1}"


def _triangulate_boundary(boundary: _Boundary, max_edge: float, min_angle: float, size: SizeField | None,
                          max_points: int | None) -> Mesh:
    """The quality mesh inside the discretised loops (the first the outer one, the others
    holes): :func:`contactfem.mesh.polygon.triangulate_domain` once its loops are discretised."""
    points, segments, areas, expected_area = _input_graph(boundary)
    result = _run_triangle(boundary, points, segments, max_edge, min_angle, size, max_points)
    tri, out_points, out_segments, source = _used_nodes(result, len(segments))
    cross = _orient_counter_clockwise(tri, out_points, areas, expected_area)

    # Orient the boundary from the triangles (body on the left) and give each edge
    # the part and curve of the input segment Triangle says it came from.
    topology = Topology.from_triangles(tri, len(out_points))
    edges, edge_source = _edge_sources(topology, out_segments, source)
    edge_parts = np.concatenate(boundary.segment_part)[edge_source]
    edge_curves = np.concatenate(boundary.segment_curve)[edge_source]
    _project_onto_arcs(boundary, out_points, tri, edges, edge_curves, cross)

    mesh = Mesh(
        points=out_points,
        triangles=tri,
        boundary_edges=edges,
        edge_parts=edge_parts,
        part_names=tuple(boundary.part_names),
        edge_curves=edge_curves,
        curves=tuple(boundary.curves),
    )
    # The topology the boundary was read from (the projection onto arcs moved points, not
    # connections): Mesh.topology, a cached property, would build it again.
    mesh.__dict__["topology"] = topology
    return mesh


def _input_graph(boundary: _Boundary) -> tuple[np.ndarray, np.ndarray, list[float], float]:
    """The loops' points (n, 2) and closed chains of segments (n, 2), each loop's enclosed
    area and the domain's (the outer loop's less the holes').

    Raises
    ------
    MeshError
        If the boundary passes twice through a point, a loop encloses no area or the
        holes cover the domain.
    """
    sizes = [len(p) for p in boundary.points]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    points = np.concatenate(boundary.points)
    segments = np.concatenate([_closed_segments(n, int(o)) for n, o in zip(sizes, offsets)])
    # Triangle silently drops duplicate input vertices, which would break the
    # segment bookkeeping; they mean touching loops or an edge revisiting a vertex.
    unique_points, first = np.unique(points, axis=0, return_index=True)
    if len(unique_points) != len(points):
        dup = np.setdiff1d(np.arange(len(points)), first)[0]
        raise MeshError(f"the boundary passes twice through the point {points[dup].tolist()}")
    areas = []
    for index, loop_points in enumerate(boundary.points):
        area = abs(_shoelace(loop_points))
        if area == 0.0:
            raise MeshError(f"{_loop_label(index)} encloses zero area")
        areas.append(area)
    expected_area = areas[0] - sum(areas[1:])
    if expected_area <= 0:
        raise MeshError("the holes cover the whole domain")
    return points, segments, areas, expected_area


def _run_triangle(boundary: _Boundary, points: np.ndarray, segments: np.ndarray, max_edge: float,
                  min_angle: float, size: SizeField | None, max_points: int | None) -> dict:
    """Triangle's mesh of the planar straight line graph, each segment marked with its index
    (plus :data:`MARKER_OFFSET`), refined to ``size`` if given.

    Raises
    ------
    MeshCapError
        If it would need ``max_points`` nodes or more (:func:`_refuse_capped`).
    MeshError
        If it gives no triangle.
    """
    pslg: dict[str, np.ndarray] = {
        "vertices": points,
        "segments": segments.astype(np.int32),
        "segment_markers": (np.arange(len(segments), dtype=np.int32) + MARKER_OFFSET)[:, None],
    }
    if len(boundary.points) > 1:
        pslg["holes"] = np.array(
            [_interior_point(boundary.points[h], _loop_label(h)) for h in range(1, len(boundary.points))]
        )
    max_area = max_edge**2 * math.sqrt(3) / 4
    # Triangle's S switch caps the Steiner points it adds, so that memory stays bounded; a
    # mesh it leaves short of the size asked for is refused (_refuse_capped), never solved.
    switches = f"pq{float(min_angle):.6f}a{_area_switch(max_area)}Q{_steiner_switch(max_points, len(points))}"
    result = triangle.triangulate(pslg, switches)
    if size is not None:
        result = _refine_to_size(result, pslg.get("holes"), size, min_angle, max_points=max_points)
    _refuse_capped(result, len(points), max_area, size, min_angle, max_points)
    tri = result.get("triangles")
    if tri is None or len(tri) == 0:
        raise MeshError("Triangle produced no triangles; are the holes inside the outer loop?")
    return result


def _refuse_capped(result: dict, n_input: int, max_area: float, size: SizeField | None, min_angle: float,
                   max_points: int | None) -> None:
    """Refuse a mesh whose refinement the cap on nodes stopped: it reached ``max_points`` nodes,
    or a triangle is larger than the size asked for (Triangle splits triangles worst angle
    first, those only too large last, so a refinement cut short leaves large ones behind:
    a rough profile of 20 000 points at mesh.size 0.01 stopped with triangles of edge 0.099).

    Raises
    ------
    MeshCapError
        If so, with the cap, the nodes reached and the largest triangle's edge over the edge
        asked for.
    """
    if max_points is None or result.get("triangles") is None or len(result["triangles"]) == 0:
        return
    excess, largest = _largest_over_size(result, max_area, size)
    nodes = len(result["vertices"])
    if nodes < max_points and excess <= 1.0:
        return
    raise MeshCapError(
        f"the mesh asked for needs more than {max_points:,} nodes (meshing from {n_input:,} boundary points "
        f"stopped there, with triangles {largest:.3g} times the edge asked for): a quality mesh (smallest angle "
        f"{min_angle:g} degrees) around a feature far smaller than the mesh size (a sliver, a narrow gap, a tiny "
        "edge, a rough profile's points) needs far more triangles than the size says",
        max_points=int(max_points), nodes=nodes, largest=largest,
    )


def _used_nodes(result: dict, n_segments: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Triangle's triangles (t, 3) on the nodes some triangle uses, those nodes (n, 2) in
    their original order, its boundary segments on them (s, 2) and the input segment each
    came from (s,).

    Raises
    ------
    MeshError
        If a boundary segment lies on no input segment.
    """
    # Keep only nodes that some triangle uses, renumbered in their original order (marked
    # and counted, O(n), rather than found by sorting the triangles' entries).
    tri = np.asarray(result["triangles"], dtype=np.int64)
    in_use = np.zeros(len(result["vertices"]), dtype=bool)
    in_use[tri] = True
    used = np.flatnonzero(in_use)
    renumber = np.full(len(result["vertices"]), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    tri = renumber[tri]
    out_points = np.array(result["vertices"][used], dtype=np.float64)
    out_segments = renumber[np.asarray(result["segments"], dtype=np.int64)]
    source = np.asarray(result["segment_markers"], dtype=np.int64).reshape(-1) - MARKER_OFFSET
    if np.any(out_segments < 0) or np.any(source < 0) or np.any(source >= n_segments):
        raise MeshError("Triangle returned boundary segments that lie on no input loop")
    return tri, out_points, out_segments, source


def _orient_counter_clockwise(tri: np.ndarray, points: np.ndarray, areas: list[float],
                              expected_area: float) -> np.ndarray:
    """Reorder, in place, any triangle that is not counter-clockwise, and return twice each
    triangle's signed area as it was (t,).

    Raises
    ------
    MeshError
        If the meshed area is not the area the loops enclose.
    """
    # Triangle's triangles are counter-clockwise; reorder any that are not, to be safe.
    corners = points[tri]
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    flip = cross < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]

    meshed_area = 0.5 * float(np.sum(np.abs(cross)))
    if abs(meshed_area - expected_area) > AREA_TOLERANCE * sum(areas):
        raise MeshError(
            f"meshed area {meshed_area:.12g} differs from the area {expected_area:.12g} enclosed by the "
            "loops: loops cross or overlap, or a hole is not inside the outer loop"
        )
    return cross


def _edge_sources(topology: Topology, segments: np.ndarray, source: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's boundary edges (e, 2), body on the left, and the input segment each lies on (e,).

    Raises
    ------
    MeshError
        If a boundary edge lies on no segment, or a segment ended up inside the mesh.
    """
    n = topology.n_points
    edges = oriented_boundary(topology)
    seg_keys = _undirected_keys(segments, n)
    order = np.argsort(seg_keys)
    edge_keys = _undirected_keys(edges, n)
    slot = np.minimum(np.searchsorted(seg_keys[order], edge_keys), len(order) - 1)
    if np.any(seg_keys[order][slot] != edge_keys):
        raise MeshError("part of the mesh boundary lies on no input loop")
    if len(segments) != len(edges):
        raise MeshError("loops touch or cross: some boundary segments ended up inside the mesh")
    return edges, source[order][slot]


def _project_onto_arcs(boundary: _Boundary, points: np.ndarray, tri: np.ndarray, edges: np.ndarray,
                       edge_curves: np.ndarray, cross: np.ndarray) -> None:
    """Move the nodes of arc edges onto their circles, in place.

    Raises
    ------
    MeshError
        If that turns a triangle over, or (no arcs) a triangle has zero area.
    """
    # Triangle may split chords of arcs; put those nodes (and, harmlessly, the chord
    # ends already there) on the circle so the boundary converges to the true curve.
    for index, circle in enumerate(boundary.curves):
        nodes = np.unique(edges[edge_curves == index])
        points[nodes] = circle.project(points[nodes])
    if boundary.curves:
        corners = points[tri]
        e1 = corners[:, 1] - corners[:, 0]
        e2 = corners[:, 2] - corners[:, 0]
        if np.any(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] <= 0):
            raise MeshError(
                "projecting boundary nodes onto their arcs inverted a triangle; use a smaller max_edge"
            )
    elif np.any(cross == 0):  # no point moved: the triangles' areas are those measured above
        raise MeshError("Triangle produced a triangle of zero area; is part of the outline degenerate?")
