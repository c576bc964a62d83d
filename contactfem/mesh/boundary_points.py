"""The points along the loops' edges that Triangle starts from, spaced by a length or a size field."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np

from contactfem.case.loops import RADIUS_TOLERANCE
from contactfem.mesh.core import Circle

if TYPE_CHECKING:
    from contactfem.case.loops import Arc, Loop

#: Largest angle one chord of an arc may span, whatever max_edge is, so that coarse
#: meshes of small circles are still recognisably round (8 chords per full circle).
MAX_CHORD_ANGLE = math.pi / 4
# A size field: target edge length at points (k, 2) -> (k,).
SizeField = Callable[[np.ndarray], np.ndarray]


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

