"""Each support part is booked the reaction along the directions it holds.

A frictionless platen holds its nodes along its normal only, a symmetry line along its own
normal only, a prescribed component along that axis. A node two parts hold (a platen's corner
on a symmetry line, a symmetry node with one component prescribed) has its reaction split
along the two directions, each share to its part: the corner node's sideways reaction used
to be booked whole to the platen (the shipped hertz_platen.yaml: a tangential force of
−30.90 on a frictionless platen).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import CASES, make_runner
from test_platen import FORCE, solved, wedge

from contactfem.cli import main
from contactfem.report import boundary_forces


def _forces(outcome, data: dict) -> dict:
    from test_semicoercive import case_of

    case = case_of(data)
    return boundary_forces(outcome.problem, outcome.solution.displacement, outcome.solution.contact.nodal_force,
                           {p.name: p.label for p in case.parts})


def chamfered_block(top: dict | None = None) -> dict:
    """A 2 x 1 block with its top right corner chamfered, pushed sideways against a symmetry
    line (the left side) by a traction of 3 000 in all on its right side and pressed onto the
    plane y = 0 by a platen on its top, which meets the symmetry line at (0, 1)."""
    return {
        "title": "chamfered block",
        "geometry": {"polygon": {"vertices": [[0, 0], [2, 0], [2, 0.8], [1.8, 1], [0, 1]],
                                 "edges": ["base", "right", "chamfer", "top", "axis"]}},
        "mesh": {"size": 0.1},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"base": "contact", "right": {"traction": [-3750, 0]}, "chamfer": "free",
                     "top": top or {"platen": {"force": 5000}}, "axis": "symmetry"},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }


def test_the_shipped_platen_reports_no_tangential_force(tmp_path):
    """hertz_platen.yaml: nothing loads the quarter disk sideways, so the frictionless platen's
    force is vertical and the symmetry line's horizontal forces balance to zero; the platen
    carries its 2 000 and the rim the same, and all parts balance."""
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(CASES / "hertz_platen.yaml"), "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.stderr
    forces = json.loads((out / "report.json").read_text(encoding="utf-8"))["boundary_forces"]
    top, axis, rim = (forces["parts"][name]["force"] for name in ("top", "axis", "rim"))
    assert abs(top[0]) <= 1e-10 * FORCE, top
    assert abs(top[1] + FORCE) <= 1e-10 * FORCE, top
    assert np.hypot(*axis) <= 1e-10 * FORCE, axis
    assert abs(rim[1] - FORCE) <= 1e-10 * FORCE, rim
    assert forces["total"]["relative_force_residual"] <= 1e-12
    assert forces["total"]["relative_moment_residual"] <= 1e-12


@pytest.mark.parametrize("top", [{"platen": {"force": 5000}}, {"platen": {"displacement": 1.0e-3}}],
                         ids=["force", "advance"])
def test_a_chamfered_block_books_the_sideways_load_to_its_symmetry_line(top):
    """The symmetry line alone holds the block sideways: it carries the whole 3 000 (it was
    booked 2 851.5 here, the platen the other 148.5), the platen nothing tangential."""
    data = chamfered_block(top)
    outcome = solved(data)
    forces = _forces(outcome, data)
    axis, platen = forces["parts"]["axis"]["force"], forces["parts"]["top"]["force"]
    scale = 3000.0
    assert abs(axis[0] - 3000.0) <= 1e-10 * scale and abs(axis[1]) <= 1e-10 * scale, axis
    assert abs(platen[0]) <= 1e-10 * scale, platen
    np.testing.assert_allclose(forces["parts"]["right"]["force"], [-3000.0, 0.0], atol=1e-10 * scale)
    # The platen presses with what the plane carries back.
    assert abs(platen[1] + forces["parts"]["base"]["force"][1]) <= 1e-10 * scale
    assert forces["total"]["relative_force_residual"] <= 1e-12
    assert forces["total"]["relative_moment_residual"] <= 1e-12


def test_an_inclined_platen_on_a_symmetry_line_presses_along_its_normal():
    """The wedge's platen is inclined (normal (−0.25, 1)/|·|) and meets the symmetry line at a
    node held along both normals, not at right angles: the platen's share is along its own
    normal, its size the platen's force, and the symmetry line's is across the line."""
    data = wedge({"left": "symmetry", "top": {"platen": {"force": FORCE}}})
    outcome = solved(data)
    forces = _forces(outcome, data)
    normal = outcome.problem.platens[0].normal
    platen = np.array(forces["parts"]["top"]["force"])
    assert abs(platen[0] * normal[1] - platen[1] * normal[0]) <= 1e-10 * FORCE, platen
    assert abs(platen @ normal + FORCE) <= 1e-10 * FORCE, platen
    axis = forces["parts"]["left"]["force"]
    assert abs(axis[1]) <= 1e-10 * FORCE, axis
    assert forces["total"]["relative_force_residual"] <= 1e-12


def test_a_symmetry_node_with_one_prescribed_component_books_each_to_its_part():
    """The square's left side a symmetry line, its top moved down (only the vertical component
    prescribed) and its right side pushed left by 1 000 in all: at the shared corner (0, 1) the
    top holds y, the symmetry line x, so the symmetry line carries the whole 1 000 and the top
    nothing sideways (the top comes first in the mesh's part order, and was booked the
    corner's sideways reaction)."""
    from conftest import square_case_dict

    data = square_case_dict(8)
    data["boundary"] = {"left": "symmetry", "top": {"displacement": [None, -1.0e-3]},
                        "right": {"traction": [-1.0e3, 0]}, "bottom": "contact"}
    outcome = solved(data)
    forces = _forces(outcome, data)
    top, left, bottom = (forces["parts"][name]["force"] for name in ("top", "left", "bottom"))
    scale = 1.0e3
    assert abs(top[0]) <= 1e-10 * scale, top
    assert abs(left[0] - 1.0e3) <= 1e-10 * scale and abs(left[1]) <= 1e-10 * scale, left
    assert abs(top[1] + bottom[1]) <= 1e-10 * scale
    assert forces["total"]["relative_force_residual"] <= 1e-12


def test_clamped_corners_stay_with_the_first_part_in_the_mesh():
    """Two parts prescribing both components of a shared node: the node's whole reaction goes
    to the first of them in the mesh's part order, as before (the held directions do not tell
    them apart)."""
    from conftest import square_case_dict

    data = square_case_dict(4)
    data["boundary"]["bottom"] = "clamped"
    data["boundary"]["left"] = "clamped"
    data.pop("obstacle")
    data["boundary"]["right"] = "contact"
    data["obstacle"] = {"point": [1.1, 0], "normal": [1, 0]}
    outcome = solved(data)
    problem = outcome.problem
    forces = _forces(outcome, data)
    from contactfem.report import contact_and_reactions

    _, reactions = contact_and_reactions(problem, outcome.solution.displacement,
                                         outcome.solution.contact.nodal_force)
    r = reactions.reshape(-1, 2)
    mesh = problem.mesh
    corner = int(np.flatnonzero(np.all(mesh.points == [0.0, 0.0], axis=1))[0])
    first = min(("bottom", "left"), key=mesh.part_names.index)
    other = "left" if first == "bottom" else "bottom"
    nodes_of = {name: np.unique(mesh.edges_of(name)) for name in ("bottom", "left")}
    np.testing.assert_allclose(forces["parts"][other]["force"],
                               r[np.setdiff1d(nodes_of[other], [corner])].sum(axis=0), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(forces["parts"][first]["force"], r[nodes_of[first]].sum(axis=0),
                               rtol=1e-12, atol=1e-9)
