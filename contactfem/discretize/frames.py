"""The kernel's view of a discrete problem: supports as fixed unknowns, contact and symmetry nodes in rotated frames."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from contactfem.case import PlatenControl
from contactfem.discretize.motion import PushedAdvance, pushed_advance
from contactfem.kernel import ContactSystem
from contactfem.mesh.core import coordinate_span
from contactfem.methods import ContactMethod

if TYPE_CHECKING:
    from contactfem.discretize.problem import DiscreteProblem


@dataclass(frozen=True, eq=False)
class ReducedSystem:
    """A :class:`ContactSystem` in rotated unknowns and the map back to mesh displacements.

    The system keeps every unknown (supports are fixed unknowns of the kernel, not sliced
    out). At a contact node with both components free, (u_x, u_y) = u_n n + u_t t: its x
    slot holds u_n and its y slot u_t. A contact node on a roller (one component
    prescribed) keeps its prescribed slot, and its free slot c, along which the normal
    lies, holds u_n (u_c = n_c u_n with n_c = ±1). A platen's first node holds its
    advance δ in its x slot; every other platen node j moves by a_j (δ + s_x) + b_j s_y
    with s_x fixed to 0, so ``rotation`` is not orthogonal there: its column of δ has an
    entry at every node of the platen.
    """

    system: ContactSystem
    rotation: sp.csr_matrix
    problem: DiscreteProblem
    #: Each framed node's 2x2 frame [a b] (k, 2, 2), the nodes (k,) and each one's platen
    #: master (−1 when it is on no platen), to map mesh displacements back (:meth:`reduce`).
    frame_nodes: np.ndarray
    frames: np.ndarray
    masters: np.ndarray
    #: A pushed obstacle's advance among the unknowns (None: no obstacle is pushed).
    pushed: PushedAdvance | None = None

    @classmethod
    def build(cls, problem: DiscreteProblem, method: ContactMethod) -> "ReducedSystem":
        n_dof = 2 * problem.mesh.n_points
        contact = problem.contact
        supported = np.zeros(n_dof, dtype=bool)
        supported[problem.dirichlet_dofs] = True
        frames = _frames(problem, supported)
        nodes, a, b = frames.nodes, frames.a, frames.b
        pushed = _pushed(problem, nodes)
        # Each framed node's slots hold u · a (x slot) and u · b (y slot): Q's 2x2 block is
        # [a b]. E = Q − I lives on those nodes only, so QᵀKQ = K + EᵀK + KE + EᵀKE costs a
        # few products with thin matrices instead of two full ones. A pushed obstacle's
        # advance adds a column to E (its held components follow s_p: PushedAdvance).
        x, y = 2 * nodes, 2 * nodes + 1
        slaves = (frames.masters >= 0) & (nodes != frames.masters)
        coupled = np.zeros(0, dtype=np.int64) if pushed is None else pushed.coupled
        rows = np.concatenate([x, x, y, y, x[slaves], y[slaves], coupled])
        cols = np.concatenate([x, y, x, y, 2 * frames.masters[slaves], 2 * frames.masters[slaves],
                               np.full(len(coupled), 0 if pushed is None else pushed.slot)])
        vals = np.concatenate([a[:, 0] - 1.0, b[:, 0], a[:, 1], b[:, 1] - 1.0, a[slaves, 0], a[slaves, 1],
                               np.zeros(0) if pushed is None else pushed.ratios])
        shift = sp.csr_matrix((vals, (rows, cols)), shape=(n_dof, n_dof))
        shift.eliminate_zeros()
        stiffness = problem.stiffness
        blocks = np.stack([a, b], axis=2)
        rotated = None if slaves.any() or pushed is not None else _rotated_in_blocks(stiffness, nodes, blocks)
        if rotated is None:
            k_shift = (stiffness @ shift).tocsr()
            # The three corrections live on the framed rows and columns: sum them first, then
            # add to K once (each full-size sparse addition costs as much as the others together).
            rotated = sp.csr_matrix(stiffness + (k_shift + k_shift.T + shift.T @ k_shift))
            rotated.sum_duplicates()
        rotation = (sp.identity(n_dof, format="csr") + shift).tocsr()
        held_dofs, held_values = problem.dirichlet_dofs, problem.dirichlet_values
        if pushed is not None:
            held_dofs, held_values = pushed.fixed(held_values)
        fixed_dofs = np.concatenate([held_dofs, frames.fixed_dofs])
        fixed_values = np.concatenate([held_values, frames.fixed_values])
        order = np.argsort(fixed_dofs)
        load = rotation.T @ problem.load
        np.add.at(load, frames.force_dofs, frames.forces)
        free_modes = None
        if problem.free_modes is not None:
            free_modes = _reduce(problem.free_modes, nodes, blocks, frames.masters)
        if pushed is not None:
            load[pushed.slot] += pushed.load
            free_modes = pushed.release(_reduce(pushed.mode(problem.drive.direction, problem.mesh.n_points),
                                                nodes, blocks, frames.masters))[:, None]
        translation = None
        if free_modes is None and not np.any(load):
            translation = _prescribed_translation(problem, nodes, blocks, frames.masters)
        system = ContactSystem(
            stiffness=rotated,
            load=load,
            normal_dofs=frames.normal_slot,
            gap=contact.gap,
            multiplier_mass=method.multiplier_mass(contact.masses),
            fixed_dofs=fixed_dofs[order],
            fixed_values=fixed_values[order],
            free_modes=free_modes,
            length_scale=float(coordinate_span(problem.mesh.points).max(initial=0.0)) or None,
            contact_edges=contact.node_edges(),
            translation=translation,
        )
        return cls(system=system, rotation=rotation, problem=problem, frame_nodes=nodes, frames=blocks,
                   masters=frames.masters, pushed=pushed)

    def displacement(self, reduced: np.ndarray) -> np.ndarray:
        """Mesh displacement (n_points, 2) from the kernel's unknowns (in rotated coordinates)."""
        return (self.rotation @ reduced).reshape(-1, 2)

    def rigid_motions(self) -> np.ndarray:
        """The body's rigid motions in the kernel's unknowns (n, 3): the translations along x
        and y and the rotation about the origin, (−y, x), as the constraints carry them."""
        points = self.problem.mesh.points
        motions = np.zeros((len(points), 2, 3))
        motions[:, 0, 0] = motions[:, 1, 1] = 1.0
        motions[:, 0, 2], motions[:, 1, 2] = -points[:, 1], points[:, 0]
        return self.reduce(motions.reshape(-1, 3))

    def reduce(self, displacement: np.ndarray) -> np.ndarray:
        """The kernel's unknowns of mesh displacements (2 n_points,) or (2 n_points, j) that
        the constraints allow (a rigid motion a platen follows): the inverse of :meth:`displacement`."""
        reduced = _reduce(displacement, self.frame_nodes, self.frames, self.masters)
        return reduced if self.pushed is None else self.pushed.release(reduced)

    def settled(self, problem: DiscreteProblem, reduced: np.ndarray) -> DiscreteProblem:
        """``problem`` (this system's own, or scaled along a path) with its pushed obstacle
        at the advance the kernel's unknowns ``reduced`` found; itself when none is pushed."""
        if self.pushed is None:
            return problem
        return problem.advanced(self.pushed.advance(reduced, problem.dirichlet_values))


def _pushed(problem: DiscreteProblem, framed_nodes: np.ndarray) -> PushedAdvance | None:
    """The coupling that makes a pushed obstacle's advance an unknown (None if none is pushed)."""
    drive = problem.drive
    if drive is None or not drive.pushed:
        return None
    framed = np.zeros(problem.mesh.n_points, dtype=bool)
    framed[framed_nodes] = True
    return pushed_advance(problem.dirichlet_dofs, drive.direction, drive.force, problem.load, framed)


def _rotated_in_blocks(stiffness: sp.csr_matrix, nodes: np.ndarray, frames: np.ndarray) -> sp.csr_matrix | None:
    """QᵀKQ for a block-diagonal Q (node ``nodes[k]``'s block ``frames[k]``, identity
    elsewhere), in K's own pattern; None when K is not laid out in 2x2 node blocks.

    The assembled stiffness is (:func:`contactfem.assembly.stiffness_matrix`): every row
    stores its columns in pairs 2j, 2j+1, and dof rows 2i and 2i+1 the same ones. So KQ
    mixes each pair of a framed column node j by Q_j, and Qᵀ(KQ) the two rows of each
    framed node i by Q_iᵀ, in place of a copy of K's values: no sparse product. Where many
    nodes are framed (a graded mesh under a rough profile frames a large share of its
    nodes) the thin products and sums this replaces cost as much as a numeric
    factorisation (benchmarks/rough.py; see docs/performance.md#measured-design-choices).
    """
    indptr, indices = stiffness.indptr, stiffness.indices
    n_dof = stiffness.shape[0]
    if n_dof % 2 or stiffness.nnz % 2:
        return None
    first, second, end = indptr[0:-1:2], indptr[1::2], indptr[2::2]
    length = second - first
    if not np.array_equal(length, end - second) or np.any(length % 2):
        return None
    pair_column = indices[0::2]
    if np.any(pair_column % 2) or not np.array_equal(indices[1::2], pair_column + 1):
        return None
    n_nodes = n_dof // 2
    q00, q01, q10, q11 = (np.ones(n_nodes), np.zeros(n_nodes), np.zeros(n_nodes), np.ones(n_nodes))
    q00[nodes], q01[nodes], q10[nodes], q11[nodes] = frames[:, 0, 0], frames[:, 0, 1], frames[:, 1, 0], frames[:, 1, 1]
    framed = np.zeros(n_nodes, dtype=bool)
    framed[nodes] = True
    data = stiffness.data.copy()
    # K Q: the pairs (k_x, k_y) of a row in the columns of framed node j become (k_x, k_y) Q_j.
    pairs = data.reshape(-1, 2)
    selected = np.flatnonzero(framed[pair_column // 2])
    j = pair_column[selected] // 2
    x, y = pairs[selected, 0], pairs[selected, 1]
    pairs[selected, 0] = x * q00[j] + y * q10[j]
    pairs[selected, 1] = x * q01[j] + y * q11[j]
    # Qᵀ (K Q): the two rows of framed node i become Q_iᵀ [row 2i; row 2i+1].
    rows = np.flatnonzero(framed & (length > 0))
    counts = length[rows]
    i = np.repeat(rows, counts)
    top = np.arange(len(i)) + np.repeat(first[rows] - np.cumsum(counts) + counts, counts)
    bottom = top + length[i]
    if not np.array_equal(indices[top], indices[bottom]):
        return None
    upper, lower = data[top], data[bottom]
    data[top] = q00[i] * upper + q10[i] * lower
    data[bottom] = q01[i] * upper + q11[i] * lower
    # K's pattern, shared: neither matrix is changed in place once assembled.
    rotated = sp.csr_matrix((data, indices, indptr), shape=stiffness.shape, copy=False)
    rotated.has_canonical_format = stiffness.has_canonical_format
    return rotated


def _prescribed_translation(problem: DiscreteProblem, nodes: np.ndarray, frames: np.ndarray,
                            masters: np.ndarray) -> np.ndarray | None:
    """The translation whose components every prescribed x and every prescribed y value is
    (a body pushed by its top, the rest free or on rollers along the push), in the kernel's
    unknowns; None when the prescribed values differ. The kernel checks it against its own
    fixed values before using it (:attr:`contactfem.kernel.ContactSystem.translation`)."""
    dofs, values = problem.dirichlet_dofs, problem.dirichlet_values
    if len(dofs) == 0:
        return None
    step = np.zeros(2)
    for component in (0, 1):
        given = values[dofs % 2 == component]
        if len(given):
            if np.ptp(given) > 0.0:
                return None
            step[component] = given[0]
    if not step.any():
        return None  # held still: the cold start's first solve is u = 0, no cost to skip
    return _reduce(np.tile(step, problem.mesh.n_points), nodes, frames, masters)


def _reduce(displacement: np.ndarray, nodes: np.ndarray, frames: np.ndarray, masters: np.ndarray) -> np.ndarray:
    """Slots s with Q s = ``displacement`` (see :meth:`ReducedSystem.reduce`)."""
    single = displacement.ndim == 1
    u = displacement.reshape(len(displacement), -1).copy()
    blocks = u.reshape(-1, 2, u.shape[1])
    slots = np.linalg.solve(frames, blocks[nodes])  # (k, 2, j)
    # A platen node's frame has a = its column of δ, so its x slot is what it moves along a beyond δ.
    on_platen = (masters >= 0) & (nodes != masters)
    position = np.full(len(blocks), -1)
    position[nodes] = np.arange(len(nodes))
    slots[on_platen, 0] -= slots[position[masters[on_platen]], 0]
    blocks[nodes] = slots
    return u[:, 0] if single else u


@dataclass(frozen=True, eq=False)
class _Frames:
    """The rotated unknowns: per framed node its frame (a, b) and platen master (−1 if
    none); the contact normal slots; the slots the frames fix (symmetry normals, platen
    slaves, a displacement-driven platen's advance) and the platens' forces on their slots."""

    nodes: np.ndarray
    a: np.ndarray
    b: np.ndarray
    masters: np.ndarray
    normal_slot: np.ndarray
    fixed_dofs: np.ndarray
    fixed_values: np.ndarray
    force_dofs: np.ndarray
    forces: np.ndarray


def _frames(problem: DiscreteProblem, supported: np.ndarray) -> _Frames:
    """Local frames (a, b) of the nodes whose unknowns are rotated, and the contact normal slots.

    - contact node with both components free: a = n, b = t (u_n in the x slot);
    - contact node with one component prescribed (a roller, n along the free axis): the
      prescribed axis stays, the free slot holds u_n;
    - symmetry node: a = n_s (its x slot is fixed to 0), b = t_s, or b = n when it is also a
      contact node (n along the symmetry line), its y slot then holding u_n;
    - platen node: a = −n_p (its x slot is the platen's advance δ at the platen's first
      node, fixed to 0 elsewhere: the node moves by a δ), b = t_p, or b = n on a contact
      node (n along the platen); on a symmetry line a is the platen's motion there
      (a · n_p = −1, a · n_s = 0), b = n_s, and the y slot is fixed to 0.
    """
    contact = problem.contact
    n_o = contact.normals  # (m, 2): a flat obstacle's one normal, or each node's own
    t_o = np.stack([-n_o[:, 1], n_o[:, 0]], axis=1)
    n_points = problem.mesh.n_points
    c = contact.nodes
    sx, sy = supported[2 * c], supported[2 * c + 1]
    sym_index = np.full(n_points, -1)
    sym_index[problem.symmetry_nodes] = np.arange(len(problem.symmetry_nodes))
    # Per node: its platen's first node (−1 off platens), its motion per unit advance, the
    # platen's tangent.
    master_of = np.full(n_points, -1)
    motion_of = np.zeros((n_points, 2))
    tangent_of = np.zeros((n_points, 2))
    for platen in problem.platens:
        master_of[platen.nodes] = platen.master
        motion_of[platen.nodes] = platen.motion
        tangent_of[platen.nodes] = platen.tangent
    on_symmetry = sym_index[c] >= 0
    m = len(c)
    a = n_o.reshape(m, 2).copy()
    b = t_o.reshape(m, 2).copy()
    slot = 2 * c
    roller_x = sx & ~sy  # u_x prescribed, normal along y
    a[roller_x] = (1.0, 0.0)
    b[roller_x] = np.stack([np.zeros(m), n_o[:, 1]], axis=1)[roller_x]
    slot = np.where(roller_x, 2 * c + 1, slot)
    roller_y = sy & ~sx  # u_y prescribed, normal along x
    a[roller_y] = np.stack([n_o[:, 0], np.zeros(m)], axis=1)[roller_y]
    b[roller_y] = (0.0, 1.0)
    a[on_symmetry] = problem.symmetry_normals[sym_index[c[on_symmetry]]]
    b[on_symmetry] = n_o[on_symmetry]
    slot = np.where(on_symmetry, 2 * c + 1, slot)
    # Contact nodes on a platen (the contact boundary keeps them only with n along it).
    platen_contact = master_of[c] >= 0
    a[platen_contact] = motion_of[c[platen_contact]]
    b[platen_contact] = n_o[platen_contact]
    slot = np.where(platen_contact, 2 * c + 1, slot)
    # Symmetry nodes that are not contact nodes: a = n_s, b = t_s (or the platen's frame).
    # (setdiff1d sorts its second argument even when the first is empty: skip it then.)
    others = np.setdiff1d(problem.symmetry_nodes, c) if len(problem.symmetry_nodes) else c[:0]
    normals = problem.symmetry_normals[sym_index[others]]
    sym_a = normals.copy()
    sym_b = np.stack([-normals[:, 1], normals[:, 0]], axis=1)
    sym_platen = master_of[others] >= 0
    sym_a[sym_platen] = motion_of[others[sym_platen]]
    sym_b[sym_platen] = normals[sym_platen]
    # Platen nodes on neither: a = −n_p, b = t_p.
    platen_nodes = np.flatnonzero(master_of >= 0)
    rest = np.setdiff1d(platen_nodes, np.concatenate([c, others])) if len(platen_nodes) else c[:0]
    nodes = np.concatenate([c, others, rest])
    masters = master_of[nodes]
    # Fixed slots, all to 0 but a displacement-driven platen's advance: the x slot of a
    # symmetry node (its normal), the y slot of a symmetry node on a platen, and the x slot
    # of every platen node but the first (the first's x slot is δ).
    slaves = nodes[(masters >= 0) & (nodes != masters)]
    fixed = [2 * c[on_symmetry], 2 * others[~sym_platen], 2 * others[sym_platen] + 1, 2 * slaves]
    fixed_values = [np.zeros(sum(len(f) for f in fixed))]
    driven = [p for p in problem.platens if p.control is PlatenControl.DISPLACEMENT]
    pushed = [p for p in problem.platens if p.control is PlatenControl.FORCE]
    fixed.append(np.array([2 * p.master for p in driven], dtype=np.int64))
    fixed_values.append(np.array([p.value for p in driven]))
    return _Frames(
        nodes=nodes, a=np.concatenate([a, sym_a, motion_of[rest]]), b=np.concatenate([b, sym_b, tangent_of[rest]]),
        masters=masters,
        normal_slot=slot, fixed_dofs=np.concatenate(fixed).astype(np.int64), fixed_values=np.concatenate(fixed_values),
        force_dofs=np.array([2 * p.master for p in pushed], dtype=np.int64),
        forces=np.array([p.value for p in pushed], dtype=float),
    )
