"""How errors leave the command line: one ``error:`` line on stderr and an exit code, never a traceback."""

from __future__ import annotations

import sys

import click

from contactfem.errors import (
    ArchiveError,
    CaseError,
    ContactFemError,
    ExistingResultError,
    FactorCapacityError,
    Interrupted,
    MeshError,
)


EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports it
EXIT_TERMINATED = 143  # 128 + SIGTERM


def _exit_code(error: ContactFemError) -> int:
    return EXIT_BAD_INPUT if isinstance(error, (CaseError, MeshError, ArchiveError, ExistingResultError)) else EXIT_FAILURE


def _fail(error: ContactFemError) -> None:
    click.echo(f"error: {_printable(str(error))}", err=True)
    sys.exit(_exit_code(error))


def _printable(text: str) -> str:
    """Escape control and separator characters a case file may carry into a message
    (a key with a record separator would otherwise split the one-line error), and show a
    byte of a file name that is not UTF-8 (a surrogate U+DC80..U+DCFF) as ``\\xNN``, the
    byte, as :func:`contactfem.io.registry.shown_text` does."""
    return "".join(c if c.isprintable() else f"\\x{ord(c) - 0xDC00:02x}" if 0xDC80 <= ord(c) <= 0xDCFF
                   else repr(c)[1:-1] for c in text)


def _shown(path) -> str:
    """A path for a line on stdout or stderr (see :func:`_printable`)."""
    import os

    return _printable(os.fsdecode(path))


def _interruptible(command):
    """Turn Ctrl-C (SIGINT) and SIGTERM into one line on stderr and exit code 130 or 143,
    and memory exhaustion into one line and exit 1, without a traceback; keep numpy's
    RuntimeWarnings off stderr (errors stay one line).

    Outputs are staged and switched in by one decided step (see io.atomic.claimed_directory),
    so an interrupted run leaves the results of an earlier one as they were.
    """
    import functools

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        import warnings

        from contactfem import interrupts

        def interrupted(cause: BaseException):
            if isinstance(cause, KeyboardInterrupt):
                word, name, code = "interrupted", "SIGINT", EXIT_INTERRUPTED
            else:
                word, name, code = "terminated", "SIGTERM", EXIT_TERMINATED
            if interrupts.switched():
                outcome = "the results were switched in before it and are complete"
            else:
                outcome = "no result was switched in, earlier results are unchanged"
            click.echo(f"error: {word} ({name}); {outcome}", err=True)
            sys.exit(code)

        try:
            # Overflow and 0/0 in numpy are caught by the finiteness checks and refused
            # with one line naming the key; numpy's own warnings would only add noise.
            with interrupts.listening(), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                result = command(*args, **kwargs)
                # A signal whose exception a finalizer swallowed: the switch-over refused to
                # decide after it, and the command ends as that signal all the same.
                interrupts.stop_if_received()
                return result
        except (KeyboardInterrupt, Interrupted) as signalled:
            interrupted(signalled)
        except MemoryError as error:
            if isinstance(error, FactorCapacityError):  # which limit, and what to do, in its words
                click.echo(f"error: {error}; nothing was written", err=True)
            else:
                click.echo("error: out of memory; nothing was written; use a coarser mesh (fewer divisions, "
                           "a larger mesh.size or fewer refinements)", err=True)
            sys.exit(EXIT_FAILURE)
        except ImportError as error:
            # The writers and pictures load their libraries (h5py, matplotlib, Dask) only when
            # they run, so one missing from the install, or one that cannot be mapped under an
            # address-space limit, fails late: the stage that needed it says so.
            text = str(error).strip()
            reason = text.splitlines()[0] if text else type(error).__name__
            outcome = ("the results were switched in before it and are complete" if interrupts.switched()
                       else "no result was switched in, earlier results are unchanged")
            click.echo(f"error: cannot load {error.name or 'a library'} ({reason}); {outcome}", err=True)
            sys.exit(EXIT_FAILURE)
        except Exception as error:
            # A signal that lands inside the interpreter's own locking (a worker thread being
            # started waits on a Condition) surfaces as another error, raised while its
            # exception unwinds ("release unlocked lock"): it is still that signal.
            cause = _interruption_behind(error)
            if cause is None:
                raise
            interrupted(cause)

    return wrapper


def _interruption_behind(error: BaseException) -> BaseException | None:
    """The KeyboardInterrupt or SIGTERM's :class:`Interrupted` that ``error`` was raised while
    handling (its chain of causes and contexts), or None."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        if isinstance(current, (KeyboardInterrupt, Interrupted)):
            return current
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return None


class _Stopped(BaseException):
    """Ctrl-C outside a command's own handling, carried past click's handler (which would
    print an empty line on stderr before its Abort) to :meth:`_OneLineErrors.main`."""


class _OneLineErrors(click.Group):
    """Usage errors (an unknown option, a bad value, a missing argument) as one ``error:`` line and
    exit 2, like every other bad input; Ctrl-C outside a command's own handling (while the
    options are parsed and their values checked, which imports the case reader) as one line
    and exit 130."""

    def make_context(self, *args, **kwargs):
        try:
            return super().make_context(*args, **kwargs)
        except KeyboardInterrupt:
            raise _Stopped() from None

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            raise _Stopped() from None

    def main(self, *args, **kwargs):
        kwargs["standalone_mode"] = False
        try:
            return super().main(*args, **kwargs)
        except click.UsageError as error:
            if type(error).__name__ == "NoArgsIsHelpError":  # bare `contactfem`: the help is the answer
                click.echo(error.ctx.get_help() if error.ctx else error.format_message())
                sys.exit(0)
            where = error.ctx.command_path if error.ctx else "contactfem"
            click.echo(f"error: {where}: {_printable(error.format_message())} (see --help)", err=True)
            sys.exit(EXIT_BAD_INPUT)
        except click.ClickException as error:
            click.echo(f"error: {_printable(error.format_message())}", err=True)
            sys.exit(error.exit_code)
        except (click.Abort, KeyboardInterrupt, _Stopped):
            click.echo("error: interrupted (SIGINT); no result was switched in, earlier results are unchanged",
                       err=True)
            sys.exit(EXIT_INTERRUPTED)
        except click.exceptions.Exit as done:  # --help, --version
            sys.exit(done.exit_code)
