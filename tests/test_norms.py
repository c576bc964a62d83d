"""Error norms: zero for fields the discrete space holds exactly, known rates for smooth fields."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import case_from

from contactfem.norms import NORM_NAMES, exact_errors, nested_errors, observed_rates
from contactfem.result import ContactFields, Solution
from contactfem.solve import prepare, solve_case

DELTA, HEIGHT = 1.0e-3, 1.0


def compression_case(divisions: int):
    """A block squeezed onto the obstacle: its exact solution is linear, so P1 holds it.

    Left side on rollers (u_x = 0), top moved down by δ (u_x free), bottom in frictionless
    contact with y ≤ 0, right free. Uniaxial plane strain: ε_yy = −δ/H, σ_xx = 0 gives
    ε_xx = λ δ / ((λ + 2μ) H), and the contact pressure is uniform:
    −σ_yy = (λ + 2μ − λ²/(λ + 2μ)) δ/H.
    """
    return case_from({
        "geometry": {"rectangle": {"lower": [0, 0], "upper": [2, HEIGHT]}},
        "mesh": {"divisions": [2 * divisions, divisions], "diagonal": "alternate"},
        "material": {"E": 1.0e3, "nu": 0.3},
        "boundary": {"left": {"displacement": [0, None]}, "top": {"displacement": [None, -DELTA]},
                     "bottom": "contact", "right": "free"},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    })


class LinearCompression:
    """The exact solution of :func:`compression_case`."""

    def __init__(self, lam: float, mu: float) -> None:
        self.exx = lam * DELTA / ((lam + 2 * mu) * HEIGHT)
        self.eyy = -DELTA / HEIGHT
        self.p = -(lam * (self.exx + self.eyy) + 2 * mu * self.eyy)

    def displacement(self, x, y):
        return np.stack([self.exx * x, self.eyy * y], axis=-1)

    def gradient(self, x, y):
        g = np.zeros(np.shape(x) + (2, 2))
        g[..., 0, 0], g[..., 1, 1] = self.exx, self.eyy
        return g

    def pressure(self, x, y):
        return np.full(np.shape(x), self.p)


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_exact_p1_solution_has_zero_error_norms(method):
    """The compression block's solution is linear: every norm against it is round-off, and
    the solution on a mesh one refinement finer differs from the coarse one by round-off."""
    coarse_case = compression_case(4)
    problem = prepare(coarse_case)
    coarse = solve_case(coarse_case, method=method, problem=problem)
    exact = LinearCompression(problem.law.lam, problem.law.mu)
    errors = exact_errors(coarse.solution, problem, exact)
    u_scale, p_scale = DELTA, exact.p
    assert errors["displacement_l2"] <= 1e-12 * u_scale
    assert errors["displacement_h1"] <= 1e-12 * u_scale
    assert errors["displacement_energy"] <= 1e-12 * np.sqrt(p_scale * DELTA)
    assert errors["multiplier_l2"] <= 1e-10 * p_scale
    assert errors["multiplier_h_minus_half"] <= 1e-10 * p_scale

    fine_problem = prepare(coarse_case, refine=2)
    fine = solve_case(coarse_case, method=method, problem=fine_problem)
    nested = nested_errors(coarse.solution, fine.solution, fine_problem, levels=2)
    assert set(nested) == set(NORM_NAMES)
    assert nested["displacement_h1"] <= 1e-12 * u_scale
    assert nested["multiplier_l2"] <= 1e-10 * p_scale


def interpolated_solution(problem, displacement, pressure) -> Solution:
    """A Solution whose fields are the nodal interpolants of given functions."""
    mesh, contact = problem.mesh, problem.contact
    x, y = mesh.points.T
    u = displacement(x, y)
    px, py = mesh.points[contact.nodes].T
    zeros = np.zeros(len(contact.nodes))
    return Solution(
        method="positive", mesh=mesh, displacement=u,
        stress=np.zeros((mesh.n_triangles, 4)), von_mises=np.zeros(mesh.n_triangles),
        contact=ContactFields(nodes=contact.nodes, edges=contact.edges, multiplier=pressure(px, py),
                              nodal_force=zeros, normal_displacement=zeros, gap=zeros,
                              active=np.ones(len(contact.nodes), bool), abscissa=contact.abscissa,
                              obstacle_point=contact.obstacle.point, obstacle_normal=contact.obstacle.normal),
        newton={},
    )


class Smooth:
    """u = (sin πx sin πy, cos x y²) and p = 1 + x²: smooth, so interpolation errors follow
    the textbook rates: h² in L², h in H¹ and energy, h² for p in L²(ΓC)."""

    def displacement(self, x, y):
        return np.stack([np.sin(np.pi * x) * np.sin(np.pi * y), np.cos(x) * y**2], axis=-1)

    def gradient(self, x, y):
        g = np.empty(np.shape(x) + (2, 2))
        g[..., 0, 0] = np.pi * np.cos(np.pi * x) * np.sin(np.pi * y)
        g[..., 0, 1] = np.pi * np.sin(np.pi * x) * np.cos(np.pi * y)
        g[..., 1, 0] = -np.sin(x) * y**2
        g[..., 1, 1] = 2 * np.cos(x) * y
        return g

    def pressure(self, x, y):
        return 1 + x**2


def test_interpolation_errors_of_a_smooth_field_converge_at_textbook_rates():
    """Fitted slopes over h = 1/8 … 1/64 within ±0.15 of 2 (L²), 1 (H¹, energy), 2 (L²(ΓC))."""
    exact = Smooth()
    rows = []
    for divisions in (4, 8, 16, 32):
        problem = prepare(compression_case(divisions))
        solution = interpolated_solution(
            problem, lambda x, y: exact.displacement(x, y), exact.pressure
        )
        rows.append(exact_errors(solution, problem, exact))
    h = 1.0 / np.array([4, 8, 16, 32])
    for name, rate in [("displacement_l2", 2), ("displacement_h1", 1), ("displacement_energy", 1),
                       ("multiplier_l2", 2)]:
        slope = np.polyfit(np.log(h), np.log([r[name] for r in rows]), 1)[0]
        assert abs(slope - rate) <= 0.15, (name, slope)


def test_observed_rates_between_levels():
    """e = C h^p gives exactly p between every pair of levels."""
    h = np.array([0.1, 0.05, 0.025])
    np.testing.assert_allclose(observed_rates(h, 3 * h**1.5), [1.5, 1.5], rtol=1e-12)
