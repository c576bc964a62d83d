"""The contact boundary ΓC: the flat obstacle's geometry, the contact nodes, their gaps and boundary masses."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from contactfem.assembly import boundary_mass, edge_geometry
from contactfem.case import Case
from contactfem.errors import CaseError
from contactfem.mesh import Mesh
from contactfem.methods import ContactBoundaryMasses


@dataclass(frozen=True, eq=False)
class FlatObstacle:
    """The rigid half-plane {p : (p − point)·normal ≥ 0}, or the finite segment of its surface
    between two ends.

    ``point`` (2,), ``normal`` (2,) the unit normal pointing from the body into the
    obstacle, ``tangent`` (2,) = (−n_y, n_x): the direction abscissae are measured along;
    ``ends`` (2, 2) the segment's end points, None for an infinite obstacle.
    """

    point: np.ndarray
    normal: np.ndarray
    ends: np.ndarray | None = None

    @classmethod
    def from_case(cls, case: Case) -> "FlatObstacle":
        ends = None if case.obstacle.ends is None else np.asarray(case.obstacle.ends, dtype=float)
        return cls(point=np.asarray(case.obstacle.point, dtype=float),
                   normal=np.asarray(case.obstacle.normal, dtype=float), ends=ends)

    @property
    def extent(self) -> tuple[float, float] | None:
        """The segment's abscissa range (low, high), None for an infinite obstacle."""
        if self.ends is None:
            return None
        low, high = sorted(self.abscissa(self.ends))
        return float(low), float(high)

    def faces(self, points: np.ndarray) -> np.ndarray:
        """Whether each of ``points`` (k, 2) lies in front of the obstacle (k,): its projection
        along the normal falls on the segment (ends included, to round-off), always for an
        infinite obstacle."""
        extent = self.extent
        if extent is None:
            return np.ones(len(points), dtype=bool)
        s = self.abscissa(points)
        slack = 1e-9 * max(extent[1] - extent[0], float(np.abs(extent).max()))
        return (s >= extent[0] - slack) & (s <= extent[1] + slack)

    @property
    def tangent(self) -> np.ndarray:
        return np.array([-self.normal[1], self.normal[0]])

    def gap(self, points: np.ndarray) -> np.ndarray:
        """Initial gap g0 (k,) of ``points`` (k, 2) along the normal: positive when apart."""
        return (self.point - points) @ self.normal

    def abscissa(self, points: np.ndarray) -> np.ndarray:
        """Position (k,) of ``points`` (k, 2) along the obstacle's tangent."""
        return points @ self.tangent


@dataclass(frozen=True, eq=False)
class ContactBoundary:
    """The contact nodes and what the methods need of them.

    ``nodes`` (m,) sorted by ``abscissa`` (coordinate along the obstacle's tangent),
    ``edges`` (k, 2) the ΓC edges, ``gap`` (m,), ``masses`` the two boundary masses,
    ``obstacle`` the flat obstacle they face. ``beyond`` (j,) are the nodes of ΓC that a
    finite obstacle does not reach (their projection falls beyond its ends): they carry
    no constraint.
    """

    nodes: np.ndarray
    edges: np.ndarray
    gap: np.ndarray
    abscissa: np.ndarray
    obstacle: FlatObstacle
    masses: ContactBoundaryMasses
    beyond: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def normal(self) -> np.ndarray:
        return self.obstacle.normal

    @property
    def tangent(self) -> np.ndarray:
        return self.obstacle.tangent


def contact_boundary(case: Case, mesh: Mesh, dirichlet_dofs: np.ndarray, symmetry_nodes: np.ndarray,
                     symmetry_normals: np.ndarray) -> ContactBoundary:
    """ΓC of ``mesh``: refuses a contact part facing away from the obstacle, naming it."""
    obstacle = FlatObstacle.from_case(case)
    normal = obstacle.normal
    edges = mesh.edges_of(list(case.contact_parts))
    for name in case.contact_parts:
        part_edges = mesh.edges_of(name)
        if len(part_edges) == 0:
            raise CaseError(f"{case.source.name}: boundary.{name}: the mesh has no edge on this part")
        _, outward = edge_geometry(mesh.points, part_edges)
        facing = outward @ normal
        if (facing <= 1e-9).any():
            bad = part_edges[np.argmin(facing)]
            a, b = mesh.points[bad[0]], mesh.points[bad[1]]
            raise CaseError(
                f"{case.source.name}: boundary.{name} = contact: the edge from ({a[0]:g}, {a[1]:g}) to "
                f"({b[0]:g}, {b[1]:g}) faces away from the obstacle (outward normal · obstacle normal = "
                f"{facing.min():.3g}); a contact part must face the obstacle"
            )
    # A node whose normal motion a support fixes carries no multiplier: both components
    # prescribed, or one prescribed while the obstacle's normal is not along the other.
    prescribed = np.zeros((mesh.n_points, 2), dtype=bool)
    prescribed[dirichlet_dofs // 2, dirichlet_dofs % 2] = True
    roller_keeps_normal = np.where(prescribed[:, 0], abs(normal[1]), abs(normal[0])) > 1 - 1e-12
    supported = prescribed.all(axis=1) | (prescribed.any(axis=1) & ~roller_keeps_normal)
    # On a symmetry line the node keeps contact only if the obstacle's normal runs along the line.
    along_line = np.abs(symmetry_normals @ obstacle.tangent) > 1 - 1e-12
    supported[symmetry_nodes[~along_line]] = True
    gamma_nodes = np.unique(edges)
    candidates = gamma_nodes[~supported[gamma_nodes]]
    facing = obstacle.faces(mesh.points[candidates])
    nodes, beyond = candidates[facing], candidates[~facing]
    if obstacle.ends is not None and len(nodes) == 0:
        span = obstacle.abscissa(mesh.points[gamma_nodes])
        low, high = obstacle.extent
        raise CaseError(
            f"{case.source.name}: obstacle.segment: no node of the contact parts "
            f"({', '.join(f'boundary.{n}' for n in case.contact_parts)}) lies in front of the segment: "
            f"it spans [{low:g}, {high:g}] along the obstacle, the contact parts [{span.min():g}, {span.max():g}]"
        )
    abscissa = obstacle.abscissa(mesh.points[nodes])
    order = np.argsort(abscissa, kind="stable")
    nodes, abscissa = nodes[order], abscissa[order]

    full_mass = boundary_mass(mesh.points, edges, mesh.n_points)
    lumped = np.asarray(full_mass.sum(axis=1)).ravel()[nodes]
    consistent = full_mass[nodes][:, nodes].tocsr()
    return ContactBoundary(
        nodes=nodes, edges=edges, gap=obstacle.gap(mesh.points[nodes]), abscissa=abscissa, obstacle=obstacle,
        masses=ContactBoundaryMasses(lumped=lumped, consistent=consistent), beyond=beyond,
    )
