"""``python -m contactfem.cli``: the ``contactfem`` command, started as the script starts it."""

from contactfem.__main__ import main

main()
