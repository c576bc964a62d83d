"""Refusals of bad input through the command line.

Each test starts from the valid cases/square.yaml (read with yaml.safe_load), changes one
thing, writes it to tmp_path and runs ``contactfem solve`` on it. A refusal must exit with
code 2 and print exactly one line on stderr, ``error: <file>: <key> ...``, naming the
file, the YAML key and (for value errors) the offending value, with no traceback, and
must not create or touch the output directory.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import pytest
import yaml
from conftest import make_runner

from contactfem.cli import main

ROOT = Path(__file__).resolve().parents[1]
SQUARE = ROOT / "cases" / "square.yaml"
CASE_NAME = "variant.yaml"




def base_case() -> dict:
    return yaml.safe_load(SQUARE.read_text(encoding="utf-8"))


def write_case(directory: Path, modify: Callable[[dict], object] | None = None, name: str = CASE_NAME) -> Path:
    data = base_case()
    if modify is not None:
        modify(data)
    path = directory / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def run(*args):
    return make_runner().invoke(main, [str(a) for a in args])


def assert_no_traceback(result) -> None:
    # CliRunner swallows a crash into result.exception; only SystemExit is a clean exit.
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    for text in (result.output, result.stdout, result.stderr):
        assert "Traceback" not in text


def assert_refused(result, out: Path, *fragments: str, code: int = 2) -> str:
    """Exit ``code``, one ``error: `` line on stderr containing every fragment, nothing written."""
    assert_no_traceback(result)
    assert result.exit_code == code, (result.exit_code, result.stderr, result.stdout)
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    line = lines[0]
    assert line.startswith("error: "), line
    for fragment in fragments:
        assert fragment in line, f"{fragment!r} not in {line!r}"
    assert not out.exists(), f"{out} was created"
    return line


def solve_variant(tmp_path: Path, modify: Callable[[dict], object] | None, *fragments: str) -> str:
    case = write_case(tmp_path, modify)
    out = tmp_path / "out"
    return assert_refused(run("solve", case, "--out", out), out, CASE_NAME, *fragments)


# --------------------------------------------------------------------------- controls


def test_unmodified_round_trip_is_valid(tmp_path):
    """The base every refusal starts from is itself valid once dumped again."""
    case = write_case(tmp_path)
    result = run("solve", case, "--out", tmp_path / "out", "--quiet")
    assert_no_traceback(result)
    assert result.exit_code == 0, result.stderr


def square_polygon(vertices: list | None = None) -> Callable[[dict], None]:
    """Replace the rectangle by a polygon (edges named like the rectangle's sides)."""
    def modify(data: dict) -> None:
        data["geometry"] = {"polygon": {
            "vertices": vertices if vertices is not None else [[0, 0], [1, 0], [1, 1], [0, 1]],
            "edges": ["bottom", "right", "top", "left"],
        }}
        data["mesh"] = {"size": 0.25}
    return modify


def test_polygon_base_is_valid(tmp_path):
    """The polygon variant the polygon refusals modify is valid as it is."""
    result = run("check", write_case(tmp_path, square_polygon()))
    assert_no_traceback(result)
    assert result.exit_code == 0, result.stderr


def write_square_msh(path: Path, names=("bottom", "right", "top", "left"), n: int = 4) -> Path:
    """A Gmsh 2.2 mesh of the unit square with a physical line per side."""
    from contactfem.mesh import structured_rectangle, write_gmsh

    sides = dict(zip(("bottom", "right", "top", "left"), names))
    return write_gmsh(structured_rectangle((0.0, 0.0), (1.0, 1.0), n, n, side_names=sides), path)


def use_mesh_file(name: str) -> Callable[[dict], None]:
    def modify(data: dict) -> None:
        data["geometry"] = {"mesh_file": name}
        data.pop("mesh")  # a mesh file takes no divisions
    return modify


def test_mesh_file_base_is_valid(tmp_path):
    write_square_msh(tmp_path / "square.msh")
    case = write_case(tmp_path, use_mesh_file("square.msh"))
    result = run("solve", case, "--out", tmp_path / "out", "--quiet")
    assert_no_traceback(result)
    assert result.exit_code == 0, result.stderr


# --------------------------------------------------------------------------- the file itself


def test_file_not_found(tmp_path):
    out = tmp_path / "out"
    missing = tmp_path / "nothere.yaml"
    assert_refused(run("solve", missing, "--out", out), out, "nothere.yaml", "cannot read")


def test_not_yaml(tmp_path):
    case = tmp_path / CASE_NAME
    case.write_text("title: broken\ngeometry: [1, 2\nmaterial: {E: 1}\n", encoding="utf-8")
    out = tmp_path / "out"
    assert_refused(run("solve", case, "--out", out), out, CASE_NAME, "not valid YAML", "line 3")


def test_yaml_list(tmp_path):
    case = tmp_path / CASE_NAME
    case.write_text("- geometry\n- material\n", encoding="utf-8")
    out = tmp_path / "out"
    assert_refused(run("solve", case, "--out", out), out, CASE_NAME, "['geometry', 'material']",
                   "expected a mapping")


# --------------------------------------------------------------------------- schema


def test_unknown_top_level_key(tmp_path):
    solve_variant(tmp_path, lambda d: d.update(colour="red"), "colour", "unknown key")


def test_unknown_nested_key(tmp_path):
    solve_variant(tmp_path, lambda d: d["material"].update(young=1.0e6), "material.young", "unknown key")


def test_missing_required_key(tmp_path):
    solve_variant(tmp_path, lambda d: d.pop("obstacle"), "obstacle", "missing")


def test_wrong_type(tmp_path):
    solve_variant(tmp_path, lambda d: d["material"].update(E="stiff"), "material.E", "'stiff'", "number")


@pytest.mark.parametrize("young", [0, -2.0e5], ids=["zero", "negative"])
def test_young_modulus_not_positive(tmp_path, young):
    solve_variant(tmp_path, lambda d: d["material"].update(E=young), f"material.E = {float(young)}", "> 0")


@pytest.mark.parametrize("nu", [0.5, -0.1])
def test_poisson_ratio_out_of_range(tmp_path, nu):
    solve_variant(tmp_path, lambda d: d["material"].update(nu=nu), f"material.nu = {nu}", "[0, 0.5)")


@pytest.mark.parametrize("mu", [0, -1.0e5], ids=["zero", "negative"])
def test_lame_mu_not_positive(tmp_path, mu):
    solve_variant(tmp_path, lambda d: d.update(material={"lambda": 5.0e5, "mu": mu}),
                  f"material.mu = {float(mu)}", "> 0")


def test_both_young_and_lame(tmp_path):
    solve_variant(tmp_path, lambda d: d["material"].update({"lambda": 5.0e5, "mu": 3.0e5}),
                  "material", "'lambda': 500000.0", "either E and nu, or lambda and mu")


def test_number_too_large_for_float(tmp_path):
    solve_variant(tmp_path, lambda d: d["material"].update(E=10**400), "material.E")


# --------------------------------------------------------------------------- boundary and supports


def test_no_clamped_part(tmp_path):
    solve_variant(tmp_path, lambda d: d["boundary"].update(left="free"), "boundary", "no clamped")


def test_boundary_part_not_in_geometry(tmp_path):
    solve_variant(tmp_path, lambda d: d["boundary"].update(front="free"), "boundary.front", "'front'",
                  "no part named")


def test_contact_part_not_in_geometry(tmp_path):
    def modify(data: dict) -> None:
        del data["boundary"]["bottom"]
        data["boundary"]["base"] = "contact"
    solve_variant(tmp_path, modify, "boundary.base", "'base'", "no part named")


def test_contact_part_facing_away(tmp_path):
    """The top as contact part, the bottom free, the obstacle below: refused when meshed."""
    def modify(data: dict) -> None:
        data["boundary"]["top"] = "contact"
        data["boundary"]["bottom"] = "free"
    solve_variant(tmp_path, modify, "boundary.top", "faces away")


def roller_lifted(data: dict) -> None:
    """A roller on the left (u_x = 0) leaves the vertical translation to the contact, and
    the top traction reversed lifts the body off: nothing holds it."""
    data["boundary"]["left"] = {"displacement": [0, None]}
    data["boundary"]["top"] = {"traction": [1.0e4, "1e4*(1-1.5*x)"]}


def test_supports_leave_rigid_motion(tmp_path):
    solve_variant(tmp_path, roller_lifted, "boundary", "left", "rigid motion")


def test_conflicting_displacements(tmp_path):
    """A top displacement disagreeing with the clamp at the shared corner (0, 1)."""
    solve_variant(tmp_path, lambda d: d["boundary"].update(top={"displacement": [0, -0.01]}),
                  "boundary.top", "boundary.left", "conflicts")


# --------------------------------------------------------------------------- geometry


def test_self_intersecting_polygon(tmp_path):
    solve_variant(tmp_path, square_polygon([[0, 0], [1, 1], [1, 0], [0, 1]]),
                  "geometry.polygon.vertices", "[1.0, 1.0]", "intersect")


def test_clockwise_polygon(tmp_path):
    solve_variant(tmp_path, square_polygon([[0, 0], [0, 1], [1, 1], [1, 0]]),
                  "geometry.polygon.vertices", "clockwise")


def test_repeated_vertex(tmp_path):
    solve_variant(tmp_path, square_polygon([[0, 0], [1, 0], [1, 1], [1, 0]]),
                  "geometry.polygon.vertices", "repeated vertex")


def test_overlapping_holes(tmp_path):
    def modify(data: dict) -> None:
        square_polygon()(data)
        data["geometry"]["polygon"]["holes"] = [
            {"circle": {"center": [0.4, 0.5], "radius": 0.2}},
            {"circle": {"center": [0.6, 0.5], "radius": 0.2}},
        ]
    # The mesher detects the overlap (meshed area differs from the loops' area) and the
    # refusal names the polygon as a whole.
    solve_variant(tmp_path, modify, "geometry.polygon", "overlap")


def test_mesh_divisions_zero(tmp_path):
    solve_variant(tmp_path, lambda d: d["mesh"].update(divisions=0), "mesh.divisions", "= 0")


def test_mesh_file_missing(tmp_path):
    solve_variant(tmp_path, use_mesh_file("nothere.msh"), "geometry.mesh_file", "nothere.msh", "no such file")


def test_mesh_file_garbage(tmp_path):
    (tmp_path / "garbage.msh").write_text("this is not a mesh\n$Nodes 3 banana\n0 0 0 1 1 1\n", encoding="utf-8")
    case = write_case(tmp_path, use_mesh_file("garbage.msh"))
    out = tmp_path / "out"
    assert_refused(run("solve", case, "--out", out), out, "garbage.msh")


def test_mesh_file_garbage_names_case_and_key(tmp_path):
    (tmp_path / "garbage.msh").write_text("this is not a mesh\n$Nodes 3 banana\n0 0 0 1 1 1\n", encoding="utf-8")
    solve_variant(tmp_path, use_mesh_file("garbage.msh"), "geometry.mesh_file", "garbage.msh")


def test_mesh_file_lacks_part(tmp_path):
    write_square_msh(tmp_path / "renamed.msh", names=("base", "right", "top", "left"))
    solve_variant(tmp_path, use_mesh_file("renamed.msh"), "boundary.bottom", "renamed.msh", "'bottom'")


# --------------------------------------------------------------------------- expressions and loads


def test_expression_import(tmp_path):
    solve_variant(tmp_path, lambda d: d["boundary"].update(top={"traction": ["__import__('os')", 0]}),
                  "boundary.top.traction[0]", "__import__('os')", "not allowed")


def test_expression_attribute_access(tmp_path):
    solve_variant(tmp_path, lambda d: d["boundary"].update(top={"traction": ["x.__class__", 0]}),
                  "boundary.top.traction[0]", "x.__class__", "attribute access")


def test_non_finite_traction(tmp_path):
    """1/(x-x) compiles but is nan everywhere: refused at assembly."""
    solve_variant(tmp_path, lambda d: d["boundary"]["top"]["traction"].__setitem__(1, "1/(x-x)"),
                  "boundary.top.traction", "1/(x-x)", "not finite")


def test_non_finite_displacement(tmp_path):
    solve_variant(tmp_path, lambda d: d["boundary"].update(right={"displacement": [0, "log(x-2)"]}),
                  "boundary.right.displacement[1]", "log(x-2)", "not finite")


def test_non_finite_body_force(tmp_path):
    solve_variant(tmp_path, lambda d: d.update(body_force=[0, "sqrt(-1-x)"]),
                  "body_force[1]", "sqrt(-1-x)", "not finite")


# --------------------------------------------------------------------------- obstacle and solver


def test_solver_tolerance_out_of_range(tmp_path):
    solve_variant(tmp_path, lambda d: d["solver"].update(tolerance=0.5), "solver.tolerance = 0.5", "1e-2")


@pytest.mark.parametrize("value", [0, 10_001, "many", 2.5, True])
def test_solver_max_iterations_out_of_range(tmp_path, value):
    solve_variant(tmp_path, lambda d: d["solver"].update(max_iterations=value), "solver.max_iterations",
                  "expected an integer in [1, 10000] or auto")


def test_solver_max_iterations_auto_or_integer():
    """auto (also the default) leaves the cap to the kernel (one step per contact node, at
    least 50); an integer is kept."""
    from conftest import case_from, square_case_dict

    for given, expected in (("auto", None), (None, None), (7, 7), (10_000, 10_000)):
        data = square_case_dict(4)
        data["solver"] = {} if given is None else {"max_iterations": given}
        assert case_from(data).solver.max_iterations == expected


def test_obstacle_normal_not_unit(tmp_path):
    solve_variant(tmp_path, lambda d: d["obstacle"].update(normal=[0, -2]), "obstacle.normal", "-2", "unit")


def test_obstacle_points_coincide(tmp_path):
    def modify(data: dict) -> None:
        data["obstacle"] = {"points": [[0.5, 0], [0.5, 0]]}
    solve_variant(tmp_path, modify, "obstacle.points", "[[0.5, 0], [0.5, 0]]", "differ")


# --------------------------------------------------------------------------- command line


def test_unknown_method_option(tmp_path):
    case = write_case(tmp_path)
    out = tmp_path / "out"
    result = run("solve", case, "--method", "foo", "--out", out)
    assert_no_traceback(result)
    assert result.exit_code == 2
    assert "--method" in result.stderr and "foo" in result.stderr
    assert not out.exists()


def test_check_refuses_like_solve(tmp_path):
    """check gives the same one-line refusal as solve."""
    case = write_case(tmp_path, lambda d: d["material"].update(nu=0.5))
    checked = run("check", case)
    solved = run("solve", case, "--out", tmp_path / "out")
    assert_no_traceback(checked)
    assert checked.exit_code == 2
    assert checked.stderr == solved.stderr
    assert checked.stderr.startswith("error: ") and len(checked.stderr.splitlines()) == 1


# --------------------------------------------------------------------------- existing results survive


def _snapshot(directory: Path) -> dict[str, bytes]:
    return {str(p.relative_to(directory)): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(
    ("modify", "code"),
    [
        (lambda d: d["material"].update(nu=0.5), 2),  # schema
        (lambda d: d["boundary"].update(top="contact", bottom="free"), 2),  # contact part facing away
        (lambda d: roller_lifted(d), 2),  # rigid motion
        (lambda d: d["boundary"]["top"]["traction"].__setitem__(1, "1/(x-x)"), 2),  # assembly
        (lambda d: d["solver"].update(max_iterations=1), 1),  # no convergence: a solve failure
    ],
    ids=["schema", "facing-away", "rigid-motion", "non-finite-load", "no-convergence"],
)
def test_failed_run_leaves_existing_results_untouched(tmp_path, modify, code):
    out = tmp_path / "results"
    good = run("solve", SQUARE, "--out", out, "--quiet")
    assert good.exit_code == 0, good.stderr
    before = _snapshot(out)
    assert {"solution.vtu", "contact.vtu", "solution.pvd", "solution.h5", "report.json"} <= set(before)

    bad = write_case(tmp_path, modify)
    result = run("solve", bad, "--out", out, "--overwrite")
    assert_no_traceback(result)
    assert result.exit_code == code, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and CASE_NAME in lines[0]
    assert _snapshot(out) == before


def test_a_free_rigid_motion_is_named(tmp_path):
    """A roller on the left (u_x = 0) and nothing else holds the body against x motion and
    rotation but not against a vertical translation, and the load lifts it off the obstacle:
    the refusal says which motion is free."""
    result = run("solve", write_case(tmp_path, roller_lifted), "--out", tmp_path / "out")
    assert_refused(result, tmp_path / "out", CASE_NAME, "leave a rigid motion of the body free",
                   "a translation along (0, ")


def test_free_motions_in_words():
    import numpy as np

    from contactfem.discretize.supports import _motion_text

    assert _motion_text(np.array([0.0, 2.0, 0.0]), np.array([0.5, 0.5]), 1.0) == "a translation along (0, 1)"
    # A pure rotation about the centre, and one about the point the translation part moves.
    assert _motion_text(np.array([0.0, 0.0, 1.0]), np.array([0.5, 0.5]), 1.0) == "a rotation about (0.5, 0.5)"
    # u = (a, b) + c (−(y − yc), x − xc)/size vanishes at (xc − b size/c, yc + a size/c).
    assert _motion_text(np.array([1.0, 0.0, 1.0]), np.array([0.5, 0.5]), 2.0) == "a rotation about (0.5, 2.5)"
