"""``contactfem plot``: the pictures of a result directory drawn as PNGs."""

from __future__ import annotations

from pathlib import Path

import click

from contactfem import __version__
from contactfem.cli.common import _end_progress, _progress
from contactfem.cli.exits import _fail, _interruptible, _shown
from contactfem.cli.options import _CheckedPath, quiet_option
from contactfem.errors import ContactFemError
from contactfem.io.registry import PLOT_SCHEMA_VERSION, to_json


@click.command()
@click.argument("result_dir", metavar="RESULT_DIR", type=_CheckedPath(file_okay=False))
@click.option("--size", default="1200x900", show_default=True, metavar="WxH",
              help="Size of each PNG in pixels.")
@click.option("--scale", default="auto", show_default=True, metavar="auto|FACTOR",
              help="Displacement magnification; auto makes the largest displacement 10% of the body's size.")
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Where the PNGs go. Default: RESULT_DIR.")
@click.option("--zoom", default=None, metavar="FROM:TO",
              help="The window of the profiles' zoom panel, as positions along the obstacle in the case's "
                   "length unit. Default: the densest stretch of contact patches, when there are many.")
@quiet_option
@click.option("--json", "as_json", is_flag=True, help="Print the written files and the factor as JSON.")
@_interruptible
def plot(result_dir: Path, size: str, scale: str, out_dir: Path | None, quiet: bool, as_json: bool,
         zoom: str | None = None) -> None:
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
      contactfem plot results/rough --zoom 0.2:0.25      # the profiles' zoom on that window
      contactfem plot results/square-compare          # compare.png from compare.json
      contactfem plot results/square-convergence      # the convergence PNGs
    """
    from contactfem.io.atomic import claimed_directory
    from contactfem.io.readback import read_results
    from contactfem.render import parse_scale, parse_size, parse_zoom, pictures_of

    try:
        pixels = parse_size(size)
        factor = parse_scale(scale)
        window = parse_zoom(zoom)
        # Every file drawn from, read and checked as untrusted input before anything is touched.
        loaded = read_results(result_dir)
        names = pictures_of(result_dir)  # refused when there is nothing to draw
        progress = _progress(quiet)
        directory = out_dir if out_dir is not None else result_dir
        with claimed_directory(directory) as claim:
            with claim.stage(replaces=names) as staging:
                if progress is not None:
                    progress("rendering pictures")
                made = _draw(result_dir, loaded, staging, pixels, factor, window)
        made["files"] = [str(Path(directory) / Path(name).name) for name in made["files"]]
        made = {"schema_version": PLOT_SCHEMA_VERSION, "contactfem_version": __version__,
                "result_dir": str(result_dir), **made}
    except ContactFemError as error:
        _fail(error)
        return
    _end_progress()
    if as_json:
        click.echo(to_json(made), nl=False)
    elif not quiet:
        magnified = f", displacement x {made['scale']:.3g}" if made["scale"] is not None else ""
        files = ", ".join(_shown(f) for f in made["files"])
        click.echo(f"wrote {files} ({made['size'][0]}x{made['size'][1]}{magnified})")


def _draw(result_dir: Path, loaded, out: Path, size: tuple[int, int], scale: float | None,
          window: tuple[float, float] | None) -> dict:
    """The pictures of what :func:`~contactfem.io.readback.read_results` read, into ``out``,
    drawn from the files already read and checked:
    ``{"files": [...], "scale": f or None, "zoom_scale": f or None, "size": [w, h]}``."""
    from contactfem.io.registry import COMPARE_PNG
    from contactfem.plots import plot_compare, plot_convergence
    from contactfem.render import make_pictures

    made = {"files": [], "scale": None, "zoom_scale": None, "size": list(size)}
    if loaded.solution is not None:
        # make_pictures reads solution.h5 again, through the same checks (read_hdf5).
        made.update(make_pictures(result_dir, out, size=size, scale=scale, window=window))
    if loaded.compare is not None:
        plot_compare(out / COMPARE_PNG, loaded.compare, window=window)
        made["files"].append(str(out / COMPARE_PNG))
    if loaded.convergence is not None:
        made["files"] += [str(p) for p in plot_convergence(out, loaded.convergence)]
    return made
