"""The edges of a triangulation and how they connect to its triangles, computed once.

Every stage that needs edges (stiffness assembly, refinement, bisection, error
estimators) reads them from one :class:`Topology`. Its construction is a linear-time
radix sort with int32 indices whenever they fit, so it is cheap and light enough for
meshes of millions of triangles; arrays that not every caller needs are derived lazily.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

__all__ = ["Topology"]

# Largest index (and element count) that int32 index arrays can hold.
_INT32_LIMIT = np.iinfo(np.int32).max


def _read_only(array: np.ndarray) -> np.ndarray:
    # The arrays are shared by everything that asks a mesh for its topology: writing into
    # one would silently corrupt the others' view of the mesh.
    array.flags.writeable = False
    return array


def _counting_sort(keys: np.ndarray, n_keys: int, payload: np.ndarray, ramp: np.ndarray):
    """Stable sort of ``keys`` (values in [0, n_keys)) in O(len + n_keys).

    A CSR matrix with one entry per row (row r, column keys[r]) converted to CSC lists
    the rows column by column, in row order: scipy's csr_tocsc is a counting sort.

    Returns
    -------
    order : positions of the keys in sorted order
    payload[order]
    starts : (n_keys + 1,) where each key's run begins in the sorted order
    """
    m = len(keys)
    by_key = sp.csr_matrix((payload, keys, ramp[: m + 1]), shape=(m, n_keys)).tocsc()
    return by_key.indices, by_key.data, by_key.indptr


@dataclass(frozen=True, eq=False, repr=False)
class Topology:
    """The undirected edges of a triangulation and their incidence with its triangles.

    Half-edge ``3 t + k`` runs from node ``k`` to node ``k + 1`` (mod 3) of triangle
    ``t``. Index arrays are int32 when every index fits (int64 otherwise), except where
    stated. All arrays are read-only: one topology is shared by every user of a mesh.

    Attributes
    ----------
    n_points : int
        Number of nodes; node indices are in [0, n_points).
    edges : (n_edges, 2) int32 or int64
        Node pairs ``lo < hi``, sorted lexicographically. Stored column-major, so that
        ``edges[:, 0]`` and ``edges[:, 1]`` are contiguous.
    half_edge_edge : (3 n_triangles,) int32 or int64
        Edge index of every half-edge.
    half_edge_flipped : (3 n_triangles,) bool
        Whether the half-edge runs from the edge's high node to its low node.

    Derived on first access:

    edge_triangles : (n_edges, 2) int64
        Column 0 the triangle in which the edge runs lo → hi, column 1 the triangle in
        which it runs hi → lo, -1 where there is none (boundary edges have exactly one).
    boundary : (n_boundary,) int64
        Increasing indices of the edges that belong to exactly one triangle.
    boundary_half_edges : (n_boundary,) int64
        The half-edge of each of those edges (its triangle is ``h // 3``).
    """

    n_points: int
    edges: np.ndarray
    half_edge_edge: np.ndarray
    half_edge_flipped: np.ndarray

    @classmethod
    def from_triangles(cls, triangles: np.ndarray, n_points: int) -> "Topology":
        """Build the topology of ``triangles`` (n_triangles, 3), node indices in [0, n_points).

        Raises
        ------
        ValueError
            If ``triangles`` is not an integer (n, 3) array with nodes in range, or a
            triangle repeats a node.
        """
        triangles = np.asarray(triangles)
        n_points = int(n_points)
        if triangles.ndim != 2 or triangles.shape[1] != 3 or not (
            np.issubdtype(triangles.dtype, np.integer) or triangles.size == 0
        ):
            raise ValueError(f"triangles must be an integer (n, 3) array, got {triangles.dtype} {triangles.shape}")
        n_tri = len(triangles)
        index_type = np.int32 if max(3 * n_tri + 1, n_points) <= _INT32_LIMIT else np.int64
        if n_tri == 0:
            return cls(
                n_points=n_points,
                edges=_read_only(np.empty((2, 0), dtype=index_type).T),
                half_edge_edge=_read_only(np.empty(0, dtype=index_type)),
                half_edge_flipped=_read_only(np.empty(0, dtype=bool)),
            )
        if int(triangles.min()) < 0 or int(triangles.max()) >= n_points:
            raise ValueError(f"triangle nodes must be in [0, {n_points})")
        tri = np.ascontiguousarray(triangles, dtype=index_type)
        start = tri.ravel()
        end = tri[:, [1, 2, 0]].ravel()
        lo = np.minimum(start, end)
        hi = np.maximum(start, end)
        flipped = start > end
        del end
        if np.any(lo == hi):
            t = int(np.flatnonzero(lo == hi)[0]) // 3
            raise ValueError(f"triangle {t} repeats a node: {tri[t].tolist()}")
        m = len(lo)
        ramp = np.arange(m + 1, dtype=index_type)
        # Radix sort by (lo, hi): by hi first, then stably by lo. No comparison sort, so
        # this stays linear whatever the node numbering.
        by_hi, lo_by_hi, _ = _counting_sort(hi, n_points, lo, ramp)
        del lo
        _, order, lo_starts = _counting_sort(lo_by_hi, n_points, by_hi, ramp)
        del by_hi, lo_by_hi, ramp
        hi_sorted = hi[order]
        del hi
        lo_sorted = np.repeat(np.arange(n_points, dtype=index_type), np.diff(lo_starts))
        first = np.empty(m, dtype=bool)
        first[0] = True
        np.not_equal(hi_sorted[1:], hi_sorted[:-1], out=first[1:])
        first[1:] |= lo_sorted[1:] != lo_sorted[:-1]
        edge_sorted = np.cumsum(first, dtype=index_type)
        edge_sorted -= 1
        edge_of = np.empty(m, dtype=index_type)
        edge_of[order] = edge_sorted
        n_edges = int(edge_sorted[-1]) + 1
        del order, edge_sorted
        edges = np.empty((2, n_edges), dtype=index_type)
        np.compress(first, lo_sorted, out=edges[0])
        np.compress(first, hi_sorted, out=edges[1])
        return cls(
            n_points=n_points,
            edges=_read_only(edges.T),
            half_edge_edge=_read_only(edge_of),
            half_edge_flipped=_read_only(flipped),
        )

    def __repr__(self) -> str:
        return f"Topology(n_points={self.n_points}, n_triangles={self.n_triangles}, n_edges={self.n_edges})"

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    @property
    def n_triangles(self) -> int:
        return len(self.half_edge_edge) // 3

    @cached_property
    def edge_triangles(self) -> np.ndarray:
        """(n_edges, 2) int64: the triangle on each side of every edge, -1 where none.

        Raises
        ------
        ValueError
            If an edge runs the same way in two triangles (they overlap, or are not
            consistently oriented) or belongs to more than two: there is then no
            pair of sides to list.
        """
        edge, flipped = self.half_edge_edge, self.half_edge_flipped
        result = np.full((self.n_edges, 2), -1, dtype=np.int64)
        for column, mask in enumerate((~flipped, flipped)):
            half = np.flatnonzero(mask)
            edge_of_half = edge[half]
            count = np.bincount(edge_of_half, minlength=self.n_edges)
            if self.n_edges and count.max() > 1:
                a, b = self.edges[int(np.argmax(count))].tolist()
                raise ValueError(
                    f"edge ({a}, {b}) runs the same way in two triangles "
                    "(overlapping or inconsistently oriented triangles, or more than two on one edge)"
                )
            result[edge_of_half, column] = half // 3
        return _read_only(result)

    @cached_property
    def boundary_half_edges(self) -> np.ndarray:
        """(n_boundary,) int64: the only half-edge of each boundary edge, in edge order.

        Counted directly from the half-edges, so it is defined for any triangulation,
        conforming or not (an edge in three triangles is not on the boundary).
        """
        edge = self.half_edge_edge
        single = np.bincount(edge, minlength=self.n_edges) == 1
        half = np.flatnonzero(single[edge])
        # Each boundary edge has one half-edge, so a plain sort by edge is unambiguous.
        return _read_only(half[np.argsort(edge[half])])

    @cached_property
    def boundary(self) -> np.ndarray:
        """(n_boundary,) int64: increasing indices of the edges in exactly one triangle."""
        return _read_only(self.half_edge_edge[self.boundary_half_edges].astype(np.int64))

    @cached_property
    def _keys(self) -> np.ndarray:
        # lo * n_points + hi: increasing, since the edges are sorted by (lo, hi).
        return self.edges[:, 0].astype(np.int64) * np.int64(self.n_points) + self.edges[:, 1]

    def edge_index(self, a, b) -> np.ndarray:
        """Undirected edge index of each node pair (a, b), -1 where the pair is not an edge.

        ``a`` and ``b`` are integer arrays (or scalars) that broadcast together; nodes
        outside [0, n_points) are allowed and give -1. Returns int64 of their broadcast
        shape.
        """
        a = np.asarray(a, dtype=np.int64)
        b = np.asarray(b, dtype=np.int64)
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        valid = (lo >= 0) & (hi < self.n_points) & (lo != hi)
        keys = self._keys
        if len(keys) == 0:
            return np.full(valid.shape, -1, dtype=np.int64)
        key = np.where(valid, lo, 0) * np.int64(self.n_points) + np.where(valid, hi, 0)
        slot = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
        return np.where(valid & (keys[slot] == key), slot, -1).astype(np.int64, copy=False)
