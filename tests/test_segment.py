"""A finite obstacle (a segment: a table, a punch): only the nodes in front of it carry a
contact condition; refusals name the key; the flat punch follows the half-space solution."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from conftest import ROOT, case_from, make_runner

from contactfem.cli import main
from contactfem.errors import CaseError
from contactfem.solve import solve_case

sys.path.insert(0, str(ROOT / "benchmarks"))
import punch  # noqa: E402


def overhang(obstacle: dict) -> dict:
    """A block 1 x 0.2, clamped on its left, pressed down on its top, resting on a table that
    ends at x = 0.6: the 0.4 beyond the table's edge is held by nothing."""
    return {
        "title": "block overhanging a table",
        "geometry": {"rectangle": {"lower": [0, 0], "upper": [1, 0.2]}},
        "mesh": {"divisions": [40, 8]},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"left": "clamped", "top": {"pressure": 1.0e3}, "right": "free", "bottom": "contact"},
        "obstacle": obstacle,
    }


def test_a_block_overhanging_a_table_goes_past_its_edge_where_a_line_would_hold_it():
    table = solve_case(case_from(overhang({"segment": [[-0.5, 0], [0.6, 0]]})))
    line = solve_case(case_from(overhang({"points": [[-0.5, 0], [0.6, 0]]})))
    mesh = table.problem.mesh
    bottom = mesh.nodes_of("bottom")
    beyond = bottom[mesh.points[bottom, 0] > 0.6 + 1e-12]
    # With the table, the overhang sags below the table's level (u_y < 0) ...
    assert set(table.problem.contact.beyond) == set(beyond[beyond != 0])
    assert table.solution.displacement[beyond, 1].min() < -1e-3 * np.abs(table.solution.displacement).max()
    # ... and nothing constrains it; with the infinite line, no node goes below y = 0.
    assert line.solution.displacement[bottom, 1].min() >= -1e-12 * np.abs(line.solution.displacement).max()
    assert len(line.problem.contact.beyond) == 0
    # Both are certified solutions of their own discrete problems.
    assert table.kernel.certificate.passed and line.kernel.certificate.passed
    # The table's edge carries the block: the last facing node is in contact.
    facing = table.problem.contact
    assert table.solution.contact.active[np.argmax(facing.abscissa)]


@pytest.mark.parametrize("obstacle, fragment", [
    ({"segment": [[0.3, 0], [0.3, 0]]}, "obstacle.segment"),
    ({"segment": [[0, 0], [1, 0]], "points": [[0, 0], [1, 0]]}, "obstacle"),
    ({"segment": [[0, 0], [1, 0]], "normal": [0, -1]}, "obstacle"),
    ({"segment": [[0, 0]]}, "obstacle.segment"),
    ({"segment": [[2, 0], [3, 0]]}, "obstacle.segment: no node of the contact parts"),
    ({"segment": [[-3, 0], [-2, 0]]}, "obstacle.segment: no node of the contact parts"),
])
def test_bad_segments_are_refused_naming_the_key(tmp_path, obstacle, fragment):
    import yaml

    path = tmp_path / "table.yaml"
    path.write_text(yaml.safe_dump(overhang(obstacle)), encoding="utf-8")
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "table.yaml" in lines[0] and fragment in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_the_segment_is_reported_and_stored(tmp_path):
    import yaml

    from contactfem.io import read_hdf5

    path = tmp_path / "table.yaml"
    path.write_text(yaml.safe_dump(overhang({"segment": [[-0.5, 0], [0.6, 0]]})), encoding="utf-8")
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.stderr
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert report["obstacle"]["ends"] == [[-0.5, 0.0], [0.6, 0.0]]
    assert report["obstacle"]["facing_nodes"] == 24 and report["obstacle"]["beyond_nodes"] == 16
    attrs = read_hdf5(out / "solution.h5")["contact"]["attrs"]
    np.testing.assert_array_equal(attrs["obstacle_ends"], [[-0.5, 0.0], [0.6, 0.0]])
    check = make_runner().invoke(main, ["check", str(path)])
    assert "the segment from (-0.5, 0) to (0.6, 0)" in check.stdout and "24 of 40 contact nodes face it" in check.stdout


def test_the_flat_punch_follows_the_half_space_pressure_in_the_middle_of_the_punch():
    """p(x) = P / (π √(a² − x²)) for a half-space. On a block 20a x 10a graded to a/25 at the
    face (a/100 at its edges), benchmarks/punch.py measures 0.48% relative L² error over the
    middle 80% of the punch (0.4% from the finite block, the rest from the mesh); asked: 1%.
    The solution is certified although the pressure is singular at the edges, every node in
    front of the punch is in contact, and the pressure is largest at the edges."""
    result = solve_case(punch.punch_case(20.0, 10.0, 0.04))
    figures = punch.punch_errors(result)
    assert result.kernel.certificate.passed
    assert figures["active_nodes"] == figures["contact_nodes"]
    assert figures["relative_l2_error_middle_80"] < 0.01, figures
    contact = result.solution.contact
    x = result.problem.mesh.points[contact.nodes, 0]
    assert contact.multiplier[np.argmax(np.abs(x))] == pytest.approx(contact.multiplier.max())


def test_the_shipped_punch_case_solves_with_both_methods():
    from contactfem.case import load_case

    case = load_case(ROOT / "cases" / "flat_punch.yaml")
    for method in ("positive", "standard"):
        result = solve_case(case, method=method)
        assert result.kernel.certificate.passed
        assert result.solution.contact.active.all()


def test_a_finite_obstacle_is_refused_only_when_it_misses_every_contact_part():
    with pytest.raises(CaseError, match="lies in front of the segment"):
        solve_case(case_from(overhang({"segment": [[1.5, 0], [1.6, 0]]})))
