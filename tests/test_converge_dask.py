"""``converge`` on Dask: the levels are tasks, the reference is solved once and handed to the
workers, and the study is the same figure for figure as one level after another in-process."""

from __future__ import annotations

import json

import pytest
import yaml
from click.testing import CliRunner
from conftest import CASES, case_from, square_case_dict

import contactfem.studies as studies
from contactfem.cli import main
from contactfem.engines import SerialEngine, open_engine
from contactfem.io.registry import to_json

pytest.importorskip("distributed", reason="Dask (distributed) is not installed: pip install -e '.[dask]'")

#: The only figures of convergence.json that are measured, not computed: wall-clock seconds.
SECONDS = ("mesh_seconds", "assemble_seconds", "solve_seconds", "total_seconds")


@pytest.fixture(scope="module")
def cluster():
    """One local cluster of 2 single-threaded workers for every test here (a few seconds to start)."""
    with open_engine(workers=2, pending=2) as engine:
        assert engine.kind == "dask" and engine.workers == 2
        yield engine


def _computed(study: dict) -> str:
    """convergence.json's text without the wall-clock seconds."""
    rows = [{k: v for k, v in row.items() if k not in SECONDS} for row in study["rows"]]
    return json.dumps({**study, "rows": rows}, sort_keys=True)


def _counting(monkeypatch) -> dict:
    """Counts the reference solves of this process."""
    count = {"n": 0}
    real = studies.nested_reference

    def counting(*args, **kwargs):
        count["n"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(studies, "nested_reference", counting)
    return count


def test_levels_on_dask_give_the_in_process_study_bit_for_bit_and_one_reference(cluster, monkeypatch):
    """Same floating-point operations on the same data in the same order: every computed figure
    (errors, rates, estimates, h, unknowns, iterations) is identical to the last bit; the nested
    reference is solved once in this process whichever engine runs the three levels, and its
    fields (a compiled traction expression among the case's loads) reach the workers."""
    count = _counting(monkeypatch)
    case = case_from(square_case_dict(4))
    here = studies.convergence_study(case, 3, methods=("positive",), engine=SerialEngine())
    assert count["n"] == 1
    solutions: list = []
    there = studies.convergence_study(case, 3, methods=("positive",), engine=cluster,
                                      on_solution=lambda level, name, field: solutions.append((level, name)))
    assert count["n"] == 2
    assert _computed(there) == _computed(here)
    assert [(r["level"], r["method"]) for r in there["rows"]] == solutions == [(0, "positive"), (1, "positive"),
                                                                              (2, "positive")]
    assert there["rows"][0]["estimated_contact_force"] is None  # no earlier level
    assert there["rows"][2]["estimated_contact_force"] is not None  # two earlier levels


def _manufactured(tmp_path, max_iterations: int):
    """The manufactured contact of cases/manufactured.yaml on a coarse mesh: 3, 5 and 5 Newton
    steps on its levels 0, 1 and 2, so that a limit of 3 fails level 1 first."""
    data = yaml.safe_load((CASES / "manufactured.yaml").read_text())
    data["mesh"]["divisions"] = [8, 4]
    data.setdefault("solver", {})["max_iterations"] = max_iterations
    data.setdefault("output", {})["directory"] = str(tmp_path / "manufactured")
    path = tmp_path / "manufactured.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_cli_converge_on_a_cluster_writes_the_in_process_json(cluster, tmp_path):
    """``--scheduler`` sends the levels to a running cluster; with an exact solution there is
    no reference; convergence.json is the in-process study's, seconds aside."""
    from contactfem.case import load_case

    path = _manufactured(tmp_path, 50)
    result = CliRunner().invoke(main, ["converge", str(path), "--levels", "2", "--method", "positive",
                                       "--out", str(tmp_path / "there"), "--scheduler",
                                       cluster.client.scheduler.address])
    assert result.exit_code == 0, result.output
    assert "solving 2 levels on 2 Dask workers of the cluster at tcp://" in result.stderr
    here = studies.convergence_study(load_case(path), 2, methods=("positive",))
    there = json.loads((tmp_path / "there" / "convergence.json").read_text())
    assert here["reference"] == "exact" and [r["iterations"] for r in here["rows"]] == [3, 5]
    assert _computed(there) == _computed(json.loads(to_json(here)))
    assert {p.name for p in (tmp_path / "there").glob("*.vtu")} >= {
        "convergence-positive-level0.vtu", "convergence-positive-level1.vtu"}


@pytest.mark.parametrize("where", ["here", "cluster"])
def test_a_failing_level_is_named_with_its_reason_and_exit_1(cluster, tmp_path, where):
    """Level 1 needs 5 Newton steps and 3 are allowed: the study stops there, whichever
    engine runs it, with the solver's reason and its exit code (1), and writes nothing."""
    path = _manufactured(tmp_path, 3)
    extra = ["--scheduler", cluster.client.scheduler.address] if where == "cluster" else []
    result = CliRunner().invoke(main, ["converge", str(path), "--levels", "3", "--method", "positive",
                                       "--out", str(tmp_path / "out"), "--quiet", *extra])
    assert result.exit_code == 1, result.output
    assert result.stderr.strip().splitlines()[-1] == (
        "error: converge level 1 (refine 1): manufactured.yaml: method positive: no convergence in 3 iterations")
    assert not (tmp_path / "out" / "convergence.json").exists()


def test_workers_with_a_scheduler_is_bad_input(tmp_path):
    result = CliRunner().invoke(main, ["converge", str(CASES / "square.yaml"), "--scheduler", "tcp://127.0.0.1:1",
                                       "--workers", "2", "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "--workers 2: sizes the local cluster; expected no --workers with --scheduler" in result.stderr
    assert not (tmp_path / "out").exists()
