"""Rigid frictionless platens: a straight boundary part whose normal motion is one unknown,
driven by its force or by its advance.

What theory says and is checked here:
- a platen driven by an advance d is a roller with u · n = −d on the part (same discrete
  problem, so the same displacements to round-off);
- driving it by the force F it then presses with gives back the advance d (the same
  problem, solved for the other variable), to the solve's tolerance;
- a platen driven by force P presses on the body with P, which the contact carries
  whole when nothing else holds the body: the contact force equals P to 1e-10;
- the Hertz quarter disk pressed by a platen with force P has Hertz's half-width and peak
  pressure within 1% (plane strain, P per unit thickness on the half-disk being 2 P).
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from conftest import CASES
from test_semicoercive import case_of, refused

from contactfem.errors import CaseError
from contactfem.kernel import Status
from contactfem.solve import prepare, solve_case
from contactfem.validation import hertz_comparison

FORCE = 2.0e3


def hertz_pressed(drive: dict) -> dict:
    data = yaml.safe_load((CASES / "hertz_quarter.yaml").read_text(encoding="utf-8"))
    data["boundary"]["top"] = {"platen": drive}
    return data


def wedge(boundary: dict, top_slope: float = 0.25) -> dict:
    """A block whose top is inclined (an inclined platen), clamped or symmetric on the left."""
    return {
        "title": "block under an inclined platen",
        "geometry": {"polygon": {"vertices": [[0, 0], [1, 0], [1, 1 + top_slope], [0, 1]],
                                 "edges": ["bottom", "right", "top", "left"]}},
        "mesh": {"size": 0.1},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"bottom": "contact", "right": "free", **boundary},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }


def solved(data: dict, method: str = "positive", refine: int | None = None):
    case = case_of(data)
    outcome = solve_case(case, method=method, problem=prepare(case, refine=refine))
    assert outcome.kernel.status is Status.CONVERGED and outcome.kernel.certificate.passed
    return outcome


def platen_of(outcome, name: str = "top"):
    from contactfem.report import contact_and_reactions, platen_figures

    problem, solution = outcome.problem, outcome.solution
    _, reactions = contact_and_reactions(problem, solution.displacement, solution.contact.nodal_force)
    return platen_figures(problem, solution.displacement, reactions)[name]


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_hertz_pressed_by_a_platen_force(method):
    outcome = solved(hertz_pressed({"force": FORCE}), method=method, refine=1)
    contact = outcome.solution.contact
    force = float(contact.nodal_force.sum())
    assert abs(force - FORCE) <= 1e-10 * FORCE
    platen = platen_of(outcome)
    assert abs(platen["force"] - FORCE) <= 1e-10 * FORCE and platen["advance"] > 0
    figures = hertz_comparison(outcome, radius=1.0, symmetry_axis=0.0)
    assert abs(figures["half_width_error"]) <= 0.01 and abs(figures["peak_pressure_error"]) <= 0.01


def test_a_platen_advance_is_a_roller_on_the_part():
    advance = 4.0e-3
    by_platen = solved(hertz_pressed({"displacement": advance}))
    roller = hertz_pressed({"displacement": advance})
    roller["boundary"]["top"] = {"displacement": [None, -advance]}
    by_roller = solved(roller)
    u, v = by_platen.solution.displacement, by_roller.solution.displacement
    assert np.abs(u - v).max() <= 1e-10 * np.abs(v).max()
    assert abs(platen_of(by_platen)["advance"] - advance) <= 1e-14


@pytest.mark.parametrize("left", ["clamped", "symmetry"])
def test_force_and_advance_drive_the_same_inclined_platen(left):
    """The platen's normal is inclined (not along an axis); on a symmetry line the corner node
    moves along the line, so its frame couples the platen's advance into both components."""
    by_force = solved(wedge({"left": left, "top": {"platen": {"force": FORCE}}}))
    platen = platen_of(by_force)
    assert abs(platen["force"] - FORCE) <= 1e-10 * FORCE
    assert np.allclose(platen["normal"], np.array([-0.25, 1.0]) / np.hypot(0.25, 1.0), atol=1e-12)
    by_advance = solved(wedge({"left": left, "top": {"platen": {"displacement": platen["advance"]}}}))
    scale = np.abs(by_force.solution.displacement).max()
    assert np.abs(by_advance.solution.displacement - by_force.solution.displacement).max() <= 1e-8 * scale
    assert abs(platen_of(by_advance)["force"] - FORCE) <= 1e-8 * FORCE
    # The platen moves rigidly: every node of the part advances by the same amount.
    problem = by_force.problem
    nodes = problem.platens[0].nodes
    advance = -(by_force.solution.displacement[nodes] @ problem.platens[0].normal)
    assert np.ptp(advance) <= 1e-12 * abs(advance).max()


def test_the_report_balances_the_platen_with_the_contact():
    from contactfem.report import boundary_forces

    outcome = solved(hertz_pressed({"force": FORCE}))
    case = case_of(hertz_pressed({"force": FORCE}))
    forces = boundary_forces(outcome.problem, outcome.solution.displacement, outcome.solution.contact.nodal_force,
                             {p.name: p.label for p in case.parts})
    assert forces["parts"]["top"]["condition"] == "platen (force 2000)"
    assert abs(forces["parts"]["top"]["force"][1] + FORCE) <= 1e-10 * FORCE
    assert forces["total"]["relative_force_residual"] <= 1e-10


def test_a_platen_pulling_the_body_away_is_refused(tmp_path):
    refused(tmp_path, hertz_pressed({"force": -FORCE}), "boundary.top platen", "pulls the body away")


def test_a_body_held_only_by_a_platen_force_and_contact_is_refused_for_sliding(tmp_path):
    """The wedge with its left side free too: a force-driven platen on top, the floor below
    and nothing else, so no prescribed support at all. Frictionless platen and floor leave
    the horizontal translation free: refused in one line naming it, as a pressure would be.
    (With no prescribed support the support matrix was an integer array, and summing the
    platen's constraints into it raised a numpy casting error with a traceback.)"""
    data = wedge({"left": "free", "top": {"platen": {"force": FORCE}}})
    refused(tmp_path, data, "a translation along (1, 0)", "contact with the obstacle cannot hold it")
    data["boundary"]["left"] = "symmetry"  # held sideways: it solves
    solved(data)


@pytest.mark.parametrize("drive, fragment", [
    ({"force": "lots"}, "top.platen.force"),
    ({"push": 1.0}, "unknown key"),
    ({"force": 1.0, "displacement": 1.0}, "expected {force: P}"),
    (3.0, "expected {force: P}"),
])
def test_a_bad_platen_drive_is_refused(drive, fragment):
    with pytest.raises(CaseError, match="boundary.top") as error:
        case_of(hertz_pressed(drive))
    assert fragment in str(error.value)


def test_a_curved_platen_is_refused():
    data = hertz_pressed({"force": FORCE})
    data["boundary"]["top"] = {"traction": [0, -1.0]}
    data["boundary"]["rim"] = {"platen": {"force": FORCE}}
    data["boundary"]["top"] = "contact"
    with pytest.raises(CaseError, match="boundary.rim = platen: the part is not straight"):
        prepare(case_of(data))


@pytest.mark.parametrize("kind", ["symmetry", {"platen": {"displacement": 0.0}}])
@pytest.mark.parametrize("divisions", [[8, 8], [7, 12]])
def test_two_opposite_sides_under_one_name_are_not_straight(kind, divisions):
    """A block's left and right sides named alike: with as many edges on each, their outward
    normals average to zero, which once made a NaN normal and a traceback; straight means
    every edge on one line, whatever the edge counts."""
    data = {"title": "sides named alike", "material": {"E": 1.0, "nu": 0.3},
            "geometry": {"polygon": {"vertices": [[-1, -2], [1, -2], [1, 0], [-1, 0]],
                                     "edges": ["base", "side", "top", "side"]}},
            "mesh": {"size": 2 / divisions[0]} if divisions[0] == divisions[1] else {"size": 0.25, "contact_size": 0.1},
            "boundary": {"base": "clamped", "side": kind, "top": "contact"},
            "obstacle": {"point": [0, 0.001], "normal": [0, 1]}}
    name = "symmetry" if kind == "symmetry" else "platen"
    with pytest.raises(CaseError, match=f"boundary.side = {name}: the part is not straight"):
        prepare(case_of(data))


def test_two_platens_sharing_a_corner_are_refused():
    data = wedge({"left": "symmetry", "top": {"platen": {"force": FORCE}}})
    data["boundary"]["right"] = {"platen": {"displacement": 0.0}}
    with pytest.raises(CaseError, match=r"boundary.(top|right) = platen: shares the node \(1, 1.25\) with the platen boundary.(right|top); two platens must not touch"):
        prepare(case_of(data))


def test_a_platen_in_line_with_a_symmetry_part_is_refused():
    data = wedge({"left": "clamped"})
    data["geometry"]["polygon"] = {"vertices": [[0, 0], [1, 0], [1, 1], [0.5, 1], [0, 1]],
                                   "edges": ["bottom", "right", "top", "mirror", "left"]}
    data["boundary"].update({"mirror": "symmetry", "top": {"platen": {"force": FORCE}}})
    with pytest.raises(CaseError, match=r"shares the node \(0.5, 1\) with a symmetry line parallel to it"):
        prepare(case_of(data))


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_a_block_between_a_platen_and_the_floor_is_in_uniform_compression(method):
    """A patch test. A W x H block on a frictionless floor, pressed by a frictionless platen
    with force P, held sideways by a symmetry line: the exact solution is uniaxial stress
    σ_yy = −P/W (plane strain: ε_yy = −(1 − ν²) P/(E W), ε_xx = ν (1 + ν) P/(E W)), linear in
    x and y, so P1 on any mesh reproduces it: the platen advances (1 − ν²) P H/(E W) and the
    contact pressure is P/W at every node (the multiplier of either method), to round-off."""
    width, height, young, nu = 2.0, 1.0, 1.0e6, 0.3
    data = {
        "title": "block in uniform compression",
        "geometry": {"polygon": {"vertices": [[0, 0], [width, 0], [width, height], [0, height]],
                                 "edges": ["floor", "right", "top", "left"]}},
        "mesh": {"size": 0.17},
        "material": {"E": young, "nu": nu},
        "boundary": {"floor": "contact", "right": "free", "top": {"platen": {"force": FORCE}}, "left": "symmetry"},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }
    outcome = solved(data, method=method)
    pressure = FORCE / width
    advance = (1 - nu**2) * FORCE * height / (young * width)
    assert platen_of(outcome)["advance"] == pytest.approx(advance, rel=1e-10)
    contact = outcome.solution.contact
    assert contact.active.all()
    assert np.abs(contact.multiplier - pressure).max() <= 1e-10 * pressure
    points = outcome.problem.mesh.points
    exact = np.stack([nu * (1 + nu) * pressure / young * points[:, 0],
                      -(1 - nu**2) * pressure / young * points[:, 1]], axis=1)
    assert np.abs(outcome.solution.displacement - exact).max() <= 1e-10 * np.abs(exact).max()
