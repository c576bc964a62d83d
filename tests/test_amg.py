"""The iterative backend: each Newton step by CG with smoothed-aggregation multigrid (pyamg).

What theory says and is checked here:
- amg and a factorisation solve the same discrete problem; CG stops when the largest
  residual entry is 1e-2 of what the certificate allows (1e-12 of the force scale at the
  default tolerance), so with the stiffness's condition estimate below 1e5 on these
  meshes the two agree to 1e-8 of the largest displacement and 1e-9 of the contact force,
  with the same active set, on a square, a Hertz quarter disk, a rough profile and a
  platen pressing a body that contact alone holds;
- the certificate passes: the same conditions as a direct solve's;
- the hierarchy's one random draw comes from a fixed seed: two runs are bit-identical;
- ``auto`` takes amg exactly when the memory model puts the direct factorisation above
  3/4 of the memory limit, and a load path keeps factorising;
- what amg does not do (load paths, an uninstalled pyamg) is refused with exit 2 and one line.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml
from conftest import CASES, case_from, make_runner, square_case_dict
from test_platen import hertz_pressed
from test_rough import CASE as ROUGH_CASE

from contactfem.cli import main
from contactfem.estimate import DIRECT_MEMORY_SHARE, MemoryLimit, choose_backend, estimate_cost
from contactfem.kernel import Status
from contactfem.linalg import resolve_backend
from contactfem.solve import prepare, solve_case

pytest.importorskip("pyamg")

DISPLACEMENT_AGREEMENT = 1e-8
FORCE_AGREEMENT = 1e-9


def with_backend(case, backend: str):
    return dataclasses.replace(case, solver=dataclasses.replace(case.solver, backend=backend))


def both(data: dict, refine: int | None = None):
    case = case_from(data)
    problem = prepare(case, refine=refine)
    direct = solve_case(with_backend(case, "auto"), problem=problem)
    iterative = solve_case(with_backend(case, "amg"), problem=problem)
    return direct, iterative


def square() -> dict:
    return square_case_dict(24)


def hertz_quarter() -> dict:
    data = yaml.safe_load((CASES / "hertz_quarter.yaml").read_text(encoding="utf-8"))
    data["mesh"]["contact_size"] = 0.01
    return data


def rough() -> dict:
    return {**ROUGH_CASE, "title": "rough", "mesh": {"size": 0.1}}


def platen() -> dict:
    data = hertz_pressed({"force": 2.0e3})
    data["mesh"]["contact_size"] = 0.01
    return data


@pytest.mark.parametrize("data", [square(), hertz_quarter(), rough(), platen()],
                         ids=["square", "hertz_quarter", "rough", "platen"])
def test_amg_agrees_with_the_direct_backend_and_is_certified(data):
    direct, iterative = both(data)
    assert direct.backend != "amg" and iterative.backend == "amg"
    for outcome in (direct, iterative):
        assert outcome.kernel.status is Status.CONVERGED and outcome.kernel.certificate.passed
    assert np.array_equal(direct.kernel.active, iterative.kernel.active)
    u, v = direct.solution.displacement, iterative.solution.displacement
    assert np.abs(u - v).max() <= DISPLACEMENT_AGREEMENT * np.abs(u).max()
    force, again = direct.solution.contact.nodal_force.sum(), iterative.solution.contact.nodal_force.sum()
    assert abs(force - again) <= FORCE_AGREEMENT * abs(force)
    linear = iterative.linear
    assert linear["iterations"] == sum(solve["iterations"] for solve in linear["solves"]) > 0
    assert len(linear["solves"]) == iterative.kernel.iterations
    assert len(linear["hierarchies"]) == iterative.kernel.factorizations >= 1
    assert all(solve["final_residual"] <= 1e-10 for solve in linear["solves"])


def test_two_runs_are_bit_identical():
    case = with_backend(case_from(square()), "amg")
    first, second = solve_case(case), solve_case(case)
    assert np.array_equal(first.solution.displacement, second.solution.displacement)
    assert np.array_equal(first.solution.contact.nodal_force, second.solution.contact.nodal_force)
    assert first.linear == second.linear


def test_the_report_says_which_backend_and_why():
    from contactfem.report import build_report

    case = with_backend(case_from(square_case_dict(8)), "amg")
    report = build_report(case, solve_case(case))
    solver = report["solver"]
    assert solver["backend"] == "amg" and solver["backend_reason"] == "solver.backend = amg"
    assert solver["linear"]["iterations"] > 0 and solver["certificate"]["passed"]
    direct = build_report(case_from(square_case_dict(8)), solve_case(case_from(square_case_dict(8))))
    assert direct["solver"]["linear"] is None and direct["solver"]["backend_reason"].startswith("auto: ")


def test_auto_turns_to_amg_exactly_where_the_factorisation_would_not_fit():
    direct = resolve_backend("auto")
    unknowns = 100_000
    needed = estimate_cost(unknowns, direct)["bytes"]
    fits = MemoryLimit(int(needed / DIRECT_MEMORY_SHARE) + 1, "a test's limit")
    short = MemoryLimit(int(needed / DIRECT_MEMORY_SHARE) - 1, "a test's limit")
    assert choose_backend(unknowns, "auto", fits).name == direct
    chosen = choose_backend(unknowns, "auto", short)
    assert chosen.name == "amg" and "a test's limit" in chosen.reason and direct in chosen.reason
    # A load path factorises whatever the memory; a named backend is taken as named.
    assert choose_backend(unknowns, "auto", short, iterative=False).name == direct
    assert choose_backend(unknowns, direct, short).name == direct
    assert choose_backend(unknowns, "amg", fits).name == "amg"


def test_a_solve_under_a_small_memory_budget_runs_amg():
    from contactfem.estimate import memory_budget

    case = case_from(square_case_dict(16))
    needed = estimate_cost(prepare(case).n_unknowns, resolve_backend("auto"))["bytes"]
    with memory_budget(MemoryLimit(int(needed / DIRECT_MEMORY_SHARE) - 1, "a test's budget")):
        outcome = solve_case(case)
    assert outcome.backend == "amg" and "a test's budget" in outcome.backend_reason
    assert outcome.kernel.status is Status.CONVERGED


def _refused(tmp_path, data: dict, *arguments: str) -> str:
    path = tmp_path / "amg.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(out), *arguments])
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.exception)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "amg.yaml" in lines[0], result.stderr
    assert not out.exists()
    return lines[0]


def test_a_load_path_with_amg_is_refused(tmp_path):
    data = {**square_case_dict(8), "load_path": {"steps": 3}, "solver": {"backend": "amg"}}
    line = _refused(tmp_path, data)
    assert "solver.backend = amg" in line and "load path" in line


def test_amg_without_pyamg_is_refused(tmp_path, monkeypatch):
    import contactfem.linalg.registry as registry

    monkeypatch.setattr(registry, "iterative_available", lambda name="amg": False)
    line = _refused(tmp_path, {**square_case_dict(8), "solver": {"backend": "amg"}})
    assert "solver.backend = amg" in line and "pyamg" in line


def test_check_names_the_backend_auto_would_take_and_why(tmp_path, monkeypatch):
    """On a machine whose memory holds the square at 64 x 64 with amg but not 4/3 of CHOLMOD's
    estimated peak, ``check`` prints amg and the figures behind the choice."""
    import json

    from test_hostile_input import a_machine_of

    data = square_case_dict(64)
    unknowns = prepare(case_from(data)).n_unknowns
    direct = resolve_backend("auto")
    memory = int(estimate_cost(unknowns, direct)["bytes"] / DIRECT_MEMORY_SHARE) - 1
    assert estimate_cost(unknowns, "amg")["bytes"] < memory
    a_machine_of(monkeypatch, memory)
    path = tmp_path / "amg.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    result = make_runner().invoke(main, ["check", str(path), "--json"])
    assert result.exit_code == 0, result.stderr
    estimate = json.loads(result.stdout)["estimate"]
    assert estimate["backend"] == "amg"
    assert estimate["backend_reason"].startswith(f"auto: a factorisation with {direct} needs about")
    text = make_runner().invoke(main, ["check", str(path)])
    assert text.exit_code == 0 and "backend    amg: auto: a factorisation with" in text.stdout
