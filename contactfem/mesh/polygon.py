"""Unstructured meshes of polygons with circular-arc edges and holes, via Shewchuk's Triangle."""

from __future__ import annotations

import itertools
import math
import operator
from functools import cached_property
from dataclasses import dataclass, field

import numpy as np

from contactfem.errors import MeshError
# Some names are re-exported: the crossing checks and the meshing's constants lived here,
# and callers import them from this module.
from contactfem.mesh.boundary_points import (  # noqa: F401
    MAX_CHORD_ANGLE,
    RADIUS_TOLERANCE,
    SizeField,
    _discretise,
)
from contactfem.mesh.core import Mesh
from contactfem.mesh.crossings import (  # noqa: F401
    CLOCKWISE,
    first_crossing,
    first_crossing_among,
    polygon_problems,
    self_crossing,
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


@dataclass(frozen=True)
class Arc:
    """Marks a loop edge as the circular arc around ``center`` from its start to its end vertex.

    Attributes
    ----------
    center : (2,) tuple of float
        Centre of the circle; the radius is the distance to the edge's start vertex.
    ccw : bool
        True for the counter-clockwise arc from start to end, False for the clockwise one.
    """

    center: tuple[float, float]
    ccw: bool = True

    def __post_init__(self) -> None:
        try:
            center = tuple(float(c) for c in self.center)
        except (TypeError, ValueError):
            raise MeshError(f"arc centre must be a pair of numbers, got {self.center!r}") from None
        if len(center) != 2 or not all(math.isfinite(c) for c in center):
            raise MeshError(f"arc centre must be a pair of finite numbers, got {self.center!r}")
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "ccw", bool(self.ccw))


@dataclass(frozen=True, eq=False)
class Loop:
    """A closed boundary curve: vertices joined by straight edges or circular arcs.

    Attributes
    ----------
    vertices : (k, 2) float64
        Corner points; edge ``i`` runs from vertex ``i`` to vertex ``(i + 1) % k``.
    edge_names : tuple of str
        ``k`` boundary part names, one per edge.
    edge_arcs : tuple of (Arc or None)
        ``k`` entries: the arc edge ``i`` follows, or None for a straight edge.
        Omitted means all edges are straight.

    Either orientation is accepted; :func:`triangulate_domain` orients the mesh's
    boundary itself.
    """

    vertices: np.ndarray
    edge_names: tuple[str, ...]
    edge_arcs: tuple[Arc | None, ...] = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        try:
            vertices = np.array(self.vertices, dtype=float)
        except (TypeError, ValueError):
            raise MeshError("loop vertices must be a (k, 2) array of numbers") from None
        if vertices.ndim != 2 or vertices.shape[1] != 2 or len(vertices) < 2:
            raise MeshError(f"loop vertices must be a (k, 2) array with k >= 2, got shape {vertices.shape}")
        if not np.all(np.isfinite(vertices)):
            raise MeshError("loop vertices must be finite")
        vertices.setflags(write=False)
        k = len(vertices)
        names = tuple(self.edge_names)
        arcs = (None,) * k if self.edge_arcs is None else tuple(self.edge_arcs)
        if len(names) != k:
            raise MeshError(f"a loop with {k} vertices needs {k} edge names, got {len(names)}")
        if len(arcs) != k:
            raise MeshError(f"a loop with {k} vertices needs {k} edge_arcs entries, got {len(arcs)}")
        # A profile has 10^5 edges: the names' types and the arcs are looked at in C
        # (map, count) and edge by edge only where something is wrong.
        if set(map(type, names)) != {str} or "" in names:
            for i, name in enumerate(names):
                if not isinstance(name, str) or not name:
                    raise MeshError(f"name of loop edge {i} must be a non-empty string, got {name!r}")
        # Edge by edge in order, but only the edges that can fail: arcs, and the first
        # degenerate straight edge.
        same = np.all(vertices == np.roll(vertices, -1, axis=0), axis=1)
        suspects = set() if arcs.count(None) == k else {i for i, arc in enumerate(arcs) if arc is not None}
        suspects.update(np.flatnonzero(same)[:1].tolist())
        for i in sorted(suspects):
            arc = arcs[i]
            if arc is not None and not isinstance(arc, Arc):
                raise MeshError(f"edge_arcs[{i}] must be an Arc or None, got {arc!r}")
            start, end = vertices[i], vertices[(i + 1) % k]
            if same[i]:
                raise MeshError(f"loop edge {i} starts and ends at the same point {start.tolist()}")
            if arc is not None:
                center = np.asarray(arc.center)
                r_start = float(np.linalg.norm(start - center))
                r_end = float(np.linalg.norm(end - center))
                if r_start == 0.0 or abs(r_end - r_start) > RADIUS_TOLERANCE * r_start:
                    raise MeshError(
                        f"arc edge {i} ({names[i]!r}): end vertex {end.tolist()} is at distance "
                        f"{r_end:.12g} from centre {arc.center}, start vertex at {r_start:.12g}"
                    )
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "edge_names", names)
        object.__setattr__(self, "edge_arcs", arcs)

    # Per-edge attributes as arrays, made in C (map, count): a profile has 10^5 edges.
    @cached_property
    def part_codes(self) -> tuple[tuple[str, ...], np.ndarray]:
        """The loop's part names in order of first appearance, and each edge's index among them (k,)."""
        names = tuple(dict.fromkeys(self.edge_names))
        index = {name: i for i, name in enumerate(names)}
        codes = np.fromiter(map(index.__getitem__, self.edge_names), dtype=np.int64, count=len(self.edge_names))
        return names, codes

    def on_parts(self, parts) -> np.ndarray:
        """Whether each edge (k,) belongs to one of ``parts`` (part names)."""
        names, codes = self.part_codes
        wanted = set(parts)
        return np.isin(codes, [i for i, name in enumerate(names) if name in wanted])

    @cached_property
    def straight_edges(self) -> np.ndarray:
        """Whether each edge (k,) is straight (not an arc); read-only."""
        k = len(self.edge_arcs)
        straight = (np.ones(k, dtype=bool) if self.edge_arcs.count(None) == k
                    else np.fromiter(map(operator.is_, self.edge_arcs, itertools.repeat(None)), dtype=bool, count=k))
        straight.setflags(write=False)
        return straight

    @property
    def arc_edges(self) -> np.ndarray:
        """The indices of the edges that are arcs, in order."""
        return np.flatnonzero(~self.straight_edges)


def _is_positive_number(value: object) -> bool:
    """Whether ``value`` is a finite real number > 0 (bools excluded)."""
    return (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and math.isfinite(value)
        and value > 0
    )


def circle_loop(center: tuple[float, float], radius: float, name: str) -> Loop:
    """A full circle as four counter-clockwise quarter arcs, all named ``name``.

    Parameters
    ----------
    center : (2,) float
    radius : float
        Positive.
    name : str
        Part name of the whole circle.

    Returns
    -------
    Loop
        Vertices at angles 0, 90, 180 and 270 degrees.
    """
    if not _is_positive_number(radius):
        raise MeshError(f"circle radius must be a positive number, got {radius!r}")
    cx, cy = (float(c) for c in center)
    r = float(radius)
    # Exact axis points (no cos/sin rounding) so all four vertices are at distance r.
    vertices = np.array([[cx + r, cy], [cx, cy + r], [cx - r, cy], [cx, cy - r]])
    arc = Arc((cx, cy), ccw=True)
    return Loop(vertices, (name,) * 4, (arc,) * 4)


def arc_sweep(start: np.ndarray, end: np.ndarray, arc: Arc) -> tuple[float, float]:
    """(θ0, sweep) of an arc edge: the angle of ``start`` seen from the centre and the signed
    angle swept to ``end`` (positive counter-clockwise, in (−2π, 2π))."""
    center = np.asarray(arc.center, dtype=float)
    theta0 = math.atan2(start[1] - center[1], start[0] - center[0])
    theta1 = math.atan2(end[1] - center[1], end[0] - center[0])
    sweep = (theta1 - theta0) % (2 * math.pi) if arc.ccw else -((theta0 - theta1) % (2 * math.pi))
    return theta0, sweep


#: Largest angle one chord spans in :func:`loop_outline`; a chord then lies within
#: r (1 − cos(ε/2)) ≈ 4e-5 r of its arc.
OUTLINE_CHORD_ANGLE = math.pi / 180


def loop_outline(loop: Loop, max_angle: float = OUTLINE_CHORD_ANGLE) -> np.ndarray:
    """The closed curve of ``loop`` as a polygon (k, 2): its vertices, and along each arc
    points at most ``max_angle`` apart (the last point is not repeated)."""
    k = len(loop.vertices)
    chunks = []
    following = 0  # the first vertex not yet in the outline
    # Runs of straight edges are their vertices; only the arcs (a few) are visited.
    for i in loop.arc_edges.tolist():
        start, end = loop.vertices[i], loop.vertices[(i + 1) % k]
        arc = loop.edge_arcs[i]
        theta0, sweep = arc_sweep(start, end, arc)
        n = max(1, math.ceil(abs(sweep) / max_angle))
        theta = theta0 + sweep * np.arange(1, n) / n
        radius = float(np.linalg.norm(start - np.asarray(arc.center)))
        inner = np.asarray(arc.center) + radius * np.stack([np.cos(theta), np.sin(theta)], axis=1)
        chunks += [loop.vertices[following:i + 1], inner]
        following = i + 1
    chunks.append(loop.vertices[following:])
    return np.concatenate(chunks)


def loop_signed_area(loop: Loop) -> float:
    """Signed area enclosed by ``loop``, arcs included (positive when counter-clockwise)."""
    vertices = loop.vertices
    following = np.roll(vertices, -1, axis=0)
    area = 0.5 * float(np.sum(vertices[:, 0] * following[:, 1] - vertices[:, 1] * following[:, 0]))
    for i in loop.arc_edges.tolist():
        arc = loop.edge_arcs[i]
        _, sweep = arc_sweep(vertices[i], following[i], arc)
        radius = float(np.linalg.norm(vertices[i] - np.asarray(arc.center)))
        # The circular segment between the chord and the arc, on the arc's side.
        area += 0.5 * radius**2 * (sweep - math.sin(sweep))
    return area


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
    if not _is_positive_number(max_edge):
        raise MeshError(f"max_edge must be a positive number, got {max_edge!r}")
    if not (_is_positive_number(min_angle) and min_angle <= MAX_MIN_ANGLE):
        raise MeshError(f"min_angle must be in (0, {MAX_MIN_ANGLE:g}] degrees, got {min_angle!r}")
    loops = [outer, *holes]
    for index, loop in enumerate(loops):
        if not isinstance(loop, Loop):
            raise MeshError(f"{_loop_label(index)} must be a Loop, got {type(loop).__name__}")
    max_edge = float(max_edge)
    boundary = _discretise(loops, max_edge, size)
    return _triangulate_boundary(boundary, max_edge, min_angle, size, max_points)
