"""Error norms of a discrete solution against a finer nested solution or an exact one.

Displacement: L²(Ω), H¹ seminorm and norm, energy norm a(e, e)^½. Multiplier: L²(ΓC)
and the discrete H^{-1/2}(ΓC) dual norm sup_v ∫ μ v_n / ‖v‖_{1,Ω} = (rᵀ A⁻¹ r)^½ with
r_i = ∫_ΓC μ φ_i·n and A the H¹ Gram matrix (supports clamped), on the mesh the
reference lives on. A nested coarse solution is interpolated exactly onto the fine
mesh, so all norms are exact quadratures of P1 fields; against an exact solution the
quadrature is of degree 5 on triangles and 5-point Gauss on ΓC edges.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import scipy.sparse as sp

from contactfem.assembly import (
    Elasticity,
    boundary_mass,
    laplacian_matrix,
    mass_matrix,
    shape_gradients,
    vector_form,
)
from contactfem.discretize import DiscreteProblem
from contactfem.linalg import factorize
from contactfem.mesh import prolongation
from contactfem.quadrature import (
    TRIANGLE_POINTS,
    TRIANGLE_WEIGHTS,
    gauss_on_unit_interval,
)
from contactfem.result import Solution

NORM_NAMES = (
    "displacement_l2", "displacement_h1_semi", "displacement_h1", "displacement_energy",
    "multiplier_l2", "multiplier_h_minus_half",
)


class ExactSolution(Protocol):
    """An exact solution: displacement (…, 2), its gradient (…, 2, 2) [a, b] = ∂u_a/∂x_b, pressure (…)."""

    def displacement(self, x: np.ndarray, y: np.ndarray) -> np.ndarray: ...
    def gradient(self, x: np.ndarray, y: np.ndarray) -> np.ndarray: ...
    def pressure(self, x: np.ndarray, y: np.ndarray) -> np.ndarray: ...


def nodal_multiplier(solution: Solution) -> np.ndarray:
    """The multiplier as a field on all mesh nodes (n_points,): zero off the contact nodes."""
    values = np.zeros(solution.mesh.n_points)
    values[solution.contact.nodes] = solution.contact.multiplier
    return values


def nested_errors(
    coarse: Solution, reference: Solution, reference_problem: DiscreteProblem, levels: int,
    reference_multiplier: np.ndarray | None = None,
) -> dict[str, float]:
    """Norms of reference − coarse on the reference mesh, ``levels`` uniform refinements finer.

    ``reference_multiplier`` (n_fine_points,) defaults to the reference solution's own
    multiplier; pass the positive method's λ to measure θ − λ_ref.
    """
    mesh = reference.mesh
    interpolate = prolongation(coarse.mesh, levels)
    if interpolate.shape[0] != mesh.n_points:
        raise ValueError("the reference mesh is not the coarse mesh refined `levels` times")
    error = (reference.displacement - interpolate @ coarse.displacement).ravel()
    mass = vector_form(mass_matrix(mesh.points, mesh.triangles))
    laplacian = vector_form(laplacian_matrix(mesh.points, mesh.triangles))
    l2 = _quadratic(error, mass)
    semi = _quadratic(error, laplacian)
    norms = {
        "displacement_l2": l2,
        "displacement_h1_semi": semi,
        "displacement_h1": float(np.hypot(l2, semi)),
        "displacement_energy": _quadratic(error, reference_problem.stiffness),
    }
    fine_multiplier = nodal_multiplier(reference) if reference_multiplier is None else reference_multiplier
    difference = fine_multiplier - interpolate @ nodal_multiplier(coarse)
    gamma_mass = boundary_mass(mesh.points, reference_problem.contact.edges, mesh.n_points)
    norms["multiplier_l2"] = _quadratic(difference, gamma_mass)
    norms["multiplier_h_minus_half"] = _dual_norm(reference_problem, gamma_mass @ difference, mass, laplacian)
    return norms


def exact_errors(solution: Solution, problem: DiscreteProblem, exact: ExactSolution) -> dict[str, float]:
    """Norms of exact − discrete by quadrature (degree 5 on triangles, 5-point Gauss on ΓC)."""
    mesh = solution.mesh
    gradients, area = shape_gradients(mesh.points, mesh.triangles)
    corners = mesh.points[mesh.triangles]  # (t, 3, 2)
    u_corners = solution.displacement[mesh.triangles]  # (t, 3, 2)
    grad_h = np.einsum("tia,tib->tab", u_corners, gradients)  # (t, 2, 2)
    l2 = semi = energy = 0.0
    for weight, bary in zip(TRIANGLE_WEIGHTS, TRIANGLE_POINTS):
        q = np.einsum("i,tia->ta", bary, corners)
        u_h = np.einsum("i,tia->ta", bary, u_corners)
        e = exact.displacement(q[:, 0], q[:, 1]) - u_h
        g = exact.gradient(q[:, 0], q[:, 1]) - grad_h
        l2 += weight * np.sum(area * np.sum(e * e, axis=1))
        semi += weight * np.sum(area * np.sum(g * g, axis=(1, 2)))
        energy += weight * np.sum(area * _energy_density(g, problem.law))
    l2, semi, energy = np.sqrt(l2), np.sqrt(semi), np.sqrt(max(energy, 0.0))

    edges = problem.contact.edges
    a, b = mesh.points[edges[:, 0]], mesh.points[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    mu = nodal_multiplier(solution)
    load = np.zeros(mesh.n_points)
    multiplier_l2 = 0.0
    for s, w in zip(*gauss_on_unit_interval()):
        q = (1 - s) * a + s * b
        difference = exact.pressure(q[:, 0], q[:, 1]) - ((1 - s) * mu[edges[:, 0]] + s * mu[edges[:, 1]])
        multiplier_l2 += w * np.sum(length * difference**2)
        load += np.bincount(edges[:, 0], w * length * difference * (1 - s), minlength=mesh.n_points)
        load += np.bincount(edges[:, 1], w * length * difference * s, minlength=mesh.n_points)
    mass = vector_form(mass_matrix(mesh.points, mesh.triangles))
    laplacian = vector_form(laplacian_matrix(mesh.points, mesh.triangles))
    return {
        "displacement_l2": float(l2),
        "displacement_h1_semi": float(semi),
        "displacement_h1": float(np.hypot(l2, semi)),
        "displacement_energy": float(energy),
        "multiplier_l2": float(np.sqrt(multiplier_l2)),
        "multiplier_h_minus_half": _dual_norm(problem, load, mass, laplacian),
    }


def observed_rates(h: np.ndarray, errors: np.ndarray) -> np.ndarray:
    """Rates log(e_k / e_{k+1}) / log(h_k / h_{k+1}) between consecutive levels (len − 1,)."""
    h, errors = np.asarray(h, dtype=float), np.asarray(errors, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(errors[:-1] / errors[1:]) / np.log(h[:-1] / h[1:])


def _quadratic(vector: np.ndarray, matrix: sp.spmatrix) -> float:
    return float(np.sqrt(max(vector @ (matrix @ vector), 0.0)))


def _dual_norm(problem: DiscreteProblem, weighted: np.ndarray, mass: sp.spmatrix, laplacian: sp.spmatrix) -> float:
    """(rᵀ A⁻¹ r)^½ with r[2i + c] = n_c · weighted[i] and A the H¹ Gram matrix, supports removed."""
    contact = problem.contact
    if getattr(contact.obstacle, "flat", False):
        normal = contact.normal
    else:  # each contact node's own normal (weighted vanishes off the contact nodes)
        normal = np.zeros((problem.mesh.n_points, 2))
        normal[contact.nodes] = contact.normals
        normal = normal.T
    r = np.zeros(2 * problem.mesh.n_points)
    r[0::2] = normal[0] * weighted
    r[1::2] = normal[1] * weighted
    free = np.ones(len(r), dtype=bool)
    free[problem.dirichlet_dofs] = False
    if not np.any(r[free]):
        return 0.0
    gram = (mass + laplacian).tocsr()[free][:, free]
    solution = factorize(gram).solve(r[free])
    return float(np.sqrt(max(r[free] @ solution, 0.0)))


def _energy_density(gradient_error: np.ndarray, law: Elasticity) -> np.ndarray:
    """σ(e):ε(e) per point for (n, 2, 2) displacement gradients, with the plane's law."""
    strain = 0.5 * (gradient_error + gradient_error.transpose(0, 2, 1))
    trace = strain[:, 0, 0] + strain[:, 1, 1]
    return law.lam * trace**2 + 2 * law.mu * np.sum(strain * strain, axis=(1, 2))
