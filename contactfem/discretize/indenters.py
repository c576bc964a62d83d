"""Curved rigid obstacles: a disk and an open polyline (a polyline or a rigid profile).

Each contact node gets the gap and normal of its closest point on the obstacle in the
reference configuration (small deformations: the normals do not follow the motion). The
normal points from the body into the obstacle; the gap is the distance to the closest
point, positive when apart. A node whose closest point is an open end of a polyline,
approached from beyond it, faces no part of the obstacle and carries no constraint (as
beyond a segment's ends). A node equidistant, to round-off, from two separate parts of a
concave obstacle (closest points in directions that differ) has no single closest point: :meth:`Closest.ambiguous` marks it and the
contact boundary refuses it.

The polyline's closest points are found without an all-pairs array: the nearest vertex
bounds the distance d_v, so only segments whose midpoints lie within d_v + L_max / 2 can be
closer; a k-d tree over the midpoints lists them (k nearest, k doubled until that radius
is covered), and the exact point-segment projection is evaluated on those pairs at once.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

#: Two candidates within this share of the obstacle's size of the least distance, whose
#: closest points lie farther apart than :data:`SEPARATE` times that distance (their
#: normals differ by more than about that angle), make a node's closest point ambiguous.
#: Neighbouring segments of a convex bend tie near their common vertex with closest
#: points about sqrt(2 d TIED size) apart: far less than SEPARATE d.
TIED = 1e-10
SEPARATE = 1e-3
#: Nearest segment midpoints asked for each node before a ball query lists the rest.
FIRST_ASK = 16


@dataclass(frozen=True, eq=False)
class Closest:
    """Each point's closest point on the obstacle: ``points`` (k, 2), ``normals`` (k, 2)
    (unit, from the body into the obstacle), ``gap`` (k,), ``abscissa`` (k,) (the position
    of the closest point along the obstacle), ``faces`` (k,) and ``ambiguous`` (k,) bool."""

    points: np.ndarray
    normals: np.ndarray
    gap: np.ndarray
    abscissa: np.ndarray
    faces: np.ndarray
    ambiguous: np.ndarray


class _Curved:
    """What the curved obstacles share: the protocol answered from :meth:`closest`."""

    flat = False
    ends = None
    normal = None
    extent = None

    def closest(self, points: np.ndarray) -> Closest:  # pragma: no cover - each shape defines it
        raise NotImplementedError

    def gap(self, points: np.ndarray) -> np.ndarray:
        return self.closest(points).gap

    def normals(self, points: np.ndarray) -> np.ndarray:
        return self.closest(points).normals

    def faces(self, points: np.ndarray) -> np.ndarray:
        return self.closest(points).faces

    def abscissa(self, points: np.ndarray) -> np.ndarray:
        return self.closest(points).abscissa


@dataclass(frozen=True, eq=False)
class Circle(_Curved):
    """The rigid disk of ``center`` (2,) and ``radius``; the body lies outside it.

    The abscissa is the arc length R φ of the closest point, φ measured clockwise (the
    sense of a flat obstacle's tangent (−n_y, n_x)) from the unit ``reference`` direction
    (from the center), so that it runs without a cut over a contact zone around it: the
    contact boundary sets it from the geometry, the same on every mesh of a case (None:
    the direction of the points' mean)."""

    center: np.ndarray
    radius: float
    reference: np.ndarray | None = None
    kind = "circle"

    @property
    def point(self) -> np.ndarray:
        return self.center

    def closest(self, points: np.ndarray) -> Closest:
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        r = p - self.center
        distance = np.hypot(r[:, 0], r[:, 1])
        ambiguous = distance <= TIED * self.radius
        radial = r / np.where(ambiguous, 1.0, distance)[:, None]
        radial[ambiguous] = (0.0, -1.0)
        mean = radial.sum(axis=0) if self.reference is None else np.asarray(self.reference, dtype=float)
        mean = mean / np.hypot(*mean) if np.hypot(*mean) > 0 else np.array([0.0, -1.0])
        angle = np.arctan2(mean[0] * radial[:, 1] - mean[1] * radial[:, 0], radial @ mean)
        return Closest(points=self.center + self.radius * radial, normals=-radial, gap=distance - self.radius,
                       abscissa=-self.radius * angle, faces=np.ones(len(p), dtype=bool), ambiguous=ambiguous)

    def outline(self, segments: int = 256) -> np.ndarray:
        """Points (segments + 1, 2) around the circle, clockwise: the disk on the right of
        the walk, as for a polyline obstacle."""
        angle = np.linspace(0.0, -2 * np.pi, segments + 1)
        return self.center + self.radius * np.stack([np.cos(angle), np.sin(angle)], axis=1)

    def describe(self) -> dict:
        return {"kind": self.kind, "center": [float(v) for v in self.center], "radius": float(self.radius),
                "small_deformations": True}


@dataclass(frozen=True, eq=False)
class Polyline(_Curved):
    """The rigid obstacle bounded by the open polyline through ``vertices`` (k, 2), lying
    on the right of the walk from the first vertex to the last.

    A segment's normal is its walk direction turned clockwise; at a corner the normal is
    the direction from the node to the corner. The abscissa is the arc length of the
    closest point from the first vertex, plus the first vertex's position along the first
    segment: a two-vertex polyline gives the segment's own abscissa."""

    vertices: np.ndarray
    kind = "polyline"

    @property
    def point(self) -> np.ndarray:
        return self.vertices[0]

    def outline(self) -> np.ndarray:
        return self.vertices

    def closest(self, points: np.ndarray) -> Closest:
        from scipy.spatial import cKDTree

        p = np.asarray(points, dtype=float).reshape(-1, 2)
        v = self.vertices
        a, b = v[:-1], v[1:]
        step = b - a
        length = np.hypot(step[:, 0], step[:, 1])
        direction = step / length[:, None]
        seg_normal = np.stack([direction[:, 1], -direction[:, 0]], axis=1)
        start = np.concatenate([[0.0], np.cumsum(length)]) + v[0] @ direction[0]
        size = float(np.ptp(v, axis=0).max(initial=0.0)) or float(length.max())
        node, seg = _candidates(p, v, cKDTree(v), cKDTree(0.5 * (a + b)), float(length.max()))
        raw = np.einsum("ij,ij->i", p[node] - a[seg], direction[seg]) / length[seg]
        t = np.clip(raw, 0.0, 1.0)
        q = a[seg] + t[:, None] * step[seg]
        d = np.hypot(*(q - p[node]).T)
        # The least distance per node, ties to the lower segment (a corner is both neighbours' end).
        order = np.lexsort((seg, d, node))
        first = np.r_[True, node[order][1:] != node[order][:-1]]
        best = order[first]
        least = np.full(len(p), np.inf)
        least[node[best]] = d[best]
        where = np.full((len(p), 2), np.nan)
        where[node[best]] = q[best]
        tied = (d <= least[node] + TIED * size) & (np.hypot(*(q - where[node]).T) > SEPARATE * least[node])
        ambiguous = np.zeros(len(p), dtype=bool)
        ambiguous[node[tied]] = True
        i, s, u, qb, db = node[best], seg[best], raw[best], q[best], d[best]
        normals = seg_normal[s].copy()
        corner = (u < 0.0) | (u > 1.0)
        # At a corner: from the node to it, signed so that it points into the obstacle
        # (the adjacent segments' normals give the obstacle's side).
        at = np.where(u[corner] < 0.0, s[corner], s[corner] + 1)  # the corner's vertex
        last = len(length) - 1
        side = (np.where((at <= last)[:, None], seg_normal[np.minimum(at, last)], 0.0)
                + np.where((at >= 1)[:, None], seg_normal[np.maximum(at - 1, 0)], 0.0))
        towards = qb[corner] - p[i[corner]]
        reach = db[corner]
        sign = np.where(np.einsum("ij,ij->i", towards, side) >= 0.0, 1.0, -1.0)
        bent = np.where(reach[:, None] > 0, sign[:, None] * towards / np.where(reach > 0, reach, 1.0)[:, None],
                        side / np.hypot(*side.T)[:, None])
        normals[corner] = bent
        gap = np.einsum("ij,ij->i", qb - p[i], normals)
        slack = 1e-9 * max(float(length.sum()), abs(start[0]), abs(start[-1])) / length[s]
        beyond = ((s == 0) & (u < -slack)) | ((s == len(length) - 1) & (u > 1.0 + slack))
        faces = np.zeros(len(p), dtype=bool)
        faces[i] = ~beyond
        out_normals, out_gap, out_abscissa, out_points = (np.zeros((len(p), 2)), np.zeros(len(p)), np.zeros(len(p)),
                                                           np.zeros((len(p), 2)))
        out_normals[i], out_gap[i], out_points[i] = normals, gap, qb
        out_abscissa[i] = start[s] + np.clip(u, 0.0, 1.0) * length[s]
        return Closest(points=out_points, normals=out_normals, gap=out_gap, abscissa=out_abscissa, faces=faces,
                       ambiguous=ambiguous)

    def describe(self) -> dict:
        return {"kind": self.kind, "vertices": np.asarray(self.vertices, dtype=float).tolist(),
                "small_deformations": True}


def _candidates(points: np.ndarray, vertices: np.ndarray, vertex_tree, midpoint_tree,
                longest: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (node (c,), segment (c,)) holding every segment that may be a node's closest:
    those whose midpoints lie within the nearest vertex's distance plus half the longest
    segment. The :data:`FIRST_ASK` nearest midpoints settle most nodes (their last one lies
    beyond that reach); the others are listed by one ball query each, in C."""
    n_segments = len(vertices) - 1
    reach = vertex_tree.query(points)[0] + 0.5 * longest * (1 + 1e-12)
    k = min(FIRST_ASK, n_segments)
    dist, index = midpoint_tree.query(points, k=k)
    dist, index = dist.reshape(len(points), -1), index.reshape(len(points), -1)
    done = (dist[:, -1] > reach) | (k >= n_segments)
    rows, cols = np.nonzero(done[:, None] & (dist <= reach[:, None]))
    nodes, segments = [rows], [index[rows, cols]]
    pending = np.flatnonzero(~done)
    if len(pending):
        lists = midpoint_tree.query_ball_point(points[pending], reach[pending], return_sorted=False)
        counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
        nodes.append(np.repeat(pending, counts))
        segments.append(np.fromiter(itertools.chain.from_iterable(lists), dtype=np.int64, count=int(counts.sum())))
    return np.concatenate(nodes), np.concatenate(segments)
