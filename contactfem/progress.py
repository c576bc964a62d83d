"""Live progress on a terminal for the pipeline's ``progress(message)`` callback (rich).

The pipeline reports stages as plain messages: a message that starts without spaces
opens a stage ("meshing", "assembling", "solving with method (4) …", "writing VTU"),
an indented one is a detail of the current stage ("  1089 nodes …", "  Newton 3: …").
:class:`StageProgress` shows one line per stage with a spinner, its latest detail and
its elapsed time; a finished stage keeps its line with a tick, so the terminal ends with
a short log of where the time went. Only the command line creates one, and only when
stderr is a terminal.
"""

from __future__ import annotations

__all__ = ["StageProgress"]


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
