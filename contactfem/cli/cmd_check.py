"""``contactfem check``: a case validated and meshed without solving, and what it models printed."""

from __future__ import annotations

from pathlib import Path

import click

from contactfem import __version__
from contactfem.cli.common import _files_of, _load
from contactfem.cli.exits import _fail, _interruptible, _printable, _shown
from contactfem.cli.options import case_argument, json_option, refine_option
from contactfem.errors import ContactFemError
from contactfem.io.registry import CHECK_SCHEMA_VERSION, shown_path, to_json


@click.command()
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
        "schema_version": CHECK_SCHEMA_VERSION,
        "contactfem_version": __version__,
        "case": shown_path(case_file),
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
        "units": case.units.to_dict(),
        "output": _output_figures(case),
    }
    if as_json:
        click.echo(to_json(summary), nl=False)
        return
    if quiet:
        return
    click.echo(f"{_shown(case_file)}: valid — {case.title}")
    click.echo(_printable(f"  geometry   {_geometry_text(summary['geometry'])}"))
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
                   "(every load, prescribed displacement, platen drive and obstacle motion times each factor)")
    output = summary["output"]
    click.echo(_printable(f"  output     {output['directory']}: {', '.join(output['files'])} "
                          f"(output.files: {', '.join(output['formats'])})"))
    cost = summary["estimate"]
    click.echo(f"  estimate   about {cost['seconds']:.2g} s and {cost['bytes'] / 2**30:.2g} GiB with "
               f"{cost['backend']} (measured on 2 cores; ±50%), of {cost['limit']}")
    click.echo(f"  backend    {cost['backend']}: {cost['backend_reason']}")


def _output_figures(case) -> dict:
    """Where a solve of the case writes, and exactly which files: those of output.files (a load
    path adds its own format and path.png)."""
    from contactfem.io.registry import PATH_PNG

    files = _files_of(case.output.files) + ([PATH_PNG] if case.load_path is not None else [])
    return {"directory": shown_path(case.output.directory), "formats": list(case.output.files), "files": files}


def _estimate(case, problem) -> dict:
    from contactfem.estimate import choose_backend, estimate_cost, memory_limit

    limit = memory_limit()
    choice = choose_backend(problem.n_unknowns, case.solver.backend, limit, case.load_path is None)
    return {"backend": choice.name, "backend_reason": choice.reason, **estimate_cost(problem.n_unknowns, choice.name),
            "limit_bytes": limit.bytes, "limit": limit.source}


def _geometry_figures(case) -> dict:
    """What the case's body is: its kind, its loops' vertices and the data files read."""
    from contactfem.case import PolygonGeometry, RectangleGeometry

    geometry = case.geometry
    figures: dict = {"files": [shown_path(path) for path in case.data_files]}  # a mesh file among them
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
    moving = ""
    if "motion" in obstacle:
        motion = obstacle["motion"]
        moving = (f", moved along {point(motion['direction'])} by {motion['advance']:g}" if motion["control"] ==
                  "displacement" else f", pushed along {point(motion['direction'])} by a force {motion['force']:g}")
    if obstacle["kind"] == "circle":
        return (f"the circle of center {point(obstacle['center'])} and radius {obstacle['radius']:g}{moving}; "
                f"{obstacle['facing_nodes']} contact nodes, each along the normal of its closest point")
    if obstacle["kind"] == "polyline":
        vertices = obstacle["vertices"]
        return (f"the polyline of {len(vertices)} points from {point(vertices[0])} to {point(vertices[-1])}{moving}; "
                f"{obstacle['facing_nodes']} of {obstacle['facing_nodes'] + obstacle['beyond_nodes']} contact nodes "
                "face it, each along the normal of its closest point")
    if obstacle["ends"] is None:
        return f"the line through {point(obstacle['point'])}, {normal}"
    low, high = obstacle["extent"]
    facing = obstacle["facing_nodes"]
    total = facing + obstacle["beyond_nodes"]
    return (f"the segment from {point(obstacle['ends'][0])} to {point(obstacle['ends'][1])}, {normal}; "
            f"{facing} of {total} contact nodes face it (positions [{low:g}, {high:g}] along the obstacle)")
