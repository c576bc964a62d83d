"""Shared builders: cases written as dictionaries, validated like files."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from contactfem.case import Case, parse_case

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"


def square_case_dict(divisions: int = 8) -> dict:
    """The square of the core issue: left clamped, top traction, bottom on y <= 0."""
    return {
        "title": "square",
        "geometry": {"rectangle": {"lower": [0, 0], "upper": [1, 1]}},
        "mesh": {"divisions": divisions},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {
            "left": "clamped",
            "top": {"traction": [1.0e4, "-1e4*(1-1.5*x)"]},
            "right": "free",
            "bottom": "contact",
        },
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }


def make_runner() -> CliRunner:
    """A runner that keeps stderr apart from stdout (click < 8.2 needs mix_stderr=False; 8.2+ always does)."""
    try:
        return CliRunner(mix_stderr=False)
    except TypeError:
        return CliRunner()


def case_from(data: dict, name: str = "test.yaml", directory: Path | None = None) -> Case:
    source = (directory or ROOT) / name
    return parse_case(yaml.safe_dump(copy.deepcopy(data), sort_keys=False), source=source)


def shipped_case(name: str) -> Case:
    from contactfem.case import load_case

    return load_case(CASES / f"{name}.yaml")


@pytest.fixture
def square_dict() -> dict:
    return square_case_dict()
