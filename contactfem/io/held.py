"""The output directory held by file descriptor, its lock, and what a claim finishes or
removes of killed runs (:mod:`contactfem.io.atomic` describes the mechanism)."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from contactfem.errors import OutputError
from contactfem.io import dirfd, exchange, journal


class Held:
    """The output directory held open: its descriptor, its parent's and its name there (when
    it can be exchanged), and the lock's descriptor."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.fd: int | None = None
        self.parent_fd: int | None = None
        self.name: str | None = None
        self.lock_fd: int | None = None
        self.exchangeable = False

    def open(self) -> None:
        """Open the directory as its path names it now, and its parent when the last
        component is a directory (not a symbolic link) that this process owns, on the
        parent's file system: only then may it be exchanged."""
        try:
            self.fd = os.open(self.directory, dirfd.DIRECTORY_FLAGS)
        except NotADirectoryError:
            raise OutputError(f"cannot write {self.directory}: not a directory") from None
        except OSError as exc:
            raise dirfd.cannot_write(self.directory, exc) from exc
        parent, name = os.path.split(os.path.abspath(self.directory))
        if not name or name in (".", "..") or dirfd.renameat2_function is None:
            return
        try:
            self.parent_fd = os.open(parent or os.sep, dirfd.DIRECTORY_FLAGS)
            held = os.fstat(self.fd)
            entry = dirfd.lstat_at(self.parent_fd, name)
            self.exchangeable = (dirfd.same_file(entry, held) and stat.S_ISDIR(entry.st_mode)
                                 and held.st_uid == os.geteuid()
                                 and os.fstat(self.parent_fd).st_dev == held.st_dev)
        except OSError:
            self.exchangeable = False
        if self.exchangeable:
            self.name = name
        else:
            dirfd.close_quietly(self.parent_fd)
            self.parent_fd = None

    def still_here(self) -> bool:
        """Whether the directory's path (and its name in the held parent) still names the
        held directory."""
        try:
            held = os.fstat(self.fd)
            if not dirfd.same_file(os.stat(self.directory), held):
                return False
            return self.parent_fd is None or dirfd.same_file(dirfd.lstat_at(self.parent_fd, self.name), held)
        except OSError:
            return False

    def check_still_here(self) -> None:
        if not self.still_here():
            raise OutputError(f"cannot write {self.directory}: the directory was moved or replaced during the run; "
                              "nothing was switched in")

    def close(self) -> None:
        dirfd.close_quietly(self.lock_fd)
        dirfd.close_quietly(self.fd)
        dirfd.close_quietly(self.parent_fd)
        self.lock_fd = self.fd = self.parent_fd = None


class Busy(OutputError):
    """Another run holds the directory's lock."""


def lock(handle: Held) -> None:
    """Take the lock of the open directory (see :func:`contactfem.io.atomic.claimed_directory`)."""
    import fcntl

    directory = handle.directory
    flags = os.O_RDWR | os.O_CREAT | dirfd.NOFOLLOW | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(journal.LOCK_FILE, flags, 0o666, dir_fd=handle.fd)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputError(f"cannot write {directory}: {journal.LOCK_FILE} is a symbolic link, which "
                              "contactfem does not follow; remove it") from None
        if exc.errno == errno.EISDIR:
            raise OutputError(f"cannot write {directory}: {journal.LOCK_FILE} is not a regular file; "
                              "remove it") from None
        raise
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OutputError(f"cannot write {directory}: {journal.LOCK_FILE} is not a regular file; remove it")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise Busy(f"cannot write {directory}: another contactfem run is writing into it; "
                       "wait for it to finish or choose another output directory") from None
    except BaseException:
        os.close(fd)
        raise
    handle.lock_fd = fd


def take(directory: Path) -> Held:
    """Open ``directory`` and take its lock; retried while a run that just finished swaps
    the directory or removes its lock file under us."""
    for _ in range(20):
        handle = Held(directory)
        try:
            handle.open()
            try:
                lock(handle)
            except FileNotFoundError:  # the directory went away under us (an exchange)
                handle.close()
                continue
            except OSError as exc:
                raise dirfd.cannot_write(directory, exc) from exc
            named = dirfd.lstat_at(handle.fd, journal.LOCK_FILE)
            if dirfd.same_file(named, os.fstat(handle.lock_fd)) and handle.still_here():
                try:
                    os.ftruncate(handle.lock_fd, 0)
                    os.write(handle.lock_fd, f"{os.getpid()}\n".encode("ascii"))
                except OSError:
                    pass  # the pid is for people only
                return handle
        except BaseException:
            handle.close()
            raise
        handle.close()
    raise OutputError(f"cannot write {directory}: its lock changed hands too often; try again")


def release(handle: Held, remove_directory: bool) -> bool:
    """Remove the lock file (if it is still ours) and release the lock. Returns whether the
    directory was left empty, with ``remove_directory``, and its path still names it (the
    caller then removes it)."""
    empty = False
    try:
        if handle.fd is not None and handle.lock_fd is not None:
            if dirfd.same_file(dirfd.lstat_at(handle.fd, journal.LOCK_FILE), os.fstat(handle.lock_fd)):
                empty = (remove_directory and os.listdir(handle.fd) == [journal.LOCK_FILE]
                         and handle.still_here())
                os.unlink(journal.LOCK_FILE, dir_fd=handle.fd)
    except OSError:
        empty = False
    finally:
        handle.close()  # closing the lock's descriptor releases the lock
    return empty


def recover(handle: Held) -> None:
    """Finish or discard what killed runs left (the lock is held, so every staging area and
    exchange here belongs to a run that is gone). Only what this mechanism provably made is
    removed, and a journal is executed only after its names are checked."""
    names = os.listdir(handle.fd)
    if journal.EXCHANGE_FILE in names:
        exchange.recover_exchange(handle)
    if handle.parent_fd is not None:
        exchange.recover_siblings(handle)
    for name in names:
        info = dirfd.lstat_at(handle.fd, name)
        if info is None:
            continue
        staging = journal.STAGING.fullmatch(name)
        if staging is not None and stat.S_ISDIR(info.st_mode):
            recover_staging(handle, name, f"{staging[1]}-{staging[2]}")
            continue
        temporary = journal.TEMPORARY.fullmatch(name)
        if temporary is not None and not stat.S_ISDIR(info.st_mode) and not dirfd.pid_alive(int(temporary[1])):
            try:
                os.unlink(name, dir_fd=handle.fd)
            except OSError:
                pass


def recover_staging(handle: Held, name: str, token: str) -> None:
    """A staging directory of a run that is gone: a decided switch-over (its journal checked)
    is completed; the directory is removed if it is provably one this mechanism made (its
    marker, or, as earlier versions left them, nothing but regular files in it) and its
    process is gone. Anything else is left alone."""
    try:
        staging_fd = dirfd.open_directory_at(handle.fd, name)
    except OSError:
        return
    try:
        decided = False
        if dirfd.lstat_at(staging_fd, journal.SWITCH_FILE) is not None:
            plan = journal.read_journal(staging_fd, journal.SWITCH_FILE)
            decided = plan is not None and plan.token in (None, token) and all(
                (info := dirfd.lstat_at(staging_fd, n)) is None or stat.S_ISREG(info.st_mode) for n in plan.files)
            if decided:
                try:
                    journal.move_in(handle.fd, staging_fd, plan)
                except OSError as exc:
                    raise dirfd.cannot_write(handle.directory, exc) from exc
        gone = decided or not dirfd.pid_alive(int(token.split("-")[0]))
        if gone and (journal.marked(staging_fd, token) or journal.only_regular_files(staging_fd)):
            dirfd.remove_directory_held(handle.fd, name, staging_fd)
    finally:
        os.close(staging_fd)
