"""The ``obstacle`` section: a flat line or segment, a circle, a polyline or a rigid profile, and how it moves."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from contactfem.case import limits
from contactfem.case.model import Obstacle, ObstacleMotion, PlatenControl
from contactfem.case.predicates import orientation, segments_intersect
from contactfem.case.profile import GRAPH_OPTIONS, PROFILE_SOURCES, profile_graph
from contactfem.case.reader import Reader
from contactfem.errors import CaseError

#: The shapes an obstacle is given by, one per case.
SHAPES = ("point and normal", "points", "segment", "circle", "polyline", "profile")
_KEYS = ("point", "normal", "points", "segment", "circle", "polyline", "profile", "motion")
#: Segment pairs tested at once for a polyline's self-intersection.
_PAIRS_PER_BLOCK = 250_000


def read_obstacle(r: Reader, data: Any, source: Path | None = None) -> Obstacle:
    data = r.mapping(data, "obstacle", _KEYS)
    motion = read_motion(r, data["motion"]) if "motion" in data else None
    given = [key for key in ("points", "segment", "circle", "polyline", "profile") if key in data]
    if given:
        key = given[0]
        if len(given) > 1 or "point" in data or "normal" in data:
            raise r.fail("obstacle", {k: "..." for k in data if k != "motion"},
                         "give one of: point and normal, points (an infinite line), segment (a finite one), "
                         "circle, polyline or profile")
        if key == "circle":
            return _circle(r, data[key], motion)
        if key == "polyline":
            return _polyline(r, data[key], motion)
        if key == "profile":
            return _profile(r, data[key], source, motion)
        return _line_through(r, key, data[key], motion)
    for key in ("point", "normal"):
        if key not in data:
            raise CaseError(f"{r.filename}: obstacle.{key}: missing (give point and normal, points, segment, "
                            "circle, polyline or profile)")
    point = r.point(data["point"], "obstacle.point")
    normal = np.array(r.point(data["normal"], "obstacle.normal"))
    length = np.hypot(*normal)
    if abs(length - 1.0) > 1e-6:
        raise r.fail("obstacle.normal", normal.tolist(), "expected a unit vector pointing into the obstacle")
    return Obstacle(point=point, normal=tuple(normal / length), motion=motion)


def read_motion(r: Reader, data: Any) -> ObstacleMotion:
    """``motion: {direction: [dx, dy], displacement: d}`` or ``{direction, force: F}``."""
    data = r.mapping(data, "obstacle.motion", ("direction", "displacement", "force"), required=("direction",))
    controls = [c for c in PlatenControl if c.value in data]
    if len(controls) != 1:
        raise r.fail("obstacle.motion", data, "expected direction and exactly one of displacement (how far the "
                                              "obstacle advances) or force (how hard it presses)")
    direction = np.array(r.point(data["direction"], "obstacle.motion.direction"))
    norm = float(np.hypot(*direction))
    if not norm > 0:
        raise r.fail("obstacle.motion.direction", direction.tolist(), "expected a nonzero vector [dx, dy]")
    (control,) = controls
    value = r.number(data[control.value], f"obstacle.motion.{control.value}", low=0, low_open=True,
                     high=limits.SCALE_LIMIT, expected=f"expected a {control.value} > 0 along the direction")
    return ObstacleMotion(direction=tuple(float(v) for v in direction / norm), control=control, value=value)


def _line_through(r: Reader, key: str, points: Any, motion: ObstacleMotion | None) -> Obstacle:
    if not isinstance(points, list) or len(points) != 2:
        raise r.fail(f"obstacle.{key}", points, "expected two points [[x0, y0], [x1, y1]] on the obstacle's surface")
    p0 = np.array(r.point(points[0], f"obstacle.{key}[0]"))
    p1 = np.array(r.point(points[1], f"obstacle.{key}[1]"))
    d = p1 - p0
    length = np.hypot(*d)
    scale = max(np.abs(p0).max(), np.abs(p1).max(), 1e-300)
    if not length > 1e-9 * scale:
        raise r.fail(f"obstacle.{key}", points, "the two points must differ (a segment of positive length)")
    # The obstacle lies to the right of the line walked from the first point to the second.
    normal = (d[1] / length, -d[0] / length)
    ends = (tuple(float(v) for v in p0), tuple(float(v) for v in p1)) if key == "segment" else None
    return Obstacle(point=tuple(float(v) for v in p0), normal=normal, ends=ends, motion=motion)


def _circle(r: Reader, data: Any, motion: ObstacleMotion | None) -> Obstacle:
    data = r.mapping(data, "obstacle.circle", ("center", "radius"), required=("center", "radius"))
    center = r.point(data["center"], "obstacle.circle.center")
    radius = r.number(data["radius"], "obstacle.circle.radius", low=0, low_open=True, high=limits.SCALE_LIMIT,
                      expected="expected a radius > 0")
    scale = max(abs(center[0]), abs(center[1]), radius)
    if not radius > 1e-9 * scale:
        raise r.fail("obstacle.circle.radius", radius, f"expected a radius > 1e-9 of the center's coordinates "
                                                       f"({scale:g}): a circle of positive size")
    return Obstacle(point=center, normal=None, shape="circle", center=center, radius=radius, motion=motion)


def _polyline(r: Reader, data: Any, motion: ObstacleMotion | None) -> Obstacle:
    limit = limits.MAX_POLYGON_VERTICES
    if not isinstance(data, list) or not 2 <= len(data) <= limit:
        raise r.fail("obstacle.polyline", data if not isinstance(data, list) else f"<{len(data)} points>",
                     f"expected a list of 2 to {limit} points [[x0, y0], [x1, y1], ...], the obstacle on the right "
                     "of the walk")
    vertices = np.array([r.point(p, f"obstacle.polyline[{i}]") for i, p in enumerate(data)])
    problem = polyline_problem(vertices)
    if problem is not None:
        raise r.fail("obstacle.polyline", f"<{len(vertices)} points>", f"expected a simple open polyline: {problem}")
    return _open_polyline(vertices, motion)


def _profile(r: Reader, spec: Any, source: Path | None, motion: ObstacleMotion | None) -> Obstacle:
    key = "obstacle.profile"
    spec = r.mapping(spec, key, (*PROFILE_SOURCES, *GRAPH_OPTIONS))
    s, h, origin, d, n = profile_graph(r, spec, key, source or Path("."), limits.MAX_POLYGON_VERTICES)
    with np.errstate(over="ignore", invalid="ignore"):
        vertices = np.asarray(origin) + s[:, None] * d + h[:, None] * n
    if not np.all(np.isfinite(vertices)) or np.abs(vertices).max() > limits.SCALE_LIMIT:
        raise r.fail(key, f"<{len(h)} points>", f"the profile's coordinates must lie within ±{limits.SCALE_LIMIT:g}")
    problem = polyline_problem(vertices)  # a graph, but float64 may merge neighbours once placed
    if problem is not None:
        raise r.fail(key, f"<{len(h)} points>", f"expected a simple open polyline: {problem}")
    return _open_polyline(vertices, motion)


def _open_polyline(vertices: np.ndarray, motion: ObstacleMotion | None) -> Obstacle:
    return Obstacle(point=tuple(float(v) for v in vertices[0]), normal=None, shape="polyline",
                    vertices=tuple((float(x), float(y)) for x, y in vertices), motion=motion)


def polyline_problem(vertices: np.ndarray) -> str | None:
    """Why the open polyline through ``vertices`` (k, 2) is not simple, or None: a repeated
    neighbour, a fold back onto the previous segment or two segments that meet other than
    neighbours at their common vertex (touching counts, exact predicates).

    Segments are compared only when their x-ranges overlap (sorted by their lowest x), in
    blocks of pairs: a profile, whose x-ranges follow one another, costs O(k)."""
    v = np.asarray(vertices, dtype=float)
    steps = np.diff(v, axis=0)
    still = np.flatnonzero(~np.any(steps != 0, axis=1))
    if still.size:
        return f"points {still[0]} and {still[0] + 1} coincide"
    back = np.flatnonzero(_collinear_back(v))
    if back.size:
        return f"segments {back[0]} and {back[0] + 1} fold back onto each other"
    a, b = v[:-1], v[1:]
    low, high = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
    order = np.argsort(low, kind="stable")
    low_sorted = low[order]
    # Segment order[i] meets only segments order[j], j > i, that start (in x) before it ends.
    reach = np.searchsorted(low_sorted, high[order], side="right")
    counts = np.maximum(reach - np.arange(len(order)) - 1, 0)
    starts = np.cumsum(counts) - counts
    total = int(counts.sum())
    for begin in range(0, total, _PAIRS_PER_BLOCK):
        index = np.arange(begin, min(total, begin + _PAIRS_PER_BLOCK))
        owner = np.searchsorted(starts, index, side="right") - 1
        first = order[owner]
        second = order[owner + 1 + index - starts[owner]]
        i, j = np.minimum(first, second), np.maximum(first, second)
        apart = j > i + 1  # neighbours share their common vertex and no more (folds are checked above)
        i, j = i[apart], j[apart]
        meet = np.flatnonzero(segments_intersect(a[i], b[i], a[j], b[j]))
        if meet.size:
            pairs = sorted(zip(i[meet].tolist(), j[meet].tolist()))
            return f"segments {pairs[0][0]} and {pairs[0][1]} intersect"
    return None


def _collinear_back(v: np.ndarray) -> np.ndarray:
    """Whether segment i and segment i + 1 of the polyline ``v`` overlap beyond their common vertex."""
    if len(v) < 3:
        return np.zeros(0, dtype=bool)
    first, middle, last = v[:-2], v[1:-1], v[2:]
    turn = orientation(first, middle, last)
    back = np.einsum("ij,ij->i", middle - first, last - middle) < 0
    return (turn == 0) & back
