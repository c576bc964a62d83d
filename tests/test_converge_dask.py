"""``converge`` on Dask: the levels are tasks, the reference is solved once and handed to the
workers, and the study is the same figure for figure as one level after another in-process.

The Dask side runs in one child process on one local cluster of 2 workers (a few seconds to
start): a Dask client leaves threads behind in its process, and this test process must stay
single-threaded for the archive tests that parse in a forked child.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner
from conftest import CASES

import contactfem.studies as studies
from contactfem.case import load_case
from contactfem.cli import main
from contactfem.io.registry import to_json

pytestmark = pytest.mark.skipif(importlib.util.find_spec("distributed") is None,
                                reason="Dask (distributed) is not installed: pip install -e '.[dask]'")

#: The only figures of convergence.json that are measured, not computed: wall-clock seconds.
SECONDS = ("mesh_seconds", "assemble_seconds", "solve_seconds", "total_seconds")
RESULT = "CONVERGE-DASK "

#: Run in the child: the square's study in-process and on the cluster, counting the reference
#: solves of the process; then the command line against the same cluster (--scheduler).
SCRIPT = """
import json
import sys

sys.path.insert(0, sys.argv[1])
from click.testing import CliRunner
from conftest import case_from, square_case_dict

import contactfem.progress
import contactfem.studies as studies
from contactfem.cli import main
from contactfem.engines import SerialEngine, open_engine
from contactfem.io.registry import to_json

count = {"n": 0}
real = studies.nested_reference


def counting(*args, **kwargs):
    count["n"] += 1
    return real(*args, **kwargs)


def run(manufactured, failing, work):
    studies.nested_reference = counting
    out = {}
    case = case_from(square_case_dict(4))
    with open_engine(workers=2, pending=2) as engine:
        out["engine"] = [engine.kind, engine.workers]
        out["here"] = to_json(studies.convergence_study(case, 3, methods=("positive",), engine=SerialEngine()))
        out["count_here"] = count["n"]
        solutions = []
        out["there"] = to_json(studies.convergence_study(
            case, 3, methods=("positive",), engine=engine,
            on_solution=lambda level, name, _: solutions.append([level, name])))
        out["count_there"], out["solutions"] = count["n"], solutions
        address = engine.client.scheduler.address
        runner = CliRunner()
        # Progress lines are held for HOLD_SECONDS and dropped by a command done sooner: write
        # them at once, so that the line naming the cluster is there however fast the study.
        contactfem.progress.HOLD_SECONDS = 0.0
        done = runner.invoke(main, ["converge", manufactured, "--levels", "2", "--method", "positive",
                                    "--out", work + "/there", "--scheduler", address])
        out["cli"] = [done.exit_code, done.stderr]
        for where, extra in (("here", []), ("cluster", ["--scheduler", address])):
            done = runner.invoke(main, ["converge", failing, "--levels", "3", "--method", "positive",
                                        "--out", work + "/fail-" + where, "--quiet", *extra])
            out["fail_" + where] = [done.exit_code, done.stderr]
    print(%r + json.dumps(out), flush=True)


if __name__ == "__main__":  # the local cluster's workers start by spawning
    run(*sys.argv[2:5])
""" % RESULT


def _manufactured(directory: Path, max_iterations: int) -> Path:
    """The manufactured contact of cases/manufactured.yaml on a coarse mesh: 3, 5 and 5 Newton
    steps on its levels 0, 1 and 2, so that a limit of 3 fails level 1 first."""
    data = yaml.safe_load((CASES / "manufactured.yaml").read_text())
    data["mesh"]["divisions"] = [8, 4]
    data.setdefault("solver", {})["max_iterations"] = max_iterations
    data.setdefault("output", {})["directory"] = str(directory / "manufactured")
    path = directory / f"manufactured-{max_iterations}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def dask_run(tmp_path_factory) -> dict:
    work = tmp_path_factory.mktemp("converge-dask")
    script = work / "run.py"
    script.write_text(SCRIPT)
    manufactured, failing = _manufactured(work, 50), _manufactured(work, 3)
    done = subprocess.run([sys.executable, str(script), str(Path(__file__).parent), str(manufactured), str(failing),
                           str(work)], capture_output=True, text=True, timeout=600)
    lines = [line for line in done.stdout.splitlines() if line.startswith(RESULT)]
    assert done.returncode == 0 and lines, done.stdout[-2000:] + done.stderr[-4000:]
    return {**json.loads(lines[-1][len(RESULT):]), "work": work, "manufactured": manufactured}


def _computed(study: dict) -> str:
    """convergence.json's text without the wall-clock seconds."""
    rows = [{k: v for k, v in row.items() if k not in SECONDS} for row in study["rows"]]
    return json.dumps({**study, "rows": rows}, sort_keys=True)


def test_levels_on_dask_give_the_in_process_study_bit_for_bit_and_one_reference(dask_run):
    """Same floating-point operations on the same data in the same order: every computed figure
    (errors, rates, estimates, h, unknowns, iterations) is identical to the last bit; the nested
    reference is solved once in the calling process whichever engine runs the three levels, and
    its fields (a compiled traction expression among the case's loads) reach the workers."""
    assert dask_run["engine"] == ["dask", 2]
    assert dask_run["count_here"] == 1 and dask_run["count_there"] == 2
    here, there = json.loads(dask_run["here"]), json.loads(dask_run["there"])
    assert _computed(there) == _computed(here)
    assert [[r["level"], r["method"]] for r in there["rows"]] == dask_run["solutions"] == [
        [0, "positive"], [1, "positive"], [2, "positive"]]
    assert there["rows"][0]["estimated_contact_force"] is None  # no earlier level
    assert there["rows"][2]["estimated_contact_force"] is not None  # two earlier levels


def test_cli_converge_on_a_cluster_writes_the_in_process_json(dask_run):
    """``--scheduler`` sends the levels to a running cluster; with an exact solution there is
    no reference; convergence.json is the in-process study's, seconds aside."""
    code, stderr = dask_run["cli"]
    assert code == 0, stderr
    assert "solving 2 levels on 2 Dask workers of the cluster at tcp://" in stderr
    here = studies.convergence_study(load_case(dask_run["manufactured"]), 2, methods=("positive",))
    out = dask_run["work"] / "there"
    there = json.loads((out / "convergence.json").read_text())
    assert here["reference"] == "exact" and [r["iterations"] for r in here["rows"]] == [3, 5]
    assert _computed(there) == _computed(json.loads(to_json(here)))
    assert {p.name for p in out.glob("*.vtu")} >= {"convergence-positive-level0.vtu",
                                                   "convergence-positive-level1.vtu"}


@pytest.mark.parametrize("where", ["here", "cluster"])
def test_a_failing_level_is_named_with_its_reason_and_exit_1(dask_run, where):
    """Level 1 needs 5 Newton steps and 3 are allowed: the study stops there, whichever
    engine runs it, with the solver's reason and its exit code (1), and writes nothing."""
    code, stderr = dask_run[f"fail_{where}"]
    assert code == 1, stderr
    assert stderr.strip().splitlines()[-1] == (
        "error: converge level 1 (refine 1): manufactured-3.yaml: method positive: no convergence in 3 iterations")
    assert not (dask_run["work"] / f"fail-{where}" / "convergence.json").exists()


def test_workers_with_a_scheduler_is_bad_input(tmp_path):
    result = CliRunner().invoke(main, ["converge", str(CASES / "square.yaml"), "--scheduler", "tcp://127.0.0.1:1",
                                       "--workers", "2", "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "--workers 2: sizes the local cluster; expected no --workers with --scheduler" in result.stderr
    assert not (tmp_path / "out").exists()
