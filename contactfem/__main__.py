"""``python -m contactfem``: the command line, as the ``contactfem`` script runs it."""

from contactfem.cli import run

if __name__ == "__main__":
    run()
