"""Each rank's share of the distributed stiffness: the nodes' layout across the ranks and PETSc's assembly."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from contactfem.assembly import Elasticity, shape_gradients
from contactfem.kernel import roundoff_bound
from contactfem.mesh.core import coordinate_span

if TYPE_CHECKING:
    from contactfem.discretize import DiscreteProblem
    from contactfem.discretize.motion import PushedAdvance

#: Triangles per block of the element loop: bounds the temporaries of assembly.
ELEMENT_CHUNK = 65536


def node_order(points: np.ndarray) -> np.ndarray:
    """Nodes sorted along the longer side of the bounding box (ties by the other coordinate).

    Contiguous blocks of this order are slabs across the body's shorter side, so each
    rank's interface with its neighbours is one cut of O(√n) nodes, and the triangles a
    rank assembles touch few rows owned elsewhere. Deterministic, so every rank finds it.
    """
    extent = coordinate_span(points)
    major = 0 if extent[0] >= extent[1] else 1
    return np.lexsort((points[:, 1 - major], points[:, major]))


def element_stiffness(points: np.ndarray, triangles: np.ndarray, law: Elasticity) -> np.ndarray:
    """The 6x6 element matrices (t, 6, 6) in interleaved unknowns (2i + c), as the serial
    element-wise assembly writes them: |T| (λ g_i^a g_j^b + μ g_j^a g_i^b + μ δ_ab g_i·g_j)."""
    g, area = shape_gradients(points, triangles)
    gi_gj = np.einsum("tia,tja->tij", g, g)
    ke = law.lam * g[:, :, :, None, None] * g[:, None, None, :, :]
    ke += law.mu * g.transpose(0, 2, 1)[:, None, :, :, None] * g[:, :, None, None, :]
    ke += law.mu * gi_gj[:, :, None, :, None] * np.eye(2)[None, None, :, None, :]
    ke *= area[:, None, None, None, None]
    return ke.reshape(len(triangles), 6, 6)


@dataclass(eq=False)
class _Layout:
    """How unknowns are numbered and shared: mesh dof 2i + c is PETSc unknown 2 position[i] + c;
    this rank owns PETSc unknowns [first, last)."""

    order: np.ndarray
    position: np.ndarray
    first: int
    last: int
    node_bounds: np.ndarray

    @classmethod
    def build(cls, points: np.ndarray, ranks: int, rank: int) -> "_Layout":
        n = len(points)
        order = node_order(points)
        position = np.empty(n, dtype=np.int64)
        position[order] = np.arange(n)
        bounds = (n * np.arange(ranks + 1, dtype=np.int64)) // ranks
        return cls(order=order, position=position, first=2 * int(bounds[rank]), last=2 * int(bounds[rank + 1]),
                   node_bounds=bounds)

    def petsc(self, dofs: np.ndarray) -> np.ndarray:
        """PETSc indices of mesh unknowns ``dofs``."""
        dofs = np.asarray(dofs, dtype=np.int64)
        return 2 * self.position[dofs // 2] + dofs % 2

    def owned(self, vector: np.ndarray) -> np.ndarray:
        """This rank's entries of a vector over all mesh unknowns (2n,), in PETSc order."""
        return vector.reshape(-1, 2)[self.order[self.first // 2: self.last // 2]].ravel()

    def to_mesh(self, petsc_vector: np.ndarray) -> np.ndarray:
        """A whole vector in PETSc order (2n,) back in mesh unknowns."""
        mesh = np.empty_like(petsc_vector)
        mesh.reshape(-1, 2)[self.order] = petsc_vector.reshape(-1, 2)
        return mesh


@dataclass(eq=False)
class _DistributedSystem:
    """The kernel's system in rotated unknowns (as :class:`contactfem.discretize.ReducedSystem`),
    with the stiffness as a PETSc MPIAIJ matrix and the rest as this rank's entries.

    Arrays named ``*_local`` hold this rank's unknowns in PETSc order; contact arrays (m,)
    are whole on every rank.
    """

    stiffness: object
    absolute: object
    load_local: np.ndarray
    supported_local: np.ndarray
    support_values_local: np.ndarray
    normal_dofs: np.ndarray  # (m,) PETSc indices of the contact normal unknowns
    normal_slots: np.ndarray  # (m,) the same in mesh numbering
    supported_mesh: np.ndarray  # (2n,) bool, mesh numbering
    gap: np.ndarray
    multiplier_mass: object
    contact_edges: np.ndarray  # (e, 2) ΓC edges as pairs of contact nodes (the kernel's order along ΓC)
    gamma: float
    layout: _Layout
    frame_nodes: np.ndarray
    frames: np.ndarray  # (k, 2, 2): node k's unknowns u = [a b] s
    owned_triangles: int
    n_dof: int
    rigid_motions_local: np.ndarray  # (3, local) in rotated unknowns: GAMG's near-null space
    masters: np.ndarray  # (k,) each framed node's platen master (−1 off platens)
    #: The rigid motions only contact holds, at the contact normals (m, j), and the load's
    #: work along each (j,): what :class:`contactfem.kernel.modes.ModeHolder` reads. None
    #: when the supports hold the body.
    free_modes_normal: np.ndarray | None
    free_modes_load: np.ndarray | None
    #: The force that strains the body by its whole size (largest diagonal entry of K times
    #: the body's size), as :class:`contactfem.kernel.ActiveSetSolver` measures it.
    force_unit: float
    #: A pushed obstacle's advance among the unknowns (None: no obstacle is pushed).
    pushed: PushedAdvance | None = None

    @classmethod
    def assemble(cls, PETSc, comm, problem: DiscreteProblem, method, layout: _Layout) -> "_DistributedSystem":
        from contactfem.discretize.frames import _frames, _pushed, _reduce

        mesh = problem.mesh
        n_dof = 2 * mesh.n_points
        supported = np.zeros(n_dof, dtype=bool)
        supported[problem.dirichlet_dofs] = True
        frames = _frames(problem, supported)
        pushed = _pushed(problem, frames.nodes)
        blocks = np.stack([frames.a, frames.b], axis=2)  # (k, 2, 2), columns a and b
        stiffness, owned = _assemble_stiffness(PETSc, comm, problem, layout, frames, blocks, pushed)
        absolute, longest_row, largest_diagonal = matrix_scales(PETSc, comm, stiffness, layout.last - layout.first,
                                                                n_dof)

        # Qᵀ F in rotated unknowns, as ReducedSystem builds it: each framed node's [a b]ᵀ F,
        # and a platen's advance the sum of its nodes' a · F (its column of Q).
        load = problem.load.copy().reshape(-1, 2)
        load[frames.nodes] = np.einsum("kca,kc->ka", blocks, load[frames.nodes])
        load = load.ravel()
        slaves = (frames.masters >= 0) & (frames.nodes != frames.masters)
        np.add.at(load, 2 * frames.masters[slaves], load[2 * frames.nodes[slaves]])
        if len(frames.force_dofs):
            np.add.at(load, frames.force_dofs, frames.forces)
        held_dofs, held_values = problem.dirichlet_dofs, problem.dirichlet_values
        if pushed is not None:  # its held components follow the advance, as a platen's nodes do
            load[pushed.slot] += pushed.ratios @ load[pushed.coupled] + pushed.load
            held_dofs, held_values = pushed.fixed(held_values)
        fixed_dofs = np.concatenate([held_dofs, frames.fixed_dofs])
        fixed_values = np.concatenate([held_values, frames.fixed_values])
        supported_all = np.zeros(n_dof, dtype=bool)
        supported_all[fixed_dofs] = True
        values_all = np.zeros(n_dof)
        values_all[fixed_dofs] = fixed_values
        rigid = _reduce(_rigid_motions(mesh.points), frames.nodes, blocks, frames.masters)
        modes_normal = modes_load = None
        modes = problem.free_modes
        if pushed is not None:
            rigid = pushed.release(rigid)
            modes = pushed.mode(problem.drive.direction, mesh.n_points)[:, None]
        if modes is not None:
            modes = _reduce(modes, frames.nodes, blocks, frames.masters)
            modes = modes if pushed is None else pushed.release(modes)
            modes_normal, modes_load = modes[frames.normal_slot], load @ modes
        span = coordinate_span(mesh.points).max(initial=0.0)
        return cls(
            stiffness=stiffness, absolute=absolute, load_local=layout.owned(load),
            supported_local=layout.owned(supported_all), support_values_local=layout.owned(values_all),
            normal_dofs=layout.petsc(frames.normal_slot), normal_slots=np.asarray(frames.normal_slot, dtype=np.int64),
            supported_mesh=supported_all, gap=np.asarray(problem.contact.gap, dtype=float),
            multiplier_mass=method.multiplier_mass(problem.contact.masses), contact_edges=problem.contact.node_edges(),
            gamma=roundoff_bound(longest_row + 2),
            layout=layout, frame_nodes=frames.nodes, frames=blocks, owned_triangles=int(len(owned)), n_dof=n_dof,
            rigid_motions_local=np.stack([layout.owned(r) for r in rigid.T]), masters=frames.masters,
            free_modes_normal=modes_normal, free_modes_load=modes_load,
            force_unit=largest_diagonal * float(span) if span else 0.0, pushed=pushed,
        )

    def mesh_vector(self, slots: np.ndarray) -> np.ndarray:
        """Mesh-frame vector (2n,) of a vector in rotated unknowns (mesh numbering): Q s, a
        platen node moving by a (δ + s_x) + b s_y."""
        vector = slots.copy().reshape(-1, 2)
        vector[self.frame_nodes] = np.einsum("kab,kb->ka", self.frames, vector[self.frame_nodes])
        slaves = (self.masters >= 0) & (self.frame_nodes != self.masters)
        advance = slots[2 * self.masters[slaves]]
        vector[self.frame_nodes[slaves]] += self.frames[slaves, :, 0] * advance[:, None]
        vector = vector.ravel()
        pushed = getattr(self, "pushed", None)
        if pushed is not None:  # a pushed obstacle's held components: u_q = s_q + r_q s_p
            vector[pushed.coupled] += pushed.ratios * slots[pushed.slot]
        return vector

    def mesh_force(self, rotated: np.ndarray) -> np.ndarray:
        """The mesh-frame force v (2n,) whose rotated form Qᵀ v is ``rotated`` (mesh
        numbering): K u from K' s. A platen's advance slot holds its nodes' a · v summed,
        each of which its node's x slot holds too."""
        w = rotated.copy()
        pushed = getattr(self, "pushed", None)
        if pushed is not None:  # the advance's slot holds v_p + Σ r_q v_q
            w[pushed.slot] -= pushed.ratios @ w[pushed.coupled]
        slaves = (self.masters >= 0) & (self.frame_nodes != self.masters)
        np.subtract.at(w, 2 * self.masters[slaves], w[2 * self.frame_nodes[slaves]])
        vector = w.reshape(-1, 2)
        transposed = np.swapaxes(self.frames, 1, 2)
        vector[self.frame_nodes] = np.linalg.solve(transposed, vector[self.frame_nodes][:, :, None])[:, :, 0]
        return vector.ravel()

    def default_c(self) -> float:
        """:func:`contactfem.kernel.default_c`: the mean normal diagonal entry of K."""
        if len(self.normal_dofs) == 0:
            return 1.0
        diagonal = self.stiffness.getDiagonal()
        values = _gather_entries(diagonal, self.normal_dofs)
        diagonal.destroy()
        return float(np.mean(values))


def matrix_scales(PETSc, comm, stiffness, n_local: int, n_dof: int):
    """|K| (entry by entry, the same pattern), the longest row's stored entries and the largest
    |diagonal entry| over all ranks: what the round-off bounds and the force unit are made of."""
    from mpi4py import MPI

    indptr, indices, values = stiffness.getValuesCSR()
    absolute = PETSc.Mat().createAIJ(size=((n_local, n_dof), (n_local, n_dof)), bsize=2,
                                     csr=(indptr, indices, np.abs(values)), comm=comm)
    mpi = comm.tompi4py()
    longest_row = mpi.allreduce(int(np.diff(indptr).max(initial=0)), op=MPI.MAX)
    del indptr, indices, values
    diagonal = stiffness.getDiagonal()
    largest_diagonal = mpi.allreduce(float(np.abs(diagonal.getArray()).max(initial=0.0)), op=MPI.MAX)
    diagonal.destroy()
    return absolute, longest_row, largest_diagonal


def _assemble_stiffness(PETSc, comm, problem: DiscreteProblem, layout: _Layout, frames, blocks: np.ndarray,
                        pushed: PushedAdvance | None = None):
    """K' = Qᵀ K Q as a PETSc MPIAIJ matrix, and the triangles this rank assembled.

    Q is block-diagonal (each framed node's [a b]) but for the platens: a platen node j
    but the first moves by a_j (δ + s_x) + b_j s_y, so the entries of its x slot are
    added to the advance δ's row and column as well (the first node's x slot). A pushed
    obstacle's held components q follow its advance's slot p the same way, weighted:
    u_q = s_q + r_q s_p adds r_q times the entries of q to p's row and column."""
    mesh = problem.mesh
    n_points, n_dof = mesh.n_points, 2 * mesh.n_points
    frame_of = np.full(n_points, -1, dtype=np.int64)
    frame_of[frames.nodes] = np.arange(len(frames.nodes))
    slaves = (frames.masters >= 0) & (frames.nodes != frames.masters)
    master_of = np.full(n_points, -1, dtype=np.int64)
    master_of[frames.nodes[slaves]] = frames.masters[slaves]
    # Mesh unknown → PETSc index of the advance its entries also go to (−1: none; PETSc skips those).
    advance_of = np.full(n_dof, -1, dtype=np.int64)
    advance_of[2 * frames.nodes[slaves]] = layout.petsc(2 * frames.masters[slaves])
    weight_of = np.ones(n_dof)  # what each unknown's entries are multiplied by there
    if pushed is not None:
        moving = pushed.coupled[pushed.ratios != 0.0]
        advance_of[moving] = layout.petsc(np.full(len(moving), pushed.slot))
        weight_of[moving] = pushed.ratios[pushed.ratios != 0.0]
        master_of[moving // 2] = pushed.slot // 2

    first, last = layout.first, layout.last
    n_local = last - first
    index_type = PETSc.IntType
    d_nnz, o_nnz = (count.astype(index_type) for count in _preallocation(mesh, layout, master_of))
    stiffness = PETSc.Mat().createAIJ(size=((n_local, n_dof), (n_local, n_dof)), bsize=2,
                                      nnz=(d_nnz, o_nnz), comm=comm)
    stiffness.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    # Triangles go to the owner of their first vertex: each is assembled once, and most of
    # a rank's entries land in its own rows.
    first_vertex = layout.position[mesh.triangles[:, 0]]
    owned = np.flatnonzero((first_vertex >= first // 2) & (first_vertex < last // 2))
    add = PETSc.InsertMode.ADD_VALUES
    for start in range(0, len(owned), ELEMENT_CHUNK):
        triangles = mesh.triangles[owned[start:start + ELEMENT_CHUNK]]
        ke = element_stiffness(mesh.points, triangles, problem.law)
        _rotate(ke, triangles, frame_of, blocks)
        mesh_dofs = (2 * triangles[:, :, None] + np.arange(2)).reshape(len(triangles), 6)
        dofs = (2 * layout.position[triangles][:, :, None] + np.arange(2)).reshape(len(triangles), 6)
        dofs = dofs.astype(index_type)
        values = ke.reshape(len(triangles), 36)
        stiffness.setValuesRCV(dofs, dofs, values, addv=add)
        advances = advance_of[mesh_dofs]
        on_platen = np.flatnonzero((advances >= 0).any(axis=1))
        if len(on_platen):
            extra, near = advances[on_platen].astype(index_type), dofs[on_platen]
            part, weight = ke[on_platen], weight_of[mesh_dofs[on_platen]]
            rows_weighted = part * weight[:, :, None]
            for rows, columns, block in ((extra, near, rows_weighted), (near, extra, part * weight[:, None, :]),
                                         (extra, extra, rows_weighted * weight[:, None, :])):
                stiffness.setValuesRCV(rows, columns, block.reshape(len(block), 36), addv=add)
    stiffness.assemblyBegin()
    stiffness.assemblyEnd()
    stiffness.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    stiffness.setOption(PETSc.Mat.Option.SPD, True)
    return stiffness, owned


def _preallocation(mesh, layout: _Layout, master_of: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Entries per owned row inside and outside this rank's columns: a full 2x2 block for the
    node itself and for each mesh edge, as the element matrices fill them, and for each
    pair of a platen's first node and a node of a triangle touching that platen
    (``master_of``: each node's platen first node, −1 off platens and for the first)."""
    first_node, last_node = layout.first // 2, layout.last // 2
    pairs = np.asarray(mesh.topology.edges, dtype=np.int64)
    if master_of is not None and (master_of >= 0).any():
        triangles = mesh.triangles
        masters = master_of[triangles]
        coupled = [np.stack([masters[:, i], triangles[:, j]], axis=1)[masters[:, i] >= 0]
                   for i in range(3) for j in range(3)]
        coupled = np.concatenate(coupled)
        coupled = coupled[coupled[:, 0] != coupled[:, 1]]
        pairs = np.unique(np.sort(np.concatenate([pairs, coupled]), axis=1), axis=0)
    edges = layout.position[pairs]
    n_local_nodes = last_node - first_node
    inside = np.ones(n_local_nodes, dtype=np.int64)  # the node's own block
    outside = np.zeros(n_local_nodes, dtype=np.int64)
    for this, other in ((edges[:, 0], edges[:, 1]), (edges[:, 1], edges[:, 0])):
        mine = (this >= first_node) & (this < last_node)
        local = this[mine] - first_node
        near = (other[mine] >= first_node) & (other[mine] < last_node)
        inside += np.bincount(local[near], minlength=n_local_nodes)
        outside += np.bincount(local[~near], minlength=n_local_nodes)
    return np.repeat(2 * inside, 2), np.repeat(2 * outside, 2)


def _rotate(ke: np.ndarray, triangles: np.ndarray, frame_of: np.ndarray, blocks: np.ndarray) -> None:
    """Element matrices in the rotated unknowns, in place: K_e' = Q_eᵀ K_e Q_e on the few
    triangles touching a framed node (contact, symmetry), Q_e block-diagonal of node frames."""
    frame_index = frame_of[triangles]
    touched = np.flatnonzero((frame_index >= 0).any(axis=1))
    if len(touched) == 0:
        return
    q = np.broadcast_to(np.eye(2), (len(touched), 3, 2, 2)).copy()
    index = frame_index[touched]
    framed = index >= 0
    q[framed] = blocks[index[framed]]
    k = ke[touched].reshape(len(touched), 3, 2, 3, 2)
    ke[touched] = np.einsum("tica,ticjd,tjdb->tiajb", q, k, q).reshape(len(touched), 6, 6)


def _rigid_motions(points: np.ndarray) -> np.ndarray:
    """The plane's rigid motions (x, y translations, rotation about the centroid) as mesh
    displacements (2n, 3); the caller reduces them to the rotated unknowns."""
    centred = points - points.mean(axis=0)
    motions = [np.tile([1.0, 0.0], (len(points), 1)), np.tile([0.0, 1.0], (len(points), 1)),
               np.stack([-centred[:, 1], centred[:, 0]], axis=1)]
    return np.stack([motion.ravel() for motion in motions], axis=1)


def _gather_entries(vector, indices: np.ndarray) -> np.ndarray:
    """Entries ``indices`` (global PETSc indices) of a distributed vector, on every rank."""
    from petsc4py import PETSc

    target = PETSc.Vec().createSeq(len(indices), comm=PETSc.COMM_SELF)
    where = PETSc.IS().createGeneral(np.asarray(indices, dtype=PETSc.IntType), comm=PETSc.COMM_SELF)
    scatter = PETSc.Scatter().create(vector, where, target, None)
    scatter.scatter(vector, target, addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
    values = target.getArray().copy()
    for item in (scatter, where, target):
        item.destroy()
    return values
