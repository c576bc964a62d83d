"""Atomic file replacement, so that a crash or an error never leaves a half-written output file."""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from contactfem.errors import OutputError

__all__ = [
    "TEMP_PREFIX",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "ensure_directory",
    "staged_directory",
]

#: Every temporary file starts with this, so leftovers of a killed process are easy to spot.
TEMP_PREFIX = ".tmp-"


def _reason(exc: OSError) -> str:
    # strerror is the short human reason ("Permission denied"); libraries such as
    # h5py raise OSError with only a message, which str() gives.
    return exc.strerror or str(exc)


def _wrap(final: Path, exc: OSError) -> OutputError:
    return OutputError(f"cannot write {final}: {_reason(exc)}")


def _create_temp(final: Path) -> Path:
    """Create an empty, uniquely named file next to ``final`` and return its path."""
    for _ in range(100):
        # The real name stays at the end so that libraries choosing a format from the
        # suffix still see ".vtu" or ".h5"; the leading dot hides it from listings.
        candidate = final.with_name(
            f"{TEMP_PREFIX}{os.getpid()}-{secrets.token_hex(4)}.{final.name}"
        )
        try:
            # O_EXCL reserves the name; 0o666 (minus the umask) gives the permissions a
            # plain open() would, unlike mkstemp's 0o600.
            fd = os.open(candidate, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return candidate
    raise FileExistsError(f"no free temporary name next to {final}")


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_directory(directory: Path) -> None:
    # Makes the rename itself durable. Some platforms and file systems cannot open or
    # fsync a directory; the file is already in place then, so this is best effort.
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _remove_quietly(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    except OSError:
        # Cleanup must not hide the error that made us clean up.
        pass


def ensure_directory(directory: Path | str) -> Path:
    """Create ``directory`` (and its parents) if needed.

    Parameters
    ----------
    directory : Path or str

    Returns
    -------
    Path
        ``directory``.

    Raises
    ------
    OutputError
        If it cannot be created, or exists and is not a directory.
    """
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _wrap(directory, exc) from exc
    return directory


@contextmanager
def atomic_path(final: Path | str) -> Iterator[Path]:
    """Yield a temporary path that replaces ``final`` only if the block completes.

    The temporary file is created (empty) in the directory of ``final``, named
    ``.tmp-<pid>-<random>.<final name>`` so that its suffix is the real one. On normal
    exit of the ``with`` block it is flushed to disk and renamed onto ``final`` with
    :func:`os.replace`, which is atomic on POSIX and Windows: readers see either the
    old file or the complete new one. If the block raises, the temporary file is
    deleted and an existing ``final`` is left untouched.

    Parameters
    ----------
    final : Path or str
        The file to create or replace. Its directory must exist.

    Yields
    ------
    Path
        The temporary path to write to; the caller may truncate or overwrite it.

    Raises
    ------
    OutputError
        If the temporary file cannot be created, synced or renamed, or if the block
        raises :class:`OSError` (``"cannot write <final>: <reason>"``). Any other
        exception of the block is re-raised unchanged after the cleanup.
    """
    final = Path(final)
    try:
        temp = _create_temp(final)
    except OSError as exc:
        raise _wrap(final, exc) from exc
    try:
        yield temp
        _fsync_file(temp)
        os.replace(temp, final)
    except BaseException as exc:
        # BaseException too: an interrupted write must not leave its temporary behind.
        _remove_quietly(temp)
        if isinstance(exc, OSError):
            raise _wrap(final, exc) from exc
        raise
    _fsync_directory(final.parent)


def atomic_write_bytes(final: Path | str, data: bytes) -> Path:
    """Write ``data`` to ``final`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    final : Path or str
        The file to create or replace.
    data : bytes
        The whole content.

    Returns
    -------
    Path
        ``final``.

    Raises
    ------
    OutputError
        If the file cannot be written.
    """
    final = Path(final)
    with atomic_path(final) as temp:
        temp.write_bytes(data)
    return final


def atomic_write_text(final: Path | str, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``final`` atomically, encoded without newline translation.

    Parameters
    ----------
    final : Path or str
        The file to create or replace.
    text : str
        The whole content.
    encoding : str, default "utf-8"

    Returns
    -------
    Path
        ``final``.

    Raises
    ------
    OutputError
        If the file cannot be written.
    """
    return atomic_write_bytes(final, text.encode(encoding))


@contextmanager
def _sigint_deferred() -> Iterator[None]:
    """Hold back SIGINT for the duration of the block, then deliver it (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    try:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    except (ValueError, OSError):  # no signal support here: nothing to defer
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        raise KeyboardInterrupt


@contextmanager
def staged_directory(directory: Path | str, replaces: tuple[str, ...] = (), last: str | None = None) -> Iterator[Path]:
    """Yield a fresh staging directory whose files land together in ``directory`` on success.

    The staging directory is a hidden sibling of ``directory`` (same file system), named
    ``.tmp-<pid>-<random>.<name>``. When the block completes, each of its files is moved
    onto ``directory`` with :func:`os.replace` (``last`` moved last, e.g. the report that
    marks a complete result), with SIGINT held back until the moves are done; then the
    files named in ``replaces`` that the run did not write are deleted, so that no stale
    file of an earlier run stays next to the new ones. If the block raises (an error,
    KeyboardInterrupt), nothing in ``directory`` changes. The staging directory is always
    removed.

    Raises
    ------
    OutputError
        If a directory cannot be created or a file cannot be moved.
    """
    directory = ensure_directory(directory)
    staging = None
    for _ in range(100):
        candidate = directory.parent / f"{TEMP_PREFIX}{os.getpid()}-{secrets.token_hex(4)}.{directory.name}"
        try:
            candidate.mkdir()
        except FileExistsError:
            continue
        except OSError as exc:
            raise _wrap(candidate, exc) from exc
        staging = candidate
        break
    if staging is None:
        raise OutputError(f"cannot write {directory}: no free temporary name next to it")
    try:
        yield staging
        names = sorted(p.name for p in staging.iterdir())
        if last in names:
            names.remove(last)
            names.append(last)
        with _sigint_deferred():
            try:
                for name in names:
                    os.replace(staging / name, directory / name)
                for name in replaces:
                    if name not in names:
                        _remove_quietly(directory / name)
            except OSError as exc:
                raise _wrap(directory, exc) from exc
            _fsync_directory(directory)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
