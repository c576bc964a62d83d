"""The ``contactfem`` command (``python -m contactfem`` too): the process's BLAS threads set
before anything numerical loads (:mod:`contactfem.threads`), then its command line.

Ctrl-C is one line and exit 130 from the moment this function runs: the imports of the
command line (numpy, SciPy, click: most of the first second) included, where Python would
print a KeyboardInterrupt traceback and die of the signal. Only the interpreter's own start,
before this module runs, is left to Python.
"""

import signal
import sys

#: 128 + SIGINT, as a shell reports it (contactfem.cli.exits.EXIT_INTERRUPTED, not imported
#: here: importing it is part of what a Ctrl-C may interrupt).
_EXIT_INTERRUPTED = 130


def main() -> None:
    try:
        from contactfem.threads import one_blas_thread

        one_blas_thread()
        from contactfem.cli import run
    except KeyboardInterrupt:
        _interrupted(" while starting; nothing was written")
    try:
        run()
    except KeyboardInterrupt:
        # The commands and the command group turn Ctrl-C into their own line and exit 130;
        # this is for one that lands outside them (between their handlers and the exit).
        _interrupted("; no result was switched in, earlier results are unchanged")


def _interrupted(outcome: str) -> None:
    """One line on stderr and exit 130, a second Ctrl-C meanwhile ignored."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except (ValueError, OSError):  # not the main thread, or no signals here
        pass
    try:
        sys.stderr.write(f"error: interrupted (SIGINT){outcome}\n")
        sys.stderr.flush()
    except (OSError, ValueError):  # stderr closed or gone: the exit code still says it
        pass
    sys.exit(_EXIT_INTERRUPTED)


if __name__ == "__main__":
    main()
