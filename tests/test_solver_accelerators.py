"""``solver.accelerators``: the switches of the solver's accelerations, read and checked like every key."""

from __future__ import annotations

import itertools

import pytest
import yaml
from conftest import case_from, make_runner, square_case_dict

from contactfem.case import ACCELERATORS, Accelerators
from contactfem.cli import main
from contactfem.errors import CaseError

CHOICES = "sequencing, zone_fronts, schur_updates, start_checks"


def with_solver(solver) -> dict:
    data = square_case_dict()
    data["solver"] = solver
    return data


def test_the_switches_are_the_accelerators_fields():
    assert ACCELERATORS == ("sequencing", "zone_fronts", "schur_updates", "start_checks")
    assert Accelerators() == Accelerators(sequencing=True, zone_fronts=True, schur_updates=True, start_checks=True)


@pytest.mark.parametrize("solver", [None, {}, {"method": "standard"}, {"accelerators": {}}, {"accelerators": None}],
                         ids=["no solver", "empty solver", "other keys", "empty mapping", "null"])
def test_every_accelerator_is_on_by_default(solver):
    data = square_case_dict() if solver is None else with_solver(solver)
    assert case_from(data).solver.accelerators == Accelerators()


@pytest.mark.parametrize("values", list(itertools.product([True, False], repeat=4)))
def test_the_switches_are_stored_as_given(values):
    given = dict(zip(ACCELERATORS, values))
    case = case_from(with_solver({"accelerators": given}))
    assert case.solver.accelerators == Accelerators(*values)
    assert case.with_solver(method="standard").solver.accelerators == Accelerators(*values)


def test_a_switch_left_out_stays_on():
    accelerators = case_from(with_solver({"accelerators": {"schur_updates": False}})).solver.accelerators
    assert accelerators == Accelerators(sequencing=True, zone_fronts=True, schur_updates=False, start_checks=True)


@pytest.mark.parametrize("value, shown", [
    (1, "1"), (0, "0"), ("no", "'no'"), ("false", "'false'"), (None, "None"), ([True], "[True]"), ({"on": 1}, "{'on': 1}"),
], ids=["one", "zero", "quoted no", "quoted false", "null", "list", "mapping"])
def test_a_switch_that_is_not_true_or_false_is_refused(value, shown):
    with pytest.raises(CaseError) as error:
        case_from(with_solver({"accelerators": {"zone_fronts": value}}))
    assert str(error.value) == f"test.yaml: solver.accelerators.zone_fronts = {shown}: expected true or false"


@pytest.mark.parametrize("key, hint", [("zone_front", " (did you mean zone_fronts?)"), ("multigrid", "")])
def test_an_unknown_switch_is_refused_with_the_choices(key, hint):
    with pytest.raises(CaseError) as error:
        case_from(with_solver({"accelerators": {key: False}}))
    assert str(error.value) == f"test.yaml: solver.accelerators.{key}: unknown key{hint}; expected one of {CHOICES}"


@pytest.mark.parametrize("value, shown", [([], "[]"), ("off", "'off'"), (False, "False")])
def test_accelerators_must_be_a_mapping(value, shown):
    with pytest.raises(CaseError) as error:
        case_from(with_solver({"accelerators": value}))
    assert str(error.value) == f"test.yaml: solver.accelerators = {shown}: expected a mapping of keys to values"


def test_the_command_line_refuses_a_bad_switch_in_one_line(tmp_path):
    path = tmp_path / "switches.yaml"
    path.write_text(yaml.safe_dump(with_solver({"accelerators": {"sequencing": "yes please"}})), encoding="utf-8")
    result = make_runner().invoke(main, ["check", str(path)])
    assert result.exit_code == 2
    assert result.stderr.splitlines() == [
        "error: switches.yaml: solver.accelerators.sequencing = 'yes please': expected true or false"]
