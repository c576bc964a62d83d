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
