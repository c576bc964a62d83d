"""Atomic file replacement, and the claim through which every writing command puts its files
into an output directory.

One file: :func:`atomic_path` writes a temporary next to the file and renames it over the
file, so a crash or an error never leaves a half-written output file.

A result (several files): a command claims its output directory with
:func:`claimed_directory` and writes into :meth:`ClaimedDirectory.stage`. What follows is
what that mechanism does and guarantees.

The claim
    The output directory ``OUT`` is opened once and held by file descriptor for the whole
    run; every later operation on it is relative to that descriptor (``dir_fd=``), and the
    path is checked to name the same directory (device and inode) before anything is
    switched in: a directory renamed away or replaced (by a symbolic link, by another
    directory) during the run is refused, never written through. The lock is the file
    ``OUT/.contactfem.lock``, opened with ``O_NOFOLLOW`` relative to the held directory (a
    symbolic link there is refused) and locked with ``flock``; the kernel releases that lock
    when its process dies, so a lock file left by a killed run does not block the next one.
    The holder removes the lock file on every way out (success, error, KeyboardInterrupt,
    SIGTERM as :mod:`contactfem.interrupts` turns it into an exception).

Staging
    The command writes plain files into ``OUT/.tmp-<pid>-<token>.staging/`` (a fresh
    directory holding the marker file ``.contactfem-staging``). If the block raises, that
    directory is removed and nothing in ``OUT`` changes.

The switch-over: one atomic step where the file system allows it
    The new result must appear in ``OUT`` itself (``OUT/report.json`` ...), so the one step
    that can switch many files at once is to exchange the directory itself. A hidden
    sibling ``PARENT/.tmp-<pid>-<token>.<OUT name>.exchange`` is built holding what ``OUT``
    will hold: hard links of everything in ``OUT`` the run neither writes nor replaces (the
    user's files, subdirectories recreated with hard links, the lock file itself, so that
    the lock stays held), hard links of the staged files, the directory's mode, group and
    extended attributes. Then ``renameat2(RENAME_EXCHANGE)`` swaps it with ``OUT`` in one
    step: a reader that opens ``OUT`` sees either the whole old directory or the whole new
    one, never files of both. The old directory, now at the sibling's name, is removed,
    after anything created in ``OUT`` by another program while the sibling was built has
    been carried over into the new one. A run killed before the exchange leaves ``OUT`` as
    it was; one killed after it leaves the new result in place, and the next claim removes
    the old directory (its journal ``OUT/.contactfem-exchange.json`` names it).

    The exchange replaces the inodes of ``OUT`` and of the directories in it: a process
    whose working directory is one of them, or that holds one open, keeps the old
    directory and sees its files go as it is removed. Filling the sibling costs one hard
    link per entry of ``OUT``, subdirectories included.

Where atomicity cannot be had: journaled moves
    Where no exchange can be made, the staged files are moved into ``OUT`` one by one
    (the last file named by ``stage(last=...)`` last), after ``.switch.json`` in the staging
    directory has recorded the decision. A reader looking while the files are moved may see
    some new files beside old ones, and a run killed during the moves leaves that mix until
    the next contactfem command that claims the directory completes it. That is the case:

    * on any system but Linux, on Linux kernels before 3.15, or where libc has no
      ``renameat2`` and the system call's number is not known here;
    * on file systems without ``RENAME_EXCHANGE`` (NFS, SMB/CIFS, most FUSE file systems);
    * when the sibling cannot be made or filled: the parent directory is not writable, the
      sibling's name would be too long, ``OUT`` is a mount point, ``OUT`` holds a mount
      point, an entry that cannot be hard-linked (another user's file under
      ``fs.protected_hardlinks``) or directories nested deeper than 64, or extended
      attributes that cannot be copied;
    * when ``OUT`` is a symbolic link (the exchange would replace the link), or a path
      such as ``/`` without a parent, is not owned by the user running the command, or
      holds the command's own working directory.

Leftovers and names read from disk
    A claim removes only what the mechanism provably made: staging directories and
    exchange siblings by their full names (pid and random token) and the marker or journal
    inside them (with the same token), once their process is gone, and temporary files of
    :func:`atomic_path` by their full name whose process is gone. A journal is executed only
    if every name in it is a plain name (no separator, no ``..``, not absolute) that a
    contactfem writer produces (:data:`OUTPUT_NAMES`); otherwise it is ignored. Nothing is
    ever deleted or written outside ``OUT`` but exchange siblings of ``OUT`` proven so.

Where the parts are: :mod:`contactfem.io.held` holds the directory and its lock and
finishes what killed runs left, :mod:`contactfem.io.exchange` makes the exchange,
:mod:`contactfem.io.journal` has the names and journals, and :mod:`contactfem.io.dirfd` the
operations relative to a held directory and ``renameat2``.
"""

from __future__ import annotations

import fnmatch
import os
import secrets
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from contactfem import interrupts
from contactfem.errors import ExistingResultError, OutputError
from contactfem.io import dirfd, exchange, held, journal
from contactfem.io.journal import (
    EXCHANGE_FILE,
    LOCK_FILE,
    OUTPUT_NAMES,
    STAGING_MARKER,
    SWITCH_FILE,
    TEMP_PREFIX,
    is_output_name,
)

__all__ = [
    "EXCHANGE_FILE",
    "LOCK_FILE",
    "OUTPUT_NAMES",
    "STAGING_MARKER",
    "SWITCH_FILE",
    "TEMP_PREFIX",
    "ClaimedDirectory",
    "claimed_directory",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "ensure_directory",
    "is_output_name",
    "remove_leftover_temporaries",
]


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
    for path in (directory, *directory.parents):
        if path.exists() or path.is_symlink():
            break
        if journal.STAGING.fullmatch(path.name):
            # Only ClaimedDirectory.stage makes a staging directory: one that is gone from
            # its path means the output directory was swapped during the run, and making it
            # again would write wherever the path leads now.
            raise OutputError(f"cannot write {path.parent}: the directory was moved or replaced during the run; "
                              "nothing was switched in")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise dirfd.cannot_write(directory, exc) from exc
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
        raise dirfd.cannot_write(final, exc) from exc
    try:
        yield temp
        _fsync_file(temp)
        interrupts.stop_if_received()  # see ClaimedDirectory.stage
        os.replace(temp, final)
    except BaseException as exc:
        # BaseException too: an interrupted write must not leave its temporary behind.
        _remove_quietly(temp)
        if isinstance(exc, OSError):
            raise dirfd.cannot_write(final, exc) from exc
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


def remove_leftover_temporaries(directory: Path | str) -> list[str]:
    """Remove from ``directory`` the temporary files :func:`atomic_path` made there for a
    process that is gone (``.tmp-<pid>-<token>.<name>``, not directories); nothing else,
    whatever its name. Returns the names removed."""
    removed = []
    try:
        fd = os.open(directory, dirfd.DIRECTORY_FLAGS)
    except OSError:
        return removed
    try:
        for name in os.listdir(fd):
            found = journal.TEMPORARY.fullmatch(name)
            if found is None or dirfd.pid_alive(int(found[1])):
                continue
            info = dirfd.lstat_at(fd, name)
            if info is None or stat.S_ISDIR(info.st_mode):
                continue
            try:
                os.unlink(name, dir_fd=fd)
                removed.append(name)
            except OSError:
                pass
    finally:
        os.close(fd)
    return removed


class ClaimedDirectory:
    """An output directory held by this process (see :func:`claimed_directory`)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self._handle: held.Held | None = None

    def _held(self) -> held.Held:
        if self._handle is None:  # made directly, not by claimed_directory: held, not locked
            handle = held.Held(Path(self.directory))
            handle.open()
            self._handle = handle
        return self._handle

    @contextmanager
    def stage(self, replaces: tuple[str, ...] = (), last: str | None = None) -> Iterator[Path]:
        """Yield a fresh staging directory inside the output directory; on success its files
        replace the directory's in one step.

        The block writes plain files into the staging directory. When it completes, the
        files named in ``replaces`` (names, or glob patterns such as ``path-*.vtu``) that
        this run did not write are to go, and the directory is switched over: exchanged in
        one step with a copy holding the new files, or, where that cannot be done, by
        moving the files in (``last`` moved last) after a journal has decided it (see the
        module's docstring), with SIGINT and SIGTERM held back. If the block raises, the
        staging directory is removed and nothing in the output directory changes.
        """
        borrowed = self._handle is None
        handle = self._held()
        token = f"{os.getpid()}-{secrets.token_hex(4)}"
        name = f"{TEMP_PREFIX}{token}.staging"
        staging = Path(self.directory) / name
        staging_fd = None
        try:
            os.mkdir(name, 0o777, dir_fd=handle.fd)
            staging_fd = dirfd.open_directory_at(handle.fd, name)
            dirfd.write_file_at(staging_fd, STAGING_MARKER, token.encode("ascii"))
        except OSError as exc:
            dirfd.close_quietly(staging_fd)
            try:
                dirfd.remove_tree(handle.fd, name)
            except OSError:
                pass
            if borrowed:
                handle.close()
                self._handle = None
            raise dirfd.cannot_write(staging, exc) from exc
        switched = False
        try:
            yield staging
            plan = self._plan(staging_fd, replaces, last, token)
            # A stop signal whose exception was swallowed on the way (in a finalizer) still
            # stops the run here, before anything is decided.
            interrupts.stop_if_received()
            handle.check_still_here()
            if handle.exchangeable and not exchange.working_directory_inside(handle.fd):
                switched = exchange.switch_by_exchange(handle, Path(self.directory), name, staging_fd, plan)
            if not switched:
                interrupts.stop_if_received()
                with interrupts.deferred():
                    handle.check_still_here()
                    try:
                        dirfd.write_file_at(staging_fd, SWITCH_FILE, plan.dump())
                        os.fsync(staging_fd)
                    except OSError as exc:
                        raise dirfd.cannot_write(staging, exc) from exc
                    switched = True
                    dirfd.reached("decided")
                    try:
                        journal.move_in(handle.fd, staging_fd, plan)
                    except OSError as exc:
                        raise dirfd.cannot_write(Path(self.directory), exc) from exc
                    interrupts.note_switched()
                    dirfd.reached("moved in")
                    self._remove_staging(name)
        finally:
            dirfd.close_quietly(staging_fd)
            if not switched:
                with interrupts.deferred():
                    self._remove_staging(name)
            if borrowed:
                handle.close()
                self._handle = None

    def _remove_staging(self, name: str) -> None:
        try:
            dirfd.remove_tree(self._handle.fd, name)
        except OSError:
            pass

    def _plan(self, staging_fd: int, replaces: tuple[str, ...], last: str | None, token: str) -> journal.Plan:
        directory = Path(self.directory)
        handle = self._handle
        names = []
        for name in sorted(os.listdir(staging_fd)):
            if name in (STAGING_MARKER, SWITCH_FILE) or name.startswith(TEMP_PREFIX):
                continue
            info = dirfd.lstat_at(staging_fd, name)
            if info is None:
                continue
            if stat.S_ISDIR(info.st_mode):
                raise OutputError(f"cannot write {directory}: a writer left a directory in the staging area")
            if not stat.S_ISREG(info.st_mode):
                raise OutputError(f"cannot write {directory}: a writer left {name!r} in the staging area, "
                                  "not a regular file")
            if not is_output_name(name):
                raise OutputError(f"cannot write {directory}: {name!r} is not the name of a file contactfem writes")
            names.append(name)
        if last in names:
            names.remove(last)
            names.append(last)
        for name in names:
            info = dirfd.lstat_at(handle.fd, name)
            if info is not None and stat.S_ISDIR(info.st_mode):
                raise OutputError(f"cannot write {directory / name}: a directory of that name is in the way")
        # A pattern (a series whose length varies from run to run) names every file of the
        # output directory it matches that a writer could have made; a plain name must be one.
        existing = os.listdir(handle.fd) if any(journal.is_pattern(r) for r in replaces) else []
        gone = []
        for pattern in replaces:
            if journal.is_pattern(pattern):
                matches = [n for n in fnmatch.filter(existing, pattern) if is_output_name(n)]
            elif is_output_name(pattern):
                matches = [pattern]
            else:
                raise OutputError(f"cannot write {directory}: {pattern!r} is not the name of a file contactfem writes")
            for name in matches:
                info = dirfd.lstat_at(handle.fd, name)
                if name not in names and name not in gone and info is not None and not stat.S_ISDIR(info.st_mode):
                    gone.append(name)
        return journal.Plan(tuple(names), tuple(gone), token)


@contextmanager
def claimed_directory(directory: Path | str, *, markers: tuple[str, ...] = (),
                      overwrite: bool = True) -> Iterator[ClaimedDirectory]:
    """Create ``directory`` if needed, check that it is writable, and hold its lock for the block.

    Taken before any work starts, so that a run that could not write its results fails at
    once: a directory that cannot be created or written, a directory another contactfem
    run is writing into, or one that holds a finished result (any of ``markers``) when
    ``overwrite`` is false. Leftovers of killed runs are completed or removed first. The
    directory is held by file descriptor, and its lock file is removed when the block ends,
    however it ends (see the module's docstring).

    Raises
    ------
    ExistingResultError
        ``markers`` are present and ``overwrite`` is false.
    OutputError
        The directory cannot be created or written, or another run holds it, or its lock
        file is a symbolic link.
    """
    directory = Path(directory)
    created = _missing_ancestors(directory)
    directory = ensure_directory(directory)
    try:
        handle = held.take(directory)
    except held.Busy:
        raise  # the directory is another run's now, whoever made it
    except OutputError:
        _remove_created(created)
        raise
    completed = False
    try:
        probe = f"{TEMP_PREFIX}{os.getpid()}-{secrets.token_hex(4)}.probe"
        try:
            dirfd.write_file_at(handle.fd, probe, b"")
            os.unlink(probe, dir_fd=handle.fd)
        except OSError as exc:
            raise dirfd.cannot_write(directory, exc) from exc
        held.recover(handle)
        if not overwrite:
            found = [name for name in markers if dirfd.lstat_at(handle.fd, name) is not None]
            if found:
                raise ExistingResultError(f"{directory}: already holds contactfem results ({', '.join(found)}); "
                                          "pass --overwrite to replace them")
        claim = ClaimedDirectory(directory)
        claim._handle = handle
        yield claim
        completed = True
    finally:
        # A run refused or failed before writing anything leaves no directory behind (only
        # the lock's holder may remove it: another run may be working in it).
        with interrupts.deferred():
            if held.release(handle, remove_directory=bool(created) and not completed):
                _remove_created(created)


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
