"""``contactfem compare``: a case solved with both methods on one mesh, and how they differ."""

from __future__ import annotations

from pathlib import Path

import click

from contactfem.cli.common import _end_progress, _load, _progress, _writable_by_vtk, _write_series
from contactfem.cli.exits import _fail, _interruptible, _shown
from contactfem.cli.options import (
    _CheckedPath,
    case_argument,
    json_option,
    overwrite_option,
    quiet_option,
    refine_option,
)
from contactfem.errors import ContactFemError
from contactfem.io.registry import COMPARE_JSON, COMPARE_PNG, to_json
from contactfem.methods import METHOD_NAMES


@click.command()
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
    from contactfem.plots import plot_compare
    from contactfem.studies import compare_methods

    try:
        case = _load(case_file)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-compare")
        with claimed_directory(directory, markers=(COMPARE_JSON,), overwrite=overwrite) as claim:
            figures, outcomes = compare_methods(case, refine=refine, progress=_progress(quiet))
            with claim.stage(last=COMPARE_JSON) as staged, _writable_by_vtk(staged) as staging:
                atomic_write_text(staging / COMPARE_JSON, to_json(figures))
                # Drawn from the figures just written, not from the file read back.
                plot_compare(staging / COMPARE_PNG, figures, title=case.title)
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
    click.echo(f"  wrote {_shown(directory / COMPARE_JSON)}, {_shown(directory / COMPARE_PNG)}, "
               f"{_shown(directory / 'compare.pvd')} (ParaView: one time step per method)")
