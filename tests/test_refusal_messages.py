"""Refusals say what is wrong with the case as given and what to turn, naming the case file.

- A body free to slide under a platen force: the remedies that keep the load (a symmetry
  line, one prescribed component), not only the one that fixes the body in place.
- A body's extent is its outline's (arcs included), not its vertices': a half-disk's top
  split by a vertex is three vertices on one line, and was refused as of extent 0.
- A numerically singular body: the message starts with the case file, like every other.
"""

from __future__ import annotations

import math

import pytest
import yaml
from conftest import make_runner
from test_platen import FORCE, solved, wedge, platen_of

from contactfem.cli import main

CASE_NAME = "told.yaml"


def _write(tmp_path, data: dict, name: str = CASE_NAME):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def _refused(tmp_path, data: dict, *fragments: str, command: str = "solve") -> str:
    path = _write(tmp_path, data)
    args = [command, str(path)] + (["--out", str(tmp_path / "out"), "--quiet"] if command == "solve" else [])
    result = make_runner().invoke(main, args)
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.stdout)
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {CASE_NAME}: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"
    assert not (tmp_path / "out").exists()
    return lines[0]


# --------------------------------------------------------------------------- a body free to slide


def test_a_body_free_to_slide_under_a_platen_force_is_told_the_remedies_that_keep_the_load(tmp_path):
    """The wedge pressed by a platen force onto a frictionless plane, nothing else holding it
    sideways: the message names the free translation, the straight free parts across it as
    symmetry lines, one prescribed component, and that there are no springs; fixing a part
    in place (both components) comes last, as what changes the problem."""
    line = _refused(tmp_path, wedge({"left": "free", "top": {"platen": {"force": FORCE}}}),
                    "a translation along (1, 0)", "keep the load", "boundary.right or boundary.left: symmetry",
                    "{displacement: [0, null]}", "no springs")
    assert line.index("symmetry line") < line.index("both components")


@pytest.mark.parametrize("remedy", [{"left": "symmetry"}, {"left": {"displacement": [0, None]}}],
                         ids=["symmetry", "one-component"])
def test_the_remedies_named_keep_the_platen_force(remedy):
    """Either remedy the message names solves, and the platen still presses with its force."""
    outcome = solved(wedge({"top": {"platen": {"force": FORCE}}, **remedy}))
    platen = platen_of(outcome)
    assert abs(platen["force"] - FORCE) <= 1e-8 * FORCE
    # The plane carries the platen's vertical part, the remedy its sideways one.
    vertical = FORCE * abs(platen["normal"][1])
    assert abs(float(outcome.solution.contact.nodal_force.sum()) - vertical) <= 1e-8 * FORCE


def test_a_slide_along_an_inclined_obstacle_names_its_direction(tmp_path):
    """An obstacle tilted so that the free translation is along (0.8, 0.6): no part of the
    wedge lies across it, so the message says which direction a symmetry line must hold."""
    data = wedge({"left": "free", "top": {"platen": {"force": FORCE}}})
    data["obstacle"]["normal"] = [0.6, -0.8]
    _refused(tmp_path, data, "a translation along (0.8, 0.6)", "across (0.8, 0.6)", "{displacement: [0, null]}")


# --------------------------------------------------------------------------- the body's extent


def _half_disk(vertices: list, edges: list, holes: list | None = None) -> dict:
    polygon = {"vertices": vertices, "edges": edges}
    if holes:
        polygon["holes"] = holes
    return {
        "title": "half disk",
        "geometry": {"polygon": polygon},
        "mesh": {"size": 0.1},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"top": {"displacement": [0, -0.01]}, "rim": "contact"},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }


RIM = {"name": "rim", "arc": {"center": [0, 1], "direction": "ccw"}}


@pytest.mark.parametrize("top", [[[1, 1], [-1, 1]], [[1, 1], [0, 1], [-1, 1]], [[1, 1], [0.5, 1], [0, 1], [-1, 1]]],
                         ids=["one-edge", "split", "split-twice"])
def test_a_half_disk_whose_top_is_split_by_vertices_is_the_half_disk(tmp_path, top):
    """The straight top split by vertices on it: the vertices lie on one line, the arc gives the
    body its height. It checks and solves like the half-disk it is (it was refused with
    "the body's extent 0 is too small")."""
    data = _half_disk(top, ["top"] * (len(top) - 1) + [RIM])
    path = _write(tmp_path, data)
    runner = make_runner()
    result = runner.invoke(main, ["check", "--json", str(path)])
    assert result.exit_code == 0, result.stderr
    out = tmp_path / "out"
    result = runner.invoke(main, ["solve", str(path), "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.stderr
    assert (out / "report.json").is_file()


def test_a_hole_whose_vertices_lie_on_one_line_is_taken_with_its_arc(tmp_path):
    """A half-disk hole: three vertices on one line, closed by an arc."""
    hole = {"vertices": [[0.3, 0.9], [0, 0.9], [-0.3, 0.9]],
            "edges": ["hole", "hole", {"name": "hole", "arc": {"center": [0, 0.9], "direction": "ccw"}}]}
    data = _half_disk([[1, 1], [-1, 1]], ["top", RIM], holes=[hole])
    data["boundary"]["hole"] = "free"
    result = make_runner().invoke(main, ["check", str(_write(tmp_path, data))])
    assert result.exit_code == 0, result.stderr


def test_a_body_whose_outline_is_too_thin_is_still_refused(tmp_path):
    """Three vertices on one line closed by an arc of radius 1e12: the arc bulges 5e-13 from
    the line, thinner than float64 resolves at this distance; refused naming the vertices."""
    radius = 1.0e12
    center = [0.0, -math.sqrt(radius**2 - 1.0)]
    data = _half_disk([[-1, 0], [0, 0], [1, 0]],
                      ["top", "top", {"name": "rim", "arc": {"center": center, "direction": "ccw"}}])
    _refused(tmp_path, data, "geometry.polygon.vertices", "too small", command="check")


def test_an_arc_loop_whose_vertices_coincide_is_refused_as_before(tmp_path):
    data = _half_disk([[1, 0], [1, 0]], [{"name": "rim", "arc": {"center": [0, 0]}}] * 2)
    _refused(tmp_path, data, "geometry.polygon.vertices", "too small", command="check")


# --------------------------------------------------------------------------- the case file, always


def _sliver(divisions: int, load_path: bool = False) -> dict:
    """A 1 x 1e-6 cantilever: clamped on the left, its contact part (the right end) far from
    the obstacle. Its bending stiffness is 1e-12 of its stretching one: at 64 x 1 divisions the
    stiffness is numerically singular (condition 1e15), at 1 000 CHOLMOD meets a pivot <= 0."""
    data = {
        "title": "a sliver of a block",
        "geometry": {"rectangle": {"lower": [0, 0], "upper": [1, 1.0e-6]}},
        "mesh": {"divisions": [divisions, 1]},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"left": "clamped", "top": {"traction": [0, -1]}, "right": "contact", "bottom": "free"},
        "obstacle": {"point": [2, 0], "normal": [1, 0]},
    }
    if load_path:
        data["load_path"] = {"steps": 2}
    return data


@pytest.mark.parametrize("divisions, load_path", [(64, False), (1000, False), (64, True)],
                         ids=["probe", "pivot", "load-path"])
def test_a_numerically_singular_body_is_refused_naming_the_case_file(tmp_path, divisions, load_path):
    """The refusal starts with the case file, like every other (it named only "the stiffness
    matrix"); a solver's failure, exit 1, and nothing written."""
    path = _write(tmp_path, _sliver(divisions, load_path))
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    assert result.exit_code == 1, (result.exit_code, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {CASE_NAME}: "), result.stderr
    assert "singular" in lines[0]
    assert lines[0].count(CASE_NAME) == 1
    assert not (tmp_path / "out").exists()


def test_a_solver_error_already_naming_the_case_is_not_named_twice():
    from test_semicoercive import case_of

    from contactfem.errors import SolverError
    from contactfem.solve import _names_the_case

    case = case_of(_sliver(4))

    @_names_the_case
    def fails(case, message):
        raise SolverError(message)

    for message in ("the matrix is singular", f"{case.source.name}: method positive: cycling"):
        with pytest.raises(SolverError) as caught:
            fails(case, message)
        assert str(caught.value).startswith(f"{case.source.name}: ")
        assert str(caught.value).count(case.source.name) == 1
