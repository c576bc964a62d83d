"""The kernel's view of a discrete problem: supports as fixed unknowns, contact and symmetry nodes in rotated frames."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from contactfem.kernel import ContactSystem
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
    lies, holds u_n (u_c = n_c u_n with n_c = ±1).
    """

    system: ContactSystem
    rotation: sp.csr_matrix
    problem: DiscreteProblem

    @classmethod
    def build(cls, problem: DiscreteProblem, method: ContactMethod) -> "ReducedSystem":
        n_dof = 2 * problem.mesh.n_points
        contact = problem.contact
        supported = np.zeros(n_dof, dtype=bool)
        supported[problem.dirichlet_dofs] = True
        nodes, normal_slot, a, b = _frames(problem, supported)
        # Each framed node's slots hold u · a (x slot) and u · b (y slot): Q's 2x2 block is
        # [a b]. E = Q − I lives on those nodes only, so QᵀKQ = K + EᵀK + KE + EᵀKE costs a
        # few products with thin matrices instead of two full ones.
        x, y = 2 * nodes, 2 * nodes + 1
        rows = np.concatenate([x, x, y, y])
        cols = np.concatenate([x, y, x, y])
        vals = np.concatenate([a[:, 0] - 1.0, b[:, 0], a[:, 1], b[:, 1] - 1.0])
        shift = sp.csr_matrix((vals, (rows, cols)), shape=(n_dof, n_dof))
        shift.eliminate_zeros()
        stiffness = problem.stiffness
        k_shift = (stiffness @ shift).tocsr()
        # The three corrections live on the framed rows and columns: sum them first, then
        # add to K once (each full-size sparse addition costs as much as the others together).
        rotated = sp.csr_matrix(stiffness + (k_shift + k_shift.T + shift.T @ k_shift))
        rotated.sum_duplicates()
        rotation = (sp.identity(n_dof, format="csr") + shift).tocsr()
        fixed_dofs = np.concatenate([problem.dirichlet_dofs, 2 * problem.symmetry_nodes])
        fixed_values = np.concatenate([problem.dirichlet_values, np.zeros(len(problem.symmetry_nodes))])
        order = np.argsort(fixed_dofs)
        system = ContactSystem(
            stiffness=rotated,
            load=rotation.T @ problem.load,
            normal_dofs=normal_slot,
            gap=contact.gap,
            multiplier_mass=method.multiplier_mass(contact.masses),
            fixed_dofs=fixed_dofs[order],
            fixed_values=fixed_values[order],
            free_modes=None if problem.free_modes is None else rotation.T @ problem.free_modes,
        )
        return cls(system=system, rotation=rotation, problem=problem)

    def displacement(self, reduced: np.ndarray) -> np.ndarray:
        """Mesh displacement (n_points, 2) from the kernel's unknowns (in rotated coordinates)."""
        return (self.rotation @ reduced).reshape(-1, 2)


def _frames(problem: DiscreteProblem, supported: np.ndarray):
    """Local frames (a, b) of the nodes whose unknowns are rotated, and the contact normal slots.

    - contact node with both components free: a = n, b = t (u_n in the x slot);
    - contact node with one component prescribed (a roller, n along the free axis): the
      prescribed axis stays, the free slot holds u_n;
    - symmetry node: a = n_s (its x slot is fixed to 0), b = t_s, or b = n when it is also a
      contact node (n along the symmetry line), its y slot then holding u_n.
    Returns nodes (k,), normal_slot (m,) aligned with the contact nodes, a (k, 2), b (k, 2).
    """
    contact = problem.contact
    n_o, t_o = contact.normal, contact.tangent
    c = contact.nodes
    sx, sy = supported[2 * c], supported[2 * c + 1]
    sym_index = np.full(problem.mesh.n_points, -1)
    sym_index[problem.symmetry_nodes] = np.arange(len(problem.symmetry_nodes))
    on_symmetry = sym_index[c] >= 0
    m = len(c)
    a = np.tile(n_o, (m, 1))
    b = np.tile(t_o, (m, 1))
    slot = 2 * c
    roller_x = sx & ~sy  # u_x prescribed, normal along y
    a[roller_x] = (1.0, 0.0)
    b[roller_x] = (0.0, n_o[1])
    slot = np.where(roller_x, 2 * c + 1, slot)
    roller_y = sy & ~sx  # u_y prescribed, normal along x
    a[roller_y] = (n_o[0], 0.0)
    b[roller_y] = (0.0, 1.0)
    a[on_symmetry] = problem.symmetry_normals[sym_index[c[on_symmetry]]]
    b[on_symmetry] = n_o
    slot = np.where(on_symmetry, 2 * c + 1, slot)
    # Symmetry nodes that are not contact nodes: a = n_s, b = t_s.
    others = np.setdiff1d(problem.symmetry_nodes, c)
    normals = problem.symmetry_normals[sym_index[others]]
    tangents = np.stack([-normals[:, 1], normals[:, 0]], axis=1)
    nodes = np.concatenate([c, others])
    return nodes, slot, np.concatenate([a, normals]), np.concatenate([b, tangents])
