"""report.json's accuracy section: the estimates against the errors they estimate.

Measured (contactfem/accuracy.py): on cases/manufactured.yaml the residual estimator's η
is 7.2 times the true energy error at every refinement; on the quarter Hertz disk the
contact-width estimate is within a factor 1.4 of the width's error against plane-strain
Hertz at contact_size 0.004 and 0.002. The tests allow η/‖e‖ in [1, 10] and the width
estimate within a factor 5 of the true error.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from jsonschema import Draft202012Validator

from contactfem.accuracy import MAX_EXTRA_SHARE, accuracy_figures, observed_order, richardson
from contactfem.case import load_case
from contactfem.io.registry import REPORT_JSON, schema_path
from contactfem.report import build_report, exact_errors
from contactfem.solve import solve_case
from contactfem.validation import hertz_comparison

ROOT = Path(__file__).resolve().parents[1]
#: η / ‖u − u_h‖_a allowed on the manufactured case (measured 7.2).
ENERGY_EFFECTIVITY = (1.0, 10.0)
#: The contact-width estimate may be this factor above or below the true error.
WIDTH_FACTOR = 5.0


@pytest.fixture(scope="module")
def manufactured():
    case = load_case(ROOT / "cases" / "manufactured.yaml")
    return case, [solve_case(case, refine=refine) for refine in (0, 1)]


def test_energy_estimate_is_within_a_stated_factor_of_the_true_error_and_falls(manufactured):
    case, results = manufactured
    estimates = []
    for result in results:
        figures = accuracy_figures(case, result, levels="solve")
        energy = figures["energy"]
        true = exact_errors(result.problem, result.solution)["displacement_energy"]
        assert energy["guaranteed"] is False
        low, high = ENERGY_EFFECTIVITY
        assert low <= energy["estimate"] / true <= high, (energy["estimate"], true)
        estimates.append(energy["estimate"])
    assert estimates[1] < 0.6 * estimates[0]  # h halved: the O(h) error halves


def test_the_extra_cost_is_bounded_in_unknowns(manufactured):
    case, results = manufactured
    for result in results:
        figures = accuracy_figures(case, result, levels="solve")
        solved = [level for level in figures["levels"] if level["source"] == "solved"]
        assert figures["cost"]["unknowns"] == sum(level["unknowns"] for level in solved)
        assert figures["cost"]["unknowns"] <= MAX_EXTRA_SHARE * result.problem.n_unknowns
        assert figures["levels"][0]["unknowns"] <= 0.28 * result.problem.n_unknowns
        assert all(level["h_ratio"] > 1 for level in figures["levels"])


def test_a_level_kept_by_sequencing_is_reused_for_nothing():
    case = load_case(ROOT / "cases" / "manufactured.yaml")
    result = solve_case(case, refine=2)  # 16 512 unknowns: sequencing solves the 4h level
    assert "solve" in result.coarse_levels
    figures = accuracy_figures(case, result, levels="solve")
    assert figures["levels"][0]["source"] == "sequencing" and figures["levels"][0]["h_ratio"] == 4.0
    assert figures["cost"]["share_of_unknowns"] < 0.1
    force = figures["quantities"]["contact_force"]
    assert force["observed_order"] == pytest.approx(2.0, abs=0.3)
    assert force["method"].endswith("observed from 3 levels")


@pytest.mark.parametrize("contact_size", [0.004, 0.002])
def test_contact_width_estimate_has_the_magnitude_of_the_true_error_on_hertz(contact_size):
    case = load_case(ROOT / "cases" / "hertz_quarter.yaml")
    case = dataclasses.replace(case, mesh=dataclasses.replace(case.mesh, contact_size=contact_size))
    result = solve_case(case)
    figures = accuracy_figures(case, result, levels="solve")
    width = figures["quantities"]["contact_width"]
    half_width = hertz_comparison(result, radius=1.0, symmetry_axis=0.0)["half_width"]
    true = abs(width["value"] - half_width)
    assert width["guaranteed"] is False
    assert true / WIDTH_FACTOR <= width["estimate"] <= WIDTH_FACTOR * true, (width, true)
    assert figures["cost"]["unknowns"] <= MAX_EXTRA_SHARE * result.problem.n_unknowns


def test_the_report_carries_the_section_and_follows_the_schema(manufactured):
    case, results = manufactured
    validator = Draft202012Validator(json.loads(schema_path(REPORT_JSON).read_text(encoding="utf-8")))
    standard = solve_case(case, method="standard")
    for result in (results[0], standard):
        report = json.loads(json.dumps(build_report(case, result)))
        assert list(validator.iter_errors(report)) == []
        accuracy = report["accuracy"]
        assert set(accuracy["quantities"]) == {"contact_force", "contact_width", "peak_pressure"}
        assert all(entry["guaranteed"] is False for entry in accuracy["quantities"].values())
        assert "accuracy" in report["timings"]
    report = build_report(case, standard)
    energy = report["accuracy"]["energy"]
    assert energy["estimate"] is None and "method (4)" in energy["reason"]
    assert not validator.is_valid({**report, "accuracy": {**report["accuracy"],
                                                         "energy": {**report["accuracy"]["energy"], "guaranteed": True}}})


def test_richardson_and_the_observed_order():
    # q_h = 1 + h²: levels h = 1, 2, 4 (× 0.01)
    values = [1 + (0.01 * r) ** 2 for r in (1, 2, 4)]
    assert observed_order(values, [1, 2, 4]) == pytest.approx(2.0)
    entry = richardson(values, [1, 2, 4], expected=1.5)
    assert entry["order"] == pytest.approx(2.0) and entry["estimate"] == pytest.approx(1e-4)
    assert observed_order([1.0, 2.0, 1.5], [1, 2, 4]) is None  # differences change sign
    assert richardson(values[:2], [1, 2], expected=2.0)["method"] == "richardson, expected order assumed"


# --------------------------------------------------------------------------- free by default


def hertz(contact_size: float = 0.004):
    """The quarter Hertz disk without its grading key (the rule's grading)."""
    case = load_case(ROOT / "cases" / "hertz_quarter.yaml")
    return dataclasses.replace(case, mesh=dataclasses.replace(case.mesh, grading_key=None, contact_size=contact_size))


def test_a_plain_solve_estimates_for_nothing():
    """7 930 unknowns: sequencing solves a level 16 times coarser, which the quantities reuse;
    no unknowns are solved for the estimates. On 1 056 unknowns (no sequencing) they say why
    they have none and how to ask for them."""
    case = hertz()
    result = solve_case(case)
    figures = accuracy_figures(case, result)
    assert [level["source"] for level in figures["levels"]] == ["sequencing"]
    assert figures["cost"]["unknowns"] == 0
    assert figures["quantities"]["contact_width"]["estimate"] is not None
    small = load_case(ROOT / "cases" / "manufactured.yaml")
    figures = accuracy_figures(small, solve_case(small))
    assert figures["levels"] == [] and figures["energy"]["estimate"] > 0
    assert all(entry["estimate"] is None and "levels: solve" in entry["reason"]
               for entry in figures["quantities"].values())


@pytest.mark.parametrize("levels", ["reuse", "solve"])
def test_a_level_no_coarser_along_the_contact_gives_no_estimate(tmp_path, levels):
    """A tall block whose contact side has an odd number of divisions: its coarser levels
    halve the divisions across ΓC only, so their ΓC edges are the solve's (h ratio 1) and a
    Richardson step would divide by 1^p − 1 = 0. The quantities then have no estimate and
    say why; the solve and its report go through."""
    path = tmp_path / "tall.yaml"
    path.write_text("""
title: a tall block on a tilted segment
material: {E: 0.257, nu: 0.3, plane: stress}
geometry: {rectangle: {lower: [0, 0], upper: [0.00606, 0.0441]}}
mesh: {divisions: [33, 200]}
boundary:
  bottom: contact
  top: {displacement: [2.05e-08, -1.04e-08]}
obstacle: {segment: [[0.0025, -0.000222], [0.0085, -0.000755]]}
""", encoding="utf-8")
    case = load_case(path)
    result = solve_case(case)
    assert result.problem.n_unknowns > 5_000  # sequencing solved a coarser level
    figures = accuracy_figures(case, result, levels=levels)
    assert all(level["h_ratio"] >= 1.4 for level in figures["levels"])
    for entry in figures["quantities"].values():
        assert entry["estimate"] is None, entry
        assert entry["reason"]
    if levels == "reuse":
        assert "ΓC edges 1 times" in figures["quantities"]["contact_force"]["reason"]


# --------------------------------------------------------------------------- towards a target


def test_the_contact_width_target_is_met_and_the_true_error_is_within_it():
    """Quarter Hertz disk, contact_size 0.004, width to 2%: the run stops at the target (15k-30k
    unknowns measured, the width within 0.25% of plane-strain Hertz), the last two estimates
    below it; the report section follows the schema."""
    from contactfem.accuracy_target import solve_to_accuracy

    case = hertz()
    run = solve_to_accuracy(case, target=0.02, quantity="contact_width")
    assert run.met and run.stop_reason == "target"
    assert all(step["estimate"] is not None and step["estimate"] <= 0.02 for step in run.steps[-2:])
    half_width = hertz_comparison(run.result, radius=1.0, symmetry_axis=0.0)["half_width"]
    width = run.accuracy["quantities"]["contact_width"]["value"]
    assert abs(width - half_width) / half_width <= 0.02
    assert run.result.problem.n_unknowns < 60_000
    validator = Draft202012Validator(json.loads(schema_path(REPORT_JSON).read_text(encoding="utf-8")))
    report = json.loads(json.dumps(build_report(case, run.result, {"accuracy": {**run.accuracy,
                                                                                "target": run.record()}})))
    assert list(validator.iter_errors(report)) == []


def test_the_energy_target_bounds_the_true_error_on_the_manufactured_case():
    """η is 1-10 times the true energy error (ENERGY_EFFECTIVITY): η / ‖u_h‖ ≤ 5% leaves the
    true relative error below 5%."""
    from contactfem.accuracy_target import solve_to_accuracy

    case = load_case(ROOT / "cases" / "manufactured.yaml")
    run = solve_to_accuracy(case, target=0.05)
    assert run.met and run.reached <= 0.05
    true = exact_errors(run.result.problem, run.result.solution)["displacement_energy"]
    u = run.result.solution.displacement.ravel()
    norm = float(np.sqrt(u @ (run.result.problem.stiffness @ u)))
    assert true / norm <= run.reached <= ENERGY_EFFECTIVITY[1] * true / norm


def test_a_budget_stops_the_run_and_says_so():
    from contactfem.accuracy_target import solve_to_accuracy

    run = solve_to_accuracy(hertz(), target=1e-5, quantity="contact_force", max_unknowns=12_000)
    assert not run.met and run.stop_reason == "max_unknowns"
    assert run.result.problem.n_unknowns <= 12_000 and run.record()["met"] is False


@pytest.mark.parametrize("value, expected", [("0.5%", 0.005), (0.005, 0.005), ("2 %", 0.02)])
def test_the_case_key_reads_a_relative_target(value, expected):
    from contactfem.case import parse_case

    text = (ROOT / "cases" / "hertz_quarter.yaml").read_text(encoding="utf-8")
    case = parse_case(text + f"solver:\n  accuracy: {{target: '{value}', quantity: contact_width, "
                             "budget: {unknowns: 50000}}\n", source=ROOT / "cases" / "hertz_quarter.yaml")
    settings = case.solver.accuracy
    assert settings.target == pytest.approx(expected) and settings.quantity == "contact_width"
    assert settings.max_unknowns == 50_000 and settings.levels == "reuse"


@pytest.mark.parametrize("body, key", [
    ("{target: 5x}", "solver.accuracy.target"), ("{target: 80%}", "solver.accuracy.target"),
    ("{quantity: stress}", "solver.accuracy.quantity"), ("{budget: {unknowns: 0}}", "solver.accuracy.budget.unknowns"),
    ("{levels: all}", "solver.accuracy.levels"), ("{aim: 1%}", "solver.accuracy"),
])
def test_a_bad_accuracy_key_is_one_line_naming_it(body, key):
    from contactfem.case import parse_case
    from contactfem.errors import CaseError

    text = (ROOT / "cases" / "hertz_quarter.yaml").read_text(encoding="utf-8")
    with pytest.raises(CaseError) as caught:
        parse_case(text + f"solver:\n  accuracy: {body}\n", source=ROOT / "cases" / "hertz_quarter.yaml")
    assert key in str(caught.value) and "\n" not in str(caught.value)


def test_the_command_line_solves_to_a_target_and_refuses_what_it_cannot(tmp_path):
    from click.testing import CliRunner

    from contactfem.cli import main

    runner = CliRunner()
    case = ROOT / "cases" / "manufactured.yaml"
    result = runner.invoke(main, ["solve", str(case), "--out", str(tmp_path / "out"), "--accuracy", "5%"])
    assert result.exit_code == 0, result.output
    assert "target       energy 5%: reached" in result.output and "(met)" in result.output
    report = json.loads((tmp_path / "out" / "report.json").read_text(encoding="utf-8"))
    assert report["accuracy"]["target"]["met"] is True
    for extra in (["--accuracy", "5x"], ["--accuracy", "1%", "--method", "standard"]):
        result = runner.invoke(main, ["solve", str(case), "--out", str(tmp_path / "no"), *extra])
        assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1, result.output


def test_converge_reports_the_estimates_of_a_solve():
    """Each level's η is 1-10 times its true energy error; the quantities are estimated from
    the previous levels (none on the first)."""
    from contactfem.studies import convergence_study

    case = load_case(ROOT / "cases" / "manufactured.yaml")
    rows = convergence_study(case, 2, methods=("positive",))["rows"]
    for row in rows:
        low, high = ENERGY_EFFECTIVITY
        assert low <= row["estimated_energy"] / row["displacement_energy"] <= high
    assert rows[0]["estimated_contact_force"] is None and rows[1]["estimated_contact_force"] is not None
