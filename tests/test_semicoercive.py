"""Bodies held by contact alone along a rigid motion the supports leave free.

The Hertz quarter disk loaded by a force on its top instead of a prescribed displacement:
its symmetry axis holds the horizontal translation and the rotation, and only the obstacle
holds the vertical translation, as long as the load presses the body onto it.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from conftest import CASES, make_runner

from contactfem.case import parse_case
from contactfem.cli import main
from contactfem.errors import CaseError
from contactfem.kernel import Status
from contactfem.solve import prepare, solve_case
from contactfem.validation import hertz_comparison

PRESSURE = 1.8e3  # on the top of length 1: about the force of the shipped displacement case


def hertz_by_force(vertical: float, horizontal: float = 0.0) -> dict:
    data = yaml.safe_load((CASES / "hertz_quarter.yaml").read_text(encoding="utf-8"))
    data["boundary"]["top"] = {"traction": [horizontal, vertical]}
    return data


def block(boundary: dict, **extra) -> dict:
    return {
        "title": "block on a floor",
        "geometry": {"rectangle": {"lower": [0, 0], "upper": [1, 1]}},
        "mesh": {"divisions": 8},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"bottom": "contact", **boundary},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
        **extra,
    }


def case_of(data: dict, name: str = "semi.yaml"):
    return parse_case(yaml.safe_dump(data, sort_keys=False), source=name)


@pytest.fixture(scope="module")
def hertz_problem():
    # Refined once: the standard method's peak pressure is within 0.9% on the case's own mesh.
    case = case_of(hertz_by_force(-PRESSURE))
    return case, prepare(case, refine=1)


def test_the_free_vertical_translation_is_recorded(hertz_problem):
    _, problem = hertz_problem
    assert problem.free_modes is not None and problem.free_modes.shape == (2 * problem.mesh.n_points, 1)
    mode = problem.free_modes[:, 0].reshape(-1, 2)
    assert np.allclose(mode[:, 0], 0.0) and np.allclose(np.abs(mode[:, 1]), 1.0)


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_hertz_loaded_by_force(hertz_problem, method):
    case, problem = hertz_problem
    outcome = solve_case(case, method=method, problem=problem)
    assert outcome.kernel.status is Status.CONVERGED and outcome.kernel.certificate.passed
    assert outcome.sequencing.get("levels", 0) >= 1  # the coarse level is the same semicoercive case
    contact = outcome.solution.contact
    force = float(contact.nodal_force.sum())
    assert abs(force - PRESSURE * 1.0) <= 1e-10 * PRESSURE
    assert contact.active[0] and abs(outcome.problem.contact.abscissa[0]) < 1e-12  # the zone starts on the axis
    # The quarter disk carries half the half-disk's force: Hertz's P is twice the reported one.
    figures = hertz_comparison(outcome, radius=1.0, symmetry_axis=0.0)
    assert abs(figures["half_width_error"]) <= 0.01 and abs(figures["peak_pressure_error"]) <= 0.01


def refused(tmp_path, data: dict, *fragments: str) -> str:
    path = tmp_path / "semi.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(out)])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code == 2, (result.exit_code, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "semi.yaml" in lines[0], result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert not out.exists()
    return lines[0]


def test_a_body_pulled_away_is_refused(tmp_path):
    refused(tmp_path, hertz_by_force(+PRESSURE), "boundary.top traction", "a translation along (0, ",
            "pulls the body away")


def test_a_load_doing_no_work_along_the_free_motion_is_refused(tmp_path):
    refused(tmp_path, hertz_by_force(0.0, horizontal=PRESSURE), "boundary.top traction",
            "a translation along (0, ", "does no work")


def test_a_block_under_gravity_on_a_symmetry_support():
    data = block({"left": "symmetry", "right": "free", "top": "free"}, body_force=[0, -1.0e4])
    case = case_of(data)
    problem = prepare(case)
    assert problem.free_modes is not None and problem.free_modes.shape[1] == 1
    for method in ("positive", "standard"):
        outcome = solve_case(case, method=method, problem=problem)
        assert outcome.kernel.status is Status.CONVERGED and outcome.kernel.certificate.passed
        weight = 1.0e4 * 1.0
        assert abs(outcome.solution.contact.nodal_force.sum() - weight) <= 1e-10 * weight


def test_a_free_tangential_motion_is_refused_naming_it(tmp_path):
    """A roller holding only u_y on the left: the rotation about it presses one end of the
    bottom into the floor either way, but nothing holds the slide along the floor."""
    line = refused(tmp_path, block({"left": {"displacement": [None, 0]}, "right": "free",
                                    "top": {"traction": [0, -1.0e3]}}),
                   "leave a rigid motion of the body free", "contact with the obstacle cannot hold it")
    assert "a translation along (1, 0)" in line or "a translation along (-1, 0)" in line


def test_a_body_with_no_support_at_all_is_refused():
    with pytest.raises(CaseError, match="could move rigidly"):
        case_of(block({"left": "free", "right": "free", "top": {"traction": [0, -1.0e3]}}))
