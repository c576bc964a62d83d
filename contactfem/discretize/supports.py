"""Supports: prescribed displacements, symmetry lines, and the refusal of supports that leave a rigid motion free."""

from __future__ import annotations

import numpy as np

from contactfem.assembly import edge_geometry
from contactfem.case import Case
from contactfem.discretize.finite import refuse_non_finite
from contactfem.errors import CaseError
from contactfem.mesh import Mesh


def supports(case: Case, mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Prescribed unknowns and their values; refuses conflicts and supports that allow rigid motion."""
    values = np.full(2 * mesh.n_points, np.nan)
    owner = np.full(2 * mesh.n_points, -1)
    for index, part in enumerate(case.parts):
        if not part.is_dirichlet:
            continue
        nodes = mesh.nodes_of(part.name)
        components = part.values if part.kind == "displacement" else (None, None)
        for component in range(2):
            if part.kind == "displacement" and components[component] is None:
                continue
            if part.kind == "clamped":
                prescribed = np.zeros(len(nodes))
            else:
                key = f"boundary.{part.name}.displacement[{component}]"
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
    symmetry_nodes, symmetry_normals = _symmetry_lines(case, mesh, prescribed)
    # A node on two symmetry lines that are not parallel cannot move at all.
    unique, first, counts = np.unique(symmetry_nodes, return_index=True, return_counts=True)
    pinned = unique[counts > 1]
    if len(pinned):
        values[np.concatenate([2 * pinned, 2 * pinned + 1])] = 0.0
        owner[np.concatenate([2 * pinned, 2 * pinned + 1])] = len(case.parts)
    keep = np.isin(unique, pinned, invert=True)
    symmetry_nodes, symmetry_normals = unique[keep], symmetry_normals[first[keep]]
    dofs = np.flatnonzero(owner >= 0)
    _refuse_rigid_motion(case, mesh, dofs, symmetry_nodes, symmetry_normals)
    return dofs, values[dofs], symmetry_nodes, symmetry_normals


def _symmetry_lines(case: Case, mesh: Mesh, prescribed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nodes of the symmetry parts (without prescribed components) and their line's normal.

    A symmetry part must be straight: all its edges on one line, whose outward unit normal
    n_s is the direction held (u · n_s = 0).
    """
    nodes, normals = [], []
    for part in case.parts:
        if part.kind != "symmetry":
            continue
        edges = mesh.edges_of(part.name)
        if len(edges) == 0:
            raise CaseError(f"{case.source.name}: boundary.{part.name}: the mesh has no edge on this part")
        _, outward = edge_geometry(mesh.points, edges)
        normal = outward.mean(axis=0)
        normal /= np.linalg.norm(normal)
        points = mesh.points[np.unique(edges)]
        offset = (points - points[0]) @ normal
        extent = np.ptp(mesh.points, axis=0).max()
        if np.abs(outward @ normal - 1.0).max() > 1e-9 or np.abs(offset).max() > 1e-9 * extent:
            raise CaseError(
                f"{case.source.name}: boundary.{part.name} = symmetry: the part is not straight; "
                "a symmetry support needs all its edges on one line"
            )
        part_nodes = np.unique(edges)
        part_nodes = part_nodes[~prescribed[part_nodes].any(axis=1)]
        nodes.append(part_nodes)
        normals.append(np.tile(normal, (len(part_nodes), 1)))
    if not nodes:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
    return np.concatenate(nodes), np.concatenate(normals)


def _refuse_rigid_motion(case: Case, mesh: Mesh, dofs: np.ndarray, symmetry_nodes: np.ndarray,
                         symmetry_normals: np.ndarray) -> None:
    """The supports must pin the three rigid motions: translations along x and y, rotation."""
    # Each constraint holds u(p) · d = 0 for a point p and direction d: a prescribed
    # component (d = e_x or e_y) or a symmetry line (d = n_s).
    directions = np.concatenate([np.eye(2)[dofs % 2], symmetry_normals])
    p = mesh.points[np.concatenate([dofs // 2, symmetry_nodes])]
    centre = p.mean(axis=0) if len(p) else np.zeros(2)
    # Rigid displacement r = a e_x + b e_y + c (−(y−yc), x−xc), seen through each constraint.
    modes = np.zeros((len(p), 3))
    modes[:, 0] = directions[:, 0]
    modes[:, 1] = directions[:, 1]
    modes[:, 2] = -(p[:, 1] - centre[1]) * directions[:, 0] + (p[:, 0] - centre[0]) * directions[:, 1]
    scale = np.ptp(mesh.points, axis=0).max()
    modes[:, 2] /= scale
    singular = np.linalg.svd(modes, compute_uv=False) if len(modes) else np.zeros(0)
    rank = int((singular > 1e-8 * max(singular.max(initial=0.0), 1.0)).sum())
    if rank < 3:
        names = ", ".join(case.dirichlet_parts)
        raise CaseError(
            f"{case.source.name}: boundary: the supports ({names}) leave a rigid motion of the body "
            "free, so the problem is ill-posed; prescribe both components on a part of positive length"
        )
