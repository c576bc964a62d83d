"""The algebraic contact problem the kernel solves: a stiffness, a load, contact normals and gaps.

In coordinates where each contact node's normal displacement is one unknown
(``normal_dofs``), the discrete problem of either method is

    K u + P B μ = F,     B μ ≥ 0,   d − G ≤ 0,   (B μ)ᵀ (d − G) = 0   (row by row)

with d = u[normal_dofs], P the injection of the contact rows into the unknowns, and B the
multiplier mass of the method: the lumped D for the positive method, the consistent M for
the standard one.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True, eq=False)
class ContactSystem:
    """The algebraic contact problem handed to the kernel.

    Attributes
    ----------
    stiffness : (n, n) sparse SPD
        Stiffness with contact nodes in normal/tangent coordinates; supports are given by
        ``fixed_dofs`` (or already eliminated).
    load : (n,)
    normal_dofs : (m,) int
        Index of the normal unknown of each contact node.
    gap : (m,)
        Initial gap G of each contact node (negative: the body starts inside the obstacle).
    multiplier_mass : (m, m) sparse SPD
        B: how the method's multiplier μ becomes nodal forces Bμ.
    fixed_dofs : (k,) int, optional
        Unknowns prescribed by supports, kept in the system (no slicing of K).
    fixed_values : (k,), optional
        Their values.
    free_modes : (n, j), optional
        Rigid motions the supports leave free and only contact holds (K r = 0); None when
        the supports hold the body. Every active set the kernel solves then holds them.
    length_scale : float, optional
        The body's size, in the case's length unit: with the stiffness it gives the force
        scale of an iterate that carries no force at all (no load, no contact force), whose
        computed forces are round-off of an exact zero (see :meth:`ActiveSetSolver.measure`).
        None: no such scale, and such an iterate is not certified.
    contact_edges : (e, 2) int, optional
        The ΓC edges as pairs of contact nodes (indices into ``normal_dofs``): the order
        along ΓC in which a creeping zone edge is recognised (:class:`ZoneFronts`). None:
        Newton's update alone.
    translation : (n,), optional
        A rigid translation of the body in these unknowns that the prescribed values are
        components of, given when nothing loads the body (a block pushed by its top): it is
        then the supports' own solution, which a cold start with no node inside the
        obstacle would factorise and solve for first (:func:`solve_contact` checks it and
        starts from its update instead). None: not known.
    """

    stiffness: sp.spmatrix
    load: np.ndarray
    normal_dofs: np.ndarray
    gap: np.ndarray
    multiplier_mass: sp.spmatrix
    fixed_dofs: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    fixed_values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    free_modes: np.ndarray | None = None
    length_scale: float | None = None
    contact_edges: np.ndarray | None = None
    translation: np.ndarray | None = None

    def scaled(self, factor: float) -> "ContactSystem":
        """The system with its load and prescribed values multiplied by ``factor`` (a step
        of a load path; the obstacle stays)."""
        return dataclasses.replace(self, load=factor * np.asarray(self.load, dtype=float),
                                   fixed_values=factor * np.asarray(self.fixed_values, dtype=float),
                                   translation=None if self.translation is None else factor * self.translation)

    def coupled_outside(self, keep: np.ndarray) -> np.ndarray:
        """The unknowns outside ``keep`` (bool, n) that a kept equation couples to: the only
        values :meth:`restricted` reads."""
        rows = sp.csr_matrix(self.stiffness)[np.flatnonzero(keep)]
        columns = np.unique(rows.indices)
        return columns[~keep[columns]]

    def restricted(self, keep: np.ndarray, values: np.ndarray) -> "ContactSystem":
        """The same contact problem on the unknowns ``keep`` (bool, n; every normal unknown
        of a contact node among them), every other unknown fixed at ``values`` (n,), or at
        its support's value where it has one.

        K_kk u_k = F_k − K_ko values_o: an exact subproblem when ``values`` are the outer
        unknowns of the solution, and held whatever the supports, since the outer unknowns
        are fixed (no free rigid motion is left to the contact).
        """
        keep = np.asarray(keep, dtype=bool)
        fixed_dofs = np.asarray(self.fixed_dofs, dtype=np.int64)
        values = np.array(values, dtype=float)
        values[fixed_dofs] = self.fixed_values
        normal_dofs = np.asarray(self.normal_dofs, dtype=np.int64)
        if not keep[normal_dofs].all():
            raise ValueError("a restricted contact system keeps every normal unknown of a contact node")
        kept = np.flatnonzero(keep)
        rows = sp.csr_matrix(self.stiffness)[kept]
        outside = np.where(keep, 0.0, np.asarray(values, dtype=float))
        position = np.full(len(keep), -1, dtype=np.int64)
        position[kept] = np.arange(len(kept))
        fixed_inside = keep[fixed_dofs]
        return ContactSystem(
            stiffness=rows[:, kept].tocsr(),
            load=np.asarray(self.load, dtype=float)[kept] - rows @ outside,
            normal_dofs=position[normal_dofs],
            gap=self.gap,
            multiplier_mass=self.multiplier_mass,
            fixed_dofs=position[fixed_dofs[fixed_inside]],
            fixed_values=np.asarray(self.fixed_values, dtype=float)[fixed_inside],
            contact_edges=self.contact_edges,
        )


def default_c(system: ContactSystem) -> float:
    """c of the order of the normal nodal stiffness, so that c (d − G) is a force like Bμ.

    Scaling K by any factor scales c with it, which keeps the iteration unit-free.
    """
    if len(system.normal_dofs) == 0:
        return 1.0
    return float(np.mean(system.stiffness.diagonal()[system.normal_dofs]))
