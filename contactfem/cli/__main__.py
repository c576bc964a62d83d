"""``python -m contactfem.cli``: the ``contactfem`` command."""

from contactfem.cli import run

run()
