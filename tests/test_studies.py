"""The compare and converge studies: the paper's identities, and what the files hold."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner
from conftest import CASES, case_from, square_case_dict

from contactfem.cli import main
from contactfem.studies import compare_methods, convergence_study


def test_compare_reports_proposition_2_2_and_the_oscillation_of_theta():
    """Same displacement and λ = D⁻¹Mθ to 1e-10; θ dips below zero in the lift-off zone while
    λ is identically zero there (its total variation over lift-off nodes is 0)."""
    figures, _ = compare_methods(case_from(square_case_dict(16)))
    assert figures["relative_displacement_difference"] <= 1e-10
    assert figures["relative_lambda_minus_pi_theta"] <= 1e-10
    assert figures["negative_theta_nodes"] > 0
    assert figures["min_theta"] < 0 <= figures["min_lambda"]
    assert figures["lambda_total_variation_in_lift_off"] == 0.0
    assert figures["theta_total_variation_in_lift_off"] > 0.0
    positions = np.array(figures["negative_theta_positions"])
    assert np.all(positions[:, 1] == 0.0)  # on ΓC, the bottom side


def test_nested_convergence_study_rows_and_rates():
    """Three levels against a reference one refinement finer: errors decrease with h, and a
    rate is reported between each pair of levels for each method and norm."""
    study = convergence_study(case_from(square_case_dict(4)), levels=3, extra=1)
    assert study["reference"].startswith("nested")
    for method in ("positive", "standard"):
        rows = [r for r in study["rows"] if r["method"] == method]
        assert [r["level"] for r in rows] == [0, 1, 2]
        h1 = [r["displacement_h1"] for r in rows]
        assert h1[0] > h1[1] > h1[2] > 0
        assert len(study["rates"][method]["displacement_h1"]) == 2


def test_cli_compare_and_converge_write_json_csv_and_pngs(tmp_path):
    runner = CliRunner()
    square = str(CASES / "square.yaml")
    result = runner.invoke(main, ["compare", square, "--out", str(tmp_path / "cmp")])
    assert result.exit_code == 0, result.output
    figures = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert figures["relative_lambda_minus_pi_theta"] <= 1e-10
    png = (tmp_path / "cmp" / "compare.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000

    result = runner.invoke(main, ["converge", square, "--levels", "2", "--method", "positive",
                                  "--out", str(tmp_path / "conv"), "--quiet"])
    assert result.exit_code == 0, result.output
    out = tmp_path / "conv"
    study = json.loads((out / "convergence.json").read_text())
    assert len(study["rows"]) == 2
    csv = (out / "convergence.csv").read_text().splitlines()
    assert csv[0].startswith("level,method,h") and len(csv) == 3
    for name in ("convergence_h.png", "convergence_time.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG"


def test_square_rates_lie_between_the_theorem_and_p1():
    """The square has clamped–free corners (left end of the top, and the lift-off zone
    meeting the clamp at the origin) and a contact/separation point, so u is only in
    H^{3/2+ν} for some 0 < ν < 1/2. Theorem 3.7 then gives ‖u − u_h‖₁ = O(h^{1/2+ν}), at
    least h^{1/2}; P1 can never beat h¹. The fitted H¹ rate over h = 1/8 … 1/32 (reference
    two refinements finer) must lie in [0.45, 1.05], and so must the energy-norm rate."""
    study = convergence_study(case_from(square_case_dict(8)), levels=3, extra=2, methods=("positive",))
    rows = study["rows"]
    h = np.log([r["h"] for r in rows])
    for norm in ("displacement_h1", "displacement_energy"):
        slope = np.polyfit(h, np.log([r[norm] for r in rows]), 1)[0]
        assert 0.45 <= slope <= 1.05, (norm, slope)
