"""Atomic file replacement, so that a crash or an error never leaves a half-written output file."""

from __future__ import annotations

import fnmatch
import json
import os
import secrets
import shutil
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from contactfem import interrupts
from contactfem.errors import ExistingResultError, OutputError

__all__ = [
    "LOCK_FILE",
    "TEMP_PREFIX",
    "ClaimedDirectory",
    "claimed_directory",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "ensure_directory",
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
        interrupts.stop_if_received()  # see ClaimedDirectory.stage
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


#: The signals held back while a staged result is switched in.
_DEFERRED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold back SIGINT and SIGTERM for the block, then deliver them (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = {}
    try:
        for number in _DEFERRED_SIGNALS:
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


#: The lock every writing command holds on its output directory from before its work
#: starts until its files are in place.
LOCK_FILE = ".contactfem.lock"
#: Written into a staging directory once all its files are complete: from then on the
#: switch-over is decided, and a run killed during it is completed by the next command
#: that claims the directory.
SWITCH_FILE = ".switch.json"


class ClaimedDirectory:
    """An output directory held by this process (see :func:`claimed_directory`)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    @contextmanager
    def stage(self, replaces: tuple[str, ...] = (), last: str | None = None) -> Iterator[Path]:
        """Yield a fresh staging directory inside the output directory; on success its files
        replace the directory's in one decided step.

        The block writes plain files into the staging directory. When it completes, a
        switch file listing them is written and synced: that single atomic rename decides
        the switch-over. The files are then moved into place with :func:`os.replace`
        (``last`` moved last), the files named in ``replaces`` (names, or glob patterns
        such as ``path-*.vtu``) that this run did not write are deleted, and the staging directory is removed, with SIGINT and SIGTERM held back.
        If the block raises, the staging directory is removed and nothing in the output
        directory changes. If the process dies after the decision, the next claim completes
        the switch-over; if before, it removes the staging directory.
        """
        staging = _fresh_name(self.directory, "staging")
        try:
            staging.mkdir()
        except OSError as exc:
            raise _wrap(staging, exc) from exc
        decided = False
        try:
            yield staging
            names = sorted(p.name for p in staging.iterdir() if not p.name.startswith(TEMP_PREFIX))
            if any((staging / name).is_dir() for name in names):
                raise OutputError(f"cannot write {self.directory}: a writer left a directory in the staging area")
            if last in names:
                names.remove(last)
                names.append(last)
            # A pattern (a series whose length varies from run to run) names every file
            # of the output directory it matches.
            existing = [p.name for p in self.directory.iterdir()] if any(_is_pattern(r) for r in replaces) else []
            expanded = [name for pattern in replaces
                        for name in (fnmatch.filter(existing, pattern) if _is_pattern(pattern) else [pattern])]
            plan = {"files": names, "replaces": [name for name in expanded if name not in names]}
            # A stop signal whose exception was swallowed on the way (in a finalizer) still
            # stops the run here, before anything is decided.
            interrupts.stop_if_received()
            with _signals_deferred():
                atomic_write_text(staging / SWITCH_FILE, json.dumps(plan))
                _fsync_directory(staging)
                decided = True
                _switch(staging, self.directory)
                interrupts.note_switched()
        finally:
            if not decided:
                shutil.rmtree(staging, ignore_errors=True)


def _is_pattern(name: str) -> bool:
    return any(character in name for character in "*?[")


def _fresh_name(directory: Path, label: str) -> Path:
    return directory / f"{TEMP_PREFIX}{os.getpid()}-{secrets.token_hex(4)}.{label}"


def _switch(staging: Path, directory: Path) -> None:
    """Carry out a decided switch-over (idempotent: a file already moved is skipped)."""
    plan = json.loads((staging / SWITCH_FILE).read_text(encoding="utf-8"))
    try:
        for name in plan["files"]:
            if (staging / name).exists():
                os.replace(staging / name, directory / name)
        for name in plan["replaces"]:
            _remove_quietly(directory / name)
    except OSError as exc:
        raise _wrap(directory, exc) from exc
    _fsync_directory(directory)
    shutil.rmtree(staging, ignore_errors=True)


def _recover(directory: Path) -> None:
    """Finish or discard what killed runs left in ``directory`` (its lock is held, so every
    staging area and temporary file here belongs to a run that is gone)."""
    for leftover in directory.glob(f"{TEMP_PREFIX}*"):
        if leftover.is_dir() and (leftover / SWITCH_FILE).is_file():
            try:
                json.loads((leftover / SWITCH_FILE).read_text(encoding="utf-8"))
            except (OSError, ValueError):
                shutil.rmtree(leftover, ignore_errors=True)  # the decision itself was never written whole
                continue
            _switch(leftover, directory)
        elif leftover.is_dir():
            shutil.rmtree(leftover, ignore_errors=True)
        else:
            _remove_quietly(leftover)


@contextmanager
def claimed_directory(directory: Path | str, *, markers: tuple[str, ...] = (),
                      overwrite: bool = True) -> Iterator[ClaimedDirectory]:
    """Create ``directory`` if needed, check that it is writable, and hold its lock for the block.

    Taken before any work starts, so that a run that could not write its results fails at
    once: a directory that cannot be created or written, a directory another contactfem
    run is writing into, or one that holds a finished result (any of ``markers``) when
    ``overwrite`` is false. Leftovers of killed runs are completed or removed first.

    Raises
    ------
    ExistingResultError
        ``markers`` are present and ``overwrite`` is false.
    OutputError
        The directory cannot be created or written, or another run holds it.
    """
    import fcntl

    directory = Path(directory)
    created = _missing_ancestors(directory)
    directory = ensure_directory(directory)
    if not directory.is_dir():
        raise OutputError(f"cannot write {directory}: not a directory")
    lock = directory / LOCK_FILE
    try:
        fd = os.open(lock, os.O_CREAT | os.O_RDWR, 0o666)
    except OSError as exc:
        _remove_created(created)
        raise _wrap(directory, exc) from exc
    switched = locked = False
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            locked = True
        except BlockingIOError:
            raise OutputError(f"cannot write {directory}: another contactfem run is writing into it; "
                              "wait for it to finish or choose another output directory") from None
        except OSError as exc:
            raise _wrap(directory, exc) from exc
        probe = _fresh_name(directory, "probe")
        try:
            probe.touch(exist_ok=False)
            probe.unlink()
        except OSError as exc:
            raise _wrap(directory, exc) from exc
        _recover(directory)
        if not overwrite:
            found = [name for name in markers if (directory / name).exists()]
            if found:
                raise ExistingResultError(f"{directory}: already holds contactfem results ({', '.join(found)}); "
                                          "pass --overwrite to replace them")
        claim = ClaimedDirectory(directory)
        yield claim
        switched = True
    finally:
        if locked and not switched and created and not any(p.name != LOCK_FILE for p in directory.iterdir()):
            # A run refused or failed before writing anything leaves no directory behind (only
            # the lock's holder may remove it: another run may be working in it).
            _remove_quietly(lock)
            _remove_created(created)
        os.close(fd)  # closing the descriptor releases the lock


def _missing_ancestors(directory: Path) -> list[Path]:
    """``directory`` and its ancestors that do not exist yet, deepest first."""
    missing = []
    for path in (directory, *directory.parents):
        if path.exists() or path.is_symlink():
            break
        missing.append(path)
    return missing


def _remove_created(created: list[Path]) -> None:
    for path in created:  # deepest first; stops at the first that is not empty
        try:
            path.rmdir()
        except OSError:
            return
