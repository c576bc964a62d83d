"""The triangle mesh with named boundary parts that every later stage works on."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from contactfem.errors import MeshError
from contactfem.mesh.topology import Topology


def coordinate_span(points: np.ndarray) -> np.ndarray:
    """Each coordinate's range (max − min) over ``points`` (n, d), zero for no points.
    Column by column: NumPy 2's reduction along the first axis of an (n, 2) array is an
    order of magnitude slower than two contiguous 1-D reductions, and a solve takes several."""
    points = np.asarray(points, dtype=float)
    if points.shape[0] == 0:
        return np.zeros(points.shape[1])
    return np.array([np.ptp(points[:, axis]) for axis in range(points.shape[1])])


@dataclass(frozen=True)
class Circle:
    """A circle that curved boundary edges lie on; refinement puts new nodes on it."""

    center: tuple[float, float]
    radius: float

    def project(self, points: np.ndarray) -> np.ndarray:
        """Move ``points`` (n, 2) radially onto the circle."""
        center = np.asarray(self.center, dtype=float)
        offset = points - center
        distance = np.linalg.norm(offset, axis=1, keepdims=True)
        return center + offset * (self.radius / distance)


@dataclass(frozen=True, eq=False)
class Mesh:
    """A conforming P1 triangulation whose boundary edges carry part names.

    Attributes
    ----------
    points : (n_points, 2) float64
        Node coordinates.
    triangles : (n_triangles, 3) int64
        Node indices of each triangle, counter-clockwise.
    boundary_edges : (n_boundary_edges, 2) int64
        Every edge of the domain's boundary, oriented so that the body lies on its
        left (outer boundary counter-clockwise, holes clockwise).
    edge_parts : (n_boundary_edges,) int64
        Index into ``part_names`` of the part each boundary edge belongs to.
    part_names : tuple of str
        Names of the boundary parts, as the case file spells them.
    edge_curves : (n_boundary_edges,) int64
        Index into ``curves`` of the circle a curved edge lies on, -1 for straight edges.
    curves : tuple of Circle
        The circles of curved boundary parts.
    """

    points: np.ndarray
    triangles: np.ndarray
    boundary_edges: np.ndarray
    edge_parts: np.ndarray
    part_names: tuple[str, ...]
    edge_curves: np.ndarray = field(default=None)  # type: ignore[assignment]
    curves: tuple[Circle, ...] = ()

    def __post_init__(self) -> None:
        if self.edge_curves is None:
            object.__setattr__(
                self, "edge_curves", np.full(len(self.boundary_edges), -1, dtype=np.int64)
            )

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    @cached_property
    def topology(self) -> Topology:
        """The edges of the triangulation and their triangles, built on first access.

        Cached on the mesh (a Mesh is never modified), so every stage shares one.

        Raises
        ------
        MeshError
            If a triangle repeats a node or has a node out of range.
        """
        try:
            return Topology.from_triangles(self.triangles, self.n_points)
        except ValueError as exc:
            raise MeshError(f"mesh has no edge structure: {exc}") from None

    @cached_property
    def boundary_edge_triangles(self) -> np.ndarray:
        """(n_boundary_edges,) int64: the triangle that each row of ``boundary_edges`` belongs to.

        Raises
        ------
        MeshError
            If a boundary edge is not an edge of the triangulation, or no triangle runs
            it in its direction (with the body on its left).
        """
        edges = self.boundary_edges
        topology = self.topology
        edge = topology.edge_index(edges[:, 0], edges[:, 1])
        try:
            sides = topology.edge_triangles
        except ValueError as exc:
            raise MeshError(f"mesh is not conforming: {exc}") from None
        # An edge running lo -> hi is column 0 of edge_triangles, hi -> lo column 1.
        triangle = sides[np.maximum(edge, 0), (edges[:, 0] > edges[:, 1]).astype(np.intp)]
        bad = np.flatnonzero((edge < 0) | (triangle < 0))
        if bad.size:
            k = int(bad[0])
            raise MeshError(
                f"boundary_edges[{k}] = {edges[k].tolist()} is not an edge of a triangle with the body on its left"
            )
        triangle.flags.writeable = False
        return triangle

    def part_index(self, name: str) -> int:
        """Index of part ``name`` in ``part_names``; ValueError if the mesh has no such part."""
        return self.part_names.index(name)

    def edges_of(self, names: str | list[str] | tuple[str, ...]) -> np.ndarray:
        """Boundary edges (k, 2) belonging to any of the named parts."""
        if isinstance(names, str):
            names = [names]
        wanted = [self.part_names.index(n) for n in names if n in self.part_names]
        return self.boundary_edges[np.isin(self.edge_parts, wanted)]

    def nodes_of(self, names: str | list[str] | tuple[str, ...]) -> np.ndarray:
        """Sorted unique node indices on the closure of the named parts."""
        return np.unique(self.edges_of(names))

    def triangle_areas(self) -> np.ndarray:
        """Signed areas (n_triangles,), positive for counter-clockwise triangles."""
        p = self.points[self.triangles]
        e1 = p[:, 1] - p[:, 0]
        e2 = p[:, 2] - p[:, 0]
        return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])

    def triangle_diameters(self) -> np.ndarray:
        """Longest edge of each triangle (n_triangles,): the h of the a priori estimates."""
        p = self.points[self.triangles]
        lengths = np.stack(
            [np.linalg.norm(p[:, (i + 1) % 3] - p[:, i], axis=1) for i in range(3)], axis=1
        )
        return lengths.max(axis=1)
