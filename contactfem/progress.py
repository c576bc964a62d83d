"""Progress for the pipeline's ``progress(message)`` callback: live lines on a terminal (rich), plain lines elsewhere.

The pipeline reports stages as plain messages: a message that starts without spaces
opens a stage ("meshing", "assembling", "solving with method (4) …", "writing VTU"),
an indented one is a detail of the current stage ("  1089 nodes …", "  Newton 3: …").

- :class:`StageProgress` (a terminal) shows one line per stage with a spinner, its latest
  detail and its elapsed time; a finished stage keeps its line with a tick, so the
  terminal ends with a short log of where the time went.
- :class:`PlainProgress` (a pipe, a log file, CI, a notebook) writes each message as one
  plain line, ``[  12.3 s] solving with method (4) …``, details indented. The lines of the
  first :data:`HOLD_SECONDS` are held back and written when that time has passed: a
  command that ends sooner (a quick solve, or a refusal, which stays one line) writes none.

Only the command line creates them.
"""

from __future__ import annotations

import sys
import threading
import time

__all__ = ["HOLD_SECONDS", "PlainProgress", "StageProgress"]

#: Seconds a command runs before :class:`PlainProgress` writes anything (the held lines first).
HOLD_SECONDS = 3.0


class StageProgress:
    """A callable ``progress(message)`` rendering stages with rich; call :meth:`close` at the end."""

    def __init__(self, console=None):
        from rich.console import Console
        from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        self._console = console if console is not None else Console(stderr=True)
        self._progress = Progress(
            SpinnerColumn(finished_text="[green]✓"),
            TextColumn("{task.description}"),
            TextColumn("[dim]{task.fields[detail]}"),
            TimeElapsedColumn(),
            console=self._console,
            transient=False,
        )
        self._task = None
        self._started = False
        self._closed = False

    def __call__(self, message: str) -> None:
        if self._closed:
            self._console.print(message.strip(), style="dim", highlight=False)
            return
        if not self._started:
            self._progress.start()
            self._started = True
        text = message.strip()
        if message[:1].isspace() and self._task is not None:
            self._progress.update(self._task, detail=text)
            return
        self._finish_current()
        self._task = self._progress.add_task(text, total=1, detail="")

    def _finish_current(self) -> None:
        if self._task is not None:
            self._progress.update(self._task, completed=1)

    def close(self) -> None:
        """Mark the last stage done and stop the live display (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self._started:
            self._finish_current()
            self._progress.stop()


class PlainProgress:
    """A callable ``progress(message)`` writing plain lines to ``stream`` (default: stderr).

    Each line is ``[elapsed s] message``. Until ``hold`` seconds (default
    :data:`HOLD_SECONDS`) have passed since creation, lines are kept; a timer then writes
    them and every later line is written at once. :meth:`close` stops the timer (lines still
    held are dropped: the command ended within the hold).
    """

    def __init__(self, stream=None, hold: float | None = None):
        self._stream = stream if stream is not None else sys.stderr
        self._started = time.monotonic()
        self._lock = threading.Lock()
        self._held: list[str] = []
        self._closed = False
        hold = HOLD_SECONDS if hold is None else float(hold)
        self._live = hold <= 0
        self._timer = None
        if not self._live:
            self._timer = threading.Timer(hold, self._release)
            self._timer.daemon = True
            self._timer.start()

    def __call__(self, message: str) -> None:
        line = f"[{time.monotonic() - self._started:7.1f} s] {message.rstrip()}"
        with self._lock:
            if self._closed:
                return
            if self._live:
                self._write([line])
            else:
                self._held.append(line)

    def _release(self) -> None:
        with self._lock:
            if self._closed or self._live:
                return
            self._live = True
            self._write(self._held)
            self._held = []

    def _write(self, lines: list[str]) -> None:
        if not lines:
            return
        try:
            self._stream.write("".join(line + "\n" for line in lines))
            self._stream.flush()
        except (OSError, ValueError):  # a closed or broken stream: progress is not worth an error
            pass

    def close(self) -> None:
        """Stop writing (idempotent)."""
        with self._lock:
            self._closed = True
            self._held = []
        if self._timer is not None:
            self._timer.cancel()

