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
from contactfem.cli.common import (
    _end_progress,
    _files_of,
    _load,
    _progress,
    _write_series,
    _write_solution,
)
from contactfem.cli.exits import (  # noqa: F401 - the exit codes and _interruptible are imported from here
    EXIT_BAD_INPUT,
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    _exit_code,
    _fail,
    _interruptible,
    _OneLineErrors,
    _printable,
)
from contactfem.cli.options import (
    _CheckedPath,
    _FiniteFloatRange,
    case_argument,
    json_option,
    overwrite_option,
    quiet_option,
    refine_option,
)
from contactfem.errors import CaseError, ContactFemError
from contactfem.heap import keep_freed_memory
from contactfem.io.registry import (
    ADAPT_JSON,
    COMPARE_JSON,
    COMPARE_PNG,
    CONVERGENCE_CSV,
    CONVERGENCE_JSON,
    CONVERGENCE_PNGS,
    REPORT_JSON,
    RESULT_FILES,
    RESULT_MARKERS,
    to_json,
)
from contactfem.linalg import BACKEND_CHOICES, DISTRIBUTED_BACKENDS
from contactfem.methods import METHOD_NAMES


@click.group(cls=_OneLineErrors, context_settings={"help_option_names": ["-h", "--help"]})
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
      contactfem sweep cases/sweeps/square.yaml   # many solves in parallel (Dask): sweep.csv/.json/.png
    """


@main.command()
@case_argument
@click.option("--method", type=click.Choice(METHOD_NAMES), default=None,
              help="Contact method: positive = (4), standard = (5). Default: the case's.")
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Output directory. Default: the case's output.directory.")
@refine_option
@click.option("--backend", type=click.Choice(BACKEND_CHOICES), default=None,
              help="Sparse direct solver. Default: the case's (auto = fastest installed).")
@quiet_option
@json_option
@overwrite_option
@click.option("--plot", "make_plot", is_flag=True,
              help="Also write deformed.png and contact_profile.png (as `contactfem plot`).")
@click.option("--petsc-solver", type=click.Choice(("mumps", "gamg")), default="mumps", show_default=True,
              help="With --backend petsc (under mpiexec): MUMPS, distributed direct, or CG with GAMG "
                   "(the least memory per rank).")
@_interruptible
def solve(case_file: Path, method: str | None, out_dir: Path | None, refine: int | None,
          backend: str | None, quiet: bool, as_json: bool, overwrite: bool, make_plot: bool = False,
          petsc_solver: str = "mumps") -> None:
    """Solve CASE and write solution.vtu/.pvd, solution.h5 and report.json.

    \b
    Examples:
      contactfem solve cases/square.yaml
      contactfem solve cases/square.yaml --method standard --json > report.json
      contactfem solve cases/square.yaml --overwrite      # replace results/square
      contactfem solve cases/square.yaml --plot           # and deformed.png, contact_profile.png
      mpiexec -n 4 contactfem solve cases/square.yaml --backend petsc   # across 4 MPI ranks
    """
    from contactfem.io.atomic import claimed_directory
    from contactfem.io.path import PathWriter
    from contactfem.io.registry import PATH_PNG
    from contactfem.plots import plot_load_path
    from contactfem.report import build_report, load_path_figures, path_step_figures
    from contactfem.solve import solve_case, solve_load_path

    progress = _progress(quiet)
    try:
        case = _load(case_file, backend, distributed=True)
        if make_plot and "h5" not in case.output.files:
            raise CaseError(f"{case_file.name}: output.files: --plot reads solution.h5; keep h5 in output.files")
        directory = out_dir if out_dir is not None else case.output.directory
        if case.solver.backend in DISTRIBUTED_BACKENDS:
            _solve_distributed(case, method, refine, petsc_solver, directory, quiet, as_json, overwrite, make_plot,
                               progress)
            return
        with claimed_directory(directory, markers=RESULT_MARKERS, overwrite=overwrite) as claim:
            with claim.stage(replaces=RESULT_FILES, last=REPORT_JSON) as staging:
                writer = None
                if case.load_path is not None:
                    # Each step's files go into the staging area as it is solved: a path
                    # holds one step in memory, and a failed one leaves nothing behind.
                    writer = PathWriter(staging, case.load_path.factors, case.text)
                    steps: list[dict] = []

                    def write_step(index: int, factor: float, step) -> None:
                        steps.append(path_step_figures(factor, step))
                        writer.add(index, step.solution)

                    try:
                        path = solve_load_path(case, method=method, refine=refine, progress=progress,
                                               accept_uncertified=True, on_step=write_step, keep_steps=False)
                    except BaseException:
                        writer.close()  # its half-written files go with the staging area
                        raise
                    result, extras = path.final, {"load_path": load_path_figures(path, steps)}
                else:
                    result = solve_case(case, method=method, refine=refine, progress=progress,
                                        accept_uncertified=True)
                    extras = {}
                report = _write_solution(staging, case, result, build_report(case, result, extras), progress,
                                         path_writer=writer)
                names = _files_of(case.output.files)
                if writer is not None:
                    names.append(plot_load_path(staging / PATH_PNG, report["load_path"]["curves"],
                                                case.units.to_dict(), title=case.title).name)
                if make_plot:
                    names += _pictures(staging, staging, progress)
    except ContactFemError as error:
        _fail(error)
        return
    _report_solve(case, result, report, [Path(directory) / name for name in names], directory, quiet, as_json)


def _report_solve(case, result, report: dict, written: list[Path], directory: Path, quiet: bool,
                  as_json: bool) -> None:
    """A finished solve on stdout (the summary, or the report with --json); exit 1 when uncertified."""
    _end_progress()
    if as_json:
        click.echo(to_json(report), nl=False)
    elif not quiet:
        click.echo(_summary(report, written))
    _refuse_uncertified(case, result, directory)


def _solve_distributed(case, method: str | None, refine: int | None, petsc_solver: str, directory: Path,
                       quiet: bool, as_json: bool, overwrite: bool, make_plot: bool, progress) -> None:
    """``solve`` under mpiexec: every rank solves its share; rank 0 alone claims the output
    directory, writes and prints. Its verdict on the directory is shared before the solve, so
    that a refusal stops every rank (the others would otherwise wait in a collective step)."""
    import contextlib

    from contactfem.distributed import distributed_report, mpi_world, solve_distributed
    from contactfem.io.atomic import claimed_directory

    if case.load_path is not None:
        raise CaseError(f"{case.source.name}: load_path: the petsc backend solves one load; "
                        "run the path with a serial backend (auto, cholmod, pardiso or superlu)")
    world = mpi_world()
    root = world.Get_rank() == 0
    with contextlib.ExitStack() as stack:
        refusal = None
        if root:
            try:
                claim = stack.enter_context(claimed_directory(directory, markers=RESULT_MARKERS, overwrite=overwrite))
            except ContactFemError as error:
                refusal = error
        code = world.bcast(_exit_code(refusal) if refusal is not None else 0, root=0)
        if code:
            if root:
                _fail(refusal)
            sys.exit(code)
        try:
            outcome = solve_distributed(case, method=method, refine=refine, solver=petsc_solver,
                                        progress=progress if root else None, accept_uncertified=True)
        except ContactFemError as error:  # raised on every rank alike: decisions use shared data
            if root:
                _fail(error)
            sys.exit(_exit_code(error))
        if not root:
            return
        result = outcome.result
        with claim.stage(replaces=RESULT_FILES, last=REPORT_JSON) as staging:
            report = _write_solution(staging, case, result, distributed_report(case, outcome), progress)
            names = _files_of(case.output.files)
            if make_plot:
                names += _pictures(staging, staging, progress)
    _report_solve(case, result, report, [Path(directory) / name for name in names], directory, quiet, as_json)


def _refuse_uncertified(case, result, directory: Path) -> None:
    """Exit 1 for a result the kernel could not certify: its files are written (report.json
    says status not_certified, with each check) but it is not an answer."""
    from contactfem.errors import SolverError
    from contactfem.kernel import Status

    if result.kernel.status is Status.NOT_CERTIFIED:
        _fail(SolverError(f"{case.source.name}: method {result.method}: not certified, "
                          f"{result.kernel.message}; the files in {directory} say so (report.json: solver.certificate)"))


@main.command()
@case_argument
@refine_option
@json_option
@click.option("--quiet", "-q", is_flag=True, help="Print nothing; the exit code tells (0 valid, 2 not).")
@_interruptible
def check(case_file: Path, refine: int | None, as_json: bool, quiet: bool = False) -> None:
    """Validate CASE and mesh it, without solving; print what it models.

    \b
    Example:
      contactfem check cases/hole.yaml
    """
    from contactfem.report import obstacle_figures
    from contactfem.solve import prepare

    try:
        case = _load(case_file)
        problem = prepare(case, refine=refine)
    except ContactFemError as error:
        _fail(error)
        return
    mesh = problem.mesh
    diameters = mesh.triangle_diameters()
    summary = {
        "case": str(case_file),
        "title": case.title,
        "geometry": _geometry_figures(case),
        "material": {"E": case.material.young, "nu": case.material.poisson, "plane": case.material.plane},
        "parts": {p.name: p.label for p in case.parts},
        "mesh": {"nodes": mesh.n_points, "triangles": mesh.n_triangles,
                 "h_min": float(diameters.min()), "h_max": float(diameters.max())},
        "unknowns": problem.n_unknowns,
        "contact_nodes": int(len(problem.contact.nodes)),
        "obstacle": obstacle_figures(problem),
        "method": case.solver.method,
        "estimate": _estimate(case, problem),
        "load_path": None if case.load_path is None else list(case.load_path.factors),
    }
    if as_json:
        click.echo(json.dumps(summary, indent=2, sort_keys=True))
        return
    if quiet:
        return
    click.echo(f"{case_file}: valid — {case.title}")
    click.echo(f"  geometry   {_geometry_text(summary['geometry'])}")
    click.echo(f"  material   E = {case.material.young:g}, nu = {case.material.poisson:g}, plane {case.material.plane}")
    for part in case.parts:
        click.echo(f"  boundary   {part.name}: {part.label}")
    click.echo(f"  mesh       {mesh.n_points} nodes, {mesh.n_triangles} triangles, h in "
               f"[{diameters.min():.3g}, {diameters.max():.3g}]")
    click.echo(f"  unknowns   {problem.n_unknowns} displacement, {len(problem.contact.nodes)} contact nodes")
    click.echo(f"  obstacle   {_obstacle_text(summary['obstacle'])}")
    if case.load_path is not None:
        factors = case.load_path.factors
        click.echo(f"  load path  {len(factors)} steps, load factors {factors[0]:g} to {factors[-1]:g} "
                   "(every load, prescribed displacement and platen drive times each factor)")
    cost = summary["estimate"]
    click.echo(f"  estimate   about {cost['seconds']:.2g} s and {cost['bytes'] / 2**30:.2g} GiB with "
               f"{cost['backend']} (measured on 2 cores; ±50%), of {cost['limit']}")


@main.command()
@case_argument
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
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
    from contactfem.io import atomic_write_text
    from contactfem.io.atomic import claimed_directory
    from contactfem.plots import plot_contact_profiles
    from contactfem.studies import compare_methods

    try:
        case = _load(case_file)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-compare")
        with claimed_directory(directory, markers=(COMPARE_JSON,), overwrite=overwrite) as claim:
            figures, outcomes = compare_methods(case, refine=refine, progress=_progress(quiet))
            with claim.stage(last=COMPARE_JSON) as staging:
                atomic_write_text(staging / COMPARE_JSON, to_json(figures))
                plot_contact_profiles(staging / COMPARE_PNG, outcomes, title=case.title)
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
        rows.append((label, *(f"{methods[m][key]:.6g}" for m in METHOD_NAMES)))
    rows.append(("min multiplier", *(f"{methods[m]['sign_conditions']['min_multiplier']:.4g}" for m in METHOD_NAMES)))
    rows.append(("active nodes", *(str(methods[m]["contact_zone"]["active_nodes"]) for m in METHOD_NAMES)))
    width = max(len(r[0]) for r in rows)
    click.echo(f"{case.title}: {figures['mesh']['unknowns']} unknowns, {figures['mesh']['contact_nodes']} contact nodes")
    for row in rows:
        click.echo(f"  {row[0]:<{width}}  {row[1]:>14}  {row[2]:>14}")
    click.echo(f"  max |u - w| / max |u|        {figures['relative_displacement_difference']:.2e}")
    click.echo(f"  max |λ - D⁻¹Mθ| / max |λ|    {figures['relative_lambda_minus_pi_theta']:.2e}")
    click.echo(f"  negative θ nodes             {figures['negative_theta_nodes']} (min θ {figures['min_theta']:.4g})")
    click.echo(f"  total variation in lift-off  θ {figures['theta_total_variation_in_lift_off']:.4g}, "
               f"λ {figures['lambda_total_variation_in_lift_off']:.4g}")
    click.echo(f"  wrote {directory / COMPARE_JSON}, {directory / COMPARE_PNG}, "
               f"{directory / 'compare.pvd'} (ParaView: one time step per method)")


@main.command()
@case_argument
@click.option("--levels", type=click.IntRange(2, 10), default=4, show_default=True,
              help="Number of nested meshes: the case's mesh refined 0 … levels−1 times.")
@click.option("--extra", type=click.IntRange(1, 4), default=1, show_default=True,
              help="Refinements beyond the last level for the reference, when the case has no exact solution.")
@click.option("--method", "methods", type=click.Choice(METHOD_NAMES), multiple=True,
              help="Method(s) to study; default both.")
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
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
    from contactfem.io import atomic_write_text
    from contactfem.io.atomic import claimed_directory
    from contactfem.plots import plot_convergence
    from contactfem.studies import convergence_study

    try:
        case = _load(case_file)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-convergence")
        kept: list = []  # (label, solution) of every level and method, for convergence-*.pvd
        with claimed_directory(directory, markers=(CONVERGENCE_JSON,), overwrite=overwrite) as claim:
            study = convergence_study(case, levels, extra=extra, methods=methods or METHOD_NAMES,
                                      progress=_progress(quiet),
                                      on_outcome=lambda level, name, o: kept.append((level, name, o.solution)))
            with claim.stage(last=CONVERGENCE_JSON) as staging:
                atomic_write_text(staging / CONVERGENCE_JSON, to_json(study))
                atomic_write_text(staging / CONVERGENCE_CSV, _csv(study["rows"]))
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
            value = rates[norm][index] if index >= 0 else None
            rate = "" if index < 0 else ("(n/a)" if value is None else f"({value:.2f})")
            cells.append(f"{row[norm]:.3e} {rate:>6}")
        click.echo(f"  {row['method']:<9}{row['h']:>9.4f}{row['unknowns']:>10}{row['iterations']:>7}"
                   f"{row['total_seconds']:>9.2f}" + "".join(f"{c:>21}" for c in cells))
    click.echo("  (observed rates between consecutive levels in parentheses; the paper predicts "
               "h^(1/2+ν), ν ≤ 1/2, for the H1 and H-1/2 errors)")
    click.echo(f"  wrote {directory}/{CONVERGENCE_JSON}, {CONVERGENCE_CSV}, {', '.join(CONVERGENCE_PNGS)}, "
               f"convergence-<method>.pvd (ParaView: one time step per level)")


@main.command()
@case_argument
@click.option("--target", type=_FiniteFloatRange(min=0, min_open=True), default=None,
              help="Stop once the estimate η is at most this (energy norm, the case's units).")
@click.option("--max-unknowns", type=click.IntRange(min=1), default=100_000, show_default=True,
              help="Do not solve a mesh with more displacement unknowns than this.")
@click.option("--max-seconds", type=_FiniteFloatRange(min=0, min_open=True), default=600.0, show_default=True,
              help="Stop after the step that passes this many seconds.")
@click.option("--theta", type=_FiniteFloatRange(0, 1, min_open=True), default=0.5, show_default=True,
              help="Dörfler bulk marking: refine a smallest set carrying θ of Σ η_T².")
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Output directory. Default: <output.directory>-adapt.")
@quiet_option
@json_option
@overwrite_option
@_interruptible
def adapt(case_file: Path, target: float | None, max_unknowns: int, max_seconds: float, theta: float,
          out_dir: Path | None, quiet: bool, as_json: bool, overwrite: bool) -> None:
    """Adaptive refinement of CASE with method (4) and its residual error estimator.

    Solve, estimate (Hild–Nicaise residual estimator, see contactfem/estimator.py), mark
    (Dörfler, θ) and refine (newest-vertex bisection) until η ≤ --target or a budget is
    reached. Writes the final solution like `solve` (report.json gains "estimator",
    solution.vtu the cell data error_indicator = η_T) and adapt.json (per step: unknowns, η,
    seconds, and the true errors when the case has an exact solution).

    \b
    Examples:
      contactfem adapt cases/square.yaml --max-unknowns 20000
      contactfem adapt cases/manufactured.yaml --target 2e-5 --theta 0.3
    """
    from contactfem.adaptive import adapt as adaptive_loop
    from contactfem.io import atomic_write_text
    from contactfem.io.atomic import claimed_directory
    from contactfem.report import build_report

    progress = _progress(quiet)
    try:
        case = _load(case_file)
        _refuse_unknowns_beyond_memory(case, max_unknowns)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-adapt")
        with claimed_directory(directory, markers=(ADAPT_JSON, *RESULT_MARKERS), overwrite=overwrite) as claim:
            run = adaptive_loop(case, theta=theta, target=target, max_unknowns=max_unknowns,
                                max_seconds=max_seconds, progress=progress)
            report = build_report(case, run.result, extras={"estimator": run.estimate.summary()})
            with claim.stage(replaces=(*RESULT_FILES, ADAPT_JSON), last=ADAPT_JSON) as staging:
                _write_solution(staging, case, run.result, report, progress)
                atomic_write_text(staging / ADAPT_JSON, to_json(run.history()))
        written = [directory / name for name in (*_files_of(case.output.files), ADAPT_JSON)]
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


def _pictures(result_dir: Path, out_dir: Path, progress, **options) -> list[str]:
    """The pictures of the result in ``result_dir`` (read from its solution.h5) into ``out_dir``."""
    from contactfem.render import make_pictures

    if progress is not None:
        progress("writing pictures")
    return [Path(p).name for p in make_pictures(result_dir, out_dir, **options)["files"]]


@main.command()
@click.argument("result_dir", metavar="RESULT_DIR", type=_CheckedPath(file_okay=False))
@click.option("--size", default="1200x900", show_default=True, metavar="WxH",
              help="Size of each PNG in pixels.")
@click.option("--scale", default="auto", show_default=True, metavar="auto|FACTOR",
              help="Displacement magnification; auto makes the largest displacement 10% of the body's size.")
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Where the PNGs go. Default: RESULT_DIR.")
@quiet_option
@click.option("--json", "as_json", is_flag=True, help="Print the written files and the factor as JSON.")
@_interruptible
def plot(result_dir: Path, size: str, scale: str, out_dir: Path | None, quiet: bool, as_json: bool) -> None:
    """Draw the result in RESULT_DIR as PNGs: a solve's, a compare's or a converge's.

    A solve (solution.h5): deformed.png, the body at x + f·u coloured by von Mises stress,
    with axes, units, a scale bar, the obstacle, the contact zone in red and a zoom on it
    (the magnification never draws the body across the obstacle: the caption says how);
    contact_profile.png, the contact pressure and the gap g0 − u_n along the obstacle.
    A compare (compare.json): compare.png. A converge (convergence.json): convergence_h.png
    and convergence_time.png. Rendered off-screen: no display is needed.

    \b
    Examples:
      contactfem plot results/square
      contactfem plot results/square --size 1600x1000 --scale 20 --out figures
      contactfem plot results/square-compare          # compare.png from compare.json
      contactfem plot results/square-convergence      # the convergence PNGs
    """
    from contactfem.io.atomic import claimed_directory
    from contactfem.render import (
        check_directory,
        draw_directory,
        parse_scale,
        parse_size,
    )

    try:
        pixels = parse_size(size)
        factor = parse_scale(scale)
        names = check_directory(result_dir)  # nothing to draw, or unreadable: refused before anything is touched
        progress = _progress(quiet)
        directory = out_dir if out_dir is not None else result_dir
        with claimed_directory(directory) as claim:
            with claim.stage(replaces=names) as staging:
                if progress is not None:
                    progress("rendering pictures")
                made = draw_directory(result_dir, staging, size=pixels, scale=factor)
        made["files"] = [str(Path(directory) / Path(name).name) for name in made["files"]]
    except ContactFemError as error:
        _fail(error)
        return
    _end_progress()
    if as_json:
        click.echo(json.dumps(made, indent=2, sort_keys=True))
    elif not quiet:
        magnified = f", displacement x {made['scale']:.3g}" if made["scale"] is not None else ""
        click.echo(f"wrote {', '.join(made['files'])} ({made['size'][0]}x{made['size'][1]}{magnified})")


@main.command()
@click.argument("path", metavar="[PATH]", required=False, default="case.yaml",
                type=_CheckedPath(dir_okay=False))
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


def _refuse_unknowns_beyond_memory(case, max_unknowns: int) -> None:
    """adapt grows its mesh up to --max-unknowns, meshes the size guard never sees: the budget
    itself must fit the memory this process may use, or nothing starts."""
    from contactfem.estimate import backend_refusal, estimate_cost, largest_mesh_points, memory_limit
    from contactfem.linalg import resolve_backend

    backend = resolve_backend(case.solver.backend)
    needed = estimate_cost(max_unknowns, backend)["bytes"]
    limit = memory_limit()
    if needed > limit.bytes:
        raise CaseError(f"--max-unknowns {max_unknowns}: a mesh of that many unknowns needs about "
                        f"{needed / 2**30:.3g} GiB with {backend}, more than {limit.source}; at most "
                        f"{2 * largest_mesh_points(backend, limit.bytes)} fit")
    refusal = backend_refusal(max_unknowns, backend)
    if refusal is not None:
        raise CaseError(f"--max-unknowns {max_unknowns}: {refusal}")


def _estimate(case, problem) -> dict:
    from contactfem.estimate import estimate_cost, memory_limit
    from contactfem.linalg import resolve_backend

    backend = resolve_backend(case.solver.backend)
    limit = memory_limit()
    return {"backend": backend, **estimate_cost(problem.n_unknowns, backend),
            "limit_bytes": limit.bytes, "limit": limit.source}


def _geometry_figures(case) -> dict:
    """What the case's body is: its kind, its loops' vertices and the data files read."""
    from contactfem.case import PolygonGeometry, RectangleGeometry

    geometry = case.geometry
    figures: dict = {"files": [str(path) for path in case.data_files]}  # a mesh file among them
    if isinstance(geometry, RectangleGeometry):
        figures.update(kind="rectangle", lower=list(geometry.lower), upper=list(geometry.upper))
    elif isinstance(geometry, PolygonGeometry):
        loops = (geometry.outer, *geometry.holes)
        figures.update(kind="polygon", vertices=int(sum(len(loop.vertices) for loop in loops)),
                       holes=len(geometry.holes), arcs=int(sum(len(loop.arc_edges) for loop in loops)))
    else:
        figures.update(kind="mesh_file")
    return figures


def _geometry_text(figures: dict) -> str:
    """The geometry of :func:`_geometry_figures` in words."""
    if figures["kind"] == "rectangle":
        (x0, y0), (x1, y1) = figures["lower"], figures["upper"]
        text = f"rectangle [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}]"
    elif figures["kind"] == "polygon":
        holes, arcs = figures["holes"], figures["arcs"]
        text = (f"polygon of {figures['vertices']} vertices" + (f", {holes} hole{'s' * (holes != 1)}" if holes else "")
                + (f", {arcs} arc{'s' * (arcs != 1)}" if arcs else ""))
    else:
        return f"mesh file {figures['files'][0]}"
    names = [Path(f).name for f in figures["files"]]
    if len(names) > 3:  # a body with hundreds of holes from files: --json lists them all
        names = [*names[:3], f"{len(names) - 3} more files"]
    return text + (f" (read from {', '.join(names)})" if names else "")


def _obstacle_text(obstacle: dict) -> str:
    """The obstacle of report.obstacle_figures in words, with plain numbers."""
    def point(p) -> str:
        return f"({p[0]:g}, {p[1]:g})"

    normal = f"normal {point(obstacle['normal'])}"
    if obstacle["ends"] is None:
        return f"the line through {point(obstacle['point'])}, {normal}"
    low, high = obstacle["extent"]
    facing = obstacle["facing_nodes"]
    total = facing + obstacle["beyond_nodes"]
    return (f"the segment from {point(obstacle['ends'][0])} to {point(obstacle['ends'][1])}, {normal}; "
            f"{facing} of {total} contact nodes face it (positions [{low:g}, {high:g}] along the obstacle)")


def _force_lines(forces: dict | None) -> list[str]:
    """One line per boundary part that carries a force: its condition, force and moment."""
    if not forces:
        return []
    lines = []
    for name, entry in forces["parts"].items():
        fx, fy = entry["force"]
        if fx == 0 and fy == 0 and entry["moment"] == 0:
            continue
        label = "forces" if not lines else ""
        lines.append(f"  {label:<12} {name} ({entry['condition']}): ({fx:.6g}, {fy:.6g}), moment {entry['moment']:.6g}")
    total = forces["total"]
    lines.append(f"  {'':<12} sum: relative {total['relative_force_residual']:.1e} "
                 f"(moments about ({forces['moment_about'][0]:.4g}, {forces['moment_about'][1]:.4g}))")
    return lines


def _platen_lines(platens: dict | None) -> list[str]:
    """One line per platen: how it is driven, its advance into the body and its force."""
    lines = []
    for name, entry in (platens or {}).items():
        label = "platens" if not lines else ""
        driven = "force" if entry["control"] == "force" else "displacement"
        lines.append(f"  {label:<12} {name} ({driven} {entry['prescribed']:.6g}): advance {entry['advance']:.6g}, "
                     f"force {entry['force']:.6g}")
    return lines


def _parallel_lines(parallel: dict | None) -> list[str]:
    """A distributed solve in one line: ranks, solver and the largest peak memory of a rank."""
    if not parallel:
        return []
    return [f"  ranks        {parallel['ranks']} (petsc {parallel['solver']}), peak memory per rank up to "
            f"{parallel['max_peak_rss_bytes'] / 2**30:.2f} GiB"]


def _path_lines(path: dict | None) -> list[str]:
    """The load path in one line: its steps and their cost, and the contact force along it."""
    if not path:
        return []
    curves = path["curves"]
    return [f"  load path    {len(curves['factor'])} steps, factors {curves['factor'][0]:.4g} to "
            f"{curves['factor'][-1]:.4g}: {path['factorizations']} factorisation{'' if path['factorizations'] == 1 else 's'}, "
            f"{path['seconds']:.2f} s; "
            f"contact force {curves['contact_force'][0]:.6g} to {curves['contact_force'][-1]:.6g}, "
            f"width {curves['contact_width'][0]:.4g} to {curves['contact_width'][-1]:.4g}"]


def _certificate_line(certificate: dict | None) -> str:
    """The kernel's certificate in one line: each condition's relative value against its tolerance."""
    if certificate is None:
        return "  certificate  none (no iteration ran)"
    checks = certificate["checks"]
    shown = ", ".join(f"{name.replace('_', ' ')} {checks[name]['value']:.1e}"
                      + ("" if checks[name]["passed"] else f" > {checks[name]['tolerance']:.1e}")
                      for name in ("equilibrium", "force_sign", "penetration", "complementarity")
                      if name in checks and checks[name]["value"] is not None)
    verdict = "passed" if certificate["passed"] else "FAILED (" + ", ".join(certificate["failed"]) + ")"
    return f"  certificate  {verdict}: {shown} (relative to the force and displacement scales)"


def _summary(report: dict, written: list[Path]) -> str:
    from contactfem.plots import zone_text

    zone = report["contact_zone"]
    signs = report["sign_conditions"]
    intervals = zone_text(tuple(i["abscissa"]) for i in zone["intervals"])
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
        _certificate_line(report["solver"].get("certificate")),
        *_force_lines(report.get("boundary_forces")),
        *_platen_lines(report.get("platens")),
        *_path_lines(report.get("load_path")),
        *_parallel_lines(report.get("parallel")),
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


@main.command()
@click.argument("sweep_file", metavar="SWEEP", type=_CheckedPath(dir_okay=False))
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Output directory. Default: the sweep file's output.directory (results/<sweep file name>).")
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Run on the Dask cluster of this scheduler, e.g. tcp://10.0.0.5:8786. Default: a local cluster.")
@click.option("--workers", type=click.IntRange(1, 4096), default=None,
              help="Worker processes of the local cluster. Default: one per core, at most one per point.")
@quiet_option
@click.option("--json", "as_json", is_flag=True, help="Print sweep.json on stdout.")
@overwrite_option
@_interruptible
def sweep(sweep_file: Path, out_dir: Path | None, scheduler: str | None, workers: int | None, quiet: bool,
          as_json: bool, overwrite: bool) -> None:
    """Solve many variants of a case, as independent points in parallel on Dask.

    SWEEP names a base case and the values of any of its keys by dotted path, as a grid
    (cartesian product) or a list of points (README: "Sweeps"). Each point is a full
    solve; its figures are stored in OUT/points/ as soon as it finishes, so a rerun solves
    only what is missing. Writes sweep.csv, sweep.json and sweep.png (error against
    seconds, Pareto front marked). Runs on a local Dask cluster (one single-threaded
    worker per core), on --scheduler's cluster, or without Dask one point after another.
    Exit 1 when a point failed (the others are in the table all the same).

    \b
    Examples:
      contactfem sweep cases/sweeps/square.yaml
      contactfem sweep cases/sweeps/square.yaml --workers 1 --out results/sweep-1
      contactfem sweep study.yaml --scheduler tcp://10.0.0.5:8786 --overwrite
    """
    from contextlib import nullcontext

    from contactfem import sweep as sweeps
    from contactfem.errors import SolverError
    from contactfem.io.atomic import (
        TEMP_PREFIX,
        atomic_write_text,
        claimed_directory,
        ensure_directory,
    )

    def say(line: str) -> None:
        if not quiet:
            click.echo(_printable(line), err=True)

    def finished(row: dict, done: int, total: int) -> None:
        if row["reused"]:
            return
        seconds = row["seconds"].get("total")
        timing = f", {seconds:.2f} s" if seconds is not None else ""
        size = f", {row['unknowns']} unknowns" if row["unknowns"] is not None else ""
        reason = f": {row['message']}" if row["status"] != "ok" and row["message"] else ""
        say(f"[{done}/{total}] point {row['index']} {row['label']}: {row['status']}{timing}{size}{reason}")

    try:
        if scheduler is not None and workers is not None:
            raise CaseError(f"--workers {workers}: sizes the local cluster; expected no --workers with --scheduler "
                            "(the cluster's own workers run the points)")
        plan = sweeps.load_sweep(sweep_file)
        directory = Path(out_dir if out_dir is not None else plan.directory)
        with claimed_directory(directory, markers=(sweeps.SWEEP_JSON,), overwrite=overwrite) as claim:
            points = directory / sweeps.POINTS_DIR
            done = sweeps.finished_points(points, plan)
            pending = plan.pending(done)
            if done:
                reused = sum(p.digest in done for p in plan.points)
                say(f"{reused} of {len(plan.points)} points are already solved in {points}; not solving them again")
            engine_context = (sweeps.open_engine(scheduler, workers, len(pending)) if pending
                              else nullcontext(sweeps.SerialEngine()))
            with engine_context as engine:
                if engine.note:
                    say(f"note: {engine.note}")
                if pending and engine.kind == "dask":
                    where = f"the cluster at {scheduler}" if scheduler else "a local cluster"
                    say(f"solving {len(pending)} points on {engine.workers} Dask workers of {where}")
                ensure_directory(points)
                for leftover in points.glob(f"{TEMP_PREFIX}*"):  # a killed run's unfinished write
                    leftover.unlink(missing_ok=True)
                table = sweeps.run_sweep(
                    plan, engine, finished=done, progress=finished,
                    store=lambda record: atomic_write_text(points / sweeps.point_file(record["digest"]),
                                                           sweeps.point_json(record)))
            with claim.stage(replaces=sweeps.SWEEP_FILES, last=sweeps.SWEEP_JSON) as staging:
                atomic_write_text(staging / sweeps.SWEEP_CSV, sweeps.table_csv(table))
                _plot_sweep(staging / sweeps.SWEEP_PNG, table)
                atomic_write_text(staging / sweeps.SWEEP_JSON, to_json(table))
    except ContactFemError as error:
        _fail(error)
        return
    if as_json:
        click.echo(to_json(table), nl=False)
    elif not quiet:
        click.echo(_sweep_summary(table, directory))
    failed = sweeps.failed_rows(table)
    if failed:
        statuses = ", ".join(f"{sum(r['status'] == s for r in failed)} {s}" for s in sweeps.STATUSES
                             if any(r["status"] == s for r in failed))
        _fail(SolverError(f"{plan.source.name}: {len(failed)} of {len(table['points'])} points did not solve "
                          f"({statuses}); first, point {failed[0]['index']}: {failed[0]['message']}; "
                          f"{directory / sweeps.SWEEP_CSV} lists every point"))


def _sweep_summary(table: dict, directory: Path) -> str:
    engine = table["engine"]
    where = ("this process" if engine["kind"] == "serial" else
             f"{engine['workers']} Dask workers" + (f" at {engine['scheduler']}" if engine["scheduler"] else ""))
    counts = table["counts"]
    rows = table["points"]
    width = min(max([len(r["label"]) for r in rows] + [6]), 60)
    lines = [f"{table['sweep']['title']}: {counts['points']} points ({counts['solved']} solved on {where}, "
             f"{counts['reused']} reused) in {table['wall_seconds']:.1f} s"
             + (f" (and {engine['startup_seconds']:.1f} s to start the cluster)" if engine["startup_seconds"] else ""),
             (f"  {'#':>4}  {'values':<{width}}  {'status':<13}{'unknowns':>9}{'Newton':>7}{'seconds':>9}"
              f"{'contact force':>15}{'error':>11}  front")]
    for r in rows:
        def number(value, spec):
            return format(value, spec) if value is not None else "-"
        label = r["label"] if len(r["label"]) <= width else r["label"][: width - 3] + "..."
        lines.append(f"  {r['index']:>4}  {label:<{width}}  {r['status']:<13}{number(r['unknowns'], 'd'):>9}"
                     f"{number(r['iterations'], 'd'):>7}{number(r['seconds'].get('total'), '.2f'):>9}"
                     f"{number(r['contact_force'], '.6g'):>15}{number(r['error'], '.3e'):>11}"
                     f"  {'*' if r['pareto'] else ''}")
    lines.append("  (error: energy norm against the exact solution, or |‖u_h‖ - ‖u_finest‖| in the energy norm "
                 "within each group; * = on its group's Pareto front of error against seconds)")
    lines.append(f"  wrote {directory}/sweep.csv, sweep.json, sweep.png; each point in {directory}/points/")
    return "\n".join(lines)


def _plot_sweep(path: Path, table: dict) -> None:
    """sweep.png: each point's error against its seconds, one colour per group, the Pareto fronts drawn."""
    import itertools

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from contactfem.io.atomic import atomic_path
    from contactfem.sweep import pareto_series

    series = list(pareto_series(table))
    figure, axes = plt.subplots(figsize=(8.5, 6))
    colours = itertools.cycle(plt.rcParams["axes.prop_cycle"].by_key()["color"])
    for (group, rows, front), colour in zip(series, colours):
        axes.scatter([r["seconds"]["total"] for r in rows], [r["error"] for r in rows], s=24, color=colour,
                     label=group or "all points", zorder=3)
        axes.plot([r["seconds"]["total"] for r in front], [r["error"] for r in front], "-", color=colour, lw=1.2)
        axes.scatter([r["seconds"]["total"] for r in front], [r["error"] for r in front], s=90,
                     facecolors="none", edgecolors="black", lw=1.0, zorder=4)
        for r in front:
            axes.annotate(str(r["index"]), (r["seconds"]["total"], r["error"]), textcoords="offset points",
                          xytext=(5, 4), fontsize=7)
    kinds = {r["error_kind"] for _, rows, _ in series for r in rows}
    if series:
        axes.set_xscale("log")
        axes.set_yscale("log")
        seconds = FuncFormatter(lambda value, _: f"{value:g}")
        axes.xaxis.set_major_formatter(seconds)
        axes.xaxis.set_minor_formatter(seconds)
        axes.tick_params(axis="x", which="minor", labelsize=7)
        axes.scatter([], [], s=90, facecolors="none", edgecolors="black", label="Pareto front (point number)")
        axes.legend(fontsize=7, loc="best")
    else:
        axes.text(0.5, 0.5, "no point has an error to plot\n(one solved point per group, or none solved)",
                  ha="center", va="center", transform=axes.transAxes)
    axes.set_xlabel("seconds per point (meshing, assembly, solve, report)")
    axes.set_ylabel("energy-norm error ‖u − u_h‖" if kinds == {"exact"} else
                    "|‖u_h‖ − ‖u_finest‖|, energy norm (finest point of the group)" if kinds == {"finest"} else
                    "error (energy norm)")
    failed = sum(r["status"] != "ok" for r in table["points"])
    axes.set_title(f"{table['sweep']['title']}: error against time"
                   + (f" ({failed} point(s) without figures)" if failed else ""), fontsize=10)
    axes.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    try:
        with atomic_path(path) as temporary:
            figure.savefig(temporary, format="png", dpi=110)
    finally:
        plt.close(figure)


def run() -> None:
    """The ``contactfem`` command: the process's heap kept for reuse (:mod:`contactfem.heap`;
    a library caller's process is left as it is), then :func:`main`."""
    keep_freed_memory()
    main()

