"""Unstructured meshes of polygons with circular-arc edges and holes, via Shewchuk's Triangle."""

from __future__ import annotations

from contactfem.errors import MeshError

# Some names are re-exported: the loops, the crossing checks and the meshing's constants
# lived here, and callers import them from this module.
from contactfem.mesh.boundary_points import (  # noqa: F401
    MAX_CHORD_ANGLE,
    RADIUS_TOLERANCE,
    SizeField,
    _discretise,
)
from contactfem.mesh.core import Mesh
from contactfem.case.crossings import (  # noqa: F401
    CLOCKWISE,
    first_crossing,
    first_crossing_among,
    polygon_problems,
    self_crossing,
)
# The loop geometry is the case's: the case reader builds and checks it, the mesher reads it.
from contactfem.case.loops import (  # noqa: F401
    OUTLINE_CHORD_ANGLE,
    Arc,
    Loop,
    arc_sweep,
    circle_loop,
    is_positive_number,
    loop_outline,
    loop_signed_area,
)
from contactfem.mesh.triangulate import (  # noqa: F401
    AREA_TOLERANCE,
    MARKER_OFFSET,
    _loop_label,
    _triangulate_boundary,
)

__all__ = ["Arc", "Loop", "arc_sweep", "circle_loop", "first_crossing", "loop_outline", "loop_signed_area",
           "polygon_problems", "self_crossing", "triangulate_domain"]

#: Largest minimum angle for which Triangle's refinement is known to terminate.
MAX_MIN_ANGLE = 34.0


def triangulate_domain(
    outer: Loop, holes: list[Loop], max_edge: float, min_angle: float = 30.0,
    size: SizeField | None = None, max_points: int | None = None,
) -> Mesh:
    """Quality triangulation of the region inside ``outer`` and outside every hole.

    Parameters
    ----------
    outer : Loop
        The outer boundary.
    holes : list of Loop
        Boundaries of holes, strictly inside ``outer`` and disjoint from each other.
    max_edge : float
        Target edge length: boundary edges are split into pieces of at most this
        length (arcs into chords, also at most 45 degrees each) and triangles are
        refined to area at most ``max_edge**2 * sqrt(3) / 4``, that of the equilateral
        triangle with this edge.
    min_angle : float, default 30
        Smallest angle Triangle's refinement guarantees, in degrees, in (0, 34].
    size : callable, optional
        A size field h(points (k, 2)) -> (k,), at most ``max_edge``: boundary points are
        spaced by it and triangles refined until each is no larger than the
        equilateral triangle of edge h at its centroid (a graded mesh).
    max_points : int, optional
        The most nodes the mesh may have: Triangle adds no more Steiner points than that
        allows (a sliver or a tiny feature can call for far more than ``max_edge``
        suggests), and a mesh that would need more is refused.

    Returns
    -------
    Mesh
        Counter-clockwise triangles; boundary edges oriented with the body on the
        left, named after the loop edge they lie on; nodes of arc edges projected
        onto their circle and the edges recorded in ``edge_curves`` / ``curves``.
        ``part_names`` lists names in order of first appearance (outer loop first).

    Raises
    ------
    MeshError
        For bad parameters, loops that repeat a point, cross, touch or overlap,
        holes outside the outer loop, or arcs too coarse for their projection.
    """
    if not is_positive_number(max_edge):
        raise MeshError(f"max_edge must be a positive number, got {max_edge!r}")
    if not (is_positive_number(min_angle) and min_angle <= MAX_MIN_ANGLE):
        raise MeshError(f"min_angle must be in (0, {MAX_MIN_ANGLE:g}] degrees, got {min_angle!r}")
    loops = [outer, *holes]
    for index, loop in enumerate(loops):
        if not isinstance(loop, Loop):
            raise MeshError(f"{_loop_label(index)} must be a Loop, got {type(loop).__name__}")
    max_edge = float(max_edge)
    boundary = _discretise(loops, max_edge, size)
    return _triangulate_boundary(boundary, max_edge, min_angle, size, max_points)
