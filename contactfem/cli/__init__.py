"""The ``contactfem`` command line: the only place that prints, and that turns errors into exit codes.

Exit codes: 0 success; 1 the solve or the writing failed; 2 bad input (case file, mesh,
command-line options), with a one-line message and no traceback.

One module per command (``cmd_<name>``); the arguments and options they share are in
:mod:`contactfem.cli.options`, and the one way errors leave the program, as a line on
stderr and an exit code, in :mod:`contactfem.cli.exits`. The library below raises; only
these modules print or exit.
"""

from __future__ import annotations

import click

from contactfem import __version__
from contactfem.cli.cmd_adapt import adapt
from contactfem.cli.cmd_check import check
from contactfem.cli.cmd_compare import compare
from contactfem.cli.cmd_converge import converge
from contactfem.cli.cmd_init import init
from contactfem.cli.cmd_plot import plot
from contactfem.cli.cmd_solve import solve
from contactfem.cli.cmd_sweep import sweep
from contactfem.cli.exits import (  # noqa: F401 - _interruptible is imported from here
    EXIT_BAD_INPUT,
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    _interruptible,
    _OneLineErrors,
)
from contactfem.cli.options import case_argument, json_option, overwrite_option, quiet_option, refine_option
from contactfem.heap import keep_freed_memory

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILURE", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "adapt", "case_argument",
           "check", "compare", "converge", "init", "json_option", "main", "overwrite_option", "plot",
           "quiet_option", "refine_option", "run", "solve", "sweep"]


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


for _command in (solve, check, compare, converge, adapt, plot, init, sweep):
    main.add_command(_command)


def run() -> None:
    """The ``contactfem`` command: the process's heap kept for reuse (:mod:`contactfem.heap`;
    a library caller's process is left as it is), text that stdout or stderr cannot encode
    escaped rather than raised, then :func:`main`."""
    keep_freed_memory()
    _escape_unencodable()
    main()


def _escape_unencodable() -> None:
    """Print what the streams' encoding cannot carry (a title on an ASCII stdout, a surrogate
    that slipped past :func:`contactfem.cli.exits._printable`) as a backslash escape instead of
    failing with a traceback. Paths are shown as text first (``\\xNN`` for a byte that is not
    UTF-8); this is the net under that."""
    import sys

    for stream in (sys.stdout, sys.stderr):
        if getattr(stream, "errors", None) == "strict" and hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (OSError, ValueError):
                pass
