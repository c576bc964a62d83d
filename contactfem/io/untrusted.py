"""The shared pieces of reading a file as untrusted input: opening it (a regular file, its
size from the descriptor that is read), reading it with a bound, and the one-line refusals
(:class:`~contactfem.errors.ArchiveError`) that name the file, the dataset or key, and what
was expected. Used by :mod:`contactfem.io.archive` (HDF5) and
:mod:`contactfem.io.json_layout` (JSON)."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import numpy as np

from contactfem.errors import ArchiveError

__all__ = ["MAX_MAGNITUDE", "Where", "number_text", "open_regular", "read_all", "reason", "shortened"]

#: Numbers that must be finite must also be at most this large in magnitude, so that
#: squares and products of them stay finite in float64.
MAX_MAGNITUDE = 1e100


# --------------------------------------------------------------------------- messages


def shortened(text: str, limit: int = 120) -> str:
    if len(text) <= limit:
        return text
    tail = (limit - 3) * 2 // 3
    return text[: limit - 3 - tail] + "..." + text[-tail:]


def number_text(value: Any) -> str:
    """A number as a message shows it (``nan``, ``-1000000000``, ``1e+300``)."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return f"{float(value):.6g}"


def reason(error: BaseException) -> str:
    """An HDF5 or OS error's reason, on one short line."""
    text = getattr(error, "strerror", None) or str(error) or type(error).__name__
    return shortened(" ".join(str(text).split()), 160)


class Where:
    """The file being read, for the one-line refusals."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.shown = shortened(str(path))

    def fail(self, where: str, problem: str) -> ArchiveError:
        return ArchiveError(f"{self.shown}: {where}: {problem}" if where else f"{self.shown}: {problem}")


# --------------------------------------------------------------------------- the file


def open_regular(path: Path | str, what: str) -> tuple[int, int]:
    """Open ``path`` for reading: (descriptor, size in bytes). Refused unless it is a
    regular, non-empty file; the size is the opened file's, not the name's."""
    where = Where(Path(path))
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except (OSError, ValueError) as error:
        raise where.fail("", f"cannot be opened ({reason(error)}); expected {what}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = "a directory" if stat.S_ISDIR(info.st_mode) else "not a regular file"
            raise where.fail("", f"is {kind}; expected {what}")
        if info.st_size == 0:
            raise where.fail("", f"is empty; expected {what}")
    except BaseException:
        os.close(fd)
        raise
    return fd, info.st_size


def read_all(fd: int, size: int, where: Where, what: str) -> bytes:
    chunks, total = [], 0
    while total <= size:
        chunk = os.read(fd, size + 1 - total)
        if not chunk:
            break
        chunks.append(chunk)
        total += len(chunk)
    if total > size:
        raise where.fail("", f"grew while it was read; expected {what}")
    return b"".join(chunks)
