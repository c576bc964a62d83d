"""Where closed polygons cross or touch (one sweep over them all), and whether a polygon is a simple boundary."""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass

import numpy as np

from contactfem.mesh.predicates import (
    _lexicographic_ranks,
    _orient,
    _orientation,
    _repeats,
    _segments_intersect,
)

#: Edge pairs tested at once by :func:`first_crossing` (about 100 MB of temporaries).
_PAIRS_PER_BLOCK = 250_000


def first_crossing(first: np.ndarray, second: np.ndarray) -> np.ndarray | None:
    """A point where the closed polygons ``first`` (k, 2) and ``second`` (l, 2) meet
    (touching counts), or None: a vertex both share, or the start of an edge of ``second``
    that meets one of ``first`` (:func:`first_crossing_among` of the two)."""
    found = first_crossing_among([first, second])
    return None if found is None else found[0]


def first_crossing_among(loops: list[np.ndarray]) -> tuple[np.ndarray, int, int] | None:
    """A point where two of the closed polygons ``loops`` meet (touching counts) and the
    two loops' indices i < j, or None: a vertex two loops share, or the start of an edge of
    the later loop that meets one of the earlier. One sweep over all of them
    (:func:`_sweep`), O(N log N) for N vertices in all (a body and its many holes); loops
    that are not simple themselves fall back to testing, pair of loops by pair, the edge
    pairs whose bounding boxes overlap."""
    loops = [np.asarray(loop, dtype=float) for loop in loops]

    def by_pairs() -> tuple[np.ndarray, int, int] | None:
        for j in range(1, len(loops)):
            for i in range(j):
                point = _first_crossing_by_pairs(loops[i], loops[j])
                if point is not None:
                    return point, i, j
        return None

    if len(loops) < 2:
        return None
    if any(len(loop) < 3 or _folds(loop) is not None for loop in loops):
        return by_pairs()
    points = np.concatenate(loops)
    owner = np.repeat(np.arange(len(loops)), [len(loop) for loop in loops])
    order, _ = _lexicographic_ranks(points)
    equal = np.flatnonzero(np.all(points[order[1:]] == points[order[:-1]], axis=1))
    if equal.size:
        a, b = owner[order[equal]], owner[order[equal + 1]]
        across = np.flatnonzero(a != b)
        if not across.size:
            return by_pairs()  # a loop that repeats a vertex of its own
        first = across[0]
        return points[order[equal[first]]].copy(), int(min(a[first], b[first])), int(max(a[first], b[first]))
    crossing = _sweep(loops)
    if crossing is None:
        return None
    g, h = crossing
    if owner[g] == owner[h]:
        return by_pairs()  # a loop that crosses itself
    return points[h].copy(), int(owner[g]), int(owner[h])


def _first_crossing_by_pairs(first: np.ndarray, second: np.ndarray) -> np.ndarray | None:
    """:func:`first_crossing` over the edge pairs whose bounding boxes overlap, in blocks."""
    a, b = first, np.roll(first, -1, axis=0)
    c, d = second, np.roll(second, -1, axis=0)
    low, high = np.minimum(c, d).min(axis=0), np.maximum(c, d).max(axis=0)
    near = np.flatnonzero(np.all((np.maximum(a, b) >= low) & (np.minimum(a, b) <= high), axis=1))
    block = max(1, _PAIRS_PER_BLOCK // max(len(c), 1))
    for begin in range(0, len(near), block):
        rows = near[begin:begin + block]
        i = np.repeat(rows, len(c))
        j = np.tile(np.arange(len(c)), len(rows))
        boxes = np.all((np.maximum(a[i], b[i]) >= np.minimum(c[j], d[j]))
                       & (np.minimum(a[i], b[i]) <= np.maximum(c[j], d[j])), axis=1)
        i, j = i[boxes], j[boxes]
        hit = np.flatnonzero(_segments_intersect(a[i], b[i], c[j], d[j]))
        if hit.size:
            return c[j[hit[0]]].copy()
    return None



#: Adjacency windows tested at once by :func:`_sweep`.
_WINDOWS_PER_BATCH = 4096


def _sweep(loops: list[np.ndarray]) -> tuple[int, int] | None:
    """Shamos–Hoey over the loops' x-monotone chains, in O(k log k) time and O(k) memory.

    Each loop (at least 3 vertices, no vertex shared with any loop or repeated, no edge
    folding back onto the previous one) is cut into chains whose vertices increase in
    (x, y) order. A sweep in that order keeps the chains crossing the
    sweep line sorted from bottom to top (a Python list, searched with exact orientation
    tests): it stops only at the chains' ends, a few per loop for smooth or graph-like
    outlines. Two chains that become neighbours are tested against each other, edge by
    edge with the vectorised exact test, over the stretch where they stay neighbours,
    once that stretch ends; the windows are tested in batches. The leftmost point shared
    by two edges lies in such a stretch of the two chains it belongs to (the classical
    argument of Shamos and Hoey), so every crossing or touching of non-adjacent edges is
    found; each vertex enters O(1) tests, so the work is O(k log k) over k edges.

    Returns the smallest pair (g, h), g < h, of edges found to share a point (edges
    numbered through the loops in order: edge g runs from vertex g to the next vertex of
    its loop), or None.
    """
    return _ChainSweep(_monotone_chains(loops)).run()


@dataclass(frozen=True, eq=False)
class _Chains:
    """The loops' edges cut into chains whose vertices increase in (x, y) rank.

    Edge g runs from vertex g to vertex ``nxt[g]`` of ``points``. Chain c's vertices, in
    increasing rank, are ``cv[vstart[c]:vstart[c + 1]]``, of ranks ``cr`` at the same
    positions; ``key`` (chain * span + rank) increases over the whole array, and
    ``edge_at[m]`` is the edge starting at chain vertex position m (-1 at a chain's last).
    """

    points: np.ndarray
    nxt: np.ndarray
    vstart: np.ndarray
    cv: np.ndarray
    cr: np.ndarray
    key: np.ndarray
    span: np.int64
    edge_at: np.ndarray


def _monotone_chains(loops: list[np.ndarray]) -> _Chains:
    """The chains of :func:`_sweep`: maximal runs of a loop's edges that go the same way in rank."""
    sizes = np.array([len(loop) for loop in loops], dtype=np.int64)
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    points = np.concatenate(loops) if loops else np.zeros((0, 2))
    k = len(points)
    loop_of = np.repeat(np.arange(len(loops)), sizes)
    local = np.arange(k) - first[loop_of]
    nxt = first[loop_of] + (local + 1) % sizes[loop_of]
    prv = first[loop_of] + (local - 1) % sizes[loop_of]
    _, rank = _lexicographic_ranks(points)

    # Edge g runs from vertex g to vertex nxt[g]; chains are maximal runs of edges going
    # the same way in rank, cut where the way changes (at least twice per loop).
    up = rank[nxt] > rank
    cut = up != up[prv]
    per_loop = np.add.reduceat(cut.astype(np.int64), first) if k else np.zeros(0, dtype=np.int64)
    label = np.cumsum(cut) - np.concatenate([[0], np.cumsum(per_loop)[:-1]])[loop_of]
    label[label == 0] = per_loop[loop_of][label == 0]  # edges before the first cut close the loop
    chain_first = np.concatenate([[0], np.cumsum(per_loop)[:-1]])
    chain = chain_first[loop_of] + label - 1
    n_chains = int(per_loop.sum())
    # Path order along the loop starting at its first cut: edges before it come last.
    cut_index = np.flatnonzero(cut)
    first_cut = local[cut_index][np.searchsorted(loop_of[cut_index], np.arange(len(loops)))]
    position = np.where(local < first_cut[loop_of], local + sizes[loop_of], local)
    # Within a chain, edges in increasing rank: path order, reversed for downward chains.
    edges = np.lexsort((np.where(up, position, -position), chain))
    chain_of_edge = chain[edges]
    edge_start = np.searchsorted(chain_of_edge, np.arange(n_chains + 1))
    lower = np.where(up, np.arange(k), nxt)
    upper = np.where(up, nxt, np.arange(k))
    # Chain c's vertices, in increasing rank, are cv[vstart[c]:vstart[c + 1]].
    vstart = edge_start + np.arange(n_chains + 1)
    cv = np.empty(k + n_chains, dtype=np.int64)
    heads = vstart[:-1]
    cv[heads] = lower[edges[edge_start[:-1]]]
    body = np.ones(k + n_chains, dtype=bool)
    body[heads] = False
    cv[body] = upper[edges]
    chain_of_vertex = np.repeat(np.arange(n_chains), np.diff(vstart))
    cr = rank[cv]
    span = np.int64(k + 1)
    key = chain_of_vertex * span + cr  # increasing over the whole array
    # The edge starting at chain vertex position m (not a chain's last vertex).
    edge_at = np.full(k + n_chains, -1, dtype=np.int64)
    edge_at[body] = edges
    edge_at = np.roll(edge_at, -1)
    return _Chains(points=points, nxt=nxt, vstart=vstart, cv=cv, cr=cr, key=key, span=span, edge_at=edge_at)


class _ChainSweep:
    """The sweep of :func:`_sweep` over ``chains``: the chains crossing the sweep line from
    bottom to top (``status``), the rank from which each pair of neighbours has been
    neighbours (``since``), the stretches of neighbours still to test (``windows``) and the
    edge pairs found to share a point (``found``)."""

    def __init__(self, chains: _Chains) -> None:
        self.chains = chains
        self.found: list[tuple[int, int]] = []
        self.windows: list[tuple[int, int, int, int]] = []
        # The event loop reads single entries: Python lists are faster at that than arrays.
        self.px, self.py = chains.points[:, 0].tolist(), chains.points[:, 1].tolist()
        self.cv_list, self.cr_list = chains.cv.tolist(), chains.cr.tolist()
        self.vstart_list = chains.vstart.tolist()
        self.edge_at_list = chains.edge_at.tolist()
        self.status: list[int] = []
        self.since: dict[tuple[int, int], int] = {}

    def run(self) -> tuple[int, int] | None:
        """The smallest pair (g, h), g < h, of edges found to share a point, or None."""
        chains = self.chains
        chain_start = chains.cr[chains.vstart[:-1]]
        chain_end = chains.cr[chains.vstart[1:] - 1]
        starts: dict[int, list[int]] = {}
        for c, r in enumerate(chain_start.tolist()):
            starts.setdefault(r, []).append(c)
        ends: dict[int, list[int]] = {}
        for c, r in enumerate(chain_end.tolist()):
            ends.setdefault(r, []).append(c)
        for r in sorted({*starts, *ends}):
            if r in ends:
                a, b = ends[r]
                if self.end(r, a, b):
                    break
            else:
                a, b = starts[r]
                if self.start(r, a, b):
                    break
            if len(self.windows) >= _WINDOWS_PER_BATCH:
                self.test_windows()
                if self.found:
                    break
        self.test_windows()
        return min(self.found) if self.found else None

    def end(self, r: int, a: int, b: int) -> bool:
        """Chains ``a`` and ``b`` end at the vertex of rank ``r``: take them out of the status.
        True when that vertex lies on another chain (a crossing, recorded)."""
        status, edge_at_list, vstart_list = self.status, self.edge_at_list, self.vstart_list
        v = self.cv_list[vstart_list[a + 1] - 1]
        count, edge = self.locate(r, self.px[v], self.py[v], skip=(a, b))
        if count < 0:
            last = [edge_at_list[vstart_list[c + 1] - 2] for c in (a, b)]
            self.found.append(min((min(edge, e), max(edge, e)) for e in last))
            return True
        if count >= len(status) or status[count] not in (a, b):
            count = status.index(a)  # only after a crossing not yet tested
        other = b if status[count] == a else a
        self.remove(count, r)
        self.remove(status.index(other), r)
        return False

    def start(self, r: int, a: int, b: int) -> bool:
        """Chains ``a`` and ``b`` start at the vertex of rank ``r``: put them into the status,
        the lower first. True when that vertex lies on another chain (a crossing, recorded)."""
        status, since = self.status, self.since
        px, py, cv_list, vstart_list = self.px, self.py, self.cv_list, self.vstart_list
        v = cv_list[vstart_list[a]]
        count, edge = self.locate(r, px[v], py[v])
        if count < 0:
            first_edges = [self.edge_at_list[vstart_list[c]] for c in (a, b)]
            self.found.append(min((min(edge, e), max(edge, e)) for e in first_edges))
            return True
        wa, wb = cv_list[vstart_list[a] + 1], cv_list[vstart_list[b] + 1]
        if _orient(px[v], py[v], px[wa], py[wa], px[wb], py[wb]) < 0:
            a, b = b, a
        below = status[count - 1] if count > 0 else None
        above = status[count] if count < len(status) else None
        if below is not None and above is not None:
            self.close(below, above, r)
        status[count:count] = [a, b]
        for pair in ((below, a), (a, b), (b, above)):
            if None not in pair:
                since[pair] = r
        return False

    def test_windows(self) -> None:
        """Test the edge pairs of the stretches closed so far, recording the smallest crossing pair."""
        windows = self.windows
        if not windows:
            return
        chains = self.chains
        points, nxt = chains.points, chains.nxt
        low, high, since, until = (np.array(column, dtype=np.int64) for column in zip(*windows))
        windows.clear()
        pairs_a, pairs_b = _window_pairs(low, high, since, until, chains.vstart, chains.cr, chains.key, chains.span)
        g, h = chains.edge_at[pairs_a], chains.edge_at[pairs_b]
        adjacent = (nxt[g] == h) | (nxt[h] == g)
        g, h = g[~adjacent], h[~adjacent]
        if g.size:
            hit = _segments_intersect(points[g], points[nxt[g]], points[h], points[nxt[h]])
            if hit.any():
                a, b = np.minimum(g[hit], h[hit]), np.maximum(g[hit], h[hit])
                best = np.lexsort((b, a))[0]
                self.found.append((int(a[best]), int(b[best])))

    def side(self, c: int, r: int, x: float, y: float) -> tuple[int, int]:
        """Where (x, y), at rank r strictly inside chain c's range, lies: +1 above, -1 below,
        0 on it; and the edge of c spanning r."""
        vstart_list, cv_list, px, py = self.vstart_list, self.cv_list, self.px, self.py
        j = bisect_right(self.cr_list, r, vstart_list[c], vstart_list[c + 1])
        a, b = cv_list[j - 1], cv_list[j]
        return _orient(px[a], py[a], px[b], py[b], x, y), self.edge_at_list[j - 1]

    def locate(self, r: int, x: float, y: float, skip: tuple[int, ...] = ()) -> tuple[int, int | None]:
        """How many chains lie below the point, or (-1, edge) if it lies on one."""
        status, side = self.status, self.side
        lo, hi = 0, len(status)
        while lo < hi:
            mid = (lo + hi) // 2
            c = status[mid]
            if c in skip:
                return mid, None
            turn, edge = side(c, r, x, y)
            if turn == 0:
                return -1, edge
            if turn > 0:
                lo = mid + 1
            else:
                hi = mid
        return lo, None

    def close(self, low: int, high: int, r: int) -> None:
        """Chains ``low`` and ``high`` stop being neighbours at rank ``r``: their stretch is to be tested."""
        self.windows.append((low, high, self.since.pop((low, high)), r))

    def remove(self, index: int, r: int) -> None:
        """Take the chain at ``index`` out of the status at rank ``r``; its neighbours meet."""
        status = self.status
        c = status[index]
        below = status[index - 1] if index > 0 else None
        above = status[index + 1] if index + 1 < len(status) else None
        if below is not None:
            self.close(below, c, r)
        if above is not None:
            self.close(c, above, r)
        del status[index]
        if below is not None and above is not None:
            self.since[(below, above)] = r


def _window_pairs(low: np.ndarray, high: np.ndarray, since: np.ndarray, until: np.ndarray, vstart: np.ndarray,
                  cr: np.ndarray, key: np.ndarray, span: np.int64) -> tuple[np.ndarray, np.ndarray]:
    """Chain vertex positions (edge starts) of the edge pairs of chains ``low[i]`` and
    ``high[i]`` whose rank ranges overlap within [since[i], until[i]]: at most as many
    pairs as the two chains have edges there, plus two."""
    def edges_within(chain: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo = np.maximum(np.searchsorted(key, chain * span + a, side="left") - 1, vstart[chain])
        hi = np.minimum(np.searchsorted(key, chain * span + b, side="right") - 1, vstart[chain + 1] - 2)
        count = np.maximum(hi - lo + 1, 0)
        owner = np.repeat(np.arange(len(chain)), count)
        offset = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        return owner, lo[owner] + offset

    owner, m = edges_within(low, since, until)
    a = np.maximum(cr[m], since[owner])
    b = np.minimum(cr[m + 1], until[owner])
    which, n = edges_within(high[owner], a, b)
    return m[which], n


#: What :func:`polygon_problems` says of a simple polygon listed clockwise.
CLOCKWISE = "vertices are clockwise; list them counter-clockwise"


def polygon_problems(vertices: np.ndarray) -> str | None:
    """Why the straight polygon through ``vertices`` is not a valid counter-clockwise boundary.

    Indices in the messages are 0-based; edge ``i`` runs from vertex ``i`` to vertex
    ``(i + 1) % k``. Intersection tests use exact orientation predicates, so touching
    counts as intersecting; adjacent edges may share only their common vertex. The
    simplicity test is a sweep (:func:`_sweep`): O(k log k) time and O(k) memory.

    Parameters
    ----------
    vertices : (k, 2) float
        The polygon's corners in order.

    Returns
    -------
    str or None
        A short reason ("fewer than 3 vertices", "repeated vertex 3", "edges 1 and 4
        intersect", "zero area", "vertices are clockwise; list them counter-clockwise",
        or a shape / finiteness complaint), or None if the polygon is simple, has
        positive area and is counter-clockwise.
    """
    try:
        v = np.array(vertices, dtype=float)
    except (TypeError, ValueError):
        return "vertices must be a (k, 2) array of numbers"
    if v.ndim != 2 or v.shape[1] != 2:
        return f"vertices must be a (k, 2) array, got shape {v.shape}"
    nonfinite = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
    if nonfinite.size:
        return f"vertex {nonfinite[0]} is not finite"
    k = len(v)
    if k < 3:
        return "fewer than 3 vertices"
    order, _ = _lexicographic_ranks(v)
    repeats = _repeats(v, order)
    if repeats.size:
        return f"repeated vertex {repeats[0]}"

    # All vertices on the line through vertices 0 and 1 (distinct, see above).
    line = _orientation(np.broadcast_to(v[0], v.shape), np.broadcast_to(v[1], v.shape), v)
    if np.all(line == 0):
        return "zero area"

    crossing = self_crossing(v)
    if crossing is not None:
        return f"edges {crossing[0]} and {crossing[1]} intersect"

    nxt = np.roll(v, -1, axis=0)
    area2 = float(np.sum(v[:, 0] * nxt[:, 1] - v[:, 1] * nxt[:, 0]))
    if area2 == 0.0:
        return "zero area"
    if area2 < 0.0:
        return CLOCKWISE
    return None


def self_crossing(v: np.ndarray) -> tuple[int, int] | None:
    """Two edges of the closed polygon ``v`` (k >= 3 distinct vertices) that meet other than
    adjacent edges at their common vertex (touching counts), or None if it is simple: a fold
    back onto the previous edge, else the first pair the sweep finds."""
    folded = _folds(v)
    return folded if folded is not None else _sweep([v])


def _folds(v: np.ndarray) -> tuple[int, int] | None:
    """The first pair of adjacent edges (i, i + 1) that overlap beyond their common vertex."""
    k = len(v)
    nxt = np.roll(v, -1, axis=0)
    # Adjacent edges i and i+1 meet at vertex i+1; they overlap elsewhere only if they
    # are collinear and the second doubles back along the first.
    after = np.roll(v, -2, axis=0)
    turn = _orientation(v, nxt, after)
    back = np.einsum("ij,ij->i", nxt - v, after - nxt) < 0
    folded = np.flatnonzero((turn == 0) & back)
    if folded.size:
        i = int(folded[0])
        j = (i + 1) % k
        return min(i, j), max(i, j)
    return None
