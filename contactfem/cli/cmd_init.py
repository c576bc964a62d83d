"""``contactfem init``: a commented starter case written to a new file."""

from __future__ import annotations

from pathlib import Path

import click

from contactfem.cli.exits import _fail, _shown
from contactfem.cli.options import _CheckedPath, quiet_option
from contactfem.errors import ContactFemError


@click.command()
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
        click.echo(f"wrote {_shown(written)}; next: contactfem check {_shown(written)}")
