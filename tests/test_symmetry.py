"""Symmetry supports: a symmetric body solved whole and as a half gives the same answer.

The whole body is (−1, 1) × (0, 1) clamped on both sides, pressed down on |x| < 0.3 and
pulled up elsewhere, on a structured mesh with alternating diagonals, which is mirror
symmetric about x = 0 for even divisions. Its right half with a symmetry support on
x = 0 uses exactly the nodes and triangles of the whole mesh's right half, so the two
discrete problems have the same solution there: agreement to solver precision (1e-10),
not merely to the discretisation error. The multipliers agree as well: at the axis node
the half has half the boundary mass and carries half the nodal force.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import case_from

from contactfem.report import contact_zone, equilibrium
from contactfem.solve import solve_case

N = 16
LOAD = "where(abs(x) < 0.3, -100, 60)"


def body(lower_x: float, divisions_x: int, left: str) -> dict:
    return {
        "geometry": {"rectangle": {"lower": [lower_x, 0], "upper": [1, 1]}},
        "mesh": {"divisions": [divisions_x, N], "diagonal": "alternate"},
        "material": {"E": 1.0e3, "nu": 0.3},
        "boundary": {"left": left, "right": "clamped", "top": {"traction": [0, LOAD]}, "bottom": "contact"},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }


def same_nodes(points: np.ndarray, subset: np.ndarray) -> np.ndarray:
    """Index in ``points`` of each point of ``subset`` (both exact copies of grid points)."""
    lookup = {tuple(p): i for i, p in enumerate(np.round(points * 1e9).astype(np.int64))}
    return np.array([lookup[tuple(p)] for p in np.round(subset * 1e9).astype(np.int64)])


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_half_with_symmetry_support_equals_the_whole(method):
    whole = solve_case(case_from(body(-1.0, 2 * N, "clamped")), method=method)
    half = solve_case(case_from(body(0.0, N, "symmetry")), method=method)
    index = same_nodes(whole.problem.mesh.points, half.problem.mesh.points)
    u_whole, u_half = whole.solution.displacement[index], half.solution.displacement
    assert np.abs(u_whole - u_half).max() <= 1e-10 * np.abs(whole.solution.displacement).max()

    contact_index = same_nodes(whole.problem.mesh.points, half.problem.mesh.points[half.solution.contact.nodes])
    position = {node: k for k, node in enumerate(whole.solution.contact.nodes)}
    rows = [position[i] for i in contact_index]
    mu_whole = whole.solution.contact.multiplier[rows]
    mu_half = half.solution.contact.multiplier
    assert np.abs(mu_whole - mu_half).max() <= 1e-10 * np.abs(mu_whole).max()
    np.testing.assert_array_equal(whole.solution.contact.active[rows], half.solution.contact.active)

    # Partial contact (the point of the case): pressed on |x| ≤ 0.5, lifted off beyond.
    (zone,) = contact_zone(half.problem, half.solution.contact.active)["intervals"]
    assert zone["abscissa"] == pytest.approx([0.0, 0.5])
    assert equilibrium(half.problem, half.solution.displacement, half.solution.contact.nodal_force)["relative_force_residual"] <= 1e-10


def test_slanted_symmetry_line_matches_the_axis_aligned_one(tmp_path):
    """The half body, rotated by 30° with its obstacle and loads, read from a gmsh file: the
    symmetry line is then slanted, and the displacement is the rotated axis-aligned one."""
    import yaml

    from contactfem.mesh import structured_rectangle, write_gmsh

    angle = np.deg2rad(30.0)
    c, s = float(np.cos(angle)), float(np.sin(angle))
    rotation = np.array([[c, -s], [s, c]])
    mesh = structured_rectangle((0.0, 0.0), (1.0, 1.0), N, N, diagonal="alternate")
    write_gmsh(replace(mesh, points=mesh.points @ rotation.T), tmp_path / "half.msh")
    # Original coordinates of a rotated point: (x0, y0) = Rᵀ (x, y); the traction rotates too.
    x0 = f"({c!r}*x + {s!r}*y)"
    g = f"where(abs({x0}) < 0.3, -100, 60)"
    rotated = {
        "geometry": {"mesh_file": "half.msh"},
        "material": {"E": 1.0e3, "nu": 0.3},
        "boundary": {"left": "symmetry", "right": "clamped",
                     "top": {"traction": [f"{-s!r}*{g}", f"{c!r}*{g}"]}, "bottom": "contact"},
        "obstacle": {"point": [0, 0], "normal": (rotation @ np.array([0.0, -1.0])).tolist()},
    }
    (tmp_path / "rotated.yaml").write_text(yaml.safe_dump(rotated))
    from contactfem.case import load_case

    slanted = solve_case(load_case(tmp_path / "rotated.yaml"))
    axis = solve_case(case_from(body(0.0, N, "symmetry")))
    expected = axis.solution.displacement @ rotation.T
    assert np.abs(slanted.solution.displacement - expected).max() <= 1e-9 * np.abs(expected).max()
    np.testing.assert_allclose(slanted.solution.contact.multiplier, axis.solution.contact.multiplier,
                               rtol=0, atol=1e-9 * axis.solution.contact.multiplier.max())
