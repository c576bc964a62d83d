"""What a solve produces: fields on the mesh and on the contact boundary, ready for the writers."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from contactfem.mesh.core import Mesh


@dataclass(frozen=True, eq=False)
class ContactFields:
    """Nodal quantities on the contact boundary ΓC.

    Attributes
    ----------
    nodes : (m,) int64
        Mesh node indices of the contact nodes (on the closure of ΓC, not on a
        Dirichlet part), sorted along ΓC.
    edges : (k, 2) int64
        Mesh node indices of the edges of ΓC (an edge may touch a Dirichlet node).
    multiplier : (m,) float64
        The method's own multiplier at the contact nodes: λh for the positive
        method, θh for the standard one (a pressure, force per unit length).
    nodal_force : (m,) float64
        Λ = D λ or M θ: the contact force carried by each node.
    normal_displacement : (m,) float64
        u·n at the contact nodes (n points from the body into the obstacle).
    gap : (m,) float64
        Initial gap g0 along n between each contact node and the obstacle.
    active : (m,) bool
        Whether the node is in the final active set (in contact).
    abscissa : (m,) float64
        Position of each contact node along the obstacle (its coordinate along the tangent).
    obstacle_point, obstacle_normal : (2,) float64
        The flat obstacle: a point of its surface and its unit normal n.
    obstacle_ends : (2, 2) float64 or None
        The end points of a finite obstacle (a segment), None for an infinite one.
    normals : (m, 2) float64 or None
        The obstacle's unit normal at each node's closest point (None: ``obstacle_normal``
        at every node, a flat obstacle).
    obstacle_points : (m, 2) float64 or None
        Each node's closest point on the obstacle, in the reference configuration.
    obstacle_outline : (k, 2) float64 or None
        A curved obstacle's surface as a polyline (a circle sampled along its arc), to draw
        it; None for a flat one. For a curved obstacle ``obstacle_point`` is its center or
        first vertex and ``obstacle_normal`` the normalised mean of ``normals``.
    obstacle_shift : (2,) float64 or None
        How far a moving obstacle went (its advance times its direction): the obstacle
        described above is where it rests; None for one that stays.
    """

    nodes: np.ndarray
    edges: np.ndarray
    multiplier: np.ndarray
    nodal_force: np.ndarray
    normal_displacement: np.ndarray
    gap: np.ndarray
    active: np.ndarray
    abscissa: np.ndarray
    obstacle_point: np.ndarray
    obstacle_normal: np.ndarray
    obstacle_ends: np.ndarray | None = None
    normals: np.ndarray | None = None
    obstacle_points: np.ndarray | None = None
    obstacle_outline: np.ndarray | None = None
    obstacle_shift: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Solution:
    """Displacement, stresses and contact fields of one solved case.

    Attributes
    ----------
    method : str
        ``"positive"`` (method 4) or ``"standard"`` (method 5).
    mesh : Mesh
    displacement : (n_points, 2) float64
    stress : (n_triangles, 4) float64
        Cauchy stress per triangle, columns xx, yy, xy, zz (zz is zero in plane stress).
    von_mises : (n_triangles,) float64
    contact : ContactFields
    newton : dict of str to ndarray
        Per Newton iteration (1-based), equal-length arrays: ``active`` (size of the
        active set), ``added``, ``removed`` (nodes entering / leaving it),
        ``proposed`` (of those, the nodes by which the set differs from Newton's update:
        an accelerator's proposal taken), ``equilibrium_residual`` and
        ``complementarity_residual`` (relative).
    cell_fields : dict of str to (n_triangles,) ndarray
        Extra per-triangle fields, e.g. ``error_indicator`` (η_T of the residual
        estimator, set by ``contactfem adapt``); empty by default.
    """

    method: str
    mesh: Mesh
    displacement: np.ndarray
    stress: np.ndarray
    von_mises: np.ndarray
    contact: ContactFields
    newton: dict[str, np.ndarray]
    cell_fields: dict[str, np.ndarray] = field(default_factory=dict)
