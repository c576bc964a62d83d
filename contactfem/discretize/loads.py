"""The loads of a case, compiled once: the body force as one vector field, the surface forces on the
natural boundary evaluated at the points of the one boundary rule, and what the supports leave free.

Assembly (the load vector), the residual estimator (‖g − σν‖ on the natural boundary) and
the reports all read this object; none of them goes back to the case.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from contactfem.assembly import (
    body_force_points,
    body_force_vector,
    edge_geometry,
    edge_load_vector,
)
from contactfem.case import SCALE_LIMIT, Case, PartKind
from contactfem.discretize.exact_checks import exact_fields, refuse_non_finite_exact
from contactfem.discretize.finite import check_finite, refuse_non_finite
from contactfem.mesh import Mesh
from contactfem.quadrature import EDGE_RULE_POINTS

#: f(x, y) -> (k, 2): a vector field evaluated at k points.
VectorField = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True, eq=False)
class NaturalBoundary:
    """Boundary edges on which the traction is (at least in one direction) prescribed.

    Attributes
    ----------
    edges : (k, 2) int64
        Mesh node indices, body on the left.
    length : (k,) float64
    normal : (k, 2) float64
        Outward unit normals.
    traction : (q, k, 2) float64
        The prescribed surface force g at the q points of :data:`EDGE_RULE_POINTS` on
        each edge (zero on traction-free parts).
    free : (k, 2, 2) float64
        Projector onto the directions the supports leave free, in which σν = g must hold:
        the identity on free, traction and pressure parts; the free axis of a roller; the
        line's tangent t tᵀ on a symmetry line, whose normal reaction is not a residual.
    parts : (k,) int64
        Index into the mesh's ``part_names`` of the part of each edge.
    """

    edges: np.ndarray
    length: np.ndarray
    normal: np.ndarray
    traction: np.ndarray
    free: np.ndarray
    parts: np.ndarray = None  # type: ignore[assignment]

    def load_vector(self, n_points: int) -> np.ndarray:
        """∫ g·v over the natural boundary (2 n_points,)."""
        return edge_load_vector(self.edges, self.length, self.traction, n_points)


@dataclass(frozen=True, eq=False)
class Loads:
    """The body force (None without one) and the natural boundary with its surface forces.

    ``body_force_values`` (q, n_triangles, 2) is f at the points of the triangle rule
    (:func:`contactfem.assembly.body_force_points`), evaluated once.
    """

    body_force: VectorField | None
    natural: NaturalBoundary
    body_force_values: np.ndarray | None = None

    def scaled(self, factor: float) -> "Loads":
        """The same loads multiplied by ``factor`` (a step of a load path)."""
        force = self.body_force
        return Loads(
            body_force=None if force is None else (lambda x, y: factor * force(x, y)),
            natural=replace(self.natural, traction=factor * self.natural.traction),
            body_force_values=None if self.body_force_values is None else factor * self.body_force_values,
        )

    def load_vector(self, mesh: Mesh) -> np.ndarray:
        """F (2 n_points,): ∫ f·v + ∫ g·v."""
        load = self.natural.load_vector(mesh.n_points)
        if self.body_force_values is not None:
            load += body_force_vector(mesh.points, mesh.triangles, self.body_force_values)
        return load


def compile_loads(case: Case, mesh: Mesh) -> Loads:
    """The case's loads on ``mesh``, checked finite where they are integrated."""
    force = _body_force(case)
    values = None
    if force is not None:
        where = body_force_points(mesh.points, mesh.triangles)
        flat = where.reshape(-1, 2)
        values = np.broadcast_to(force(flat[:, 0], flat[:, 1]), flat.shape).reshape(where.shape)
        _refuse_non_finite_body_force(case, values.reshape(-1, 2), flat)
    return Loads(body_force=force, natural=_natural_boundary(case, mesh), body_force_values=values)


def _body_force(case: Case) -> VectorField | None:
    if case.exact is not None:
        return exact_fields(case).body_force
    if case.body_force is None:
        return None
    fx, fy = case.body_force
    return lambda x, y: np.stack([np.broadcast_to(fx(x, y), np.shape(x)), np.broadcast_to(fy(x, y), np.shape(x))],
                                 axis=-1)


def _refuse_non_finite_body_force(case: Case, values: np.ndarray, where: np.ndarray) -> None:
    """f must be finite (and integrable in float64) at every point where it is integrated."""
    if case.exact is not None:
        refuse_non_finite_exact(case, "body_force = 'exact' (-div sigma)", values, where)
        return
    for component, expression in enumerate(case.body_force):
        bad = ~(np.abs(values[:, component]) <= SCALE_LIMIT)
        if bad.any():
            refuse_non_finite(case, f"body_force[{component}]", expression, values[:, component], where)


def _natural_boundary(case: Case, mesh: Mesh) -> NaturalBoundary:
    """Every boundary edge whose traction is prescribed in some direction, part by part."""
    parts = {p.name: p for p in case.parts}
    exact = exact_fields(case)
    pieces = []
    for index, name in enumerate(mesh.part_names):
        edges = mesh.boundary_edges[mesh.edge_parts == index]
        part = parts.get(name)
        kind = part.kind if part is not None else PartKind.FREE  # a part the case does not list is free
        if len(edges) == 0 or kind in (PartKind.CLAMPED, PartKind.CONTACT):
            continue
        length, normal = edge_geometry(mesh.points, edges)
        where = [(1 - s) * mesh.points[edges[:, 0]] + s * mesh.points[edges[:, 1]] for s in EDGE_RULE_POINTS]
        traction = np.zeros((len(EDGE_RULE_POINTS), len(edges), 2))
        free = np.broadcast_to(np.eye(2), (len(edges), 2, 2)).copy()
        if kind is PartKind.TRACTION and part.exact:
            for q, points in enumerate(where):
                traction[q] = exact.traction(points[:, 0], points[:, 1], normal)
            samples = np.concatenate(where)
            refuse_non_finite_exact(case, f"boundary.{name}.traction = 'exact' (sigma n)",
                                    traction.reshape(-1, 2), samples)
        elif kind is PartKind.TRACTION:
            check_finite(case, f"boundary.{name}.traction", part.values, np.concatenate(where))
            for q, points in enumerate(where):
                for component, field in enumerate(part.values):
                    traction[q, :, component] = field(points[:, 0], points[:, 1])
        elif kind is PartKind.PRESSURE:
            check_finite(case, f"boundary.{name}.pressure", part.values, np.concatenate(where))
            for q, points in enumerate(where):
                traction[q] = -normal * np.broadcast_to(part.values[0](points[:, 0], points[:, 1]), length.shape)[:, None]
        elif kind is PartKind.DISPLACEMENT:
            held = np.array([value is not None for value in part.values])
            if held.all():
                continue
            free = np.broadcast_to(np.diag((~held).astype(float)), (len(edges), 2, 2)).copy()
        elif kind in (PartKind.SYMMETRY, PartKind.PLATEN):
            # The line (or the platen) holds the normal direction: only σν · t = 0 is a residual.
            tangent = np.stack([-normal[:, 1], normal[:, 0]], axis=1)
            free = np.einsum("ka,kb->kab", tangent, tangent)
        pieces.append((edges, length, normal, traction, free, np.full(len(edges), index, dtype=np.int64)))
    if not pieces:
        return NaturalBoundary(edges=np.zeros((0, 2), dtype=np.int64), length=np.zeros(0), normal=np.zeros((0, 2)),
                               traction=np.zeros((len(EDGE_RULE_POINTS), 0, 2)), free=np.zeros((0, 2, 2)),
                               parts=np.zeros(0, dtype=np.int64))
    edges, length, normal, traction, free, indices = zip(*pieces)
    return NaturalBoundary(edges=np.concatenate(edges), length=np.concatenate(length),
                           normal=np.concatenate(normal), traction=np.concatenate(traction, axis=1),
                           free=np.concatenate(free), parts=np.concatenate(indices))
