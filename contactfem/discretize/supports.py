"""Supports: prescribed displacements, symmetry lines, and the refusal of supports that leave a rigid motion free."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from contactfem.assembly import edge_geometry
from contactfem.case import Case, PartKind, PlatenControl
from contactfem.discretize.finite import refuse_non_finite
from contactfem.errors import CaseError
from contactfem.mesh import Mesh
from contactfem.mesh.core import coordinate_span

if TYPE_CHECKING:
    from contactfem.discretize.contact import ContactBoundary


@dataclass(frozen=True, eq=False)
class PlatenConstraint:
    """A platen part on the mesh: its nodes move along ``normal`` (outward, unit) by one
    common amount, minus δ, the platen's advance into the body; the first node carries δ.

    ``nodes`` (k,) excludes nodes with a prescribed component (the prescription wins, as
    on a symmetry line); ``on_symmetry`` (k,) marks nodes also on a symmetry line, whose
    motion is then δ times a fixed vector. ``motion`` (k, 2) is each node's displacement
    per unit advance where the platen alone would leave it free: −n, or on a symmetry line
    of normal n_s the vector m with m · n = −1 and m · n_s = 0. The platen's force on the
    body is the work of the nodes' reactions along it: Σ motion · R.
    """

    name: str
    nodes: np.ndarray
    normal: np.ndarray
    control: PlatenControl
    value: float
    on_symmetry: np.ndarray
    motion: np.ndarray

    @property
    def master(self) -> int:
        return int(self.nodes[0])

    @property
    def tangent(self) -> np.ndarray:
        return np.array([-self.normal[1], self.normal[0]])


@dataclass(frozen=True, eq=False)
class Holds:
    """Every direction a support holds a node in, and the part that holds it: row i says that
    the part ``names[parts[i]]`` holds ``nodes[i]`` along the unit vector ``directions[i]`` (a
    prescribed component e_x or e_y, a symmetry line's normal, a platen's normal).

    A node's reaction is one force along each direction holding it, each the part's own: a
    frictionless platen's along its normal only, a symmetry line's along its normal only
    (:func:`contactfem.report.booked_reactions`). A node a part prescribes is held by that
    part, whatever else it lies on: a symmetry line or a platen through it holds nothing more."""

    nodes: np.ndarray
    directions: np.ndarray
    parts: np.ndarray
    names: tuple[str, ...]

    @classmethod
    def of(cls, rows: list[tuple[np.ndarray, np.ndarray, str]]) -> "Holds":
        """From (nodes (k,), directions (k, 2), part name) groups, in the order given."""
        rows = [row for row in rows if len(row[0])]
        names = tuple(dict.fromkeys(name for _, _, name in rows))
        if not rows:
            return cls(np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros(0, dtype=np.int64), names)
        return cls(np.concatenate([np.asarray(nodes, dtype=np.int64) for nodes, _, _ in rows]),
                   np.concatenate([np.asarray(directions, dtype=float).reshape(-1, 2) for _, directions, _ in rows]),
                   np.concatenate([np.full(len(nodes), names.index(name)) for nodes, _, name in rows]), names)


@dataclass(frozen=True, eq=False)
class Supports:
    """What holds the body: prescribed unknowns ``dirichlet_dofs`` (sorted) with their
    ``dirichlet_values``, the nodes held on symmetry lines with each line's unit normal,
    and the platens."""

    dirichlet_dofs: np.ndarray
    dirichlet_values: np.ndarray
    symmetry_nodes: np.ndarray
    symmetry_normals: np.ndarray
    platens: tuple[PlatenConstraint, ...] = ()
    holds: Holds | None = None

    @property
    def platen_nodes(self) -> np.ndarray:
        return np.concatenate([p.nodes for p in self.platens]) if self.platens else np.zeros(0, dtype=np.int64)


def supports(case: Case, mesh: Mesh) -> Supports:
    """Prescribed unknowns and their values, symmetry lines and platens; refuses conflicting supports.

    Whether they leave a rigid motion free is decided by :func:`free_rigid_modes`, once the
    contact nodes and the load are known: contact may hold a motion the supports leave free."""
    values = np.full(2 * mesh.n_points, np.nan)
    owner = np.full(2 * mesh.n_points, -1)
    for index, part in enumerate(case.parts):
        if not part.is_dirichlet:
            continue
        nodes = mesh.nodes_of(part.name)
        components = part.values if part.kind is PartKind.DISPLACEMENT else (None, None)
        for component in range(2):
            if part.kind is PartKind.DISPLACEMENT and components[component] is None:
                continue
            if part.kind is PartKind.CLAMPED:
                prescribed = np.zeros(len(nodes))
            else:
                key = f"boundary.{part.name}.displacement[{component}]"
                if part.exact:
                    key += " (from exact.displacement)"
                x, y = mesh.points[nodes].T
                prescribed = np.broadcast_to(components[component](x, y), x.shape)
                refuse_non_finite(case, key, components[component], prescribed, mesh.points[nodes])
            dofs = 2 * nodes + component
            clash = (owner[dofs] >= 0) & ~np.isclose(values[dofs], prescribed, rtol=1e-9, atol=0)
            if clash.any():
                other = case.parts[owner[dofs][clash][0]].name
                where = mesh.points[nodes[clash][0]]
                raise CaseError(
                    f"{case.source.name}: boundary.{part.name}: prescribes a displacement that "
                    f"conflicts with boundary.{other} at the shared node ({where[0]:g}, {where[1]:g})"
                )
            values[dofs] = prescribed
            owner[dofs] = index
    prescribed = owner.reshape(-1, 2) >= 0
    # Which part holds each node along which direction, for the reactions' bookkeeping: every
    # part prescribing a component (several may, consistently), then what the symmetry lines
    # and platens add below.
    holds = [(nodes, np.tile(np.eye(2)[component], (len(nodes), 1)), part.name)
             for part, nodes, component in _prescriptions(case, mesh)]
    symmetry_nodes, symmetry_normals, symmetry_parts = _symmetry_lines(case, mesh)
    # A symmetry node with one component prescribed is held completely when the line is not
    # along that component: u · n_s = 0 then gives the other one.
    one = prescribed[symmetry_nodes].sum(axis=1) == 1
    given = np.argmax(prescribed[symmetry_nodes[one]], axis=1)
    n_given = symmetry_normals[one, given]
    n_other = symmetry_normals[one, 1 - given]
    across = np.abs(n_other) > 1e-12
    nodes_one = symmetry_nodes[one][across]
    value = values[2 * nodes_one + given[across]]
    values[2 * nodes_one + 1 - given[across]] = -n_given[across] * value / n_other[across]
    owner[2 * nodes_one + 1 - given[across]] = len(case.parts)
    for index in np.unique(symmetry_parts[one][across]):
        line = symmetry_parts[one][across] == index
        holds.append((nodes_one[line], symmetry_normals[one][across][line], case.parts[index].name))
    prescribed = owner.reshape(-1, 2) >= 0
    keep = ~prescribed[symmetry_nodes].any(axis=1)
    symmetry_nodes, symmetry_normals, symmetry_parts = symmetry_nodes[keep], symmetry_normals[keep], symmetry_parts[keep]
    # Each symmetry line holds its nodes along its normal (a node on two lines, pinned below,
    # along both).
    for index in np.unique(symmetry_parts):
        line = symmetry_parts == index
        holds.append((symmetry_nodes[line], symmetry_normals[line], case.parts[index].name))
    # A node on two symmetry lines that are not parallel cannot move at all.
    unique, first, counts = np.unique(symmetry_nodes, return_index=True, return_counts=True)
    pinned = unique[counts > 1]
    if len(pinned):
        values[np.concatenate([2 * pinned, 2 * pinned + 1])] = 0.0
        owner[np.concatenate([2 * pinned, 2 * pinned + 1])] = len(case.parts)
    keep = np.isin(unique, pinned, invert=True)
    symmetry_nodes, symmetry_normals = unique[keep], symmetry_normals[first[keep]]
    platens = _platens(case, mesh, owner.reshape(-1, 2) >= 0, symmetry_nodes, symmetry_normals)
    holds += [(p.nodes, np.tile(p.normal, (len(p.nodes), 1)), p.name) for p in platens]
    dofs = np.flatnonzero(owner >= 0)
    return Supports(dofs, values[dofs], symmetry_nodes, symmetry_normals, platens, Holds.of(holds))


def _prescriptions(case: Case, mesh: Mesh) -> list[tuple["object", np.ndarray, int]]:
    """(part, nodes, component) for every component a clamped or displacement part prescribes."""
    found = []
    for part in case.parts:
        if not part.is_dirichlet:
            continue
        nodes = mesh.nodes_of(part.name)
        for component in range(2):
            if part.kind is PartKind.DISPLACEMENT and part.values[component] is None:
                continue
            found.append((part, nodes, component))
    return found


def _straight_normal(case: Case, mesh: Mesh, name: str, kind: PartKind) -> tuple[np.ndarray, np.ndarray]:
    """The outward unit normal of a straight part and its nodes; refuses a part that is not straight."""
    edges = mesh.edges_of(name)
    if len(edges) == 0:
        raise CaseError(f"{case.source.name}: boundary.{name}: the mesh has no edge on this part")
    _, outward = edge_geometry(mesh.points, edges)
    mean = outward.mean(axis=0)
    # Edges facing opposite ways (two sides of a block under one name) may average to zero:
    # such a part is not straight, and has no normal to test the others against.
    length = float(np.linalg.norm(mean))
    normal = mean / length if length > 0.5 else np.zeros(2)
    points = mesh.points[np.unique(edges)]
    offset = (points - points[0]) @ normal
    extent = coordinate_span(mesh.points).max()
    if length <= 0.5 or np.abs(outward @ normal - 1.0).max() > 1e-9 or np.abs(offset).max() > 1e-9 * extent:
        raise CaseError(
            f"{case.source.name}: boundary.{name} = {kind}: the part is not straight; "
            f"a {kind} {'support' if kind is PartKind.SYMMETRY else 'part'} needs all its edges on one line"
        )
    return normal, np.unique(edges)


def _symmetry_lines(case: Case, mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes of the symmetry parts, their line's normal and the part's index in the case.

    A symmetry part must be straight: all its edges on one line, whose outward unit normal
    n_s is the direction held (u · n_s = 0).
    """
    nodes, normals, parts = [], [], []
    for index, part in enumerate(case.parts):
        if part.kind is PartKind.SYMMETRY:
            normal, part_nodes = _straight_normal(case, mesh, part.name, PartKind.SYMMETRY)
            nodes.append(part_nodes)
            normals.append(np.tile(normal, (len(part_nodes), 1)))
            parts.append(np.full(len(part_nodes), index))
    if not nodes:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    return np.concatenate(nodes), np.concatenate(normals), np.concatenate(parts)


def _platens(case: Case, mesh: Mesh, prescribed: np.ndarray, symmetry_nodes: np.ndarray,
             symmetry_normals: np.ndarray) -> tuple[PlatenConstraint, ...]:
    """The platen parts on the mesh; refuses a platen sharing a node with another platen or
    with a symmetry line parallel to it (the node would be held twice along one direction)."""
    platens: list[PlatenConstraint] = []
    taken = np.full(mesh.n_points, -1)
    sym_index = np.full(mesh.n_points, -1)
    sym_index[symmetry_nodes] = np.arange(len(symmetry_nodes))
    for part in case.parts:
        if part.kind is not PartKind.PLATEN:
            continue
        normal, nodes = _straight_normal(case, mesh, part.name, PartKind.PLATEN)
        nodes = nodes[~prescribed[nodes].any(axis=1)]
        if len(nodes) == 0:
            raise CaseError(f"{case.source.name}: boundary.{part.name} = platen: every node of the part has a "
                            "prescribed displacement, so the platen holds nothing; make it free or drop the prescription")
        shared = taken[nodes] >= 0
        if shared.any():
            where = mesh.points[nodes[shared][0]]
            raise CaseError(
                f"{case.source.name}: boundary.{part.name} = platen: shares the node ({where[0]:g}, {where[1]:g}) "
                f"with the platen boundary.{platens[taken[nodes[shared][0]]].name}; two platens must not touch")
        on_symmetry = sym_index[nodes] >= 0
        parallel = on_symmetry.copy()
        parallel[on_symmetry] = np.abs(symmetry_normals[sym_index[nodes[on_symmetry]]] @ normal) > 1 - 1e-9
        if parallel.any():
            where = mesh.points[nodes[parallel][0]]
            raise CaseError(
                f"{case.source.name}: boundary.{part.name} = platen: shares the node ({where[0]:g}, {where[1]:g}) "
                "with a symmetry line parallel to it, which holds that node where the platen moves it")
        taken[nodes] = len(platens)
        motion = np.tile(-normal, (len(nodes), 1))
        line = symmetry_normals[sym_index[nodes[on_symmetry]]]
        along_line = np.stack([-line[:, 1], line[:, 0]], axis=1)
        motion[on_symmetry] = -along_line / (along_line @ normal)[:, None]
        platens.append(PlatenConstraint(part.name, nodes, normal, part.platen.control, part.platen.value,
                                        on_symmetry, motion))
    return tuple(platens)


#: A piece whose constraints see a rigid motion (unit translations, rotations scaled by the
#: piece's size) weaker than this fraction of the strongest leaves that motion free: the
#: Gram matrix's eigenvalue ratio, so 1e-14 is a singular value ratio of 1e-7.
RIGID_MOTION_TOLERANCE = 1e-14


def free_rigid_modes(case: Case, mesh: Mesh, held: Supports, contact: "ContactBoundary",
                     load: np.ndarray) -> np.ndarray:
    """The rigid motions (2 n_points, k) the supports leave free and contact holds; refuses the others."""
    modes = _refuse_rigid_motion(case, mesh, held, contact, load)
    return np.zeros((2 * mesh.n_points, 0)) if modes is None else modes


#: The load's work along a free rigid motion counts as zero below this fraction of
#: ‖F‖ ‖r‖: it neither presses the body onto the obstacle nor pulls it away.
LOAD_WORK_TOLERANCE = 1e-10


def _refuse_rigid_motion(case: Case, mesh: Mesh, held: Supports, contact: "ContactBoundary | None" = None,
                         load: np.ndarray | None = None) -> np.ndarray:
    """Every connected piece of the mesh must have its three rigid motions (translations along
    x and y, rotation) pinned by its own supports, or by its contact nodes pressed onto the
    obstacle by the load: a piece joined to the rest by no edge is held by nothing else.

    A platen driven by displacement holds its nodes along its normal, like a symmetry line;
    one driven by force holds only their relative normal motion (the platen is rigid), so
    a translation along its normal is free and its force is part of the load.

    Returns the free motions contact holds as nodal displacements (2 n_points, k)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    dofs, symmetry_nodes, symmetry_normals = held.dirichlet_dofs, held.symmetry_nodes, held.symmetry_normals
    edges = mesh.topology.edges
    n_pieces, piece_of = connected_components(
        coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(mesh.n_points, mesh.n_points)),
        directed=False)
    used = np.zeros(mesh.n_points, dtype=bool)
    used[mesh.triangles.ravel()] = True
    # Each constraint holds u(p) · d = 0 for a point p and direction d: a prescribed
    # component (d = e_x or e_y) or a symmetry line (d = n_s).
    fixed_platens = [p for p in held.platens if p.control is PlatenControl.DISPLACEMENT]
    directions = np.concatenate([np.eye(2)[dofs % 2], symmetry_normals,
                                 *(np.tile(p.normal, (len(p.nodes), 1)) for p in fixed_platens)])
    nodes = np.concatenate([dofs // 2, symmetry_nodes, *(p.nodes for p in fixed_platens)])
    # Each piece's own centre and size, so that its rotation is measured in its own units.
    count = np.bincount(piece_of[used], minlength=n_pieces).astype(float)
    centre = np.stack([np.bincount(piece_of[used], mesh.points[used, k], minlength=n_pieces) for k in range(2)],
                      axis=1) / np.maximum(count, 1)[:, None]
    # Per coordinate: numpy's unbuffered reductions (ufunc.at) take a fast path on 1-D
    # operands only, several times faster than both coordinates at once.
    low = np.full((n_pieces, 2), np.inf)
    high = np.full((n_pieces, 2), -np.inf)
    for k in range(2):
        coordinate = np.ascontiguousarray(mesh.points[used, k])
        column_low, column_high = low[:, k].copy(), high[:, k].copy()
        np.minimum.at(column_low, piece_of[used], coordinate)
        np.maximum.at(column_high, piece_of[used], coordinate)
        low[:, k], high[:, k] = column_low, column_high
    size = np.where(count > 0, (high - low).max(axis=1), 1.0)
    size = np.where(size > 0, size, 1.0)

    def seen_through(points_nodes: np.ndarray, d: np.ndarray) -> np.ndarray:
        # Rigid displacement r = a e_x + b e_y + c (−(y−yc), x−xc)/size, seen through u(p)·d.
        arm = (mesh.points[points_nodes] - centre[piece_of[points_nodes]]) / size[piece_of[points_nodes]][:, None]
        return np.stack([d[:, 0], d[:, 1], -arm[:, 1] * d[:, 0] + arm[:, 0] * d[:, 1]], axis=1)

    def gram_of(rows: np.ndarray, where: np.ndarray) -> np.ndarray:
        # Entry by entry through bincount: np.add.at on (k, 3, 3) operands leaves numpy's
        # fast path, and nine bincounts of 1-D weights cost less than one such call.
        outer = (rows[:, :, None] * rows[:, None, :]).reshape(len(rows), 9)
        owner = piece_of[where]
        # float: bincount of no rows returns integers whatever its weights (a body held by
        # a force-driven platen and contact only has no prescribed support at all).
        return np.stack([np.bincount(owner, weights=outer[:, k], minlength=n_pieces) for k in range(9)],
                        axis=1).reshape(n_pieces, 3, 3).astype(float)

    def loose(gram: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        eigenvalues, eigenvectors = np.linalg.eigh(gram)
        weak = eigenvalues <= RIGID_MOTION_TOLERANCE * np.maximum(eigenvalues[:, 2:], 1.0)
        return weak & (count > 0)[:, None], eigenvalues, eigenvectors

    support_gram = gram_of(seen_through(nodes, directions), nodes)
    for platen in held.platens:
        if platen.control is PlatenControl.FORCE and len(platen.nodes) > 1:
            # (u_i − u_master) · n = 0: what a rigid platen holds whatever its advance.
            others = platen.nodes[1:]
            normals = np.tile(platen.normal, (len(others), 1))
            relative = seen_through(others, normals) - seen_through(np.full(len(others), platen.master), normals)
            support_gram += gram_of(relative, others)
    weak, _, eigenvectors = loose(support_gram)
    free = weak[:, 0]
    if not free.any():
        return np.zeros((2 * mesh.n_points, 0))
    if contact is not None:
        c_nodes = contact.nodes
        contact_rows = seen_through(c_nodes, contact.normals)
        held_weak, _, held_vectors = loose(support_gram + gram_of(contact_rows, c_nodes))
    else:
        c_nodes, contact_rows = np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        held_weak, held_vectors = weak, eigenvectors
    unheld = held_weak[:, 0]
    if unheld.any():
        _refuse_unheld(case, mesh, int(np.flatnonzero(unheld)[0]), held_vectors, centre, size, count, piece_of,
                       n_pieces, held_by_contact=len(c_nodes) > 0)
    modes = []
    for piece in np.flatnonzero(free):
        basis = eigenvectors[piece][:, weak[piece]]  # (3, k): the motions the supports leave free
        members = np.flatnonzero(piece_of == piece)
        arm = (mesh.points[members] - centre[piece]) / size[piece]
        nodal = np.zeros((2 * mesh.n_points, basis.shape[1]))
        nodal[2 * members] = basis[0] - np.outer(arm[:, 1], basis[2])
        nodal[2 * members + 1] = basis[1] + np.outer(arm[:, 0], basis[2])
        if load is not None:
            _refuse_unpressed(case, nodal, contact_rows[piece_of[c_nodes] == piece] @ basis, basis,
                              load, centre[piece], size[piece], held.platens)
        modes.append(nodal / np.abs(nodal).max(axis=0))
    return np.concatenate(modes, axis=1)


def _refuse_unheld(case: Case, mesh: Mesh, loose: int, vectors: np.ndarray, centre: np.ndarray, size: np.ndarray,
                   count: np.ndarray, piece_of: np.ndarray, n_pieces: int, held_by_contact: bool) -> None:
    names = _support_names(case)
    motion = _motion_text(vectors[loose, :, 0], centre[loose], size[loose])
    unheld = " and contact with the obstacle cannot hold it" if held_by_contact else ""
    if n_pieces - int((count == 0).sum()) == 1:
        raise CaseError(
            f"{case.source.name}: boundary: the supports ({names}) leave a rigid motion of the body free "
            f"({motion}){unheld}, so the problem is ill-posed; {_holding_remedies(case, mesh, vectors[loose, :, 0])}"
        )
    where = mesh.points[np.flatnonzero(piece_of == loose)[0]]
    raise CaseError(
        f"{case.source.name}: boundary: the mesh has {int((count > 0).sum())} separate pieces (no edge joins "
        f"them) and the one through ({where[0]:g}, {where[1]:g}) is not held: the supports ({names}) leave "
        f"a rigid motion of it free ({motion}){unheld}; join the pieces in the mesh or support each one"
    )


def _holding_remedies(case: Case, mesh: Mesh, mode: np.ndarray) -> str:
    """What holds a free rigid motion (a, b, c) and nothing else, so that a load or a platen
    force still drives the body: a symmetry line across it, or one prescribed component
    along it. Prescribing both components on a part also holds it, but turns a problem
    driven by force into one driven by displacement, so it comes last."""
    kinds = "clamped, displacement, symmetry, platen, traction, pressure, contact or free"
    last = (f"; there are no springs (a part is {kinds}); prescribing both components on a part holds it "
            "too, but fixes that part where the load would move it")
    a, b, c = np.where(np.abs(mode) > 1e-9 * np.abs(mode).max(), mode, 0.0) / np.abs(mode).max()
    if abs(c) >= 1e-6:
        return ("to hold it and keep the load, make a straight part a symmetry line (boundary.<part>: symmetry) "
                "or prescribe one component on a part away from the centre of rotation (boundary.<part>: "
                f"{{displacement: [0, null]}} or [null, 0]){last}")
    direction = np.array([a, b]) / np.hypot(a, b)
    component = "[0, null]" if abs(direction[0]) >= abs(direction[1]) else "[null, 0]"
    across = _straight_parts_across(case, mesh, direction)
    line = (" or ".join(f"boundary.{name}" for name in across[:2]) + ": symmetry" if across
            else f"boundary.<part>: symmetry, the part straight and across ({direction[0]:.3g}, {direction[1]:.3g})")
    return (f"to hold it and keep the load, make a straight part across it a symmetry line ({line}) or "
            f"prescribe its one component on a part (boundary.<part>: {{displacement: {component}}}){last}")


def _straight_parts_across(case: Case, mesh: Mesh, direction: np.ndarray) -> list[str]:
    """The free parts that are straight with their normal along ``direction`` (k,), which as a
    symmetry line would hold a translation along it."""
    found = []
    for part in case.parts:
        if part.kind is not PartKind.FREE:
            continue
        edges = mesh.edges_of(part.name)
        if len(edges) == 0:
            continue
        _, outward = edge_geometry(mesh.points, edges)
        normal = outward.mean(axis=0)
        if np.linalg.norm(normal) == 0:
            continue
        normal = normal / np.linalg.norm(normal)
        offset = (mesh.points[np.unique(edges)] - mesh.points[edges[0, 0]]) @ normal
        if (abs(abs(normal @ direction) - 1.0) <= 1e-9 and np.abs(outward @ normal - 1.0).max() <= 1e-9
                and np.abs(offset).max() <= 1e-9 * coordinate_span(mesh.points).max()):
            found.append(part.name)
    return found


def platen_work(platens: tuple[PlatenConstraint, ...], motion: np.ndarray) -> float:
    """The work of the force-driven platens' forces along a nodal motion (2 n_points,):
    each platen advances by −u(master) · n and presses with its force."""
    return float(sum(p.value * -(motion[2 * p.master: 2 * p.master + 2] @ p.normal)
                     for p in platens if p.control is PlatenControl.FORCE))


def _refuse_unpressed(case: Case, nodal: np.ndarray, normal_part: np.ndarray, basis: np.ndarray,
                      load: np.ndarray, centre: np.ndarray, size: float,
                      platens: tuple[PlatenConstraint, ...] = ()) -> None:
    """Contact holds a free motion r (coefficients ``basis`` @ ray) only one way: the load
    must do positive work along every r that moves the body into the obstacle
    (r · n ≥ 0 at every contact node), or it lifts the body off or leaves it unheld.

    ``normal_part`` (m, k): r · n at the piece's contact nodes for each free motion.
    """
    k = basis.shape[1]
    if k == 1:
        rays = np.array([[1.0], [-1.0]])
    else:
        # The cone {ray : normal_part @ ray ≥ 0} of a 2-D coefficient space is spanned by
        # boundary rays, each orthogonal to a row.
        perpendicular = np.stack([-normal_part[:, 1], normal_part[:, 0]], axis=1)
        rays = np.concatenate([perpendicular, -perpendicular])
        rays = rays[np.linalg.norm(rays, axis=1) > 0]
        rays /= np.linalg.norm(rays, axis=1)[:, None]
    slack = 1e-9 * np.abs(normal_part).max(initial=0.0)
    for ray in rays:
        if (normal_part @ ray).min(initial=0.0) < -slack:
            continue  # presses into the obstacle somewhere and lifts off elsewhere: contact holds it
        r = nodal @ ray
        work = float(load @ r) + platen_work(platens, r)
        forces = np.linalg.norm(np.concatenate([load, [p.value for p in platens if p.control is PlatenControl.FORCE]]))
        scale = float(forces * np.linalg.norm(r))
        if work > LOAD_WORK_TOLERANCE * scale:
            continue
        motion = _motion_text(basis @ ray, centre, size)
        loads = _load_names(case)
        why = ("does no work along it, so contact cannot hold the body" if abs(work) <= LOAD_WORK_TOLERANCE * scale
               else "pulls the body away from the obstacle along it")
        raise CaseError(
            f"{case.source.name}: boundary: the supports ({_support_names(case)}) leave "
            f"a rigid motion of the body free ({motion}) that only contact can hold, and the load ({loads}) "
            f"{why}; press the body onto the obstacle or support it"
        )


def _support_names(case: Case) -> str:
    return ", ".join(p.name for p in case.parts
                     if p.is_support and not p.is_force_driven) or "none"


def _load_names(case: Case) -> str:
    names = [f"boundary.{p.name} {p.kind}" for p in case.parts
             if p.kind in (PartKind.TRACTION, PartKind.PRESSURE) or p.is_force_driven]
    if case.body_force is not None:
        names.append("body_force")
    return ", ".join(names) or "none"


def _motion_text(mode: np.ndarray, centre: np.ndarray, size: float) -> str:
    """A free rigid motion (a, b, c): u = (a, b) + c (−(y − yc), x − xc)/size, in words."""
    a, b, c = np.where(np.abs(mode) > 1e-9 * np.abs(mode).max(), mode, 0.0) / np.abs(mode).max()
    if abs(c) < 1e-6:
        return f"a translation along ({a / np.hypot(a, b):.3g}, {b / np.hypot(a, b):.3g})"
    # The rotation's fixed point: (a, b) + c/size · (−(y − yc), x − xc) = 0.
    x = centre[0] - b * size / c
    y = centre[1] + a * size / c
    return f"a rotation about ({x:.4g}, {y:.4g})"
