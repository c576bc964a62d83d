"""``contactfem sweep``: many variants of a case solved as independent points, in parallel on Dask."""

from __future__ import annotations

from pathlib import Path

import click

from contactfem.cli.exits import _fail, _interruptible, _printable
from contactfem.cli.common import _check_engine_options, _engine
from contactfem.cli.options import _CheckedPath, engine_options, overwrite_option, quiet_option
from contactfem.cli.sweep_report import _plot_sweep, _sweep_summary
from contactfem.errors import ContactFemError
from contactfem.io.registry import shown_data, to_json


@click.command()
@click.argument("sweep_file", metavar="SWEEP", type=_CheckedPath(dir_okay=False))
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Output directory. Default: the sweep file's output.directory (results/<sweep file name>).")
@engine_options(default="a local cluster", tasks="points")
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
    from contactfem import sweep as sweeps
    from contactfem.errors import SolverError
    from contactfem.io.atomic import (
        atomic_write_text,
        claimed_directory,
        ensure_directory,
        remove_leftover_temporaries,
    )
    from contactfem.io.readback import read_point_record

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
        _check_engine_options(scheduler, workers, "points")
        plan = sweeps.load_sweep(sweep_file, progress=say)
        directory = Path(out_dir if out_dir is not None else plan.directory)
        with claimed_directory(directory, markers=(sweeps.SWEEP_JSON,), overwrite=overwrite) as claim:
            points = directory / sweeps.POINTS_DIR
            done = sweeps.finished_points(points, plan, read=read_point_record)
            pending = plan.pending(done)
            if done:
                reused = sum(p.digest in done for p in plan.points)
                say(f"{reused} of {len(plan.points)} points are already solved in {points}; not solving them again")
            with _engine(scheduler, workers, len(pending), say, "points") as engine:
                ensure_directory(points)
                remove_leftover_temporaries(points)  # a killed run's unfinished writes, only those
                # Messages naming a file whose name is not UTF-8 are stored and shown as text.
                table = shown_data(sweeps.run_sweep(
                    plan, engine, finished=done, progress=finished,
                    store=lambda record: atomic_write_text(points / sweeps.point_file(record["digest"]),
                                                           sweeps.point_json(shown_data(record)))))
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
