"""The ``contactfem`` command line: the only place that prints, and that turns errors into exit codes.

Exit codes: 0 success; 1 the solve or the writing failed; 2 bad input (case file, mesh,
command-line options), with a one-line message and no traceback.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from contactfem import __version__
from contactfem.errors import CaseError, ContactFemError, MeshError

EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2


def _fail(error: ContactFemError) -> None:
    code = EXIT_BAD_INPUT if isinstance(error, (CaseError, MeshError)) else EXIT_FAILURE
    click.echo(f"error: {error}", err=True)
    sys.exit(code)


def _progress(quiet: bool):
    """Stage messages on stderr when it is a terminal and --quiet is not given."""
    if quiet or not sys.stderr.isatty():
        return None
    return lambda message: click.echo(message, err=True)


case_argument = click.argument("case_file", metavar="CASE", type=click.Path(dir_okay=False, path_type=Path))
refine_option = click.option("--refine", type=click.IntRange(0, 12), default=None,
                             help="Uniform refinements of the case's mesh (each halves h).")
quiet_option = click.option("--quiet", "-q", is_flag=True, help="Print nothing but errors.")
json_option = click.option("--json", "as_json", is_flag=True, help="Print the report as JSON on stdout.")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="contactfem")
def main() -> None:
    """Frictionless contact of a 2D elastic body on a rigid flat obstacle (P1 mixed methods).

    \b
    Examples:
      contactfem solve cases/square.yaml
      contactfem solve cases/square.yaml --method standard --refine 2 --out results/sq
      contactfem check cases/hertz.yaml
    """


@main.command()
@case_argument
@click.option("--method", type=click.Choice(["positive", "standard"]), default=None,
              help="Contact method: positive = (4), standard = (5). Default: the case's.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Output directory. Default: the case's output.directory.")
@refine_option
@click.option("--backend", type=click.Choice(["auto", "cholmod", "pardiso", "superlu"]), default=None,
              help="Sparse direct solver. Default: the case's (auto = fastest installed).")
@quiet_option
@json_option
def solve(case_file: Path, method: str | None, out_dir: Path | None, refine: int | None,
          backend: str | None, quiet: bool, as_json: bool) -> None:
    """Solve CASE and write solution.vtu/.pvd, solution.h5 and report.json.

    \b
    Examples:
      contactfem solve cases/square.yaml
      contactfem solve cases/square.yaml --method standard --json > report.json
    """
    from contactfem.case import load_case
    from contactfem.solve import solve_case, to_json, write_outputs

    progress = _progress(quiet)
    try:
        case = load_case(case_file)
        if backend is not None:
            case = case.with_solver(backend=backend)
        outcome = solve_case(case, method=method, refine=refine, progress=progress)
        directory = out_dir if out_dir is not None else case.output.directory
        written = write_outputs(outcome, directory, progress=progress)
    except ContactFemError as error:
        _fail(error)
        return
    if as_json:
        click.echo(to_json(outcome.report), nl=False)
    elif not quiet:
        click.echo(_summary(outcome.report, written))


@main.command()
@case_argument
@refine_option
@json_option
def check(case_file: Path, refine: int | None, as_json: bool) -> None:
    """Validate CASE and mesh it, without solving; print what it models.

    \b
    Example:
      contactfem check cases/hole.yaml
    """
    from contactfem.case import load_case
    from contactfem.solve import prepare

    try:
        case = load_case(case_file)
        problem = prepare(case, refine=refine)
    except ContactFemError as error:
        _fail(error)
        return
    mesh = problem.mesh
    diameters = mesh.triangle_diameters()
    summary = {
        "case": str(case_file),
        "title": case.title,
        "material": {"E": case.material.young, "nu": case.material.poisson, "plane": case.material.plane},
        "parts": {p.name: p.kind for p in case.parts},
        "mesh": {"nodes": mesh.n_points, "triangles": mesh.n_triangles,
                 "h_min": float(diameters.min()), "h_max": float(diameters.max())},
        "unknowns": problem.n_unknowns,
        "contact_nodes": int(len(problem.contact.nodes)),
        "obstacle": {"point": list(case.obstacle.point), "normal": list(case.obstacle.normal)},
        "method": case.solver.method,
    }
    if as_json:
        click.echo(json.dumps(summary, indent=2, sort_keys=True))
        return
    click.echo(f"{case_file}: valid — {case.title}")
    click.echo(f"  material   E = {case.material.young:g}, nu = {case.material.poisson:g}, plane {case.material.plane}")
    for part in case.parts:
        click.echo(f"  boundary   {part.name}: {part.kind}")
    click.echo(f"  mesh       {mesh.n_points} nodes, {mesh.n_triangles} triangles, h in "
               f"[{diameters.min():.3g}, {diameters.max():.3g}]")
    click.echo(f"  unknowns   {problem.n_unknowns} displacement, {len(problem.contact.nodes)} contact nodes")
    n = case.obstacle.normal
    click.echo(f"  obstacle   through {list(case.obstacle.point)}, normal ({n[0]:g}, {n[1]:g})")


def _summary(report: dict, written: list[Path]) -> str:
    zone = report["contact_zone"]
    signs = report["sign_conditions"]
    intervals = ", ".join(
        f"[{i['abscissa'][0]:.4g}, {i['abscissa'][1]:.4g}]" for i in zone["intervals"]
    ) or "none"
    timings = report["timings"]
    lines = [
        f"{report['case']['title']} — method {report['method']['equation']} {report['method']['name']}",
        f"  mesh         {report['mesh']['nodes']} nodes, {report['mesh']['triangles']} triangles, "
        f"{report['unknowns']['displacement']} unknowns",
        f"  Newton       {report['solver']['iterations']} iterations ({report['solver']['backend']})",
        f"  contact      {zone['active_nodes']} of {zone['contact_nodes']} nodes active; zone along ΓC: {intervals}",
        f"  force        {report['contact_force']['normal']:.6g} (normal, total)",
        f"  signs        min multiplier {signs['min_multiplier']:.3g}, "
        f"max u_n - g {signs['max_normal_displacement_minus_gap']:.3g}",
        f"  equilibrium  relative residual {report['equilibrium']['relative_force_residual']:.1e}",
        "  time         " + ", ".join(f"{k} {v:.2f} s" for k, v in timings.items()),
    ]
    if written:
        lines.append(f"  wrote        {', '.join(str(p) for p in written)}")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
