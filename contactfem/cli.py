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
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports it
#: The files of one solve; report.json or solution.h5 mark a directory as holding results.
RESULT_FILES = ("solution.vtu", "contact.vtu", "solution.pvd", "solution.h5", "report.json",
                "solution.xdmf", "solution-xdmf.h5", "deformed.png", "contact_profile.png")


def _fail(error: ContactFemError) -> None:
    code = EXIT_BAD_INPUT if isinstance(error, (CaseError, MeshError)) else EXIT_FAILURE
    click.echo(f"error: {_printable(str(error))}", err=True)
    sys.exit(code)


def _printable(text: str) -> str:
    """Escape control and separator characters a case file may carry into a message
    (a key with a record separator would otherwise split the one-line error)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _interruptible(command):
    """Turn Ctrl-C (SIGINT) into one line on stderr and exit code 130, without a traceback;
    keep numpy's RuntimeWarnings off stderr (errors stay one line).

    Outputs are staged and moved into place together (see io.atomic.staged_directory), so
    an interrupted run leaves the results of an earlier one as they were.
    """
    import functools

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        import warnings

        try:
            # Overflow and 0/0 in numpy are caught by the finiteness checks and refused
            # with one line naming the key; numpy's own warnings would only add noise.
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                return command(*args, **kwargs)
        except KeyboardInterrupt:
            click.echo("error: interrupted (SIGINT); nothing was written, earlier results are unchanged", err=True)
            sys.exit(EXIT_INTERRUPTED)

    return wrapper


def _refuse_existing(directory: Path, markers: tuple[str, ...], overwrite: bool) -> None:
    """Exit 2 if ``directory`` already holds contactfem results and --overwrite is absent."""
    if overwrite:
        return
    found = [name for name in markers if (Path(directory) / name).exists()]
    if found:
        click.echo(f"error: {directory}: already holds contactfem results ({', '.join(found)}); "
                   "pass --overwrite to replace them", err=True)
        sys.exit(EXIT_BAD_INPUT)


def _refuse_non_finite(outcome) -> None:
    """A solve whose fields or report hold NaN/inf is a failure, never an output."""
    import numpy as np

    from contactfem.errors import SolverError
    from contactfem.solve import to_json

    solution, contact = outcome.solution, outcome.solution.contact
    arrays = {"displacement": solution.displacement, "stress": solution.stress, "von_mises": solution.von_mises,
              "multiplier": contact.multiplier, "nodal_force": contact.nodal_force}
    bad = [name for name, values in arrays.items() if not np.isfinite(values).all()]
    try:
        to_json(outcome.report)
    except ValueError:
        bad.append("report")
    if bad:
        raise SolverError(f"{outcome.case.source.name}: the solution is not finite ({', '.join(bad)}): the "
                          "data's scales overflow float64; rescale the units of lengths, moduli and loads")


def _progress(quiet: bool):
    """Stage messages on stderr when it is a terminal and --quiet is not given."""
    if quiet or not sys.stderr.isatty():
        return None
    from contactfem.progress import StageProgress  # rich: one live line per stage

    reporter = StageProgress()
    context = click.get_current_context(silent=True)
    if context is not None:
        context.meta.setdefault("contactfem.progress", []).append(reporter)
        context.call_on_close(reporter.close)
    return reporter


def _end_progress() -> None:
    """Stop the live progress lines before a command prints its summary on stdout."""
    context = click.get_current_context(silent=True)
    for reporter in (context.meta.get("contactfem.progress", []) if context is not None else []):
        reporter.close()


case_argument = click.argument("case_file", metavar="CASE", type=click.Path(dir_okay=False, path_type=Path))
refine_option = click.option("--refine", type=click.IntRange(0, 12), default=None,
                             help="Uniform refinements of the case's mesh (each halves h).")
quiet_option = click.option("--quiet", "-q", is_flag=True, help="Print nothing but errors.")
json_option = click.option("--json", "as_json", is_flag=True, help="Print the report as JSON on stdout.")
overwrite_option = click.option("--overwrite", is_flag=True,
                                help="Replace the results already in the output directory (refused otherwise).")


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
      contactfem plot results/square              # deformed.png, contact_profile.png
      contactfem init my-case.yaml                # a commented starter case
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
@overwrite_option
@click.option("--plot", "make_plot", is_flag=True,
              help="Also write deformed.png and contact_profile.png (as `contactfem plot`).")
@_interruptible
def solve(case_file: Path, method: str | None, out_dir: Path | None, refine: int | None,
          backend: str | None, quiet: bool, as_json: bool, overwrite: bool, make_plot: bool = False) -> None:
    """Solve CASE and write solution.vtu/.pvd, solution.h5 and report.json.

    \b
    Examples:
      contactfem solve cases/square.yaml
      contactfem solve cases/square.yaml --method standard --json > report.json
      contactfem solve cases/square.yaml --overwrite      # replace results/square
      contactfem solve cases/square.yaml --plot           # and deformed.png, contact_profile.png
    """
    from contactfem.case import load_case
    from contactfem.io.atomic import staged_directory
    from contactfem.solve import solve_case, to_json, write_outputs

    progress = _progress(quiet)
    try:
        case = load_case(case_file)
        if backend is not None:
            case = case.with_solver(backend=backend)
        directory = out_dir if out_dir is not None else case.output.directory
        _refuse_existing(directory, ("report.json", "solution.h5"), overwrite)
        outcome = solve_case(case, method=method, refine=refine, progress=progress)
        _refuse_non_finite(outcome)
        # All files of the run are written aside and land together (or not at all).
        with staged_directory(directory, replaces=RESULT_FILES, last="report.json") as staging:
            staged = write_outputs(outcome, staging, progress=progress)
        written = [Path(directory) / path.name for path in staged]
        if make_plot:
            written += _plot_after_solve(directory, outcome, progress)
    except ContactFemError as error:
        _fail(error)
        return
    _end_progress()
    if as_json:
        click.echo(to_json(outcome.report), nl=False)
    elif not quiet:
        click.echo(_summary(outcome.report, written))


@main.command()
@case_argument
@refine_option
@json_option
@click.option("--quiet", "-q", is_flag=True, help="Print nothing; the exit code tells (0 valid, 2 not).")
def check(case_file: Path, refine: int | None, as_json: bool, quiet: bool = False) -> None:
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
        "estimate": _estimate(case, problem),
    }
    if as_json:
        click.echo(json.dumps(summary, indent=2, sort_keys=True))
        return
    if quiet:
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
    cost = summary["estimate"]
    click.echo(f"  estimate   about {cost['seconds']:.2g} s and {cost['bytes'] / 2**30:.2g} GiB with "
               f"{cost['backend']} (measured on 2 cores; ±50%)")


@main.command()
@case_argument
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Where compare.json and compare.png go. Default: <output.directory>-compare.")
@refine_option
@quiet_option
@json_option
@overwrite_option
@_interruptible
def compare(case_file: Path, out_dir: Path | None, refine: int | None, quiet: bool, as_json: bool,
            overwrite: bool) -> None:
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
    from contactfem.io.atomic import staged_directory
    from contactfem.plots import plot_contact_profiles
    from contactfem.solve import to_json
    from contactfem.studies import compare_methods

    try:
        case = load_case(case_file)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-compare")
        _refuse_existing(directory, ("compare.json",), overwrite)
        figures, outcomes = compare_methods(case, refine=refine, progress=_progress(quiet))
        with staged_directory(directory, last="compare.json") as staging:
            atomic_write_text(staging / "compare.json", to_json(figures))
            plot_contact_profiles(staging / "compare.png", outcomes)
            _write_series(staging, "compare", [(name, o.solution) for name, o in outcomes.items()])
    except ContactFemError as error:
        _fail(error)
        return
    _end_progress()
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
    click.echo(f"  wrote {directory / 'compare.json'}, {directory / 'compare.png'}, "
               f"{directory / 'compare.pvd'} (ParaView: one time step per method)")


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
@overwrite_option
@_interruptible
def converge(case_file: Path, levels: int, extra: int, methods: tuple[str, ...], out_dir: Path | None,
             quiet: bool, as_json: bool, overwrite: bool) -> None:
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
    from contactfem.io.atomic import staged_directory
    from contactfem.plots import plot_convergence
    from contactfem.solve import to_json
    from contactfem.studies import METHOD_NAMES, convergence_study

    try:
        case = load_case(case_file)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-convergence")
        _refuse_existing(directory, ("convergence.json",), overwrite)
        kept: list = []  # (label, solution) of every level and method, for convergence-*.pvd
        study = convergence_study(case, levels, extra=extra, methods=methods or METHOD_NAMES,
                                  progress=_progress(quiet),
                                  on_outcome=lambda level, name, o: kept.append((level, name, o.solution)))
        with staged_directory(directory, last="convergence.json") as staging:
            atomic_write_text(staging / "convergence.json", to_json(study))
            atomic_write_text(staging / "convergence.csv", _csv(study["rows"]))
            plot_convergence(staging, study)
            for name in dict.fromkeys(name for _, name, _ in kept):
                _write_series(staging, f"convergence-{name}",
                              [(f"level{level}", s) for level, n, s in kept if n == name])
    except ContactFemError as error:
        _fail(error)
        return
    _end_progress()
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
    click.echo("  (observed rates between consecutive levels in parentheses; the paper predicts "
               "h^(1/2+ν), ν ≤ 1/2, for the H1 and H-1/2 errors)")
    click.echo(f"  wrote {directory}/convergence.json, convergence.csv, convergence_h.png, convergence_time.png, "
               f"convergence-<method>.pvd (ParaView: one time step per level)")


@main.command()
@case_argument
@click.option("--target", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Stop once the estimate η is at most this (energy norm, the case's units).")
@click.option("--max-unknowns", type=click.IntRange(min=1), default=100_000, show_default=True,
              help="Do not solve a mesh with more displacement unknowns than this.")
@click.option("--max-seconds", type=click.FloatRange(min=0, min_open=True), default=600.0, show_default=True,
              help="Stop after the step that passes this many seconds.")
@click.option("--theta", type=click.FloatRange(0, 1, min_open=True), default=0.5, show_default=True,
              help="Dörfler bulk marking: refine a smallest set carrying θ of Σ η_T².")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Output directory. Default: <output.directory>-adapt.")
@quiet_option
@json_option
def adapt(case_file: Path, target: float | None, max_unknowns: int, max_seconds: float, theta: float,
          out_dir: Path | None, quiet: bool, as_json: bool) -> None:
    """Adaptive refinement of CASE with method (4) and its residual error estimator.

    Solve, estimate (Hild–Nicaise residual estimator, see contactfem/estimator.py), mark
    (Dörfler, θ) and refine (newest-vertex bisection) until η ≤ --target or a budget is
    reached. Writes the final solution like `solve` (report.json gains "estimator"),
    estimator.vtu (cell data error_indicator = η_T) and adapt.json (per step: unknowns, η,
    seconds, and the true errors when the case has an exact solution).

    \b
    Examples:
      contactfem adapt cases/square.yaml --max-unknowns 20000
      contactfem adapt cases/manufactured.yaml --target 2e-5 --theta 0.3
    """
    from contactfem.adaptive import adapt as adaptive_loop
    from contactfem.adaptive import write_estimator_vtu
    from contactfem.case import load_case
    from contactfem.io import atomic_write_text
    from contactfem.solve import to_json, write_outputs

    progress = _progress(quiet)
    try:
        case = load_case(case_file)
        run = adaptive_loop(case, theta=theta, target=target, max_unknowns=max_unknowns,
                            max_seconds=max_seconds, progress=progress)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-adapt")
        written = write_outputs(run.outcome, directory, progress=progress)
        written.append(write_estimator_vtu(run.outcome.solution, directory / "estimator.vtu"))
        written.append(atomic_write_text(directory / "adapt.json", to_json(run.history())))
    except ContactFemError as error:
        _fail(error)
        return
    if as_json:
        click.echo(to_json(run.history()), nl=False)
        return
    if quiet:
        return
    click.echo(f"{case.title} — adaptive, method (4), θ = {theta:g}; stopped: {run.stop_reason}")
    click.echo(f"  {'step':>4}{'unknowns':>10}{'eta':>12}{'energy error':>14}{'effectivity':>12}{'seconds':>9}")
    for row in run.steps:
        energy = (row["errors"] or {}).get("displacement_energy")
        cells = (f"{energy:>14.4e}{row['effectivity']:>12.3f}" if energy else f"{'-':>14}{'-':>12}")
        click.echo(f"  {row['step']:>4}{row['unknowns']:>10}{row['eta']:>12.4e}{cells}{row['seconds']:>9.2f}")
    click.echo(f"  wrote {', '.join(str(p) for p in written)}")


def _write_series(directory: Path, stem: str, entries: list) -> list[Path]:
    """compare/converge: every solution as VTU files and one series PVD (io/series.py)."""
    from contactfem.io.series import write_series

    return write_series(directory, stem, entries)


def _plot_after_solve(directory: Path, outcome, progress) -> list[Path]:
    """solve --plot: the pictures of the directory just written (needs solution.h5)."""
    from contactfem.errors import OutputError
    from contactfem.render import make_pictures

    if "h5" not in outcome.case.output.files:
        raise OutputError("--plot reads solution.h5: keep h5 in the case's output.files")
    if progress is not None:
        progress("writing pictures")
    return [Path(p) for p in make_pictures(directory)["files"]]


@main.command()
@click.argument("result_dir", metavar="RESULT_DIR", type=click.Path(file_okay=False, path_type=Path))
@click.option("--size", default="1200x900", show_default=True, metavar="WxH",
              help="Size of each PNG in pixels.")
@click.option("--scale", default="auto", show_default=True, metavar="auto|FACTOR",
              help="Displacement magnification; auto makes the largest displacement 10% of the body's size.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Where the PNGs go. Default: RESULT_DIR.")
@quiet_option
@click.option("--json", "as_json", is_flag=True, help="Print the written files and the factor as JSON.")
@_interruptible
def plot(result_dir: Path, size: str, scale: str, out_dir: Path | None, quiet: bool, as_json: bool) -> None:
    """Draw the result in RESULT_DIR (read from its solution.h5) as two PNGs.

    deformed.png: the deformed mesh coloured by von Mises stress, the magnification
    factor written in the picture, the obstacle's line and the contact zone in red;
    contact_profile.png: the contact pressure and the gap g0 − u_n along ΓC.
    Rendered off-screen (VTK's EGL window): no display is needed.

    \b
    Examples:
      contactfem plot results/square
      contactfem plot results/square --size 1600x1000 --scale 20 --out figures
    """
    from contactfem.render import make_pictures, parse_scale, parse_size

    try:
        pixels = parse_size(size)
        factor = parse_scale(scale)
        progress = _progress(quiet)
        if progress is not None:
            progress("rendering pictures")
        made = make_pictures(result_dir, out_dir, size=pixels, scale=factor)
    except ContactFemError as error:
        _fail(error)
        return
    _end_progress()
    if as_json:
        click.echo(json.dumps(made, indent=2, sort_keys=True))
    elif not quiet:
        click.echo(f"wrote {', '.join(made['files'])} ({made['size'][0]}x{made['size'][1]}, "
                   f"displacement x {made['scale']:.3g})")


@main.command()
@click.argument("path", metavar="[PATH]", required=False, default="case.yaml",
                type=click.Path(dir_okay=False, path_type=Path))
@quiet_option
def init(path: Path, quiet: bool) -> None:
    """Write a commented starter case to PATH (default case.yaml); never overwrites.

    The case (a block pushed onto a rigid floor) passes `contactfem check` as written;
    edit it from there.

    \b
    Examples:
      contactfem init
      contactfem init cases/mine.yaml && contactfem solve cases/mine.yaml --plot
    """
    from contactfem.starter import write_starter_case

    try:
        written = write_starter_case(path)
    except ContactFemError as error:
        _fail(error)
        return
    if not quiet:
        click.echo(f"wrote {written}; next: contactfem check {written}")


def _csv(rows: list[dict]) -> str:
    keys = list(rows[0])
    lines = [",".join(keys)]
    lines += [",".join(str(row[k]) for k in keys) for row in rows]
    return "\n".join(lines) + "\n"


def _estimate(case, problem) -> dict:
    from contactfem.estimate import estimate_cost
    from contactfem.linalg import resolve_backend

    backend = resolve_backend(case.solver.backend)
    return {"backend": backend, **estimate_cost(problem.n_unknowns, backend)}


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
    for warning in report.get("warnings", []):
        lines.append(f"  warning      {warning}")
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
