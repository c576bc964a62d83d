"""The discrete problem: the assembled linear elastic system with its loads, supports and contact boundary."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from contactfem.assembly import Elasticity, stiffness_matrix
from contactfem.case import Case
from contactfem.discretize.contact import ContactBoundary, contact_boundary
from contactfem.discretize.exact_checks import check_exact_contact, exact_fields
from contactfem.discretize.frames import ReducedSystem
from contactfem.discretize.loads import Loads, compile_loads
from contactfem.discretize.meshing import MeshRequest
from contactfem.discretize.motion import ObstacleDrive, obstacle_drive, refuse_receding
from contactfem.errors import CaseError
from contactfem.discretize.supports import Holds, PlatenConstraint, free_rigid_modes, supports
from contactfem.mesh import Mesh
from contactfem.methods import ContactMethod

if TYPE_CHECKING:
    from contactfem.exact import ExactSolution


@dataclass(frozen=True, eq=False)
class DiscreteProblem:
    """The assembled linear elastic system with its supports and contact boundary.

    ``stiffness`` (2n, 2n) and ``load`` (2n,) carry no boundary condition;
    ``dirichlet_dofs`` (k,) sorted, with ``dirichlet_values`` (k,). ``loads`` is what
    ``load`` was assembled from; ``exact`` the manufactured solution the loads derive
    from, when the case has one. Everything after this stage reads the problem, never the case.
    """

    mesh: Mesh
    law: Elasticity
    stiffness: sp.csr_matrix
    load: np.ndarray
    dirichlet_dofs: np.ndarray
    dirichlet_values: np.ndarray
    contact: ContactBoundary
    loads: Loads
    exact: "ExactSolution | None" = None
    refinements: int = 0  # uniform refinements of the case's own mesh (for mesh sequencing)
    # Nodes held on a symmetry line (u · n_s = 0) and the line's unit normal at each.
    symmetry_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    symmetry_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    # Rigid motions (2n, k) the supports leave free and only contact holds (the load presses
    # the body onto the obstacle along them); None when the supports hold the body.
    free_modes: np.ndarray | None = None
    # Rigid frictionless platens: their nodes' normal motion is one unknown each.
    platens: tuple[PlatenConstraint, ...] = ()
    # What the mesh was made from (the case's geometry and sizes, or a coarser level's):
    # mesh sequencing derives the next coarser level from it.
    mesh_request: MeshRequest | None = None
    # Which part holds each held node along which direction: the reactions are booked by it.
    holds: Holds | None = None
    # A moving obstacle: its advance, carried by the prescribed values (contactfem.discretize.motion).
    drive: ObstacleDrive | None = None

    @property
    def n_unknowns(self) -> int:
        """Displacement unknowns once the supports are eliminated."""
        return 2 * self.mesh.n_points - len(self.dirichlet_dofs)

    def scaled(self, factor: float) -> "DiscreteProblem":
        """The problem with its loads, prescribed displacements and platen drives multiplied
        by ``factor`` (a step of a load path); the stiffness and the obstacle are shared."""
        return replace(
            self, load=factor * self.load, dirichlet_values=factor * self.dirichlet_values,
            loads=self.loads.scaled(factor),
            platens=tuple(replace(p, value=factor * p.value) for p in self.platens),
            drive=None if self.drive is None else replace(
                self.drive, advance=factor * self.drive.advance,
                force=None if self.drive.force is None else factor * self.drive.force),
        )

    def advanced(self, advance: float) -> "DiscreteProblem":
        """The problem with its moving obstacle advanced by ``advance`` (a pushed obstacle at
        the advance its solve found)."""
        shift = advance - self.drive.advance
        dofs = self.dirichlet_dofs
        return replace(self, dirichlet_values=self.dirichlet_values - shift * self.drive.direction[dofs % 2],
                       drive=replace(self.drive, advance=advance, free=False))

    def contact_system(self, method: ContactMethod) -> ReducedSystem:
        """The kernel's view: supports eliminated, contact nodes in (normal, tangent) unknowns."""
        return ReducedSystem.build(self, method)


def build_problem(case: Case, mesh: Mesh, refinements: int = 0, assemble_stiffness: bool = True,
                  request: MeshRequest | None = None) -> DiscreteProblem:
    """Assemble stiffness and loads, impose the supports and find the contact nodes.

    Without ``assemble_stiffness`` the problem's ``stiffness`` is None: a caller that
    assembles it in parts (each MPI rank its own, :mod:`contactfem.distributed`) gets the rest."""
    material = case.material
    law = Elasticity.from_lame(material.lame_lambda, material.lame_mu, material.plane)
    stiffness = (stiffness_matrix(mesh.points, mesh.triangles, law, topology=mesh.topology)
                 if assemble_stiffness else None)
    loads = compile_loads(case, mesh)
    held = supports(case, mesh)
    contact = contact_boundary(case, mesh, held)
    load = loads.load_vector(mesh)
    free_modes = free_rigid_modes(case, mesh, held, contact, load)
    drive, held = obstacle_drive(case, held)
    refuse_receding(case, drive, contact.gap, contact.normals)
    if drive is not None and free_modes.shape[1]:
        raise CaseError(f"{case.source.name}: obstacle.motion: the supports leave the body a rigid motion that only "
                        "contact holds; expected supports that hold the body still while the obstacle moves")
    exact = exact_fields(case)
    if exact is not None:
        check_exact_contact(case, mesh, contact.edges)
    return DiscreteProblem(
        mesh=mesh, law=law, stiffness=stiffness, load=load,
        dirichlet_dofs=held.dirichlet_dofs, dirichlet_values=held.dirichlet_values, contact=contact, loads=loads,
        exact=exact, refinements=refinements, symmetry_nodes=held.symmetry_nodes,
        symmetry_normals=held.symmetry_normals, free_modes=free_modes if free_modes.shape[1] else None,
        platens=held.platens, mesh_request=MeshRequest.of(case) if request is None else request,
        holds=held.holds, drive=drive,
    )
