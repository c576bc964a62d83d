"""Load paths: the case solved at a sequence of load factors with one factorisation.

What theory says and is checked here:
- the discrete Signorini problem has one solution for each load, so every step of a path
  equals a separate solve of the case with its loads scaled by that step's factor (to the
  solver's tolerance), whatever the steps before it and whatever the path reuses;
- with no initial gap and nothing prescribed but zero, the solution is positively
  homogeneous in the load: u(f) = f u(1), the active set is the same at every factor, so
  the path needs one factorisation, and no solve after the first step;
- a platen driven by force P at factor f presses with f P, and the contact carries it all
  when nothing else holds the body (to 1e-10).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest
import yaml
from conftest import CASES, make_runner
from test_platen import hertz_pressed
from test_semicoercive import case_of

from contactfem.case import parse_case
from contactfem.cli import main
from contactfem.errors import CaseError, SolverError
from contactfem.kernel import Status
from contactfem.solve import prepare, solve_case, solve_load_path

FORCE = 2.0e3


def square_path(factors) -> dict:
    data = yaml.safe_load((CASES / "square.yaml").read_text(encoding="utf-8"))
    data["mesh"]["divisions"] = 16
    data["load_path"] = {"factors": list(factors)}
    return data


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_each_step_is_the_solve_of_the_scaled_load(method, monkeypatch):
    """Each step equals the direct solve of its load. And the first step's factorisation
    serves the path: with the cost model, which weighs measured seconds (a machine under
    load chose 2 or 3 factorisations on this path), replaced by a fixed bound of 20 changed
    nodes (about what a CHOLMOD factorisation is worth), no later step refactorises."""
    from contactfem.kernel import ActiveSetSolver

    monkeypatch.setattr(ActiveSetSolver, "_refactorize_first",
                        lambda self, active: int(np.count_nonzero(active != self.reference)) > 20)
    factors = [0.25, 0.5, 0.8, 1.0]
    data = hertz_pressed({"force": FORCE})
    data["load_path"] = {"factors": factors}
    path = solve_load_path(case_of(data), method=method)
    assert len(path.steps) == len(factors)
    for factor, step in zip(factors, path.steps):
        assert step.kernel.status is Status.CONVERGED and step.kernel.certificate.passed
        alone = hertz_pressed({"force": factor * FORCE})
        direct = solve_case(case_of(alone), method=method)
        scale = np.abs(direct.solution.displacement).max()
        assert np.abs(step.solution.displacement - direct.solution.displacement).max() <= 1e-8 * scale
        assert np.array_equal(step.solution.contact.active, direct.solution.contact.active)
        pressure = np.abs(direct.solution.contact.multiplier).max()
        assert np.abs(step.solution.contact.multiplier - direct.solution.contact.multiplier).max() <= 1e-8 * pressure
        assert abs(step.solution.contact.nodal_force.sum() - factor * FORCE) <= 1e-10 * FORCE
    # One factorisation serves the path (the first step's); later steps reuse it.
    assert path.steps[0].kernel.factorizations == path.factorizations == 1


def test_a_proportional_path_is_homogeneous_and_needs_one_factorisation(monkeypatch):
    """Each step is the final solution scaled. Whether the first step's Newton iterations
    refactorise is the measured-seconds cost model's choice (a faster refactorisation made
    it 2 on this 16-node zone): with the fixed bound of 20 changed nodes, one factorisation
    serves the whole path, and later steps cost no solve at all."""
    from contactfem.kernel import ActiveSetSolver

    monkeypatch.setattr(ActiveSetSolver, "_refactorize_first",
                        lambda self, active: int(np.count_nonzero(active != self.reference)) > 20)
    factors = [0.1, 0.35, 0.7, 1.0]
    path = solve_load_path(case_of(square_path(factors)))
    final = path.steps[-1].solution
    for factor, step in zip(factors, path.steps):
        assert np.abs(step.solution.displacement - factor * final.displacement).max() \
            <= 1e-10 * np.abs(final.displacement).max()
        assert np.array_equal(step.solution.contact.active, final.contact.active)
    assert path.factorizations == 1
    # The reference solution is linear in the factor: a later step costs no solve at all.
    assert sum(step.kernel.column_solves for step in path.steps[1:]) == 0


def test_a_push_that_reaches_the_obstacle_midway_is_certified_at_every_step():
    """cases/punch.yaml pushed in 3 steps: the first third moves the punch down without
    touching the plane (no load, no contact: a rigid motion whose forces are round-off of
    zero), the second brings one node exactly onto it (in contact with a round-off force or
    apart by a round-off gap: the same answer to round-off, whichever start the step took),
    the third presses. Every step is certified (the first two against the body's force unit, see
    kernel.ZERO_FORCE_STRAIN); the path stopped at its first step as not certified before.
    The last step is the direct solve of the full push."""
    data = yaml.safe_load((CASES / "punch.yaml").read_text(encoding="utf-8"))
    data.pop("output", None)
    data["load_path"] = {"steps": 3}
    case = case_of(data)
    path = solve_load_path(case)
    assert [step.kernel.status for step in path.steps] == [Status.CONVERGED] * 3
    assert all(step.kernel.certificate.passed for step in path.steps)
    assert [int(step.kernel.active.sum()) for step in path.steps][:2] in ([0, 1], [0, 0])
    touching = path.steps[1].solution.contact
    size = path.steps[1].kernel.certificate.scales["displacement"]
    assert abs((touching.normal_displacement - touching.gap).max()) <= 1e-12 * size
    assert np.abs(touching.nodal_force).max() <= 1e-10 * path.steps[1].kernel.certificate.scales["force"]
    direct = solve_case(case_of({key: value for key, value in data.items() if key != "load_path"}))
    np.testing.assert_array_equal(path.steps[-1].kernel.active, direct.kernel.active)
    scale = np.abs(direct.solution.displacement).max()
    np.testing.assert_allclose(path.steps[-1].solution.displacement, direct.solution.displacement,
                               rtol=0, atol=1e-9 * scale)


def test_a_step_that_does_not_converge_is_named():
    data = hertz_pressed({"force": FORCE})
    data["load_path"] = {"steps": 3}
    data["solver"] = {"max_iterations": 1}
    with pytest.raises(SolverError, match=r"load step 1 of 3 \(factor 0.333333\)"):
        solve_load_path(case_of(data))


def test_the_path_files(tmp_path):
    data = hertz_pressed({"force": FORCE})
    data["load_path"] = {"steps": 4}
    data["mesh"]["contact_size"] = 0.004
    case_file = tmp_path / "path.yaml"
    case_file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(case_file), "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.stderr
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    factors = [0.25, 0.5, 0.75, 1.0]
    curves = report["load_path"]["curves"]
    assert curves["factor"] == factors
    assert np.allclose(curves["contact_force"], np.multiply(factors, FORCE), rtol=1e-10)
    assert np.allclose(curves["platen_top_force"], np.multiply(factors, FORCE), rtol=1e-10)
    assert all(np.diff(curves["platen_top_advance"]) > 0) and all(np.diff(curves["contact_width"]) >= 0)
    assert report["platens"]["top"]["force"] == pytest.approx(FORCE, rel=1e-10)
    try:
        import jsonschema
    except ImportError:
        pass
    else:
        from contactfem.io.registry import schema_path

        jsonschema.validate(report, json.loads(schema_path("report.json").read_text(encoding="utf-8")))
    rows = (out / "path.csv").read_text(encoding="utf-8").splitlines()
    assert rows[0].split(",")[:3] == ["factor", "contact_force", "contact_width"] and len(rows) == 5
    with h5py.File(out / "path.h5", "r") as file:
        assert file.attrs["format"] == "contactfem-path"
        assert np.array_equal(file["factors"][()], factors)
        n = len(file["mesh/points"])
        assert file["steps/displacement"].shape == (4, n, 2)
        assert np.allclose(file["curves/contact_force"][()], curves["contact_force"])
        with h5py.File(out / "solution.h5", "r") as final:
            assert np.array_equal(file["steps/displacement"][-1], final["fields/displacement"][()])
    sets = ET.parse(out / "path.pvd").getroot().iter("DataSet")
    assert [(float(d.get("timestep")), d.get("file")) for d in sets if d.get("part") == "0"] == \
        [(f, f"path-{k}.vtu") for k, f in enumerate(factors, start=1)]
    assert (out / "path.png").stat().st_size > 0
    # A shorter path replacing this result leaves none of the longer one's steps behind.
    data["load_path"] = {"steps": 2}
    case_file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    result = make_runner().invoke(main, ["solve", str(case_file), "--out", str(out), "--quiet", "--overwrite"])
    assert result.exit_code == 0, result.stderr
    assert sorted(p.name for p in out.glob("path-*.vtu")) == ["path-1-contact.vtu", "path-1.vtu",
                                                              "path-2-contact.vtu", "path-2.vtu"]


@pytest.mark.parametrize("load_path, fragment", [
    ({"steps": 0}, "load_path.steps = 0: expected a whole number from 1 to 1000"),
    ({"steps": 2.5}, "load_path.steps = 2.5"),
    ({"factors": [0.5, -1]}, "load_path.factors[1] = -1.0: expected a load factor > 0"),
    ({"factors": []}, "load_path.factors"),
    ({"factors": [1], "steps": 1}, "give one of steps"),
    ({"increments": 3}, "unknown key"),
])
def test_a_bad_load_path_is_refused(load_path, fragment):
    data = square_path([1.0])
    data["load_path"] = load_path
    with pytest.raises(CaseError) as error:
        case_of(data)
    assert fragment in str(error.value)


def test_a_load_path_with_a_manufactured_solution_is_refused():
    data = yaml.safe_load((CASES / "manufactured.yaml").read_text(encoding="utf-8"))
    data["load_path"] = {"steps": 2}
    with pytest.raises(CaseError, match="load_path.*manufactured solution"):
        case_of(data)


def test_the_problem_scaled_by_a_factor_scales_every_load():
    data = hertz_pressed({"displacement": 2.0e-3})
    data["body_force"] = [0, -10.0]
    problem = prepare(case_of(data))
    half = problem.scaled(0.5)
    assert np.array_equal(half.load, 0.5 * problem.load)
    assert half.platens[0].value == 0.5 * problem.platens[0].value
    assert half.stiffness is problem.stiffness
    assert np.allclose(half.loads.load_vector(problem.mesh), 0.5 * problem.loads.load_vector(problem.mesh))


def test_a_path_whose_steps_would_not_fit_in_memory_is_refused_before_solving(monkeypatch):
    import contactfem.estimate as estimate

    data = square_path([0.5, 1.0])
    data["mesh"]["divisions"] = 128  # the mesh fits in 1 GiB (0.23 GB), 1 000 steps' fields (1.6 GB) do not
    data["load_path"] = {"steps": 1000}
    monkeypatch.setattr(estimate, "machine_memory", lambda: 2**30)
    monkeypatch.setattr(estimate, "_cgroup_limit", lambda proc, cgroups: None)
    monkeypatch.setattr(estimate, "_address_space_limit", lambda: None)
    with pytest.raises(CaseError, match=r"load_path: 1000 steps of this mesh .* of this machine's 1 GiB; "
                                        r"use at most \d+ steps"):
        solve_load_path(case_of(data))


def test_steps_taken_one_by_one_leave_one_step_in_the_result():
    data = square_path([0.5, 1.0])
    seen = []
    path = solve_load_path(case_of(data), on_step=lambda index, factor, step: seen.append((index, factor)),
                           keep_steps=False)
    assert seen == [(0, 0.5), (1, 1.0)] and len(path.steps) == 1 and path.final.solution is path.steps[0].solution


def test_a_path_that_fails_writes_nothing(tmp_path):
    data = hertz_pressed({"force": FORCE})
    data["load_path"] = {"steps": 3}
    data["solver"] = {"max_iterations": 1}
    case_file = tmp_path / "fails.yaml"
    case_file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(case_file), "--out", str(out)])
    assert result.exit_code == 1, result.stderr
    assert "load step 1 of 3" in result.stderr
    assert not out.exists() or not [p for p in out.iterdir() if not p.name.startswith(".")]


def rough_path(factors) -> tuple:
    """cases/rough.yaml (a 4 001-point rough base, 26 742 unknowns) with a load path."""
    source = CASES / "rough.yaml"
    data = yaml.safe_load(source.read_text(encoding="utf-8"))
    data.pop("output")
    data["load_path"] = {"factors": list(factors)}
    return data, source


def test_a_rough_profile_path_starts_each_step_from_the_coarser_level():
    """Under a rough profile hundreds of asperities come into contact along the path, and the
    zone stiffens as they do: extrapolating the last steps overshoots (the second of ten
    steps on a 16 000-point profile predicted 769 nodes wrong). Each step therefore starts
    from the coarser level solved at its factor. What must hold: every step is the direct
    solve of its load (the discrete problem has one solution), and starting from the
    coarser level takes fewer than 0.6 times the Newton steps of extrapolating (measured:
    14 against 30)."""
    from contactfem.kernel import default_c, solve_path
    from contactfem.methods import get_method

    factors = [0.25, 0.5, 0.75, 1.0]
    data, source = rough_path(factors)
    case = parse_case(yaml.safe_dump(data), source=source)
    path = solve_load_path(case)
    assert path.sequencing["started_from"] == {"coarse": 4, "extrapolated": 0, "solved": 0}
    assert path.sequencing["coarse_steps"] == 4 and path.sequencing["levels"] >= 1
    push = data["boundary"]["top"]["displacement"][1]
    for factor, step in zip(factors, path.steps):
        assert step.kernel.status is Status.CONVERGED and step.kernel.certificate.passed
        alone = {key: value for key, value in data.items() if key != "load_path"}
        alone["boundary"] = dict(data["boundary"], top={"displacement": [0, factor * push]})
        direct = solve_case(parse_case(yaml.safe_dump(alone), source=source))
        assert np.array_equal(step.solution.contact.active, direct.solution.contact.active)
        scale = np.abs(direct.solution.displacement).max()
        assert np.abs(step.solution.displacement - direct.solution.displacement).max() <= 1e-8 * scale
    problem = prepare(case)
    reduced = problem.contact_system(get_method(case.solver.method))
    extrapolated = list(solve_path(reduced.system, factors, c=default_c(reduced.system), backend="auto"))
    assert all(k.status is Status.CONVERGED for k in extrapolated)
    newton = sum(step.kernel.iterations for step in path.steps)
    assert newton < 0.6 * sum(k.iterations for k in extrapolated)


def test_a_path_whose_zone_stays_put_asks_the_coarser_level_twice():
    """A traction on the square: the active set is the same at every factor, which
    extrapolation gets exactly from the third step on. The coarser level is solved for the
    first two steps (the second compares both predictions) and never again, every later
    step settles in its first Newton step, and each step is the final solution scaled."""
    factors = [(i + 1) / 8 for i in range(8)]
    data = square_path(factors)
    data["mesh"]["divisions"] = 64  # 8 320 unknowns: a coarser level pays for itself
    path = solve_load_path(case_of(data))
    assert path.sequencing["started_from"] == {"coarse": 2, "extrapolated": 6, "solved": 0}
    assert path.sequencing["coarse_steps"] == 2
    assert [step.kernel.iterations for step in path.steps[2:]] == [1] * 6
    final = path.steps[-1].solution
    for factor, step in zip(factors, path.steps):
        assert np.abs(step.solution.displacement - factor * final.displacement).max() \
            <= 1e-10 * np.abs(final.displacement).max()


def test_a_set_two_steps_share_costs_no_schur_solve_after_them(monkeypatch):
    """A path started two nodes off the square's zone: the first step's factorisation is of
    the wrong set and the zone is reached by a Schur update, which every later step needs
    too. u is affine in the load factor for a fixed set, so once two steps have solved it
    (two Schur solves), later steps solve none, and each is still the final solution
    scaled (to 1e-10)."""
    from contactfem.kernel import ActiveSetSolver, default_c, solve_path
    from contactfem.methods import get_method

    factors = [0.2, 0.4, 0.6, 0.8, 1.0]
    case = case_of(square_path(factors))
    reduced = prepare(case).contact_system(get_method("positive"))
    zone = solve_case(case).solution.contact.active
    monkeypatch.setattr(ActiveSetSolver, "_refactorize_first",
                        lambda self, active: int(np.count_nonzero(active != self.reference)) > 20)
    solved_at = []
    schur = ActiveSetSolver._solve_changed

    def counted(self, released, added, *args):
        if len(released) or len(added):
            solved_at.append(self.load_factor)
        return schur(self, released, added, *args)

    monkeypatch.setattr(ActiveSetSolver, "_solve_changed", counted)
    start = zone.copy()
    start[np.flatnonzero(~zone)[:2]] = True
    steps = list(solve_path(reduced.system, factors, c=default_c(reduced.system), backend="auto",
                            initial_active=start))
    assert all(np.array_equal(step.active, zone) for step in steps)
    assert [step.factorizations for step in steps] == [1, 0, 0, 0, 0]
    assert solved_at == factors[:2]
    final = reduced.displacement(steps[-1].displacement)
    for factor, step in zip(factors, steps):
        assert np.abs(reduced.displacement(step.displacement) - factor * final).max() <= 1e-10 * np.abs(final).max()


def test_a_gap_opening_like_the_three_halves_power_of_the_edge_distance_is_extrapolated_exactly():
    """Beyond the edge a(f) of a growing smooth contact the gap opens like δ^{3/2} (δ = x − a
    the distance from the edge): with the edge moving steadily with the load, (G − d)^{2/3}
    = δ is linear in the factor, so extrapolating it from two steps predicts the next set
    exactly, while the slack's own linear extrapolation crosses zero early, predicting
    active every node up to δ* beyond the edge, where 2 (δ* + s)^{3/2} = (δ* + 2 s)^{3/2}
    for an advance s a step: δ* = s (2^{1/3} − 1) / (1 − 2^{−2/3}) ≈ 0.70 s."""
    from contactfem.kernel import extrapolated_active

    spacing, advance = 0.01, 0.0637  # the edge moves 6.37 node spacings a step
    x = (np.arange(400) + 0.5) * spacing

    def state(factor: float) -> tuple[float, np.ndarray, np.ndarray]:
        edge = 0.3 + advance * factor
        inside = x < edge
        force = np.where(inside, np.sqrt(np.abs(edge - x)), 0.0)  # the pressure's √δ inside
        slack = np.where(inside, 0.0, -np.abs(x - edge) ** 1.5)
        return factor, force, slack

    for factor in (2.0, 7.0, 11.0):
        states = [state(factor - 2.0), state(factor - 1.0)]
        expected = x < 0.3 + advance * factor
        predicted = extrapolated_active(states, factor, c=1.0, apart=states[1][2] < 0)
        np.testing.assert_array_equal(predicted, expected)
        # The slack extrapolated linearly overshoots the edge by δ*.
        (f0, force0, slack0), (f1, force1, slack1) = states
        linear = (2 * force1 - force0) + (2 * slack1 - slack0) > 0
        beyond = x - (0.3 + advance * factor)
        reach = advance * (2 ** (1 / 3) - 1) / (1 - 2 ** (-2 / 3))
        np.testing.assert_array_equal(linear & ~expected, (beyond > 0) & (beyond < reach))
        assert np.count_nonzero(linear & ~expected) >= 4


def test_the_start_of_a_step_is_the_prediction_that_missed_fewer_nodes():
    from contactfem.sequencing import PredictedStarts

    asked = []
    coarse = np.array([True, True, False, False])

    def predict(factor):
        asked.append(factor)
        return coarse.copy()

    starts = PredictedStarts(predict)
    # First step: nothing extrapolated yet, the coarser level answers.
    assert np.array_equal(starts.choose(0.25, None), coarse)
    starts.settled(np.array([True, True, True, False]))
    # Second step: both known; the coarser level is still preferred (nothing compared yet).
    right = np.array([True, True, True, False])
    assert np.array_equal(starts.choose(0.5, right), coarse)
    starts.settled(right)  # extrapolation missed 0 nodes, the coarser level 1
    # Third: extrapolation alone, the coarser level not solved.
    assert starts.choose(0.75, right) is None and asked == [0.25, 0.5]
    # Extrapolation missed a node, no more than the coarser level last did: it goes on, the
    # coarser level's record spent.
    starts.settled(np.array([True, True, True, True]))
    assert starts.choose(0.875, right) is None and asked == [0.25, 0.5]
    starts.settled(np.array([True, True, True, True]))  # extrapolation missed a node again
    # Fourth: the coarser level again, and a tie between the two goes to extrapolation.
    assert np.array_equal(starts.choose(1.0, coarse), coarse) and asked == [0.25, 0.5, 1.0]
    starts.settled(coarse)
    assert starts.choose(1.25, coarse) is None
    starts.settled(right)  # extrapolation missed a node, the coarser level none when compared: it next
    # A factor solved before starts from its own set (the path solver's): nothing is
    # predicted, and the step judges nothing.
    starts.revisited(1.25)
    starts.settled(right)
    assert np.array_equal(starts.choose(1.5, right), coarse) and asked == [0.25, 0.5, 1.0, 1.5]
    assert starts.started == {"coarse": 4, "extrapolated": 3, "solved": 1}


def test_a_repeated_factor_starts_from_its_own_set_and_judges_nothing():
    """A factor given twice: its second step starts from the first one's set (one Newton
    step), its two identical states are not extrapolated from, and the step after it still
    starts from the coarser level, where extrapolating from 0 through 0.5 would overshoot
    the rough block's zone. Every step is the same solve whichever path reached it."""
    data, source = rough_path([0.5, 0.5, 1.0])
    repeated = solve_load_path(parse_case(yaml.safe_dump(data), source=source))
    data, source = rough_path([0.5, 1.0])
    plain = solve_load_path(parse_case(yaml.safe_dump(data), source=source))
    assert repeated.steps[1].kernel.iterations == 1
    assert repeated.sequencing["started_from"] == {"coarse": 2, "extrapolated": 0, "solved": 1}
    assert repeated.steps[2].kernel.iterations == plain.steps[1].kernel.iterations
    for mine, theirs in ((repeated.steps[0], plain.steps[0]), (repeated.steps[1], plain.steps[0]),
                         (repeated.steps[2], plain.steps[1])):
        assert np.array_equal(mine.solution.contact.active, theirs.solution.contact.active)
        force = abs(theirs.solution.contact.nodal_force.sum())
        assert abs(mine.solution.contact.nodal_force.sum() - theirs.solution.contact.nodal_force.sum()) <= 1e-10 * force


def test_the_time_spent_writing_steps_is_not_the_solves():
    """What on_step takes (the command writes each step's files there) is timed as
    write_steps, not as the path's contact solve."""
    import time

    def slow_writer(index, factor, step):
        time.sleep(0.25)

    path = solve_load_path(case_of(square_path([0.25, 0.5, 0.75, 1.0])), on_step=slow_writer)
    assert path.timings["write_steps"] >= 1.0
    assert path.timings["solve"] < 1.0 and path.seconds < 1.0
    assert "write_steps" not in solve_load_path(case_of(square_path([0.5, 1.0]))).timings


def test_a_path_that_unloads_and_loads_again_revisits_each_factor_in_one_newton_step():
    """Loading, unloading and loading again (1, 0.5, 0.25, 0.5, 1, 0.5): a factor solved
    before starts from its own settled set, the answer, so it takes one Newton step, asks
    no coarser level, and gives the same solution as the first time (the problem is
    path-independent: elastic and frictionless). Whether that step refactorises or takes
    Schur columns is the cost model's choice from measured seconds, not asserted here."""
    data, source = rough_path([1.0, 0.5, 0.25, 0.5, 1.0, 0.5])
    path = solve_load_path(parse_case(yaml.safe_dump(data), source=source))
    assert path.sequencing["started_from"]["solved"] == 3
    for again, first in ((3, 1), (4, 0), (5, 1)):
        step, earlier = path.steps[again], path.steps[first]
        assert step.kernel.iterations == 1
        assert np.array_equal(step.solution.contact.active, earlier.solution.contact.active)
        force = abs(earlier.solution.contact.nodal_force.sum())
        assert abs(step.solution.contact.nodal_force.sum() - earlier.solution.contact.nodal_force.sum()) <= 1e-10 * force


def test_a_start_corrected_from_its_schur_system_is_the_step_answer():
    """The Schur system of a set gives, without the displacement, the same multipliers of
    the nodes it adds and the same slack of the nodes beside it as the full solve of that
    set (one linear system, two ways: identity to round-off, 1e-9 of the largest). A
    Hertz platen step started with one node too many beyond the zone's edge and one too
    few inside it is therefore corrected before Newton's first step: the step settles in
    one Newton step on the answer of the step solved from scratch, where the start
    uncorrected takes two."""
    from contactfem.kernel import PathSolver, PathStarts, solve_path
    from contactfem.methods import get_method

    case = case_of(yaml.safe_load((CASES / "hertz_platen.yaml").read_text(encoding="utf-8")))
    problem = prepare(case)
    system = problem.contact_system(get_method("positive")).system
    answer = list(solve_path(system, [0.36]))[-1].active

    class Given(PathStarts):
        def choose(self, factor, extrapolated):
            return start if factor == 0.36 else None

    path = PathSolver(system, starts=Given())
    assert path.step(0.25).status is Status.CONVERGED and path.linear.forward
    outside = path._beside(answer)[0]
    inside = np.flatnonzero(answer)[np.argmin(np.abs(np.flatnonzero(answer) - outside))]
    start = answer.copy()
    start[[outside, inside]] = [True, False]
    linear = path.linear
    linear.set_load_factor(0.36)
    reaction, slack = linear.preview(start, path._beside(start))
    u, reactions = linear.solve(start)
    full_reaction = np.zeros(len(start))
    full_reaction[start] = reactions
    full_slack = u[system.normal_dofs] - system.gap
    assert not np.isnan(reaction[outside]) and not np.isnan(slack[inside])
    for seen, full in ((reaction, full_reaction), (slack, full_slack)):
        known = ~np.isnan(seen)
        assert np.abs(seen[known] - full[known]).max() <= 1e-9 * np.abs(full).max()
    assert reaction[outside] < 0 < slack[inside]
    np.testing.assert_array_equal(path.checked_start(start), answer)
    result = path.step(0.36)
    assert result.status is Status.CONVERGED and result.iterations == 1
    np.testing.assert_array_equal(result.active, answer)
    unchecked = PathSolver(system, starts=Given())
    unchecked.check_starts = False
    unchecked.step(0.25)
    assert unchecked.step(0.36).iterations == 2
