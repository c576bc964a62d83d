"""The contact boundary ΓC: the contact nodes, their gaps, normals and boundary masses against the obstacle."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from contactfem.assembly import boundary_mass, edge_geometry
from contactfem.case import Case, PolygonGeometry, RectangleGeometry
from contactfem.discretize.obstacles import Obstacle, obstacle_of
from contactfem.errors import CaseError
from contactfem.mesh import Mesh
from contactfem.mesh.polygon import arc_sweep, loop_signed_area
from contactfem.methods import ContactBoundaryMasses

if TYPE_CHECKING:
    from contactfem.discretize.supports import Supports


@dataclass(frozen=True, eq=False)
class ContactBoundary:
    """The contact nodes and what the methods need of them.

    ``nodes`` (m,) sorted by ``abscissa`` (position along the obstacle's surface),
    ``edges`` (k, 2) the ΓC edges, ``gap`` (m,), ``normals`` (m, 2) the obstacle's unit
    normal at each node's closest point, ``masses`` the two boundary masses, ``obstacle``
    what they face (:class:`contactfem.discretize.obstacles.Obstacle`). ``beyond`` (j,) are
    the nodes of ΓC that the obstacle does not face (beyond a segment's ends): they carry
    no constraint.
    """

    nodes: np.ndarray
    edges: np.ndarray
    gap: np.ndarray
    abscissa: np.ndarray
    obstacle: Obstacle
    masses: ContactBoundaryMasses
    beyond: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    normals: np.ndarray | None = None
    positions: np.ndarray | None = None

    @property
    def normal(self) -> np.ndarray:
        """The one normal of a flat obstacle (the rotated frames and the rigid-mode checks
        take one direction)."""
        if not getattr(self.obstacle, "flat", False):
            raise NotImplementedError(f"a {self.obstacle.kind} obstacle has no single normal")
        return self.obstacle.normal

    @property
    def tangent(self) -> np.ndarray:
        normal = self.normal
        return np.array([-normal[1], normal[0]])

    @property
    def flat(self) -> bool:
        return bool(getattr(self.obstacle, "flat", False))

    @property
    def reference_normal(self) -> np.ndarray:
        """A flat obstacle's normal; a curved one's normalised mean normal over the contact
        nodes (what a picture or an archive that takes one direction is given)."""
        if self.flat:
            return self.obstacle.normal
        total = np.asarray(self.normals, dtype=float).sum(axis=0)
        norm = float(np.hypot(*total))
        return total / norm if norm > 0 else np.array([0.0, -1.0])

    def output_fields(self) -> dict:
        """What the result records of the obstacle (:class:`contactfem.result.ContactFields`)."""
        fields = {"obstacle_point": np.asarray(self.obstacle.point, dtype=float),
                  "obstacle_normal": np.asarray(self.reference_normal, dtype=float),
                  "obstacle_ends": self.obstacle.ends}
        if not self.flat:
            closest = self.obstacle.closest(self.obstacle_points_of())
            fields.update(normals=self.normals, obstacle_points=closest.points,
                          obstacle_outline=self.obstacle.outline())
        return fields

    def obstacle_points_of(self) -> np.ndarray:
        """The contact nodes' reference positions (m, 2) (kept for the closest points)."""
        return self.positions

    def node_edges(self) -> np.ndarray:
        """The ΓC edges as pairs of positions in ``nodes`` (k', 2): those whose two ends
        carry a constraint (an edge reaching beyond a finite obstacle is left out)."""
        return node_pairs(self.nodes, self.edges)


def node_pairs(nodes: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """``edges`` (k, 2 mesh node indices) as pairs of positions in ``nodes`` (k', 2): those
    whose two ends are among ``nodes``."""
    nodes, edges = np.asarray(nodes, dtype=np.int64), np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if len(nodes) == 0 or len(edges) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    position = np.full(int(max(nodes.max(), edges.max())) + 1, -1, dtype=np.int64)
    position[nodes] = np.arange(len(nodes))
    pairs = position[edges]
    return pairs[(pairs >= 0).all(axis=1)]


def contact_patches(abscissa: np.ndarray, active: np.ndarray,
                    pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The contact zone's intervals: active contact nodes joined by ``pairs`` (ΓC's edges as
    positions in the contact nodes, :func:`node_pairs`) whose two ends are active form one.

    For each interval, in order of its lowest ``abscissa``: the position of its node of
    lowest abscissa, of its node of highest abscissa (ties: the lower position) and its
    number of nodes. Found by sorting, not by a pass over ΓC per interval: a rough
    profile's zone has thousands of them.
    """
    from scipy.sparse.csgraph import connected_components

    active = np.asarray(active, dtype=bool)
    s = np.asarray(abscissa, dtype=float)
    m = len(active)
    members = np.flatnonzero(active)
    if len(members) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    joined = pairs[active[pairs[:, 0]] & active[pairs[:, 1]]]
    graph = sp.coo_matrix((np.ones(len(joined)), (joined[:, 0], joined[:, 1])), shape=(m, m))
    _, labels = connected_components(graph, directed=False)
    label, along = labels[members], s[members]
    low = members[np.lexsort((members, along, label))]
    high = members[np.lexsort((-members, along, label))]
    sorted_labels = np.sort(label)
    starts = np.flatnonzero(np.r_[True, sorted_labels[1:] != sorted_labels[:-1]])
    stops = np.r_[starts[1:], len(members)]
    first, last, counts = low[starts], high[stops - 1], stops - starts
    order = np.lexsort((sorted_labels[starts], s[first]))
    return first[order], last[order], counts[order]


def contact_boundary(case: Case, mesh: Mesh, held: "Supports") -> ContactBoundary:
    """ΓC of ``mesh``: refuses a contact part facing away from the obstacle, naming it."""
    obstacle = obstacle_of(case.obstacle)
    edges = mesh.edges_of(list(case.contact_parts))
    for name in case.contact_parts:
        part_edges = mesh.edges_of(name)
        if len(part_edges) == 0:
            raise CaseError(f"{case.source.name}: boundary.{name}: the mesh has no edge on this part")
        if not obstacle.flat:
            continue  # a curved obstacle is judged node by node (:func:`_curved_reach`)
        problem = facing_problem(case, name, mesh, part_edges, obstacle.normal)
        if problem is not None:
            raise CaseError(f"{case.source.name}: boundary.{name} = contact: {problem}; a contact part must "
                            f"face the obstacle (outward normal · obstacle normal ≥ −{FACING_TOLERANCE:g} all "
                            f"along each edge and > {FACING_TOLERANCE:g} somewhere on it)")
    gamma_nodes = np.unique(edges)
    if getattr(obstacle, "kind", "") == "circle":
        obstacle = replace(obstacle, reference=_circle_reference(case, mesh, gamma_nodes, obstacle.center))
    # Each node's obstacle normal (a flat obstacle's one normal; a curved one's at the closest point).
    normal_at = np.zeros((mesh.n_points, 2))
    closest = None
    if obstacle.flat:
        normal_at[:] = obstacle.normal
    else:
        closest = obstacle.closest(mesh.points[gamma_nodes])
        normal_at[gamma_nodes] = closest.normals
    # A node whose normal motion a support fixes carries no multiplier: both components
    # prescribed, or one prescribed while the obstacle's normal is not along the other.
    dirichlet_dofs, symmetry_nodes, symmetry_normals = held.dirichlet_dofs, held.symmetry_nodes, held.symmetry_normals
    prescribed = np.zeros((mesh.n_points, 2), dtype=bool)
    prescribed[dirichlet_dofs // 2, dirichlet_dofs % 2] = True
    roller_keeps_normal = np.where(prescribed[:, 0], abs(normal_at[:, 1]), abs(normal_at[:, 0])) > 1 - 1e-12
    supported = prescribed.all(axis=1) | (prescribed.any(axis=1) & ~roller_keeps_normal)
    # On a symmetry line the node keeps contact only if the obstacle's normal runs along the line.
    along_line = np.abs(np.einsum("ij,ij->i", symmetry_normals, normal_at[symmetry_nodes][:, ::-1] * (-1.0, 1.0))) > 1 - 1e-12
    supported[symmetry_nodes[~along_line]] = True
    # A platen holds its nodes' motion along its normal: like a roller, a node keeps
    # contact only if the obstacle's normal runs along the platen, and not on a symmetry line too.
    for platen in held.platens:
        along_platen = np.abs(normal_at[platen.nodes] @ platen.tangent) > 1 - 1e-12
        supported[platen.nodes[platen.on_symmetry | ~along_platen]] = True
    keep = ~supported[gamma_nodes]
    candidates = gamma_nodes[keep]
    if closest is None:
        facing = obstacle.faces(mesh.points[candidates])
    else:
        facing = closest.faces[keep]
        _refuse_ambiguous(case, mesh.points[candidates], closest.ambiguous[keep] & facing)
        _curved_reach(case, mesh, edges, candidates[facing], normal_at)
    nodes, beyond = candidates[facing], candidates[~facing]
    if obstacle.extent is not None and len(nodes) == 0:
        span = obstacle.abscissa(mesh.points[gamma_nodes])
        low, high = obstacle.extent
        raise CaseError(
            f"{case.source.name}: obstacle.segment: no node of the contact parts "
            f"({', '.join(f'boundary.{n}' for n in case.contact_parts)}) lies in front of the segment: "
            f"it spans [{low:g}, {high:g}] along the obstacle, the contact parts [{span.min():g}, {span.max():g}]"
        )
    if closest is None:
        abscissa = obstacle.abscissa(mesh.points[nodes])
    else:
        abscissa = closest.abscissa[keep][facing]
    order = np.argsort(abscissa, kind="stable")
    nodes, abscissa = nodes[order], abscissa[order]

    full_mass = boundary_mass(mesh.points, edges, mesh.n_points)
    lumped = np.asarray(full_mass.sum(axis=1)).ravel()[nodes]
    consistent = full_mass[nodes][:, nodes].tocsr()
    points = mesh.points[nodes]
    if closest is None:
        gap, normals = obstacle.gap(points), obstacle.normals(points)
    else:
        position = np.full(mesh.n_points, -1)
        position[gamma_nodes] = np.arange(len(gamma_nodes))
        gap, normals = closest.gap[position[nodes]], closest.normals[position[nodes]]
    return ContactBoundary(
        nodes=nodes, edges=edges, gap=gap, abscissa=abscissa, obstacle=obstacle,
        masses=ContactBoundaryMasses(lumped=lumped, consistent=consistent), beyond=beyond,
        normals=normals, positions=points,
    )


def _circle_reference(case: Case, mesh: Mesh, gamma_nodes: np.ndarray, center: np.ndarray) -> np.ndarray:
    """The direction from a circle's center to the nearest point of the contact parts' geometry
    (edges as chords; a mesh file's nodes): where a circle's abscissae start, the same on
    every mesh of the case, so that levels of mesh sequencing share them. A moving circle's
    is its direction of motion: it first touches there."""
    motion = case.obstacle.motion
    if motion is not None:
        return np.asarray(motion.direction, dtype=float)
    starts, ends = [], []
    for name in case.contact_parts:
        for a, b, _, _ in _geometry_edges(case, name):
            starts.append(a)
            ends.append(b)
    if starts:
        a, b = np.concatenate(starts), np.concatenate(ends)
        step = b - a
        t = np.clip(np.einsum("ij,ij->i", center - a, step) / np.maximum(np.einsum("ij,ij->i", step, step), 1e-300),
                    0.0, 1.0)
        near = a + t[:, None] * step
    else:
        near = mesh.points[gamma_nodes]
    direction = near[np.argmin(np.hypot(*(near - center).T))] - center
    norm = float(np.hypot(*direction))
    return direction / norm if norm > 0 else np.array([0.0, -1.0])


def _refuse_ambiguous(case: Case, points: np.ndarray, ambiguous: np.ndarray) -> None:
    """Refuse a contact node with no single closest point on the obstacle."""
    if ambiguous.any():
        x, y = points[np.flatnonzero(ambiguous)[0]]
        raise CaseError(f"{case.source.name}: obstacle: the contact node at ({x:g}, {y:g}) is equidistant, to "
                        f"round-off, from two separate parts of the obstacle; expected each contact node to have "
                        f"one closest point (move the obstacle or the body so that no node lies on a concave "
                        f"corner's bisector)")


def _curved_reach(case: Case, mesh: Mesh, edges: np.ndarray, nodes: np.ndarray, normal_at: np.ndarray) -> None:
    """Refuse a curved obstacle that no contact node can reach: none facing it with its
    outward normal (the mean of its ΓC edges') towards the obstacle."""
    _, outward = edge_geometry(mesh.points, edges)
    mean = np.zeros((mesh.n_points, 2))
    np.add.at(mean, edges[:, 0], outward)
    np.add.at(mean, edges[:, 1], outward)
    towards = np.einsum("ij,ij->i", mean[nodes], normal_at[nodes]) > FACING_TOLERANCE
    if not towards.any():
        parts = ", ".join(f"boundary.{n}" for n in case.contact_parts)
        raise CaseError(f"{case.source.name}: obstacle.{case.obstacle.shape}: no contact node ({parts}) faces it "
                        f"with its outward normal towards it; expected the obstacle in front of a contact part")


#: Whether a contact part faces the obstacle is decided on the geometry, not on the mesh: its
#: outward normal m must satisfy m·n ≥ −FACING_TOLERANCE at every point of each of its edges
#: (an arc's ends may be tangent to the obstacle, as a disk's sides are) and m·n >
#: FACING_TOLERANCE somewhere on each edge. Only a mesh file, which has no geometry, is judged
#: on its mesh edges.
FACING_TOLERANCE = 1e-9


def facing_problem(case: Case, name: str, mesh: Mesh, part_edges: np.ndarray, normal: np.ndarray) -> str | None:
    """Why contact part ``name`` does not face the obstacle of unit normal ``normal``, or None."""
    for starts, ends, arcs, body_on_left in _geometry_edges(case, name):
        # Straight edges at once (a rough profile has 10^5 of them), arcs one by one.
        d = ends - starts
        side = 1.0 if body_on_left else -1.0
        with np.errstate(invalid="ignore", divide="ignore"):
            low = side * (d[:, 1] * normal[0] - d[:, 0] * normal[1]) / np.hypot(d[:, 0], d[:, 1])
        high = low.copy()
        for i in np.flatnonzero([arc is not None for arc in arcs]):
            low[i], high[i] = _arc_facing(starts[i], ends[i], arcs[i], body_on_left, normal)
        failing = np.flatnonzero((low < -FACING_TOLERANCE) | (high <= FACING_TOLERANCE))
        if len(failing):
            i = failing[0]
            start, end, arc = starts[i], ends[i], arcs[i]
            what = ("edge" if arc is None else
                    f"arc around ({arc.center[0]:g}, {arc.center[1]:g})")
            shown = f"{low[i]:.3g}" if low[i] == high[i] else f"between {low[i]:.3g} and {high[i]:.3g}"
            return (f"the {what} from ({start[0]:g}, {start[1]:g}) to ({end[0]:g}, {end[1]:g}) faces away "
                    f"from the obstacle (outward normal · obstacle normal {shown})")
    if isinstance(case.geometry, (RectangleGeometry, PolygonGeometry)):
        return None
    _, outward = edge_geometry(mesh.points, part_edges)
    facing = outward @ normal
    if (facing <= FACING_TOLERANCE).any():
        bad = part_edges[np.argmin(facing)]
        a, b = mesh.points[bad[0]], mesh.points[bad[1]]
        return (f"the mesh edge from ({a[0]:g}, {a[1]:g}) to ({b[0]:g}, {b[1]:g}) faces away from the obstacle "
                f"(outward normal · obstacle normal = {facing.min():.3g})")
    return None


def _geometry_edges(case: Case, name: str):
    """The case's geometry edges on part ``name``, a batch per loop: starts (e, 2), ends
    (e, 2), each edge's arc or None, and whether the body lies on the edges' left."""
    geometry = case.geometry
    if isinstance(geometry, RectangleGeometry):
        (x0, y0), (x1, y1) = geometry.lower, geometry.upper
        corners = {"bottom": ((x0, y0), (x1, y0)), "right": ((x1, y0), (x1, y1)),
                   "top": ((x1, y1), (x0, y1)), "left": ((x0, y1), (x0, y0))}
        sides = [corners[side] for side, part in geometry.side_names.items() if part == name]
        if sides:
            edges = np.array(sides, dtype=float)
            yield edges[:, 0], edges[:, 1], [None] * len(sides), True
    elif isinstance(geometry, PolygonGeometry):
        for index, loop in enumerate((geometry.outer, *geometry.holes)):
            area = loop_signed_area(loop)
            body_on_left = area > 0 if index == 0 else area < 0
            on_part = np.flatnonzero(loop.on_parts((name,)))
            if len(on_part):
                vertices = np.asarray(loop.vertices, dtype=float)
                yield (vertices[on_part], vertices[(on_part + 1) % len(vertices)],
                       [loop.edge_arcs[i] for i in on_part], body_on_left)


def _arc_facing(start: np.ndarray, end: np.ndarray, arc, body_on_left: bool, normal: np.ndarray) -> tuple[float, float]:
    """Least and greatest outward normal · ``normal`` over the arc (its normals sweep an angle interval)."""
    theta0, sweep = arc_sweep(start, end, arc)
    # The normal to the right of the direction of travel is the radial direction on a
    # counter-clockwise arc; the body's outward normal is that one when the body is on the left.
    flip = (sweep > 0) != body_on_left
    phi0 = theta0 + (np.pi if flip else 0.0)
    low_angle = phi0 if sweep > 0 else phi0 + sweep
    width = abs(sweep)
    psi = float(np.arctan2(normal[1], normal[0]))
    ends = (np.cos(low_angle - psi), np.cos(low_angle + width - psi))
    least = -1.0 if (psi + np.pi - low_angle) % (2 * np.pi) <= width else float(min(ends))
    greatest = 1.0 if (psi - low_angle) % (2 * np.pi) <= width else float(max(ends))
    return least, greatest
