"""Exact orientation predicates on straight segments, the tests the crossing checks are built on."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

#: Relative error bound of the floating-point orientation determinant
#: (Shewchuk's ccwerrboundA is (3 + 16 eps) eps = 3.3e-16; rounded up for safety).
_ORIENT_ERROR_BOUND = 1e-15


def _orientation(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Sign of the turn p -> q -> r: +1 left, -1 right, 0 collinear, exact for float input.

    Parameters
    ----------
    p, q, r : (m, 2) float64

    Returns
    -------
    (m,) int8
    """
    left = (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1])
    right = (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
    det = left - right
    sign = np.sign(det).astype(np.int8)
    # Floating point decides unless the determinant is within its rounding error
    # bound; those few near-collinear triples are redone in exact rational arithmetic.
    bound = _ORIENT_ERROR_BOUND * (np.abs(left) + np.abs(right))
    for m in np.flatnonzero((np.abs(det) <= bound) & (bound > 0)):
        px, py, qx, qy, rx, ry = (Fraction(float(v)) for v in (*p[m], *q[m], *r[m]))
        exact = (qx - px) * (ry - py) - (qy - py) * (rx - px)
        sign[m] = (exact > 0) - (exact < 0)
    return sign


def _on_segment(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Whether point c, known to be collinear with segment ab, lies on the closed segment."""
    return (
        (np.minimum(a[:, 0], b[:, 0]) <= c[:, 0])
        & (c[:, 0] <= np.maximum(a[:, 0], b[:, 0]))
        & (np.minimum(a[:, 1], b[:, 1]) <= c[:, 1])
        & (c[:, 1] <= np.maximum(a[:, 1], b[:, 1]))
    )


def _segments_intersect(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Whether closed segments ab and cd share a point (touching counts).

    Parameters
    ----------
    a, b, c, d : (m, 2) float64

    Returns
    -------
    (m,) bool
    """
    o1 = _orientation(a, b, c)
    o2 = _orientation(a, b, d)
    o3 = _orientation(c, d, a)
    o4 = _orientation(c, d, b)
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)
    touching = (
        ((o1 == 0) & _on_segment(a, b, c))
        | ((o2 == 0) & _on_segment(a, b, d))
        | ((o3 == 0) & _on_segment(c, d, a))
        | ((o4 == 0) & _on_segment(c, d, b))
    )
    return proper | touching


def _orient(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> int:
    """Scalar :func:`_orientation`: the sign of the turn a -> b -> c, exact for float input."""
    left = (bx - ax) * (cy - ay)
    right = (by - ay) * (cx - ax)
    det = left - right
    bound = _ORIENT_ERROR_BOUND * (abs(left) + abs(right))
    if det > bound:
        return 1
    if det < -bound:
        return -1
    if bound == 0.0 and (bx == ax or cy == ay) and (by == ay or cx == ax):
        return 0  # both products have an exactly zero factor
    exact = ((Fraction(bx) - Fraction(ax)) * (Fraction(cy) - Fraction(ay))
             - (Fraction(by) - Fraction(ay)) * (Fraction(cx) - Fraction(ax)))
    return (exact > 0) - (exact < 0)


def _lexicographic_ranks(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order of ``points`` by (x, y), and the rank of each point in it."""
    order = np.lexsort((points[:, 1], points[:, 0]))
    rank = np.empty(len(points), dtype=np.int64)
    rank[order] = np.arange(len(points), dtype=np.int64)
    return order, rank


def _repeats(points: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Indices of the points equal to a point of smaller index (``order``: the stable (x, y) sort)."""
    ordered = points[order]
    same = np.all(ordered[1:] == ordered[:-1], axis=1)
    later = np.flatnonzero(same) + 1
    # A group of equal points keeps index order (the sort is stable): all but its first repeat.
    return np.sort(order[later])

