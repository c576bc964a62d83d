"""The petsc backend on 2 MPI ranks agrees with the serial solve: displacements and multipliers
to 1e-8 relative, the same active set, on the square and the plate with a hole, both methods,
and on punches pressed into the block over their whole face (the flat punch, which starts
from its overlap, and a tilted one that releases half of it, which then asks the coarse
levels solved across the ranks for its second guess). Platens (force and displacement), a
body held by contact alone and a 10-step load path agree to 1e-10, the path also through
the solve command. Refined cases, each rank refining only its piece of the coarse mesh (a
square, a graded quarter disk, a flat punch), agree to 1e-10 as well.

Skipped unless petsc4py and mpi4py import and an ``mpiexec`` is on the PATH (see README:
the petsc extra needs PETSc itself, e.g. Debian's petsc-dev, and PETSC_DIR to build).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from contactfem.case import load_case
from contactfem.solve import solve_case

CASES = Path(__file__).resolve().parent.parent / "cases"
RANKS = 2
AGREEMENT = 1e-8
SOLVES = [(name, method) for name in ("square", "hole") for method in ("positive", "standard")] + [
    ("flat_punch", "positive"), ("tilted_punch", "standard"), ("strip", "positive"),
    ("platen_force", "positive"), ("platen_displacement", "standard"), ("held", "positive"),
    ("square_pieces", "positive"), ("hertz_pieces", "standard"), ("punch_pieces", "positive"),
    ("platen_refined", "positive"), ("hertz_levels_pieces", "positive")]
#: The features the serial path reduces to more unknowns or to rigid motions agree tighter.
TIGHT = 1e-10
#: The Hertz quarter disk of cases/hertz_platen.yaml at one load on a small mesh (2 838
#: unknowns): pressed by the platen's force (its advance an unknown, nothing but contact
#: holding the body vertically), by its prescribed advance, and, without the platen, by a
#: traction on its top (held by contact alone, no platen).
SMALL_HERTZ = {"mesh": {"size": 0.1, "contact_size": 0.01, "grading": 0.2}}
VARIANTS = {"platen_force": ("hertz_platen", {}),
            "platen_displacement": ("hertz_platen", {"boundary": {"top": {"platen": {"displacement": 0.008}},
                                                                   "axis": "symmetry", "rim": "contact"}}),
            "held": ("hertz_quarter", {"boundary": {"top": {"traction": [0, -1.8e3]}, "axis": "symmetry",
                                                    "rim": "contact"}})}
#: The tilted punch: cases/flat_punch.yaml pressed in everywhere (4e-3 at x = 1.05, 2e-4 at
#: x = −1.05) on a mesh fine enough (15 000 unknowns) for a coarse level to pay: its coarser
#: level keeps 13% of the unknowns (on a mesh of size 0.5 graded from 0.02 at 0.15 the coarse
#: level kept 39% of 7 800, and the cost model refuses it; the solve is 10% faster without).
TILTED_PUNCH = {"obstacle": {"segment": [[1.05, -4e-3], [-1.05, -2e-4]]},
                "mesh": {"size": 0.25, "contact_size": 0.01, "grading": 0.3}}

#: Refined once: each rank refines only its piece of the coarse mesh (a structured square; the
#: graded quarter disk with its symmetry axis, prescribed top and curved rim; the flat punch)
#: and agrees with the serial solve to 1e-10; a platen keeps the replicated mesh, and agrees too.
PIECES = {"square_pieces": ("square", {"mesh": {"divisions": 16, "diagonal": "right", "refine": 1}}),
          "hertz_pieces": ("hertz_quarter", {"mesh": {**SMALL_HERTZ["mesh"], "refine": 1}}),
          "punch_pieces": ("flat_punch", {"mesh": {"size": 1.0, "contact_size": 0.08, "grading": 0.15, "refine": 1}}),
          "platen_refined": ("hertz_platen", {"mesh": {**SMALL_HERTZ["mesh"], "refine": 1}}),
          # Refined 3 times (35 000 unknowns): its coarser sequencing level (refined once) is in pieces too.
          "hertz_levels_pieces": ("hertz_quarter", {"mesh": {"size": 0.2, "contact_size": 0.03, "grading": 0.3,
                                                             "refine": 3}})}

_have_petsc = all(importlib.util.find_spec(name) is not None for name in ("petsc4py", "mpi4py"))
_mpiexec = shutil.which("mpiexec")
needs_mpi = pytest.mark.skipif(not (_have_petsc and _mpiexec),
                                reason="petsc4py, mpi4py or mpiexec not available (pip install 'contactfem[petsc]')")

# Rank 0 stores each distributed solve's fields; the comparison runs in the test process.
SCRIPT = """
import sys
import numpy as np
from contactfem.case import load_case
from contactfem.distributed import distributed_report, solve_distributed
from contactfem.distributed_mumps import mumps_ordering
from petsc4py import PETSc

out = sys.argv[1]
fields = {}
for name, path, method in [item.split(":") for item in sys.argv[2:]]:
    case = load_case(path)
    outcome = solve_distributed(case, method=method)
    if outcome.result is not None:
        solution = outcome.result.solution
        report = distributed_report(case, outcome)
        key = f"{name}_{method}"
        fields[key + "_u"] = solution.displacement
        fields[key + "_mu"] = solution.contact.multiplier
        fields[key + "_force"] = solution.contact.nodal_force
        fields[key + "_active"] = solution.contact.active
        fields[key + "_ranks"] = np.array(report["parallel"]["ranks"])
        fields[key + "_mesh"] = np.array(report["parallel"]["mesh"])
        fields[key + "_rss"] = np.array([r["peak_rss_bytes"] for r in report["parallel"]["per_rank"]])
        fields[key + "_residual"] = np.array(report["equilibrium"]["relative_force_residual"])
        fields[key + "_status"] = np.array(report["solver"]["status"])
        fields[key + "_first_active"] = np.array(report["newton"][0]["active"])
        fields[key + "_levels"] = np.array(report["solver"]["sequencing"].get("levels", 0))
        fields[key + "_proposed"] = np.array([step["proposed"] for step in report["newton"]])
        fields[key + "_ordering"] = np.array([r["factor"].get("ordering", -1) for r in report["parallel"]["per_rank"]])
        fields[key + "_chosen_ordering"] = np.array(mumps_ordering(PETSc))
if fields:
    np.savez(out, **fields)
"""


def _mpi_environment() -> dict[str, str]:
    """Open MPI refuses root and more ranks than cores unless told; other MPIs ignore these."""
    env = dict(os.environ)
    env.update({"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                "OMPI_MCA_rmaps_base_oversubscribe": "1", "OMP_NUM_THREADS": "1"})
    return env


@pytest.fixture(scope="module")
def case_files(tmp_path_factory) -> dict[str, Path]:
    """Each solve's case file: the shipped ones, and the tilted punch written beside them."""
    import yaml

    directory = tmp_path_factory.mktemp("cases")
    written = {}
    for name, (base, changes) in {"tilted_punch": ("flat_punch", TILTED_PUNCH), **VARIANTS}.items():
        data = yaml.safe_load((CASES / f"{base}.yaml").read_text(encoding="utf-8"))
        data.pop("load_path", None)
        data.update(changes if name == "tilted_punch" else {**SMALL_HERTZ, **changes})
        written[name] = directory / f"{name}.yaml"
        written[name].write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    for name, (base, changes) in PIECES.items():
        data = yaml.safe_load((CASES / f"{base}.yaml").read_text(encoding="utf-8"))
        data.pop("load_path", None)
        data.update(changes)
        written[name] = directory / f"{name}.yaml"
        written[name].write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return {name: written.get(name, CASES / f"{name}.yaml") for name, _ in SOLVES}


@pytest.fixture(scope="module")
def distributed(tmp_path_factory, case_files) -> dict[str, np.ndarray]:
    directory = tmp_path_factory.mktemp("distributed")
    script = directory / "solve.py"
    script.write_text(f"CASES = {str(CASES)!r}\n" + SCRIPT)
    out = directory / "fields.npz"
    command = [_mpiexec, "-n", str(RANKS), sys.executable, str(script), str(out),
               *(f"{name}:{case_files[name]}:{method}" for name, method in SOLVES)]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    with np.load(out) as data:
        return dict(data)


@needs_mpi
@pytest.mark.parametrize("name, method", SOLVES)
def test_two_ranks_agree_with_the_serial_solve(distributed, case_files, name, method):
    case = load_case(case_files[name])
    solved = solve_case(case, method=method)
    serial = solved.solution
    key = f"{name}_{method}"
    if name in ("flat_punch", "tilted_punch"):  # both start from the whole face pressed in
        assert solved.kernel.history[0].active == int(distributed[key + "_first_active"]) == len(serial.contact.active)
    if name == "hertz_levels_pieces":  # the coarse level predicted the start, on both sides
        assert solved.sequencing["levels"] >= 1 and int(distributed[key + "_levels"]) >= 1
    if name == "tilted_punch":  # which releases half of it: the coarse levels give the second guess
        assert solved.sequencing["levels"] >= 1 and int(distributed[key + "_levels"]) >= 1
    if name == "strip":  # peeling off in bending: its creep is extrapolated alike on every rank
        steps = [step.proposed for step in solved.kernel.history]
        assert sum(steps) > 0 and distributed[key + "_proposed"].tolist() == steps
    assert int(distributed[key + "_ranks"]) == RANKS
    assert str(distributed[key + "_status"]) == "converged"
    if name in VARIANTS:  # the platen's advance, or the rigid motion contact alone holds
        assert bool(solved.problem.platens) == name.startswith("platen")
        assert (solved.problem.free_modes is not None) == (name != "platen_displacement")
    # Each rank refines only its piece when the case is refined and held by its supports.
    assert str(distributed[key + "_mesh"]) == ("pieces" if name.endswith("_pieces") else "replicated")
    agreement = TIGHT if name in VARIANTS or name in PIECES else AGREEMENT
    np.testing.assert_array_equal(distributed[key + "_active"], serial.contact.active)
    u = distributed[key + "_u"]
    assert np.abs(u - serial.displacement).max() <= agreement * np.abs(serial.displacement).max()
    for field, reference in (("_mu", serial.contact.multiplier), ("_force", serial.contact.nodal_force)):
        assert np.abs(distributed[key + field] - reference).max() <= agreement * np.abs(reference).max()
    # report.json's figures come from K u computed across the ranks: the balance still closes.
    assert float(distributed[key + "_residual"]) < 1e-10
    assert len(distributed[key + "_rss"]) == RANKS and (distributed[key + "_rss"] > 0).all()
    # MUMPS used, on every rank, the ordering contactfem asked its library for (or, when the
    # library has neither METIS nor SCOTCH, one of its own choice, the same on every rank).
    chosen, used = int(distributed[key + "_chosen_ordering"]), distributed[key + "_ordering"].tolist()
    assert used == [chosen] * RANKS if chosen != 7 else used == [used[0]] * RANKS and used[0] in (0, 2, 4, 6)


@needs_mpi
def test_mumps_orders_with_the_best_ordering_its_library_has():
    """METIS (ICNTL(7) = 5), else SCOTCH (3), else MUMPS's automatic choice (7): asked of the
    library, not timed. An ordering the library lacks falls back to the automatic choice, so
    the one chosen is the first whose analysis reports using it, and every ordering before it
    in the preference reports another; PORD (4), built into every MUMPS, reports itself."""
    from petsc4py import PETSc

    from contactfem.distributed_mumps import MUMPS_AUTOMATIC, MUMPS_ORDERINGS, _mumps_used, mumps_ordering

    assert _mumps_used(PETSc, 4) == 4
    chosen = mumps_ordering(PETSc)
    preference = (*MUMPS_ORDERINGS, MUMPS_AUTOMATIC)
    assert chosen in preference
    if chosen != MUMPS_AUTOMATIC:
        assert _mumps_used(PETSc, chosen) == chosen
    for better in preference[:preference.index(chosen)]:
        assert _mumps_used(PETSc, better) != better
    assert not PETSc.Options().hasName("contactfem_ordering_probe_mat_mumps_icntl_7")  # the probe leaves nothing


def test_module_imports_and_refuses_clearly_without_petsc(monkeypatch):
    """Without petsc4py the module still imports; the solve says what to install, in one line."""
    import builtins

    from contactfem import distributed as module
    from contactfem.errors import SolverError

    real_import = builtins.__import__

    def no_petsc(name, *args, **kwargs):
        if name.split(".")[0] in ("petsc4py", "mpi4py"):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_petsc)
    with pytest.raises(SolverError, match="petsc4py") as error:
        module.solve_distributed(load_case(CASES / "square.yaml"))
    assert "\n" not in str(error.value)


@needs_mpi
def test_the_solve_command_under_mpiexec(tmp_path):
    """`mpiexec -n 2 contactfem solve CASE --backend petsc`: rank 0 alone writes the usual files
    and report.json records the ranks; a second run into the same result is refused on every
    rank, in one line, with exit code 2."""
    import json

    out = tmp_path / "out"
    command = [_mpiexec, "-n", str(RANKS), sys.executable, "-m", "contactfem.cli", "solve", str(CASES / "hole.yaml"),
               "--backend", "petsc", "--out", str(out), "--quiet"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert report["parallel"]["ranks"] == RANKS and report["solver"]["status"] == "converged"
    assert {"solution.vtu", "solution.h5", "contact.csv"} <= {p.name for p in out.iterdir()}
    again = subprocess.run(command, capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert again.returncode == 2
    errors = [line for line in again.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "--overwrite" in errors[0], again.stderr


def test_other_commands_refuse_the_petsc_backend(tmp_path):
    from click.testing import CliRunner

    from contactfem.cli import main

    case = tmp_path / "square.yaml"
    case.write_text((CASES / "square.yaml").read_text(encoding="utf-8").replace(
        "solver:\n", "solver:\n  backend: petsc\n"), encoding="utf-8")
    result = CliRunner().invoke(main, ["compare", str(case), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    assert "solver.backend = petsc" in result.output and not (tmp_path / "out").exists()


@needs_mpi
def test_the_solve_command_runs_a_load_path_under_mpiexec(tmp_path):
    """A load path under `mpiexec -n 2 contactfem solve CASE --backend petsc` (it was refused):
    rank 0 writes each step as it is solved, and report.json has the path and the ranks."""
    import json

    import yaml

    data = yaml.safe_load((CASES / "hertz_platen.yaml").read_text(encoding="utf-8"))
    data.update(SMALL_HERTZ)
    data["load_path"] = {"steps": 3}
    case_file = tmp_path / "hertz_platen.yaml"
    case_file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    command = [_mpiexec, "-n", str(RANKS), sys.executable, "-m", "contactfem.cli", "solve", str(case_file),
               "--backend", "petsc", "--out", str(out), "--quiet"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert report["parallel"]["ranks"] == RANKS and report["solver"]["status"] == "converged"
    assert len(report["load_path"]["steps"]) == 3
    assert report["platens"]["top"]["force"] == pytest.approx(2000, rel=1e-10)
    assert {"path.h5", "path.csv", "path.pvd", "path-3.vtu", "report.json"} <= {p.name for p in out.iterdir()}

PATH_SCRIPT = """
import sys
import numpy as np
from contactfem.case import load_case
from contactfem.distributed_path import solve_distributed_path

out, path, solver = sys.argv[1:4]
outcome = solve_distributed_path(load_case(path), solver=solver)
if outcome.result is not None:
    steps = outcome.result.steps
    np.savez(out, u=np.stack([s.solution.displacement for s in steps]),
             mu=np.stack([s.solution.contact.multiplier for s in steps]),
             active=np.stack([s.solution.contact.active for s in steps]),
             status=np.array([s.kernel.status.value for s in steps]),
             factorizations=np.array(outcome.result.factorizations),
             iterations=np.array(sum(s.kernel.iterations for s in steps)))
"""


@needs_mpi
@pytest.mark.parametrize("solver", ["mumps", "gamg"])
def test_a_load_path_on_two_ranks_agrees_with_the_serial_path(tmp_path, case_files, solver):
    """cases/hertz_platen.yaml's 10 steps of platen force on a small mesh: every step's
    displacement and multiplier agree with the serial path to 1e-10, with the same active
    sets; one distributed solver carries over the steps, and a step that starts from the
    set factorised last (the one the step before settled on) keeps its factorisation."""
    from contactfem.solve import solve_load_path

    import yaml

    data = yaml.safe_load((CASES / "hertz_platen.yaml").read_text(encoding="utf-8"))
    data.update(SMALL_HERTZ)
    case_file = tmp_path / "hertz_platen.yaml"
    case_file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    script, out = tmp_path / "path.py", tmp_path / "path.npz"
    script.write_text(PATH_SCRIPT)
    run = subprocess.run([_mpiexec, "-n", str(RANKS), sys.executable, str(script), str(out), str(case_file), solver],
                         capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    serial = solve_load_path(load_case(case_file)).steps
    with np.load(out) as distributed:
        assert len(serial) == len(distributed["u"]) == 10
        assert (distributed["status"] == "converged").all()
        # Fewer factorisations than Newton steps: the steps that start from the last set reuse it.
        assert int(distributed["factorizations"]) < int(distributed["iterations"])
        for index, step in enumerate(serial):
            np.testing.assert_array_equal(distributed["active"][index], step.solution.contact.active)
            u, mu = step.solution.displacement, step.solution.contact.multiplier
            assert np.abs(distributed["u"][index] - u).max() <= TIGHT * np.abs(u).max()
            assert np.abs(distributed["mu"][index] - mu).max() <= TIGHT * np.abs(mu).max()


@needs_mpi
def test_a_mesh_too_large_for_the_ranks_is_refused_per_rank(tmp_path):
    """The size guard estimates each rank's share when each refines its piece: the square at
    --refine 8 (134M unknowns, about 155 GiB on each of 2 ranks) is refused on every rank,
    in one line naming the ranks, with exit 2 and nothing written."""
    out = tmp_path / "out"
    command = [_mpiexec, "-n", str(RANKS), sys.executable, "-m", "contactfem.cli", "solve", str(CASES / "square.yaml"),
               "--backend", "petsc", "--refine", "8", "--out", str(out), "--quiet"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode == 2, run.stdout[-2000:] + run.stderr[-4000:]
    errors = [line for line in run.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and f"on each of {RANKS} ranks" in errors[0], run.stderr
    assert not out.exists()


def _block(obstacle: dict, divisions: tuple[int, int], refine: int = 0) -> dict:
    """A 2 x 0.5 block, bottom clamped, top the contact part, under a rigid indenter."""
    mesh = {"divisions": list(divisions), **({"refine": refine} if refine else {})}
    return {"title": "block under an indenter", "geometry": {"rectangle": {"lower": [-1, -0.5], "upper": [1, 0]}},
            "mesh": mesh, "material": {"E": 1.0e6, "nu": 0.3},
            "boundary": {"bottom": "clamped", "left": "free", "right": "free", "top": "contact"},
            "obstacle": obstacle}


#: Rigid indenters (2 210 unknowns each): a circle pressed 0.02 by its prescribed advance
#: (every contact node its own normal in the ranks' frames, the supports shifted by the
#: advance), on the replicated mesh and refined once in pieces; a wedge (a polyline with a
#: corner at its tip) in place, and moved down 0.01 in pieces.
_CIRCLE = {"circle": {"center": [0, 0.5], "radius": 0.5}, "motion": {"direction": [0, -1], "displacement": 0.02}}
_WEDGE = [[0.6, 0.05], [0.013, -0.02], [-0.6, 0.05]]  # its tip between two nodes
INDENTERS = {"circle_pressed": _block(_CIRCLE, (64, 16)),
             "circle_pieces": _block(_CIRCLE, (32, 8), refine=1),
             "wedge": _block({"polyline": _WEDGE}, (64, 16)),
             "wedge_moved_pieces": _block({"polyline": [[x, y + 0.002] for x, y in _WEDGE],
                                           "motion": {"direction": [0, -1], "displacement": 0.01}}, (32, 8),
                                          refine=1)}


#: The circle pushed by a force instead, and what rank 0 adds to the fields: its advance and reaction.
PUSHED = dict(INDENTERS["circle_pressed"], obstacle={**_CIRCLE, "motion": {"direction": [0, -1], "force": 2.0e4}})
_REPORT_LINE = """
if fields:
    motion = report["obstacle"]["motion"]
    fields[key + "_motion"] = np.array([motion["advance"], motion["reaction"]])
    np.savez(out, **fields)
"""


@needs_mpi
@pytest.mark.parametrize("method", ["positive", "standard"])
def test_two_ranks_agree_with_the_serial_solve_under_an_indenter(tmp_path, method):
    """Curved and cornered obstacles, still or moved by a prescribed advance, on the replicated
    mesh and in pieces: 2 ranks reproduce the serial solve (the same frames, gaps, shifted
    supports and moved-back field) to 1e-10, and the obstacle's reaction with it."""
    import yaml

    files = {}
    for name, data in INDENTERS.items():
        files[name] = tmp_path / f"{name}.yaml"
        files[name].write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    script = tmp_path / "solve.py"
    script.write_text(SCRIPT)
    out = tmp_path / "fields.npz"
    command = [_mpiexec, "-n", str(RANKS), sys.executable, str(script), str(out),
               *(f"{name}:{path}:{method}" for name, path in files.items())]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    with np.load(out) as distributed:
        for name, path in files.items():
            solved = solve_case(load_case(path), method=method)
            serial, key = solved.solution, f"{name}_{method}"
            assert not solved.problem.contact.flat
            assert (solved.problem.drive is not None) == ("motion" in INDENTERS[name]["obstacle"])
            assert str(distributed[key + "_mesh"]) == ("pieces" if name.endswith("_pieces") else "replicated")
            assert str(distributed[key + "_status"]) == "converged"
            assert serial.contact.active.sum() >= 5
            _assert_same_solution(distributed, key, serial)
            assert float(distributed[key + "_residual"]) < 1e-10


@needs_mpi
@pytest.mark.parametrize("method", ["positive", "standard"])
def test_two_ranks_agree_with_the_serial_solve_under_a_pushed_indenter(tmp_path, method):
    """The circle pushed by a force of 2e4 along −y: its advance is one more unknown, coupled
    to the held components as a platen's nodes are to its advance. 2 ranks reproduce the
    serial solve (field, multiplier, active set) and its advance to 1e-10; the contact
    force holding the obstacle is the force given, to 1e-10."""
    import yaml

    from contactfem.report import build_report

    path = tmp_path / "pushed.yaml"
    path.write_text(yaml.safe_dump(PUSHED, sort_keys=False), encoding="utf-8")
    script = tmp_path / "solve.py"
    script.write_text(SCRIPT + _REPORT_LINE)
    out = tmp_path / "fields.npz"
    run = subprocess.run([_mpiexec, "-n", str(RANKS), sys.executable, str(script), str(out), f"pushed:{path}:{method}"],
                         capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    case = load_case(path)
    solved = solve_case(case, method=method)
    serial, key = solved.solution, f"pushed_{method}"
    motion = build_report(case, solved)["obstacle"]["motion"]
    with np.load(out) as distributed:
        assert str(distributed[key + "_mesh"]) == "replicated" and str(distributed[key + "_status"]) == "converged"
        assert serial.contact.active.sum() >= 5
        _assert_same_solution(distributed, key, serial)
        advance, reaction = distributed[key + "_motion"]
        assert abs(advance - motion["advance"]) <= TIGHT * motion["advance"]
        assert abs(reaction - 2e4) <= TIGHT * 2e4 and abs(motion["reaction"] - 2e4) <= TIGHT * 2e4
        assert float(distributed[key + "_residual"]) < 1e-10


@needs_mpi
@pytest.mark.parametrize("name", ["circle_pressed", "pushed"])
def test_a_load_path_of_an_indenter_on_two_ranks_agrees_with_the_serial_path(tmp_path, name):
    """The circle pressed 0.02, or pushed by 2e4, in 3 steps: a prescribed advance is the
    factor times 0.02 (the shifted supports scale with the other prescribed values), a
    pushed one balances the factor times the force. 2 ranks reproduce every serial step
    (active set, displacement moved back by the advance, multiplier) to 1e-10."""
    import yaml

    from contactfem.solve import solve_load_path

    data = PUSHED if name == "pushed" else INDENTERS[name]
    case_file = tmp_path / f"{name}_path.yaml"
    case_file.write_text(yaml.safe_dump({**data, "load_path": {"steps": 3}}, sort_keys=False), encoding="utf-8")
    script = tmp_path / "path.py"
    script.write_text(PATH_SCRIPT)
    out = tmp_path / "path.npz"
    run = subprocess.run([_mpiexec, "-n", str(RANKS), sys.executable, str(script), str(out), str(case_file), "mumps"],
                         capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    serial = solve_load_path(load_case(case_file)).steps
    advances = [step.problem.drive.advance for step in serial]
    if name == "pushed":  # contact stiffens as the zone grows: less advance per step
        assert 0 < advances[2] - advances[1] < advances[1] - advances[0] < advances[0]
    else:
        assert advances == pytest.approx([0.02 / 3, 0.04 / 3, 0.02], rel=1e-15)
    with np.load(out) as distributed:
        assert len(distributed["u"]) == len(serial) == 3
        assert serial[0].solution.contact.active.sum() < serial[-1].solution.contact.active.sum()
        for index, step in enumerate(serial):
            np.testing.assert_array_equal(distributed["active"][index], step.solution.contact.active)
            u, mu = step.solution.displacement, step.solution.contact.multiplier
            assert np.abs(distributed["u"][index] - u).max() <= TIGHT * np.abs(u).max()
            assert np.abs(distributed["mu"][index] - mu).max() <= TIGHT * np.abs(mu).max()


def _assert_same_solution(distributed, key: str, serial) -> None:
    """The ranks' active set equals the serial one, and their displacement, multiplier and
    nodal contact force agree with it to TIGHT relative to each field's largest entry."""
    np.testing.assert_array_equal(distributed[key + "_active"], serial.contact.active)
    u = distributed[key + "_u"]
    assert np.abs(u - serial.displacement).max() <= TIGHT * np.abs(serial.displacement).max()
    for field, reference in (("_mu", serial.contact.multiplier), ("_force", serial.contact.nodal_force)):
        assert np.abs(distributed[key + field] - reference).max() <= TIGHT * np.abs(reference).max()
