"""Unstructured meshes of polygons with circular-arc edges and holes, via Shewchuk's Triangle."""

from __future__ import annotations

import itertools
import math
import operator
from functools import cached_property
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import triangle

from contactfem.errors import MeshError
from contactfem.mesh.core import Circle, Mesh
# Re-exported: the crossing checks lived here, and callers import them from this module.
from contactfem.mesh.crossings import (  # noqa: F401
    CLOCKWISE,
    first_crossing,
    first_crossing_among,
    polygon_problems,
    self_crossing,
)
from contactfem.mesh.refine import _undirected_keys, oriented_boundary
from contactfem.mesh.topology import Topology

__all__ = ["Arc", "Loop", "arc_sweep", "circle_loop", "first_crossing", "loop_outline", "loop_signed_area",
           "polygon_problems", "self_crossing", "triangulate_domain"]

#: Relative tolerance on the radius of an arc's end vertex.
RADIUS_TOLERANCE = 1e-9
#: Largest minimum angle for which Triangle's refinement is known to terminate.
MAX_MIN_ANGLE = 34.0
#: Largest angle one chord of an arc may span, whatever max_edge is, so that coarse
#: meshes of small circles are still recognisably round (8 chords per full circle).
MAX_CHORD_ANGLE = math.pi / 4
#: Triangle gives marker 1 to boundary edges on no input segment and 0 to interior
#: edges, so input segment s is given marker s + MARKER_OFFSET.
MARKER_OFFSET = 2
#: Relative mismatch between the meshed area and the area enclosed by the loops that
#: reveals crossing loops or a hole outside the domain.
AREA_TOLERANCE = 1e-9


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


# --------------------------------------------------------------------------------------
# Triangulation
# --------------------------------------------------------------------------------------


@dataclass
class _Boundary:
    """The discretised loops: the planar straight line graph handed to Triangle."""

    points: list[np.ndarray] = field(default_factory=list)  # per loop, (n_l, 2)
    segment_part: list[np.ndarray] = field(default_factory=list)  # per loop, (n_l,)
    segment_curve: list[np.ndarray] = field(default_factory=list)  # per loop, (n_l,)
    part_names: list[str] = field(default_factory=list)
    curves: list[Circle] = field(default_factory=list)

    def part(self, name: str) -> int:
        """Index of part ``name``, added on first use."""
        if name not in self.part_names:
            self.part_names.append(name)
        return self.part_names.index(name)

    def curve(self, center: tuple[float, float], radius: float) -> int:
        """Index of the circle, shared by arcs of (numerically) the same circle."""
        for index, circle in enumerate(self.curves):
            if (
                circle.center == center
                and abs(circle.radius - radius) <= RADIUS_TOLERANCE * circle.radius
            ):
                return index
        self.curves.append(Circle(center=center, radius=radius))
        return len(self.curves) - 1


def _arc_points(
    start: np.ndarray, end: np.ndarray, arc: Arc, max_edge: float, size: SizeField | None = None
) -> tuple[np.ndarray, float]:
    """Points along an arc, start included and end excluded, and its radius.

    Returns
    -------
    points : (n, 2) float64
        ``n`` chords of length at most ``max_edge`` and angle at most ``MAX_CHORD_ANGLE``.
    radius : float
    """
    center = np.asarray(arc.center)
    radius = float(np.linalg.norm(start - center))
    theta0 = math.atan2(start[1] - center[1], start[0] - center[0])
    theta1 = math.atan2(end[1] - center[1], end[0] - center[0])
    sweep = (theta1 - theta0) % (2 * math.pi) if arc.ccw else -((theta0 - theta1) % (2 * math.pi))
    if size is not None:
        def on_arc(t: np.ndarray) -> np.ndarray:
            angle = theta0 + sweep * t
            return center + radius * np.stack([np.cos(angle), np.sin(angle)], axis=1)

        t = _graded_parameters(on_arc, radius * abs(sweep), size)
        # Keep at most MAX_CHORD_ANGLE per chord even where the size field is coarse.
        extra = math.ceil(abs(sweep) / MAX_CHORD_ANGLE * (1 - 1e-12))
        if len(t) < extra:
            t = np.arange(extra) / extra
        return on_arc(t), radius
    # A chord is shorter than its arc, so arc length / n <= max_edge suffices.
    n = max(
        1,
        math.ceil(radius * abs(sweep) / max_edge * (1 - 1e-12)),
        math.ceil(abs(sweep) / MAX_CHORD_ANGLE * (1 - 1e-12)),
    )
    theta = theta0 + sweep * np.arange(1, n) / n
    inner = center + radius * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    return np.concatenate([start[None, :], inner]), radius


# A size field: target edge length at points (k, 2) -> (k,).
SizeField = Callable[[np.ndarray], np.ndarray]


def _graded_parameters(curve: Callable[[np.ndarray], np.ndarray], length: float, size: SizeField) -> np.ndarray:
    """Parameters t in [0, 1) of points spaced by the local size along a curve of ``length``.

    The number of pieces equidistributes ∫ ds / h(s): each piece spans about one local
    target length, so a graded boundary meets the graded triangles inside.
    """
    t = np.linspace(0.0, 1.0, 2049)
    density = length / np.maximum(size(curve(t)), 1e-300)
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(t))])
    n = max(1, math.ceil(cumulative[-1] * (1 - 1e-12)))
    return np.interp(np.arange(n) / n * cumulative[-1], cumulative, t)


def _line_points(start: np.ndarray, end: np.ndarray, max_edge: float, size: SizeField | None = None) -> np.ndarray:
    """Points along a straight edge, start included and end excluded, spaced <= max_edge."""
    points, _ = _lines_points(start[None, :], end[None, :], max_edge, size)
    return points


#: Most samples of the size field along one straight edge when grading its points.
_MAX_EDGE_SAMPLES = 2049
#: Samples of the size field per local target length along a straight edge.
_SAMPLES_PER_SIZE = 16


def _lines_points(starts: np.ndarray, ends: np.ndarray, max_edge: float,
                  size: SizeField | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Points along many straight edges at once: for edge e, its start and the points
    after it up to its end (excluded), spaced <= max_edge, or by the size field as
    :func:`_graded_parameters` spaces them. Returns the points (n, 2), edge after edge,
    and how many each edge has (e,).

    With a size field, edge e is sampled at about 16 points per local target length
    (its smallest at the ends and the middle; 2 to 2049 samples), so an outline of k
    short edges costs O(k) evaluations, not 2049 per edge.
    """
    starts = np.asarray(starts, dtype=float).reshape(-1, 2)
    ends = np.asarray(ends, dtype=float).reshape(-1, 2)
    delta = ends - starts
    length = np.hypot(delta[:, 0], delta[:, 1])
    if size is None:
        # The factor keeps lengths that are exact multiples of max_edge from gaining a
        # segment through rounding.
        counts = np.maximum(1, np.ceil(length / max_edge * (1 - 1e-12))).astype(np.int64)
        edge, t = _ragged(counts)
        return starts[edge] + (t / counts[edge])[:, None] * delta[edge], counts
    e = len(starts)
    probe = np.maximum(size(np.concatenate([starts, ends, starts + 0.5 * delta])), 1e-300).reshape(3, e).min(axis=0)
    samples = np.clip(np.ceil(_SAMPLES_PER_SIZE * length / probe) + 1, 2, _MAX_EDGE_SAMPLES).astype(np.int64)
    edge, j = _ragged(samples)
    t = j / (samples[edge] - 1)
    density = length[edge] / np.maximum(size(starts[edge] + t[:, None] * delta[edge]), 1e-300)
    first = np.cumsum(samples) - samples  # each edge's first sample
    piece = np.zeros_like(density)
    piece[1:] = 0.5 * (density[1:] + density[:-1]) * np.diff(t)
    piece[first] = 0.0
    total_before = np.cumsum(piece)  # ∫ ds / h from the first edge's start, edge after edge
    total = total_before[first + samples - 1] - total_before[first]
    counts = np.maximum(1, np.ceil(total * (1 - 1e-12))).astype(np.int64)
    owner, i = _ragged(counts)
    target = total_before[first[owner]] + i / counts[owner] * total[owner]
    # The sample interval of each target, inside its own edge; then linear interpolation.
    slot = np.searchsorted(total_before, target, side="right") - 1
    slot = np.clip(slot, first[owner], first[owner] + samples[owner] - 2)
    step = total_before[slot + 1] - total_before[slot]
    with np.errstate(divide="ignore", invalid="ignore"):
        fraction = np.where(step > 0, (target - total_before[slot]) / step, 0.0)
    tt = t[slot] + np.clip(fraction, 0.0, 1.0) * (t[slot + 1] - t[slot])
    return starts[owner] + tt[:, None] * delta[owner], counts


def _ragged(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For counts (e,): the owner e and the index 0..counts[e]-1 of each of sum(counts) items."""
    counts = np.asarray(counts, dtype=np.int64)
    owner = np.repeat(np.arange(len(counts)), counts)
    index = np.arange(len(owner), dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
    return owner, index


def _discretise(loops: list[Loop], max_edge: float, size: SizeField | None = None) -> _Boundary:
    """Split every edge of every loop into segments of length <= max_edge (or graded by
    ``size``): straight edges all at once, arcs one by one."""
    boundary = _Boundary()
    for loop in loops:
        k = len(loop.vertices)
        starts = loop.vertices
        ends = np.roll(loop.vertices, -1, axis=0)
        names, codes = loop.part_codes
        part = np.array([boundary.part(name) for name in names], dtype=np.int64)[codes]
        straight = loop.straight_edges
        arcs = np.flatnonzero(~straight).tolist()
        curve = np.full(k, -1, dtype=np.int64)
        counts = np.zeros(k, dtype=np.int64)
        line_points, counts[straight] = _lines_points(starts[straight], ends[straight], max_edge, size)
        arc_points = {}
        for i in arcs:
            pts, radius = _arc_points(starts[i], ends[i], loop.edge_arcs[i], max_edge, size)
            arc_points[i] = pts
            counts[i] = len(pts)
            curve[i] = boundary.curve(loop.edge_arcs[i].center, radius)
        offsets = np.cumsum(counts) - counts
        points = np.empty((int(counts.sum()), 2))
        owner, local = _ragged(counts[straight])
        points[offsets[straight][owner] + local] = line_points
        for i, pts in arc_points.items():
            points[offsets[i]:offsets[i] + counts[i]] = pts
        boundary.points.append(points)
        boundary.segment_part.append(np.repeat(part, counts))
        boundary.segment_curve.append(np.repeat(curve, counts))
    return boundary


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


def _refine_to_size(result: dict, holes: np.ndarray | None, size: SizeField, min_angle: float,
                    rounds: int = 12, steiner: str = "") -> dict:
    """Refine Triangle's mesh until every triangle is at most the equilateral one of edge
    h(centroid); Triangle's ``r`` switch keeps segments and their markers."""
    switches = f"rpq{float(min_angle):.6f}aQ{steiner}"
    for _ in range(rounds):
        vertices = np.asarray(result["vertices"])
        tri = np.asarray(result["triangles"])
        corners = vertices[tri]
        e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        target = np.sqrt(3) / 4 * size(corners.mean(axis=1)) ** 2
        if np.all(area <= 1.5 * target):
            break
        refine = {key: result[key] for key in ("vertices", "triangles", "segments", "segment_markers")}
        refine["triangle_max_area"] = target[:, None]
        if holes is not None:
            refine["holes"] = holes
        result = triangle.triangulate(refine, switches)
    return result


def _loop_label(index: int) -> str:
    """'the outer loop' or 'hole 2', for messages."""
    return "the outer loop" if index == 0 else f"hole {index - 1}"


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

    sizes = [len(p) for p in boundary.points]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    points = np.concatenate(boundary.points)
    segments = np.concatenate([_closed_segments(n, int(o)) for n, o in zip(sizes, offsets)])
    seg_part = np.concatenate(boundary.segment_part)
    seg_curve = np.concatenate(boundary.segment_curve)
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

    pslg: dict[str, np.ndarray] = {
        "vertices": points,
        "segments": segments.astype(np.int32),
        "segment_markers": (np.arange(len(segments), dtype=np.int32) + MARKER_OFFSET)[:, None],
    }
    if holes:
        pslg["holes"] = np.array(
            [_interior_point(boundary.points[h], _loop_label(h)) for h in range(1, len(loops))]
        )
    max_area = max_edge**2 * math.sqrt(3) / 4
    # Triangle's S switch caps the Steiner points it adds, so that memory stays bounded.
    steiner = "" if max_points is None else f"S{max(int(max_points) - len(points), 0)}"
    switches = f"pq{float(min_angle):.6f}a{_area_switch(max_area)}Q{steiner}"
    result = triangle.triangulate(pslg, switches)
    if size is not None:
        result = _refine_to_size(result, pslg.get("holes"), size, min_angle, steiner=steiner)
    if max_points is not None and len(result["vertices"]) >= max_points:
        raise MeshError(
            f"meshing with a smallest angle of {min_angle:g} degrees needs more than {max_points:.3g} nodes, "
            "more than this machine can solve: the geometry has a feature far smaller than the mesh size "
            "(a sliver, a narrow gap or a tiny edge); widen it or remove it"
        )
    tri = result.get("triangles")
    if tri is None or len(tri) == 0:
        raise MeshError("Triangle produced no triangles; are the holes inside the outer loop?")

    # Keep only nodes that some triangle uses, renumbered in their original order (marked
    # and counted: sorting the triangles' million entries took 76 ms at 354 000 triangles).
    tri = np.asarray(tri, dtype=np.int64)
    in_use = np.zeros(len(result["vertices"]), dtype=bool)
    in_use[tri] = True
    used = np.flatnonzero(in_use)
    renumber = np.full(len(result["vertices"]), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    tri = renumber[tri]
    out_points = np.array(result["vertices"][used], dtype=np.float64)
    out_segments = renumber[np.asarray(result["segments"], dtype=np.int64)]
    source = np.asarray(result["segment_markers"], dtype=np.int64).reshape(-1) - MARKER_OFFSET
    if np.any(out_segments < 0) or np.any(source < 0) or np.any(source >= len(segments)):
        raise MeshError("Triangle returned boundary segments that lie on no input loop")

    # Triangle's triangles are counter-clockwise; reorder any that are not, to be safe.
    corners = out_points[tri]
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

    # Orient the boundary from the triangles (body on the left) and give each edge
    # the part and curve of the input segment Triangle says it came from.
    n = len(out_points)
    topology = Topology.from_triangles(tri, n)
    edges = oriented_boundary(topology)
    seg_keys = _undirected_keys(out_segments, n)
    order = np.argsort(seg_keys)
    edge_keys = _undirected_keys(edges, n)
    slot = np.minimum(np.searchsorted(seg_keys[order], edge_keys), len(order) - 1)
    if np.any(seg_keys[order][slot] != edge_keys):
        raise MeshError("part of the mesh boundary lies on no input loop")
    if len(out_segments) != len(edges):
        raise MeshError("loops touch or cross: some boundary segments ended up inside the mesh")
    edge_source = source[order][slot]
    edge_parts = seg_part[edge_source]
    edge_curves = seg_curve[edge_source]

    # Triangle may split chords of arcs; put those nodes (and, harmlessly, the chord
    # ends already there) on the circle so the boundary converges to the true curve.
    for index, circle in enumerate(boundary.curves):
        nodes = np.unique(edges[edge_curves == index])
        out_points[nodes] = circle.project(out_points[nodes])
    if boundary.curves:
        corners = out_points[tri]
        e1 = corners[:, 1] - corners[:, 0]
        e2 = corners[:, 2] - corners[:, 0]
        if np.any(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] <= 0):
            raise MeshError(
                "projecting boundary nodes onto their arcs inverted a triangle; use a smaller max_edge"
            )
    elif np.any(cross == 0):  # no point moved: the triangles' areas are those measured above
        raise MeshError("Triangle produced a triangle of zero area; is part of the outline degenerate?")

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
