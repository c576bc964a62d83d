"""Checks of a manufactured (exact) solution against the case: finite where used, and a true contact solution."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from contactfem.case import Case
from contactfem.discretize.obstacles import obstacle_of
from contactfem.errors import CaseError
from contactfem.mesh import Mesh

if TYPE_CHECKING:
    from contactfem.exact import ExactSolution

#: Where on each ΓC edge the exact solution's contact conditions are checked (0 and 1: its ends).
EXACT_CHECK_POINTS = np.array([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
#: Relative tolerance of those checks, against the scales of the exact displacement and stress.
EXACT_CHECK_TOLERANCE = 1e-9


def exact_fields(case: Case) -> "ExactSolution | None":
    """The fields derived from the case's exact: block (:func:`contactfem.exact.exact_solution`),
    or None without one; sympy is imported only for a case that has one."""
    if case.exact is None:
        return None
    from contactfem.exact import exact_solution

    return exact_solution(case)


def check_exact_contact(case: Case, mesh: Mesh, edges: np.ndarray) -> None:
    """Refuse an exact solution that violates a frictionless contact condition on ΓC.

    At the ends and 4 interior points of every contact edge, with g the initial gap of
    the point, u_n = u·n, p = −n·σ n and σ_t = t·σ n: u_n − g ≤ τ_u, p ≥ −τ_σ,
    |p (u_n − g)| ≤ τ_σ τ_u / 1e-9 and |σ_t| ≤ τ_σ, where τ_u = 1e-9 × the largest |u| (at
    the mesh nodes and the check points) or |g|, and τ_σ = 1e-9 × the largest |σ| (at the
    check points and the triangle centroids). Points where the exact stress is not
    finite (the 0/0 of a derivative formula at a singular point such as the tip of
    r^{3/2}) are left out of the stress conditions; the displacement must be finite.

    Raises
    ------
    CaseError
        ``file: exact.displacement: <condition> fails at (x, y) (value ..., tolerance ...)``.
    """
    exact = exact_fields(case)
    obstacle = obstacle_of(case.obstacle)
    a, b = mesh.points[edges[:, 0]], mesh.points[edges[:, 1]]
    where = np.concatenate([(1 - s) * a + s * b for s in EXACT_CHECK_POINTS])
    x, y = where.T
    u = exact.displacement(x, y)
    refuse_non_finite_exact(case, "exact.displacement", u, where, "on the contact boundary")
    gap = obstacle.gap(where)
    slack = exact.normal_displacement(x, y) - gap
    pressure = exact.pressure(x, y)
    tangential = exact.tangential_traction(x, y)
    stress_finite = np.isfinite(pressure) & np.isfinite(tangential)

    def largest(values: np.ndarray) -> float:
        values = np.abs(values[np.isfinite(values)])
        return float(values.max(initial=0.0))

    u_scale = max(largest(exact.displacement(*mesh.points.T)), largest(u), largest(gap))
    centroids = _centroids(mesh)
    s_scale = max(largest(exact.stress(x, y)), largest(exact.stress(*centroids.T)))
    tol_u = EXACT_CHECK_TOLERANCE * u_scale
    tol_s = EXACT_CHECK_TOLERANCE * s_scale
    complementarity = np.where(stress_finite, np.abs(pressure * slack), 0.0)
    conditions = (
        ("non-penetration u_n <= g", slack, slack > tol_u, tol_u),
        ("pressure -sigma_nn >= 0", pressure, stress_finite & (pressure < -tol_s), tol_s),
        ("complementarity pressure * (u_n - g) = 0", complementarity,
         complementarity > EXACT_CHECK_TOLERANCE * s_scale * u_scale, EXACT_CHECK_TOLERANCE * s_scale * u_scale),
        ("zero tangential traction sigma_t = 0 (frictionless)", tangential,
         stress_finite & (np.abs(tangential) > tol_s), tol_s),
    )
    for name, values, fails, tolerance in conditions:
        if fails.any():
            worst = np.flatnonzero(fails)[np.argmax(np.abs(values[fails]))]
            px, py = where[worst]
            raise CaseError(
                f"{case.source.name}: exact.displacement: {name} fails at ({px:g}, {py:g}) "
                f"(value {values[worst]:.3g}, tolerance {tolerance:.3g}); the exact solution must satisfy "
                f"the frictionless contact conditions on {', '.join(f'boundary.{n}' for n in case.contact_parts)}"
            )


def refuse_non_finite_exact(case: Case, key: str, values: np.ndarray, where: np.ndarray,
                             reason: str = "where the load is integrated") -> None:
    """Refuse non-finite values (len(where), ...) of a field derived from exact.displacement."""
    bad = ~np.isfinite(values.reshape(len(where), -1)).all(axis=1)
    if bad.any():
        x, y = where[np.argmax(bad)]
        raise CaseError(
            f"{case.source.name}: {key}: not finite at ({x:g}, {y:g}) (derived from exact.displacement); "
            f"expected finite values {reason} (keep singular points off the mesh's quadrature points)"
        )


def _centroids(mesh: Mesh) -> np.ndarray:
    return mesh.points[mesh.triangles].mean(axis=1)
