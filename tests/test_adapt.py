"""Newest-vertex bisection, Dörfler marking and the adaptive loop."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import CASES, shipped_case

from contactfem.adaptive import Reference, adapt, common_refinement
from contactfem.discretize import build_mesh, build_problem
from contactfem.mesh import check_mesh
from contactfem.mesh.adapt import (
    bisect,
    bisect_uniform,
    dorfler_mark,
    label_longest_edge,
    min_angle,
)
from contactfem.mesh.transfer import interpolate_p1
from contactfem.solve import solve_case


def _square(divisions: int = 8):
    case = shipped_case("square")
    return replace(case, mesh=replace(case.mesh, divisions=(divisions, divisions)))


@pytest.mark.parametrize("name", ["square", "hole"])
def test_bisection_keeps_conformity_names_and_area(name):
    case = shipped_case(name)
    mesh = label_longest_edge(build_mesh(case))
    area = mesh.triangle_areas().sum()
    lengths = {p: _length(mesh, p) for p in mesh.part_names}
    angle = min_angle(mesh)
    rng = np.random.default_rng(1)
    for _ in range(6):
        old_points = mesh.points.copy()
        mesh = bisect(mesh, rng.random(mesh.n_triangles) < 0.08)
        check_mesh(mesh)  # conforming, counter-clockwise, boundary edges = boundary, on their circles
        assert np.array_equal(mesh.points[: len(old_points)], old_points)  # old nodes keep their indices
    assert mesh.part_names == build_mesh(case).part_names
    for part, length in lengths.items():
        # Straight parts keep their length exactly; arcs get longer as nodes go onto the circle.
        assert _length(mesh, part) >= length * (1 - 1e-12)
    if name == "square":
        assert mesh.triangle_areas().sum() == pytest.approx(area, rel=1e-13)
        for part, length in lengths.items():
            assert _length(mesh, part) == pytest.approx(length, rel=1e-13)
    assert min_angle(mesh) >= angle / 2 - 1e-9  # NVB: bounded angles (exactly kept on the square)


def _length(mesh, part):
    e = mesh.edges_of(part)
    return float(np.linalg.norm(mesh.points[e[:, 1]] - mesh.points[e[:, 0]], axis=1).sum())


def test_uniform_bisection_and_marking():
    mesh = label_longest_edge(build_mesh(_square(4)))
    twice = bisect_uniform(mesh, 2)
    assert twice.n_triangles == 4 * mesh.n_triangles
    assert min_angle(twice) == pytest.approx(45.0)
    eta2 = np.array([4.0, 1.0, 3.0, 0.5, 1.5])
    assert dorfler_mark(eta2, 0.4).tolist() == [True, False, False, False, False]
    assert dorfler_mark(eta2, 0.5).tolist() == [True, False, True, False, False]
    assert dorfler_mark(eta2, 0.7).tolist() == [True, False, True, False, False]
    assert dorfler_mark(eta2, 1.0).all()


def test_reference_errors_are_exact_for_nested_and_overlaid_meshes():
    """A field that is P1 on a coarse mesh has zero error against itself on a finer NVB mesh;
    the common refinement of two NVB meshes holds the nodes of both."""
    case = _square(4)
    coarse = label_longest_edge(build_mesh(case))
    problem = build_problem(case, coarse)
    outcome = solve_case(case, problem=problem)
    fine_mesh = bisect(coarse, np.arange(coarse.n_triangles) % 3 == 0)
    fine_problem = build_problem(case, fine_mesh)
    values = interpolate_p1(coarse, outcome.solution.displacement, fine_mesh.points)
    fine_solution = replace(outcome.solution, mesh=fine_mesh, displacement=values)
    reference = Reference(fine_problem, fine_solution)
    assert reference.errors(problem, outcome.solution)["displacement_energy"] <= 1e-12 * np.sqrt(
        values.ravel() @ (fine_problem.stiffness @ values.ravel()))
    other = bisect(coarse, np.arange(coarse.n_triangles) % 5 == 1)
    common = common_refinement(fine_mesh, other)
    for mesh in (fine_mesh, other):
        distance = np.min(np.linalg.norm(common.points[None, :, :] - mesh.points[:, None, :], axis=2), axis=1)
        assert distance.max() == 0.0


def test_adaptive_loop_beats_uniform_refinement_on_the_square():
    """From an 8×8 mesh, the adaptive loop reaches the energy error of the 32×32 NVB-uniform
    mesh with fewer unknowns; errors against the last adaptive mesh (nested) decrease."""
    case = _square(8)
    initial = label_longest_edge(build_mesh(case))
    kept = []
    run = adapt(case, max_unknowns=12_000, mesh=initial, on_step=lambda row, p, s: kept.append((row, p, s)))
    assert run.stop_reason == "max_unknowns"
    assert run.steps[-1]["unknowns"] <= 12_000
    assert all(b["eta"] < a["eta"] for a, b in zip(run.steps, run.steps[1:]))
    assert all(row["min_angle"] == pytest.approx(45.0) for row in run.steps)
    reference = Reference(run.result.problem, run.result.solution)
    errors = [reference.errors(p, s)["displacement_energy"] for _, p, s in kept if p.n_unknowns <= 1_500]
    assert all(b < a for a, b in zip(errors, errors[1:]))

    uniform = bisect_uniform(initial, 4)  # 32×32
    problem = build_problem(case, uniform)
    outcome = solve_case(case, problem=problem)
    uniform_error = reference.overlay_errors(problem, outcome.solution)["displacement_energy"]
    reached = [p.n_unknowns for (row, p, s), e in zip(kept, errors) if e <= uniform_error]
    assert reached and reached[0] < problem.n_unknowns / 2
    assert run.estimate.total == pytest.approx(run.steps[-1]["eta"])
    assert run.result.solution.cell_fields["error_indicator"].shape == (run.result.problem.mesh.n_triangles,)


def test_adapt_command_writes_history_and_indicator(tmp_path):
    import json

    import meshio
    from click.testing import CliRunner

    from contactfem.cli import main

    result = CliRunner().invoke(main, ["adapt", str(CASES / "manufactured.yaml"), "--max-unknowns", "3000",
                                       "--out", str(tmp_path), "--quiet"])
    assert result.exit_code == 0, result.output
    history = json.loads((tmp_path / "adapt.json").read_text())
    assert history["stop_reason"] == "max_unknowns"
    assert all(1 < row["effectivity"] < 20 for row in history["steps"])
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["estimator"]["eta"] == pytest.approx(history["steps"][-1]["eta"])
    vtu = meshio.read(tmp_path / "solution.vtu")
    assert vtu.cell_data["error_indicator"][0].shape == (report["mesh"]["triangles"],)
