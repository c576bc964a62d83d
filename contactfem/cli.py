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
      contactfem compare cases/square.yaml
      contactfem converge cases/square.yaml --levels 4
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
        "parts": {p.name: p.label for p in case.parts},
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
        click.echo(f"  boundary   {part.name}: {part.label}")
    click.echo(f"  mesh       {mesh.n_points} nodes, {mesh.n_triangles} triangles, h in "
               f"[{diameters.min():.3g}, {diameters.max():.3g}]")
    click.echo(f"  unknowns   {problem.n_unknowns} displacement, {len(problem.contact.nodes)} contact nodes")
    n = case.obstacle.normal
    click.echo(f"  obstacle   through {list(case.obstacle.point)}, normal ({n[0]:g}, {n[1]:g})")


@main.command()
@case_argument
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Where compare.json and compare.png go. Default: <output.directory>-compare.")
@refine_option
@quiet_option
@json_option
def compare(case_file: Path, out_dir: Path | None, refine: int | None, quiet: bool, as_json: bool) -> None:
    """Solve CASE with both methods on one mesh and show how they differ.

    Prints the displacement difference, max |λ − D⁻¹Mθ|, the negative θ nodes, the
    oscillation of θ where the body lifts off, the sign conditions and the cost, and
    writes compare.json and compare.png (λh, θh and the gap along ΓC).

    \b
    Example:
      contactfem compare cases/square.yaml --refine 1
    """
    from contactfem.case import load_case
    from contactfem.io import atomic_write_text
    from contactfem.io.atomic import ensure_directory
    from contactfem.plots import plot_contact_profiles
    from contactfem.solve import to_json
    from contactfem.studies import compare_methods

    try:
        case = load_case(case_file)
        figures, outcomes = compare_methods(case, refine=refine, progress=_progress(quiet))
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-compare")
        ensure_directory(directory)
        atomic_write_text(directory / "compare.json", to_json(figures))
        plot_contact_profiles(directory / "compare.png", outcomes)
    except ContactFemError as error:
        _fail(error)
        return
    if as_json:
        click.echo(to_json(figures), nl=False)
        return
    if quiet:
        return
    rows = [("", "positive (4)", "standard (5)")]
    methods = figures["methods"]
    for label, key in (("Newton iterations", "iterations"), ("solve seconds", "solve_seconds"),
                       ("contact force", "contact_force")):
        rows.append((label, *(f"{methods[m][key]:.6g}" for m in ("positive", "standard"))))
    rows.append(("min multiplier", *(f"{methods[m]['sign_conditions']['min_multiplier']:.4g}"
                                     for m in ("positive", "standard"))))
    rows.append(("active nodes", *(str(methods[m]["contact_zone"]["active_nodes"]) for m in ("positive", "standard"))))
    width = max(len(r[0]) for r in rows)
    click.echo(f"{case.title}: {figures['mesh']['unknowns']} unknowns, {figures['mesh']['contact_nodes']} contact nodes")
    for row in rows:
        click.echo(f"  {row[0]:<{width}}  {row[1]:>14}  {row[2]:>14}")
    click.echo(f"  max |u - w| / max |u|        {figures['relative_displacement_difference']:.2e}")
    click.echo(f"  max |λ - D⁻¹Mθ| / max |λ|    {figures['relative_lambda_minus_pi_theta']:.2e}")
    click.echo(f"  negative θ nodes             {figures['negative_theta_nodes']} (min θ {figures['min_theta']:.4g})")
    click.echo(f"  total variation in lift-off  θ {figures['theta_total_variation_in_lift_off']:.4g}, "
               f"λ {figures['lambda_total_variation_in_lift_off']:.4g}")
    click.echo(f"  wrote {directory / 'compare.json'}, {directory / 'compare.png'}")


@main.command()
@case_argument
@click.option("--levels", type=click.IntRange(2, 10), default=4, show_default=True,
              help="Number of nested meshes: the case's mesh refined 0 … levels−1 times.")
@click.option("--extra", type=click.IntRange(1, 4), default=1, show_default=True,
              help="Refinements beyond the last level for the reference, when the case has no exact solution.")
@click.option("--method", "methods", type=click.Choice(["positive", "standard"]), multiple=True,
              help="Method(s) to study; default both.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Where convergence.json/.csv and the PNGs go. Default: <output.directory>-convergence.")
@quiet_option
@json_option
def converge(case_file: Path, levels: int, extra: int, methods: tuple[str, ...], out_dir: Path | None,
             quiet: bool, as_json: bool) -> None:
    """Convergence and cost study of CASE on nested meshes, both methods.

    For each level: h, unknowns, seconds per stage, Newton iterations, every error norm
    and the observed rate between levels; writes convergence.json, convergence.csv and
    PNGs of error against h (with the h^1 slope of the a priori estimate) and against time.

    \b
    Example:
      contactfem converge cases/square.yaml --levels 4
    """
    from contactfem.case import load_case
    from contactfem.io import atomic_write_text
    from contactfem.io.atomic import ensure_directory
    from contactfem.plots import plot_convergence
    from contactfem.solve import to_json
    from contactfem.studies import METHOD_NAMES, convergence_study

    try:
        case = load_case(case_file)
        study = convergence_study(case, levels, extra=extra, methods=methods or METHOD_NAMES,
                                  progress=_progress(quiet))
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-convergence")
        ensure_directory(directory)
        atomic_write_text(directory / "convergence.json", to_json(study))
        atomic_write_text(directory / "convergence.csv", _csv(study["rows"]))
        plot_convergence(directory, study)
    except ContactFemError as error:
        _fail(error)
        return
    if as_json:
        click.echo(to_json(study), nl=False)
        return
    if quiet:
        return
    click.echo(f"{case.title} — reference: {study['reference']}")
    short = {"displacement_l2": "u L2", "displacement_h1": "u H1", "displacement_energy": "energy",
             "multiplier_l2": "mult L2", "multiplier_h_minus_half": "mult H-1/2"}
    header = f"  {'method':<9}{'h':>9}{'unknowns':>10}{'Newton':>7}{'seconds':>9}" + "".join(
        f"{short[n]:>21}" for n in short)
    click.echo(header)
    for row in study["rows"]:
        rates = study["rates"][row["method"]]
        index = row["level"] - 1
        cells = []
        for norm in short:
            rate = f"({rates[norm][index]:.2f})" if index >= 0 else ""
            cells.append(f"{row[norm]:.3e} {rate:>6}")
        click.echo(f"  {row['method']:<9}{row['h']:>9.4f}{row['unknowns']:>10}{row['iterations']:>7}"
                   f"{row['total_seconds']:>9.2f}" + "".join(f"{c:>21}" for c in cells))
    click.echo(f"  (observed rates between consecutive levels in parentheses; the paper predicts "
               f"h^(1/2+ν), ν ≤ 1/2, for the H1 and H-1/2 errors)")
    click.echo(f"  wrote {directory}/convergence.json, convergence.csv, convergence_h.png, convergence_time.png")


def _csv(rows: list[dict]) -> str:
    keys = list(rows[0])
    lines = [",".join(keys)]
    lines += [",".join(str(row[k]) for k in keys) for row in rows]
    return "\n".join(lines) + "\n"


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
    errors = report.get("errors")
    if errors:
        shown = ", ".join(f"{name} {errors[key]:.3g}" if errors[key] is not None else f"{name} n/a"
                          for name, key in (("L2", "displacement_l2"), ("energy", "displacement_energy"),
                                            ("multiplier L2", "multiplier_l2")))
        lines.append(f"  exact error  {shown}")
    if written:
        lines.append(f"  wrote        {', '.join(str(p) for p in written)}")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
