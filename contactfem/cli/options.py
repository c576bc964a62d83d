"""The arguments and options the commands share, and the click types that check a value before it is used."""

from __future__ import annotations

from pathlib import Path

import click

from contactfem.cli.exits import _printable, _shown


class _CheckedPath(click.Path):
    """A path checked as text first (no NUL, components and the whole within the file system's
    limits, room kept for the staging names an output directory receives), so that the file
    system is never asked about a path it would refuse with a traceback."""

    def __init__(self, *, output: bool = False, **kwargs) -> None:
        super().__init__(path_type=Path, **kwargs)
        self.output = output

    def convert(self, value, param, ctx):
        from contactfem.case import (
            OUTPUT_NAME_RESERVE,
            OUTPUT_PATH_RESERVE,
            path_problem,
            shortened,
        )

        reserves = {"name_reserve": OUTPUT_NAME_RESERVE, "path_reserve": OUTPUT_PATH_RESERVE} if self.output else {}
        problem = path_problem(value, **reserves) if isinstance(value, (str, bytes, Path)) else None
        if problem is not None:
            text = value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)
            self.fail(f"{_printable(shortened(text))}: the path {problem}", param, ctx)
        try:
            return super().convert(value, param, ctx)
        except click.BadParameter as error:
            # click shows a byte of the name that is not UTF-8 as U+FFFD; the other messages show
            # it as \xNN, the byte.
            from click.utils import format_filename

            if isinstance(value, (str, Path)):
                error.message = error.message.replace(format_filename(value), _shown(value))
            raise


class _FiniteFloatRange(click.FloatRange):
    """A float range that also refuses nan and ±inf (click's own range lets them through)."""

    def convert(self, value, param, ctx):
        import math

        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{number} is not a finite number", param, ctx)
        return number


case_argument = click.argument("case_file", metavar="CASE", type=_CheckedPath(dir_okay=False))
refine_option = click.option("--refine", type=click.IntRange(0, 12), default=None,
                             help="Uniform refinements of the case's mesh (each halves h).")
quiet_option = click.option("--quiet", "-q", is_flag=True, help="Print nothing but errors.")
json_option = click.option("--json", "as_json", is_flag=True, help="Print the report as JSON on stdout.")
overwrite_option = click.option("--overwrite", is_flag=True,
                                help="Replace the results already in the output directory (refused otherwise).")


def engine_options(default: str, tasks: str):
    """--scheduler and --workers, as every command that runs independent solves on Dask spells
    them (``default``: where the ``tasks`` run without either)."""
    scheduler = click.option("--scheduler", metavar="ADDRESS", default=None,
                             help=f"Run the {tasks} on the Dask cluster of this scheduler, e.g. tcp://10.0.0.5:8786. "
                                  f"Default: {default}.")
    workers = click.option("--workers", type=click.IntRange(1, 4096), default=None,
                           help=f"Worker processes of a local Dask cluster. Default: one per core, at most one "
                                f"per {tasks[:-1]}.")
    return lambda command: scheduler(workers(command))


class _RelativeTarget(click.ParamType):
    """A relative accuracy: 0.5% or 0.005 (see :func:`contactfem.case.relative_target`)."""

    name = "TARGET"

    def convert(self, value, param, ctx):
        from contactfem.case import relative_target
        from contactfem.case.sections import ACCURACY_TARGET_RANGE

        if isinstance(value, float):
            return value
        target = relative_target(value)
        if target is None:
            low, high = ACCURACY_TARGET_RANGE
            self.fail(f"{_printable(str(value))!r} is not a relative error in [{low:g}, {high:g}] "
                      "(e.g. 0.5% or 0.005)", param, ctx)
        return target
