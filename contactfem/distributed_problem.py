"""The discrete problem on a distributed mesh: each rank assembles the stiffness and body force of its
own piece (:mod:`contactfem.distributed_mesh`), and every rank holds the whole boundary (O(√n)
nodes), on which supports, surface loads and the contact arrays are built by the serial code.

The boundary mesh holds every boundary node of the refined mesh (numbered by increasing global id)
and every boundary edge in the serially refined mesh's row order, gathered from the pieces: the
boundary rows each piece refines are its own coarse boundary edges', so no rank holds the interior
of another's piece. Its contact nodes, gaps, masses and frames are the serial ones (the same edges
in the same order, the same coordinates), so every rank takes the kernel's decisions alike.

The route is taken when the fine mesh comes from uniform refinement (``--refine R`` or
``mesh.refine``, R ≥ 1) of a body held by its supports without platens or a pushed obstacle; other cases keep the
replicated mesh of :mod:`contactfem.distributed`. A coarser level of mesh sequencing made of
fewer refinements of the same mesh is in pieces too; a rectangle's (fewer divisions) is meshed
whole on every rank (a sixteenth of the unknowns). After the solve, rank 0 meshes the whole
case once more for the writers, when the solver's memory is freed; the solve command instead
keeps the result in pieces (:mod:`contactfem.distributed_output`), each rank writing its own share.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from contactfem.assembly import Elasticity, body_force_vector
from contactfem.case import Case
from contactfem.discretize import DiscreteProblem, build_mesh, build_problem
from contactfem.discretize.contact import contact_boundary
from contactfem.discretize.exact_checks import exact_fields
from contactfem.discretize.loads import Loads, _body_force, _natural_boundary, compile_loads
from contactfem.discretize.meshing import MeshRequest
from contactfem.discretize.motion import obstacle_drive
from contactfem.discretize.supports import supports
from contactfem.distributed_assembly import (
    ELEMENT_CHUNK,
    _DistributedSystem,
    _Layout,
    _rigid_motions,
    _rotate,
    element_stiffness,
    matrix_scales,
)
from contactfem.distributed_mesh import MeshPiece, mesh_piece, petsc_numbers
from contactfem.kernel import roundoff_bound
from contactfem.mesh import Mesh
from contactfem.mesh.refine import refine_uniform


@dataclass(frozen=True, eq=False)
class PieceProblem(DiscreteProblem):
    """A :class:`DiscreteProblem` whose ``mesh`` is the boundary mesh (every boundary node and
    edge of the refined mesh, no triangle) and ``load`` its surface loads; the interior is
    this rank's ``piece``, with each node's PETSc number (``numbers``), this rank's range of
    node numbers, and the body force's load on the piece (None without one)."""

    piece: MeshPiece | None = None
    numbers: np.ndarray | None = None
    node_range: tuple[int, int] = (0, 0)
    boundary_ids: np.ndarray | None = None  # global id of each boundary mesh node
    boundary_numbers: np.ndarray | None = None  # PETSc number of each boundary mesh node
    n_points_total: int = 0
    body_load: np.ndarray | None = None
    #: Entries per owned row inside and outside this rank's columns (PETSc's preallocation),
    #: counted from the piece's edges, which the piece then drops.
    preallocation: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def n_unknowns(self) -> int:
        return 2 * self.n_points_total - len(self.dirichlet_dofs)


@dataclass(frozen=True, eq=False)
class PieceLayout:
    """This rank's unknowns [first, last) of a piece problem; ``owned_ids`` the global ids of its
    owned nodes in PETSc order (what the singularity probe, drawn over global ids, reads)."""

    first: int
    last: int
    owned_ids: np.ndarray

    def owned(self, vector: np.ndarray) -> np.ndarray:
        """This rank's entries (PETSc order) of a vector (2N,) over the global node ids."""
        return vector.reshape(-1, 2)[self.owned_ids].ravel()


def piece_problem(case: Case, mpi, refine: int | None = None) -> PieceProblem | None:
    """This rank's :class:`PieceProblem` of ``case``, or None when the case keeps the replicated
    mesh (no refinement, platens, a pushed obstacle, or a body only contact holds). Collective over ``mpi``."""
    times = case.mesh.refine if refine is None else refine
    coarse = _coarse_for_pieces(case, times, mpi.Get_size())
    if coarse is None:
        return None
    _refuse_oversized(case, coarse.n_triangles * 4**times, times, mpi)
    piece = mesh_piece(coarse, times, mpi.Get_size(), mpi.Get_rank())
    numbers, first, last = petsc_numbers(piece, mpi)
    preallocation = _piece_preallocation(piece, numbers, (first, last), mpi)
    boundary, ids = _boundary_mesh(piece, mpi)
    owned = piece.owned
    sorter = np.argsort(ids)
    on_boundary = _members(ids, sorter, piece.node_ids[owned])
    gathered = mpi.allgather((piece.node_ids[owned][on_boundary], numbers[owned][on_boundary]))
    known_ids = np.concatenate([pair[0] for pair in gathered])
    known_numbers = np.concatenate([pair[1] for pair in gathered])
    boundary_numbers = np.empty(len(ids), dtype=np.int64)
    boundary_numbers[np.searchsorted(ids, known_ids)] = known_numbers

    material = case.material
    law = Elasticity.from_lame(material.lame_lambda, material.lame_mu, material.plane)
    # The surface loads on the boundary mesh, the body force on the piece (the boundary mesh has no triangle).
    loads = Loads(body_force=_body_force(case), natural=_natural_boundary(case, boundary))
    held = supports(case, boundary)
    contact = contact_boundary(case, boundary, held)
    # A moving obstacle shifts the supports (the coarse problem ran its checks).
    drive, held = obstacle_drive(case, held)
    body = None
    if loads.body_force is not None:
        piece_loads = compile_loads(case, piece.as_mesh())
        body = body_force_vector(piece.points, piece.triangles, piece_loads.body_force_values)
    # Assembly reads the piece's nodes and triangles only: its edges need not stay through the solve.
    piece = replace(piece, edges=piece.edges[:0], edge_ids=piece.edge_ids[:0], edge_owner=piece.edge_owner[:0],
                    triangle_edges=piece.triangle_edges[:0], triangle_ids=piece.triangle_ids[:0])
    return PieceProblem(
        mesh=boundary, law=law, stiffness=None, load=loads.natural.load_vector(boundary.n_points),
        dirichlet_dofs=held.dirichlet_dofs, dirichlet_values=held.dirichlet_values, contact=contact, loads=loads,
        exact=exact_fields(case), refinements=times, symmetry_nodes=held.symmetry_nodes,
        symmetry_normals=held.symmetry_normals, free_modes=None, platens=held.platens,
        mesh_request=MeshRequest.of(case), holds=held.holds, drive=drive, piece=piece, numbers=numbers,
        node_range=(first, last),
        boundary_ids=ids, boundary_numbers=boundary_numbers, n_points_total=int(piece.global_counts[0]),
        body_load=body, preallocation=preallocation)


def takes_pieces(case: Case, refine: int | None, ranks: int) -> bool:
    """Whether :func:`piece_problem` meshes ``case`` in pieces on ``ranks`` ranks (no message:
    every rank decides alike), for what must be refused before the solve."""
    return _coarse_for_pieces(case, case.mesh.refine if refine is None else refine, ranks) is not None


def _coarse_for_pieces(case: Case, times: int, ranks: int) -> Mesh | None:
    """The coarse mesh the pieces refine ``times`` times, or None when the case keeps the replicated mesh."""
    if not times:
        return None
    coarse = build_mesh(case, refine=0)
    # The coarse problem runs every check of the case (held, loaded, contact facing) and tells
    # whether the fine one has platens or free rigid motions.
    checked = build_problem(case, coarse, assemble_stiffness=False)
    pushed = checked.drive is not None and checked.drive.pushed
    if checked.platens or checked.free_modes is not None or pushed or coarse.n_triangles < ranks:
        return None
    return coarse


def _refuse_oversized(case: Case, triangles: int, times: int, mpi) -> None:
    """The size guard per rank: the ranks on this machine (sharing its memory) each need
    :func:`contactfem.estimate.estimate_cost` of ``ranks`` ranks; refused on every rank alike."""
    from mpi4py import MPI

    from contactfem.errors import CaseError
    from contactfem.estimate import estimate_cost, guard_text, guarded_bytes, memory_limit, unknowns_of_triangles

    ranks = mpi.Get_size()
    unknowns = unknowns_of_triangles(triangles)
    per_rank = estimate_cost(unknowns, "petsc", ranks)["bytes"]
    here = mpi.Split_type(MPI.COMM_TYPE_SHARED)
    local = here.Get_size()
    here.Free()
    limit = memory_limit()
    needed = per_rank * local
    refused = mpi.allreduce(bool(needed > guarded_bytes(limit)), op=MPI.LOR)
    if refused:
        raise CaseError(
            f"{case.source.name}: mesh: about {triangles:.3g} triangles requested (with the refinements), "
            f"{unknowns:.3g} unknowns, whose solve needs about {per_rank / 2**30:.3g} GiB on each of {ranks} ranks "
            f"with petsc, {local} of them sharing what {guard_text(limit)}; use more machines, or "
            f"fewer refinements (--refine or mesh.refine, now {times}; each multiplies the triangles by four)")


def _members(ids: np.ndarray, sorter: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """Whether each of ``wanted`` is among ``ids`` (``sorter`` sorts ``ids``)."""
    if len(ids) == 0:
        return np.zeros(len(wanted), dtype=bool)
    where = np.minimum(np.searchsorted(ids, wanted, sorter=sorter), len(ids) - 1)
    return ids[sorter[where]] == wanted


def _boundary_mesh(piece: MeshPiece, mpi) -> tuple[Mesh, np.ndarray]:
    """The refined mesh's whole boundary on every rank: its nodes by increasing global id (and
    those ids), its edges in the serial mesh's row order with their parts and curves."""
    nodes = np.unique(piece.boundary_edges)
    gathered = mpi.allgather((piece.node_ids[nodes], piece.points[nodes], piece.boundary_ids,
                              piece.node_ids[piece.boundary_edges], piece.edge_parts, piece.edge_curves))
    ids, first = np.unique(np.concatenate([item[0] for item in gathered]), return_index=True)
    points = np.concatenate([item[1] for item in gathered])[first]
    rows = np.concatenate([item[2] for item in gathered])
    order = np.argsort(rows)
    edges = np.searchsorted(ids, np.concatenate([item[3] for item in gathered])[order])
    parts = np.concatenate([item[4] for item in gathered])[order]
    curves = np.concatenate([item[5] for item in gathered])[order]
    mesh = Mesh(points=points, triangles=np.zeros((0, 3), dtype=np.int64), boundary_edges=edges, edge_parts=parts,
                part_names=piece.part_names, edge_curves=curves, curves=piece.curves)
    return mesh, ids


def assemble_piece_system(PETSc, comm, problem: PieceProblem, method) -> _DistributedSystem:
    """:meth:`_DistributedSystem.assemble` of a piece problem: the stiffness of this rank's
    triangles (each triangle on one rank), the rotated load and supports of its owned nodes."""
    from contactfem.discretize.frames import _frames

    mpi = comm.tompi4py()
    piece, numbers = problem.piece, problem.numbers
    first_node, last_node = problem.node_range
    n_dof = 2 * problem.n_points_total
    n_local = 2 * (last_node - first_node)
    bnum, bids = problem.boundary_numbers, problem.boundary_ids
    supported_b = np.zeros(2 * problem.mesh.n_points, dtype=bool)
    supported_b[problem.dirichlet_dofs] = True
    frames = _frames(problem, supported_b)
    blocks = np.stack([frames.a, frames.b], axis=2)
    sorter = np.argsort(piece.node_ids)
    framed_ids = bids[frames.nodes]
    here = _members(piece.node_ids, sorter, framed_ids)
    frame_of = np.full(piece.n_points, -1, dtype=np.int64)
    frame_of[sorter[np.searchsorted(piece.node_ids, framed_ids[here], sorter=sorter)]] = np.flatnonzero(here)

    stiffness = _piece_stiffness(PETSc, comm, problem, frame_of, blocks)
    absolute, longest_row, largest_diagonal = matrix_scales(PETSc, comm, stiffness, n_local, n_dof)

    # The load: body force of the piece's triangles (summed over the ranks sharing a node), the
    # surface loads at the owned boundary nodes, then Qᵀ F at the owned framed nodes.
    vector = PETSc.Vec().createMPI((n_local, n_dof), comm=comm)
    vector.set(0.0)
    if problem.body_load is not None:
        dofs = (2 * numbers[:, None] + np.arange(2)).ravel().astype(PETSc.IntType)
        vector.setValues(dofs, problem.body_load, addv=PETSc.InsertMode.ADD_VALUES)
    vector.assemblyBegin()
    vector.assemblyEnd()
    load = vector.getArray().copy().reshape(-1, 2)
    vector.destroy()
    mine = np.flatnonzero((bnum >= first_node) & (bnum < last_node))
    load[bnum[mine] - first_node] += problem.load.reshape(-1, 2)[mine]
    framed = (bnum[frames.nodes] >= first_node) & (bnum[frames.nodes] < last_node)
    at = bnum[frames.nodes[framed]] - first_node
    load[at] = np.einsum("kca,kc->ka", blocks[framed], load[at])

    def petsc_dofs(dofs: np.ndarray) -> np.ndarray:
        return 2 * bnum[dofs // 2] + dofs % 2

    fixed = np.concatenate([problem.dirichlet_dofs, frames.fixed_dofs]).astype(np.int64)
    fixed_values = np.concatenate([problem.dirichlet_values, frames.fixed_values])
    rows = petsc_dofs(fixed) - 2 * first_node
    keep = (rows >= 0) & (rows < n_local)
    supported_local = np.zeros(n_local, dtype=bool)
    supported_local[rows[keep]] = True
    values_local = np.zeros(n_local)
    values_local[rows[keep]] = fixed_values[keep]
    supported_mesh = np.zeros(n_dof, dtype=bool)  # over global ids: the probe's numbering
    supported_mesh[2 * bids[fixed // 2] + fixed % 2] = True

    owned = piece.owned
    owned = owned[np.argsort(numbers[owned])]
    n_total = mpi.allreduce(len(owned))
    centre = mpi.allreduce(piece.points[owned].sum(axis=0)) / max(n_total, 1)
    rigid = _rigid_motions(piece.points[owned]).T.reshape(3, -1, 2)  # (3, owned, 2) about the local mean
    shift = piece.points[owned].mean(axis=0) - centre if len(owned) else np.zeros(2)
    rigid[2] += np.array([-shift[1], shift[0]])  # the rotation about the body's centre
    rigid[:, at] = np.linalg.solve(blocks[framed][None], rigid[:, at][..., None])[..., 0]
    extents = np.array(mpi.allgather((piece.points.min(axis=0), piece.points.max(axis=0))))  # (ranks, 2, 2)
    span = float(np.max(extents[:, 1].max(axis=0) - extents[:, 0].min(axis=0)))
    slot = frames.normal_slot
    return _DistributedSystem(
        stiffness=stiffness, absolute=absolute, load_local=load.ravel(), supported_local=supported_local,
        support_values_local=values_local, normal_dofs=petsc_dofs(slot),
        normal_slots=2 * bids[slot // 2] + slot % 2, supported_mesh=supported_mesh,
        gap=np.asarray(problem.contact.gap, dtype=float), multiplier_mass=method.multiplier_mass(problem.contact.masses),
        contact_edges=problem.contact.node_edges(), gamma=roundoff_bound(longest_row + 2),
        layout=PieceLayout(first=2 * first_node, last=2 * last_node, owned_ids=piece.node_ids[owned]),
        frame_nodes=frames.nodes, frames=blocks, owned_triangles=len(piece.triangles), n_dof=n_dof,
        rigid_motions_local=rigid.reshape(3, -1), masters=frames.masters, free_modes_normal=None,
        free_modes_load=None, force_unit=largest_diagonal * span if span else 0.0)


def _piece_stiffness(PETSc, comm, problem: PieceProblem, frame_of: np.ndarray, blocks: np.ndarray):
    """K' = Qᵀ K Q of this rank's triangles as a PETSc MPIAIJ matrix (rows sent to their owners)."""
    piece, numbers = problem.piece, problem.numbers
    first_node, last_node = problem.node_range
    n_local, n_dof = 2 * (last_node - first_node), 2 * problem.n_points_total
    d_nnz, o_nnz = (count.astype(PETSc.IntType) for count in problem.preallocation)
    stiffness = PETSc.Mat().createAIJ(size=((n_local, n_dof), (n_local, n_dof)), bsize=2,
                                      nnz=(d_nnz, o_nnz), comm=comm)
    stiffness.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    add = PETSc.InsertMode.ADD_VALUES
    for start in range(0, len(piece.triangles), ELEMENT_CHUNK):
        triangles = piece.triangles[start:start + ELEMENT_CHUNK]
        ke = element_stiffness(piece.points, triangles, problem.law)
        _rotate(ke, triangles, frame_of, blocks)
        dofs = (2 * numbers[triangles][:, :, None] + np.arange(2)).reshape(len(triangles), 6).astype(PETSc.IntType)
        stiffness.setValuesRCV(dofs, dofs, ke.reshape(len(triangles), 36), addv=add)
    stiffness.assemblyBegin()
    stiffness.assemblyEnd()
    stiffness.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    stiffness.setOption(PETSc.Mat.Option.SPD, True)
    return stiffness


def _piece_preallocation(piece: MeshPiece, numbers: np.ndarray, node_range: tuple[int, int],
                         mpi) -> tuple[np.ndarray, np.ndarray]:
    """Entries per owned row inside and outside this rank's columns: the node's own 2x2 block
    and one per edge, each edge counted by the lowest rank holding it and sent to the owners
    of its two rows."""
    from petsc4py import PETSc

    comm = PETSc.Comm(mpi)
    first_node, last_node = node_range
    bounds = np.concatenate([[0], np.cumsum(mpi.allgather(last_node - first_node))])
    counted = piece.edges[piece.edge_owner == piece.rank]
    pairs = numbers[np.concatenate([counted, counted[:, ::-1]])]
    row_rank = np.searchsorted(bounds, pairs[:, 0], side="right") - 1
    inside = row_rank == np.searchsorted(bounds, pairs[:, 1], side="right") - 1
    counts = []
    for which in (inside, ~inside):
        vector = PETSc.Vec().createMPI((last_node - first_node, int(bounds[-1])), comm=comm)
        vector.set(0.0)
        rows, total = np.unique(pairs[which, 0], return_counts=True)
        vector.setValues(rows.astype(PETSc.IntType), total.astype(float), addv=PETSc.InsertMode.ADD_VALUES)
        vector.assemblyBegin()
        vector.assemblyEnd()
        counts.append(np.rint(vector.getArray()).astype(np.int64))
        vector.destroy()
    return np.repeat(2 * (counts[0] + 1), 2), np.repeat(2 * counts[1], 2)


def gather_coordinates(linear, problem: PieceProblem) -> np.ndarray | None:
    """The coordinates of every node in PETSc order (n, 2), on rank 0 (None elsewhere): how
    rank 0 matches the solution to the mesh it builds for the writers."""
    piece = problem.piece
    owned = piece.owned
    owned = owned[np.argsort(problem.numbers[owned])]
    vector = linear.u.duplicate()
    vector.setArray(piece.points[owned].ravel())
    whole = linear.gather_to_zero(vector)
    vector.destroy()
    return None if whole is None else whole.reshape(-1, 2)


@dataclass(eq=False)
class _WholeSystem:
    """What :func:`contactfem.distributed.step_solution` reads of the system on rank 0: the
    layout from PETSc order to the serial mesh's nodes and the serial frames."""

    layout: _Layout
    frame_nodes: np.ndarray
    frames: np.ndarray
    masters: np.ndarray

    mesh_vector = _DistributedSystem.mesh_vector
    mesh_force = _DistributedSystem.mesh_force


def whole_problem(case: Case, refinements: int, coordinates: np.ndarray) -> tuple[DiscreteProblem, _WholeSystem]:
    """On rank 0, once the solver is freed: the serially refined mesh's problem (for the writers
    and the report; no stiffness), and the system that matches the gathered solution, in PETSc
    order, to its nodes by their coordinates (which agree bit for bit), for
    :func:`contactfem.distributed.step_solution`."""
    from contactfem.discretize.frames import _frames

    # The pieces passed the guard per rank; the whole mesh now holds no solver beside it.
    mesh = refine_uniform(build_mesh(case, refine=0), refinements)
    problem = build_problem(case, mesh, refinements=refinements, assemble_stiffness=False)
    n = mesh.n_points
    by_petsc, by_mesh = np.lexsort(coordinates.T[::-1]), np.lexsort(mesh.points.T[::-1])
    if not np.array_equal(coordinates[by_petsc], mesh.points[by_mesh]):
        raise AssertionError("the distributed mesh's nodes are not the serially refined mesh's")
    order = np.empty(n, dtype=np.int64)
    order[by_petsc] = by_mesh
    position = np.empty(n, dtype=np.int64)
    position[order] = np.arange(n)
    supported = np.zeros(2 * n, dtype=bool)
    supported[problem.dirichlet_dofs] = True
    frames = _frames(problem, supported)
    system = _WholeSystem(layout=_Layout(order=order, position=position, first=0, last=2 * n,
                                         node_bounds=np.array([0, n])),
                          frame_nodes=frames.nodes, frames=np.stack([frames.a, frames.b], axis=2),
                          masters=frames.masters)
    return problem, system
