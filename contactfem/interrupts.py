"""The stop signals a command has received, remembered where Python would lose them.

SIGINT and SIGTERM stop a command by raising KeyboardInterrupt or :class:`Interrupted` in
the main thread, wherever it is. Raised inside a finalizer (a CHOLMOD factor freed by
``weakref.finalize`` when the collector runs, a ``__del__``), that exception is printed as
"Exception ignored" and dropped: the command would go on, switch its result in and exit 0.
So the handlers installed here also record the signal; the switch-over
(:mod:`contactfem.io.atomic`) refuses to decide once one is recorded, and the command exits
as that signal, whatever swallowed its exception.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from contactfem.errors import Interrupted

__all__ = ["deferred", "listening", "note_switched", "stop_if_received", "switched"]

#: The signals received since a command began listening, the earliest first.
_received: list[int] = []
#: Whether a staged result was switched in since the command began listening.
_switched = False
#: Whether a command is listening now (outside one, library callers never see a record).
_active = False


def _stop(signum: int) -> BaseException:
    return KeyboardInterrupt() if signum == signal.SIGINT else Interrupted()


def _handle(signum: int, frame) -> None:
    _received.append(signum)
    raise _stop(signum)


def stop_if_received() -> None:
    """While a command listens, raise the first recorded signal's exception again
    (KeyboardInterrupt for SIGINT, :class:`Interrupted` for SIGTERM), so that nothing is
    decided after it."""
    if _active and _received:
        raise _stop(_received[0])


def note_switched() -> None:
    """Record that a staged result was switched in (the command's message then says so)."""
    global _switched
    if _active:
        _switched = True


def switched() -> bool:
    """Whether a result was switched in since the command began listening."""
    return _switched


@contextmanager
def listening() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM raise KeyboardInterrupt and :class:`Interrupted`
    and are recorded; an exception of theirs that Python swallows (in a finalizer) is not
    printed, since the record stands for it. Outside the main thread (an embedding
    application) signals cannot be handled here and are left alone."""
    global _switched, _active
    _received.clear()
    _switched = False
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous: dict[int, Callable | int | None] = {}
    try:
        for number in (signal.SIGINT, signal.SIGTERM):
            previous[number] = signal.signal(number, _handle)
    except (ValueError, OSError):  # no signal support here
        _restore(previous)
        yield
        return
    hook = sys.unraisablehook

    def quiet_about_stops(unraisable) -> None:
        if not isinstance(unraisable.exc_value, (KeyboardInterrupt, Interrupted)):
            hook(unraisable)

    sys.unraisablehook = quiet_about_stops
    _active = True
    try:
        yield
    finally:
        _active = False
        sys.unraisablehook = hook
        _restore(previous)


def _restore(previous: dict) -> None:
    for number, handler in previous.items():
        signal.signal(number, handler if handler is not None else signal.SIG_DFL)


#: The signals :func:`deferred` holds back.
_DEFERRED = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold back SIGINT and SIGTERM for the block (a switch-over, a lock's release), then
    deliver them (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = {}
    try:
        for number in _DEFERRED:
            previous[number] = signal.signal(number, lambda signum, frame: received.append(signum))
    except (ValueError, OSError):  # no signal support here: nothing to defer
        for number, handler in previous.items():
            signal.signal(number, handler)
        yield
        return
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    for number in received:
        signal.raise_signal(number)
