"""One knob that converges: without mesh.grading the grading follows mesh.contact_size, and
the size guard counts the mesh the size field will make (uniform, graded, profile, punch)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from contactfem.case import parse_case
from contactfem.case.model import GRADING_CONSTANT, GRADING_RANGE, grading_of
from contactfem.discretize.meshing import build_mesh, estimate_triangles

CASES = Path(__file__).resolve().parents[1] / "cases"


def variant(name: str, tmp_path: Path | None = None, **mesh) -> object:
    data = yaml.safe_load((CASES / name).read_text(encoding="utf-8"))
    data["mesh"] = mesh
    source = CASES / name
    if "profile" in data["geometry"]:
        data["geometry"]["profile"]["file"] = str(CASES / data["geometry"]["profile"]["file"])
        if tmp_path is not None:
            source = tmp_path / name
            source.write_text(yaml.safe_dump(data), encoding="utf-8")
    return parse_case(yaml.safe_dump(data), source=source)


def test_the_grading_follows_the_contact_size_unless_the_case_gives_one():
    case = variant("hertz_quarter.yaml", size=0.05, contact_size=0.002)
    assert case.mesh.grading_key is None
    assert case.mesh.grading == pytest.approx(GRADING_CONSTANT * np.sqrt(0.002 / 0.05))
    # Halving contact_size divides the grading by √2, within its range.
    assert grading_of(0.001, 0.05) == pytest.approx(grading_of(0.002, 0.05) / np.sqrt(2))
    assert grading_of(0.05, 0.05) == GRADING_RANGE[1] and grading_of(1e-9, 1.0) == GRADING_RANGE[0]
    assert variant("hertz_quarter.yaml", size=0.05, contact_size=0.002, grading=0.3).mesh.grading == 0.3
    # The contact_size floor is round-off's, no longer extent / 100 000.
    assert variant("hertz_quarter.yaml", size=0.05, contact_size=1e-8).mesh.contact_size == 1e-8


def test_halving_the_contact_mesh_alone_brings_the_hertz_half_width_closer():
    """Two coarse levels of the quarter Hertz disk without a grading key (the long study,
    down to 0.15%: benchmarks/mesh_knob.py): the half-width error falls when contact_size
    is halved, in a few seconds."""
    from contactfem.solve import prepare, solve_case
    from contactfem.validation import hertz_comparison

    started = time.process_time()
    errors = []
    for contact_size in (0.004, 0.002):
        case = variant("hertz_quarter.yaml", size=0.05, contact_size=contact_size)
        outcome = solve_case(case, problem=prepare(case))
        errors.append(abs(hertz_comparison(outcome, radius=1.0, symmetry_axis=0.0)["half_width_error"]))
    assert errors[1] < 0.8 * errors[0] and errors[1] < 0.015, errors
    assert time.process_time() - started < 30


@pytest.mark.parametrize("name, mesh", [
    ("hertz_quarter.yaml", {"size": 0.2}),                                   # uniform, an arc
    ("hertz_quarter.yaml", {"size": 0.05, "contact_size": 0.004}),           # graded, curved ΓC
    ("flat_punch.yaml", {"size": 1.0, "contact_size": 0.05}),                # a punch's face and ends
    ("rough.yaml", {"size": 0.05}),                                          # a profile's points
    ("rough.yaml", {"size": 0.05, "contact_size": 0.002}),                   # a graded profile
])
def test_the_triangle_estimate_is_within_half_again_of_the_mesh(name, mesh):
    case = variant(name, **mesh)
    estimate, triangles = estimate_triangles(case), build_mesh(case).n_triangles
    assert triangles / 1.5 <= estimate <= 1.5 * triangles, (estimate, triangles)
    assert estimate_triangles(case, refine=2) == pytest.approx(16 * estimate, rel=0.02)


def test_a_refined_graded_rough_block_is_checked_not_refused(tmp_path):
    """A graded rough block of about 125k unknowns refined once: about four times the
    unknowns, not refused (its estimate used to count a band π · extent long)."""
    from contactfem.cli import main

    variant("rough.yaml", tmp_path, size=0.05, contact_size=0.0005)
    runner = CliRunner()
    counts = []
    for refine in (0, 1):
        result = runner.invoke(main, ["check", "--json", "--refine", str(refine), str(tmp_path / "rough.yaml")])
        assert result.exit_code == 0, result.output
        counts.append(json.loads(result.stdout)["unknowns"])
    assert counts[0] > 100_000 and 3.7 < counts[1] / counts[0] < 4.1, counts


def test_a_refusal_names_the_knobs_to_turn(tmp_path):
    from contactfem.errors import CaseError

    case = variant("rough.yaml", tmp_path, size=0.05, contact_size=1e-7)
    with pytest.raises(CaseError) as caught:
        build_mesh(case, refine=1)
    message = str(caught.value)
    assert "mesh.contact_size" in message and "mesh.grading" in message and "--refine" in message
