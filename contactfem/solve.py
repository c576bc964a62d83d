"""The pipeline: validated case → mesh → assembled system → contact kernel → solution and report.

Nothing here prints or touches files; progress goes through an optional callback and
:func:`write_outputs` is the only function that writes.
"""

from __future__ import annotations

import itertools
import json
import platform
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from contactfem import __version__
from contactfem.assembly import stresses, von_mises
from contactfem.case import Case
from contactfem.discretize import DiscreteProblem, build_mesh, build_problem
from contactfem.errors import SolverError
from contactfem.kernel import Iteration, KernelResult, Status, default_c, solve_contact
from contactfem.linalg import resolve_backend
from contactfem.methods import get_method
from contactfem.report import SCHEMA_VERSION, contact_zone, equilibrium, material_warnings, sign_conditions
from contactfem.sequencing import predict_active_set
from contactfem.result import ContactFields, Solution

Progress = Callable[[str], None]


@dataclass
class Outcome:
    """A solved case: the fields, the kernel's account and the report's figures."""

    case: Case
    problem: DiscreteProblem
    solution: Solution
    kernel: KernelResult
    backend: str
    timings: dict[str, float] = field(default_factory=dict)
    sequencing: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)


def solve_case(
    case: Case,
    *,
    method: str | None = None,
    refine: int | None = None,
    progress: Progress | None = None,
    problem: DiscreteProblem | None = None,
) -> Outcome:
    """Mesh, assemble and solve ``case`` with ``method`` (default: the case's).

    A ``problem`` already assembled for this case (see :func:`prepare`) skips meshing and
    assembly, which is how ``compare`` solves both methods on one system.

    Raises
    ------
    SolverError
        If the kernel does not converge (cycling, iteration cap, inaccurate solves).
    """
    say = progress or (lambda message: None)
    method_name = method or case.solver.method
    contact_method = get_method(method_name)
    backend = resolve_backend(case.solver.backend)
    timings: dict[str, float] = {}
    if problem is None:
        problem = prepare(case, refine=refine, progress=say, timings=timings)

    clock = time.perf_counter()
    say(f"solving with method {contact_method.equation} ({method_name}), backend {backend}")
    reduced = problem.contact_system(contact_method)

    numbers = itertools.count(1)

    def on_iteration(record: Iteration) -> None:
        say(
            f"  Newton {next(numbers)}: {record.active} active (+{record.added} -{record.removed}), "
            f"residuals {record.equilibrium_residual:.1e} / {record.complementarity_residual:.1e}, "
            f"{record.seconds:.2f} s"
        )

    c = case.solver.c if case.solver.c is not None else default_c(reduced.system)
    started = time.perf_counter()
    initial_active, sequencing = predict_active_set(case, problem, c, progress=say)
    if sequencing:
        sequencing["seconds"] = time.perf_counter() - started
    kernel = solve_contact(
        reduced.system,
        c=c,
        initial_active=initial_active,
        tolerance=case.solver.tolerance,
        max_iterations=case.solver.max_iterations,
        backend=backend,
        on_iteration=on_iteration,
    )
    timings["solve"] = time.perf_counter() - clock
    if kernel.status is not Status.CONVERGED:
        raise SolverError(f"{case.source.name}: method {method_name}: {kernel.message}")

    clock = time.perf_counter()
    displacement = reduced.displacement(kernel.displacement)
    mesh = problem.mesh
    stress = stresses(mesh.points, mesh.triangles, displacement, problem.law)
    contact = problem.contact
    normal_displacement = displacement[contact.nodes] @ contact.normal
    solution = Solution(
        method=method_name,
        mesh=mesh,
        displacement=displacement,
        stress=stress,
        von_mises=von_mises(stress),
        contact=ContactFields(
            nodes=contact.nodes,
            edges=contact.edges,
            multiplier=kernel.multiplier,
            nodal_force=kernel.nodal_force,
            normal_displacement=normal_displacement,
            gap=contact.gap,
            active=kernel.active,
        ),
        newton=_history_arrays(kernel.history),
    )
    timings["postprocess"] = time.perf_counter() - clock
    outcome = Outcome(case=case, problem=problem, solution=solution, kernel=kernel, backend=backend,
                      timings=timings, sequencing=sequencing)
    outcome.report = build_report(outcome)
    return outcome


def prepare(
    case: Case,
    *,
    refine: int | None = None,
    progress: Progress | None = None,
    timings: dict[str, float] | None = None,
) -> DiscreteProblem:
    """Mesh and assemble ``case``; ``timings`` receives the seconds of each stage."""
    say = progress or (lambda message: None)
    timings = {} if timings is None else timings
    clock = time.perf_counter()
    say("meshing")
    mesh = build_mesh(case, refine=refine)
    timings["mesh"] = time.perf_counter() - clock
    say(f"  {mesh.n_points} nodes, {mesh.n_triangles} triangles ({timings['mesh']:.2f} s)")
    clock = time.perf_counter()
    say("assembling")
    problem = replace(build_problem(case, mesh), refinements=case.mesh.refine if refine is None else refine)
    timings["assemble"] = time.perf_counter() - clock
    say(f"  {problem.n_unknowns} unknowns, {len(problem.contact.nodes)} contact nodes ({timings['assemble']:.2f} s)")
    return problem


def build_report(outcome: Outcome) -> dict:
    """The report.json content: deterministic but for the timings and the machine."""
    case, problem, solution, kernel = outcome.case, outcome.problem, outcome.solution, outcome.kernel
    mesh = problem.mesh
    contact = solution.contact
    method = get_method(solution.method)
    diameters = mesh.triangle_diameters()
    material = case.material
    return {
        "schema_version": SCHEMA_VERSION,
        "contactfem_version": __version__,
        "case": {"file": str(case.source), "title": case.title, "sha256": case.digest},
        "method": {"name": method.name, "equation": method.equation,
                   "multiplier": method.multiplier_symbol, "summary": method.summary},
        "material": {"E": material.young, "nu": material.poisson, "lambda": material.lame_lambda,
                     "mu": material.lame_mu, "plane": material.plane},
        "mesh": {
            "nodes": mesh.n_points,
            "triangles": mesh.n_triangles,
            "h_min": float(diameters.min()),
            "h_max": float(diameters.max()),
            "contact_nodes": int(len(contact.nodes)),
            "contact_edges": int(len(contact.edges)),
        },
        "unknowns": {"displacement": problem.n_unknowns, "multiplier": int(len(contact.nodes))},
        "solver": {
            "backend": outcome.backend,
            "status": kernel.status.value,
            "message": kernel.message,
            "iterations": kernel.iterations,
            "c": kernel.c,
            "tolerance": case.solver.tolerance,
            "cycle_detected_at": kernel.cycle_detected_at,
            "factorizations": kernel.factorizations,
            "column_solves": kernel.column_solves,
            "sequencing": outcome.sequencing,
        },
        "newton": [
            {"iteration": i + 1, **{k: getattr(r, k) for k in
                                    ("active", "added", "removed", "equilibrium_residual",
                                     "complementarity_residual", "seconds")}}
            for i, r in enumerate(kernel.history)
        ],
        "sign_conditions": sign_conditions(
            solution.method, contact.gap, contact.normal_displacement, contact.multiplier, contact.nodal_force
        ),
        "contact_zone": contact_zone(problem, contact.active),
        "contact_force": {
            "normal": float(contact.nodal_force.sum()),
            "vector": (-problem.contact.normal * contact.nodal_force.sum()).tolist(),
        },
        "equilibrium": equilibrium(problem, solution.displacement, contact.nodal_force),
        "errors": _exact_errors(case, problem, solution),
        "warnings": material_warnings(case.material),
        "timings": dict(outcome.timings),
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
    }


def _exact_errors(case: Case, problem: DiscreteProblem, solution: Solution) -> dict | None:
    """The six norms of exact − discrete for a case with an exact: block (None otherwise).

    The multiplier is compared with the exact pressure −σ_nn(u_exact) on ΓC. A norm
    that is not finite (a singular exact field hit by a quadrature point) is null.
    """
    if case.exact is None:
        return None
    from contactfem.norms import exact_errors

    errors = exact_errors(solution, problem, case.exact.solution)
    return {name: (float(value) if np.isfinite(value) else None) for name, value in errors.items()}


def write_outputs(outcome: Outcome, directory: Path, files: tuple[str, ...] | None = None,
                  progress: Progress | None = None) -> list[Path]:
    """Write the requested files (vtu, h5, json) into ``directory``, each atomically.

    report.json is written last so that its timings include the other writers.
    """
    from contactfem.io import atomic_write_text, write_hdf5, write_vtu
    from contactfem.io.atomic import ensure_directory

    say = progress or (lambda message: None)
    files = files or outcome.case.output.files
    clock = time.perf_counter()
    ensure_directory(directory)
    written: list[Path] = []
    if "vtu" in files:
        say("writing VTU")
        written += write_vtu(outcome.solution, directory)
    if "h5" in files:
        say("writing HDF5")
        written.append(write_hdf5(
            outcome.solution, Path(directory) / "solution.h5",
            case_text=outcome.case.text, case_hash=outcome.case.digest,
            attributes={"contactfem_version": __version__, "plane": outcome.case.material.plane,
                        "backend": outcome.backend},
        ))
    if "xdmf" in files:
        from contactfem.io.xdmf import write_xdmf  # solution.xdmf for ParaView, beside solution.h5

        say("writing XDMF")
        written += write_xdmf(outcome.solution, directory)
    outcome.timings["write"] = time.perf_counter() - clock
    outcome.report["timings"] = dict(outcome.timings)
    if "json" in files:
        written.append(atomic_write_text(Path(directory) / "report.json", to_json(outcome.report)))
    return written


def to_json(report: dict) -> str:
    return json.dumps(report, indent=2, sort_keys=True, allow_nan=False) + "\n"


def _history_arrays(history: list[Iteration]) -> dict[str, np.ndarray]:
    names = ("active", "added", "removed", "equilibrium_residual", "complementarity_residual", "seconds")
    return {name: np.array([getattr(r, name) for r in history]) for name in names}
