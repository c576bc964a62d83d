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
"""

from __future__ import annotations

import ctypes
import errno
import fnmatch
import json
import os
import platform
import re
import secrets
import shutil
import signal
import stat
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from contactfem import interrupts
from contactfem.errors import ExistingResultError, OutputError

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

#: Every temporary file starts with this, so leftovers of a killed process are easy to spot.
TEMP_PREFIX = ".tmp-"

#: A temporary made here: ``.tmp-<pid>-<8 hex digits>.<the final name>``.
_TEMPORARY = re.compile(r"\.tmp-([0-9]{1,10})-([0-9a-f]{8})\.(.+)", re.DOTALL)
#: A staging directory: ``.tmp-<pid>-<8 hex digits>.staging``.
_STAGING = re.compile(r"\.tmp-([0-9]{1,10})-([0-9a-f]{8})\.staging")
#: A run's token: ``<pid>-<8 hex digits>``.
_TOKEN = re.compile(r"[0-9]{1,10}-[0-9a-f]{8}")

#: The names contactfem's writers give their files (glob patterns for series whose length
#: varies). Only such names are moved in or deleted on the word of a journal read from disk.
OUTPUT_NAMES = (
    "report.json", "contact.csv",
    "solution.vtu", "contact.vtu", "solution.pvd", "solution.h5", "solution.xdmf", "solution-xdmf.h5",
    "path.pvd", "path.h5", "path.csv", "path.png", "path-*.vtu",
    "deformed.png", "contact_profile.png",
    "compare.json", "compare.png", "compare.pvd", "compare-*.vtu",
    "convergence.json", "convergence.csv", "convergence_h.png", "convergence_time.png",
    "convergence-*.pvd", "convergence-*.vtu",
    "adapt.json",
    "sweep.json", "sweep.csv", "sweep.png",
)
#: The characters of a written name (the parts a pattern leaves open are labels and numbers).
_PLAIN_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")


def is_output_name(name: object) -> bool:
    """Whether ``name`` is a plain file name that contactfem's writers produce
    (:data:`OUTPUT_NAMES`): no separator, no ``..``, not absolute, not hidden."""
    if not isinstance(name, str) or len(name) > 255 or not _PLAIN_NAME.fullmatch(name):
        return False
    return any(fnmatch.fnmatchcase(name, pattern) for pattern in OUTPUT_NAMES)


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
    for path in (directory, *directory.parents):
        if path.exists() or path.is_symlink():
            break
        if _STAGING.fullmatch(path.name):
            # Only ClaimedDirectory.stage makes a staging directory: one that is gone from
            # its path means the output directory was swapped during the run, and making it
            # again would write wherever the path leads now.
            raise OutputError(f"cannot write {path.parent}: the directory was moved or replaced during the run; "
                              "nothing was switched in")
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


def _pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (when unsure: yes, so that nothing of it is removed)."""
    if pid <= 0:
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OverflowError:
        return False  # beyond any pid the system hands out
    except OSError:  # PermissionError: it exists, another user's
        return True
    return True


def remove_leftover_temporaries(directory: Path | str) -> list[str]:
    """Remove from ``directory`` the temporary files :func:`atomic_path` made there for a
    process that is gone (``.tmp-<pid>-<token>.<name>``, not directories); nothing else,
    whatever its name. Returns the names removed."""
    removed = []
    try:
        fd = os.open(directory, _DIRECTORY_FLAGS)
    except OSError:
        return removed
    try:
        for name in os.listdir(fd):
            found = _TEMPORARY.fullmatch(name)
            if found is None or _pid_alive(int(found[1])):
                continue
            info = _lstat_at(fd, name)
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
#: starts until its files are in place; removed by its holder when the command ends.
LOCK_FILE = ".contactfem.lock"
#: Written into a staging directory once all its files are complete, when they are moved in
#: one by one (see the module's docstring): from then on the switch-over is decided, and a
#: run killed during it is completed by the next command that claims the directory.
SWITCH_FILE = ".switch.json"
#: The file inside every staging directory that marks it as made by this mechanism; it holds
#: the directory's ``<pid>-<token>``.
STAGING_MARKER = ".contactfem-staging"
#: The journal of an exchange: inside the sibling while it is built, in the output directory
#: from the exchange until the old directory is removed.
EXCHANGE_FILE = ".contactfem-exchange.json"
#: The largest journal read back (a journal lists file names only).
_JOURNAL_LIMIT = 1 << 20
#: How deep the subdirectories of an output directory may be nested for it to be exchanged.
_MAX_DEPTH = 64

_DIRECTORY_FLAGS = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0)
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)


def _reached(step: str) -> None:
    """Called as each step of a switch-over is done (the tests stop a run here)."""


def _lstat_at(directory_fd: int, name: str) -> os.stat_result | None:
    try:
        return os.stat(name, dir_fd=directory_fd, follow_symlinks=False)
    except FileNotFoundError:
        return None


def _same(a: os.stat_result | None, b: os.stat_result | None) -> bool:
    return a is not None and b is not None and (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _open_directory_at(directory_fd: int, name: str) -> int:
    """The directory ``name`` in ``directory_fd``, never through a symbolic link."""
    return os.open(name, _DIRECTORY_FLAGS | _NOFOLLOW, dir_fd=directory_fd)


def _close(fd: int | None) -> None:
    if fd is not None:
        try:
            os.close(fd)
        except OSError:
            pass


def _write_file_at(directory_fd: int, name: str, data: bytes) -> None:
    """Create ``name`` (it must not exist) in ``directory_fd`` with ``data``, synced."""
    fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o666,
                 dir_fd=directory_fd)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        os.close(fd)


def _read_file_at(directory_fd: int, name: str, limit: int = _JOURNAL_LIMIT) -> bytes | None:
    """The content of the regular file ``name`` (not through a link), or None."""
    try:
        fd = os.open(name, os.O_RDONLY | _NOFOLLOW | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0),
                     dir_fd=directory_fd)
    except OSError:
        return None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or info.st_size > limit:
            return None
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, 65536)
            if not chunk:
                return b"".join(chunks)
            chunks.append(chunk)
            size += len(chunk)
        return None
    except OSError:
        return None
    finally:
        os.close(fd)


def _remove_tree(directory_fd: int, name: str) -> None:
    """Remove ``name`` in ``directory_fd`` and all it holds, following no symbolic link."""
    info = _lstat_at(directory_fd, name)
    if info is None:
        return
    if stat.S_ISDIR(info.st_mode):
        shutil.rmtree(name, dir_fd=directory_fd)
    else:
        os.unlink(name, dir_fd=directory_fd)


def _remove_directory_held(parent_fd: int, name: str, held_fd: int) -> None:
    """Remove the directory ``name`` of ``parent_fd`` and all it holds, if it is still the
    directory held by ``held_fd`` (never whatever was put in its place)."""
    if _same(_lstat_at(parent_fd, name), os.fstat(held_fd)):
        try:
            shutil.rmtree(name, dir_fd=parent_fd)
        except OSError:
            pass


def _fsync_fd(fd: int) -> None:
    try:
        os.fsync(fd)
    except OSError:
        pass


# ----------------------------------------------------------------------------- renameat2

_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2
#: The renameat2 system call's number where libc lacks the function (glibc before 2.28).
_RENAMEAT2_SYSCALL = {"x86_64": 316, "aarch64": 276, "riscv64": 276, "i386": 353, "i686": 353,
                      "ppc64le": 357, "ppc64": 357, "s390x": 347}


def _load_renameat2():
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None
    function = getattr(libc, "renameat2", None)
    if function is not None:
        function.argtypes = (ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint)
        function.restype = ctypes.c_int
        return function
    number = _RENAMEAT2_SYSCALL.get(platform.machine())
    syscall = getattr(libc, "syscall", None)
    if number is None or syscall is None:
        return None
    syscall.restype = ctypes.c_long

    def renameat2(old_fd, old, new_fd, new, flags):
        return syscall(ctypes.c_long(number), ctypes.c_int(old_fd), ctypes.c_char_p(old), ctypes.c_int(new_fd),
                       ctypes.c_char_p(new), ctypes.c_uint(flags))

    return renameat2


_renameat2_function = _load_renameat2()


def _renameat2(old_fd: int, old: str, new_fd: int, new: str, flags: int) -> None:
    """Linux renameat2(2); OSError(ENOSYS) where it cannot be called."""
    if _renameat2_function is None:
        raise OSError(errno.ENOSYS, os.strerror(errno.ENOSYS))
    if _renameat2_function(old_fd, os.fsencode(old), new_fd, os.fsencode(new), flags) != 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code))


def _exchange(directory_fd: int, first: str, second: str) -> None:
    """Swap the entries ``first`` and ``second`` of ``directory_fd`` in one step."""
    _renameat2(directory_fd, first, directory_fd, second, _RENAME_EXCHANGE)


def _rename_without_replacing(source_fd: int, name: str, target_fd: int) -> None:
    try:
        _renameat2(source_fd, name, target_fd, name, _RENAME_NOREPLACE)
    except OSError as exc:
        if exc.errno not in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP, errno.ENOTSUP):
            raise
        if _lstat_at(target_fd, name) is not None:
            raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST)) from None
        os.rename(name, name, src_dir_fd=source_fd, dst_dir_fd=target_fd)


# ----------------------------------------------------------------------------- journals


@dataclass(frozen=True)
class _Plan:
    """The files a switch-over moves in (the last one last) and the files it removes."""

    files: tuple[str, ...]
    replaces: tuple[str, ...]
    token: str | None = None

    def dump(self) -> bytes:
        return json.dumps({"token": self.token, "files": list(self.files),
                           "replaces": list(self.replaces)}).encode("utf-8")


def _read_journal(directory_fd: int, name: str) -> _Plan | None:
    """The plan in the journal ``name``, or None if it is not one this mechanism wrote: not
    JSON, a name that is not a plain output name (:func:`is_output_name`), a token that is
    not ``<pid>-<8 hex digits>``. A journal read from disk is never trusted further than
    that; the caller checks that its token is the one it expects."""
    data = _read_file_at(directory_fd, name)
    if data is None:
        return None
    try:
        content = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        return None
    if not isinstance(content, dict):
        return None
    files, replaces, token = content.get("files"), content.get("replaces"), content.get("token")
    if not isinstance(files, list) or not isinstance(replaces, list):
        return None
    if token is not None and not (isinstance(token, str) and _TOKEN.fullmatch(token)):
        return None
    names = files + replaces
    if not all(is_output_name(n) for n in names) or len(set(names)) != len(names):
        return None
    return _Plan(tuple(files), tuple(replaces), token)


def _marked(staging_fd: int, token: str) -> bool:
    return _read_file_at(staging_fd, STAGING_MARKER, 64) == token.encode("ascii")


def _only_regular_files(directory_fd: int) -> bool:
    for name in os.listdir(directory_fd):
        info = _lstat_at(directory_fd, name)
        if info is not None and not stat.S_ISREG(info.st_mode):
            return False
    return True


def _move_in(directory_fd: int, staging_fd: int, plan: _Plan) -> None:
    """Move the plan's files from the staging directory into the output directory, then
    remove the files it replaces (idempotent: a file already moved is skipped)."""
    for name in plan.files:
        info = _lstat_at(staging_fd, name)
        if info is None:
            continue
        if not stat.S_ISREG(info.st_mode):
            raise OSError(errno.EINVAL, f"{name} in the staging area is not a regular file")
        os.replace(name, name, src_dir_fd=staging_fd, dst_dir_fd=directory_fd)
        _reached(f"moved {name}")
    for name in plan.replaces:
        info = _lstat_at(directory_fd, name)
        if info is not None and not stat.S_ISDIR(info.st_mode):
            os.unlink(name, dir_fd=directory_fd)
    _fsync_fd(directory_fd)


# ----------------------------------------------------------------------------- exchange


class _NotExchangeable(Exception):
    """The output directory cannot be rebuilt beside itself (see the module's docstring)."""


def _copy_directory_metadata(source_fd: int, target_fd: int, times: bool) -> None:
    """Give the directory ``target_fd`` the group, mode and extended attributes of
    ``source_fd`` (and its times, ``times``); _NotExchangeable where that cannot be done."""
    source = os.fstat(source_fd)
    try:
        if os.fstat(target_fd).st_gid != source.st_gid:
            os.fchown(target_fd, -1, source.st_gid)
        os.fchmod(target_fd, stat.S_IMODE(source.st_mode))
        if stat.S_IMODE(os.fstat(target_fd).st_mode) != stat.S_IMODE(source.st_mode):
            raise _NotExchangeable("mode")
        try:
            attributes = os.listxattr(source_fd)
        except OSError as exc:
            if exc.errno not in (errno.ENOTSUP, errno.EOPNOTSUPP, errno.ENOSYS):
                raise
            attributes = []
        for attribute in attributes:
            if attribute.startswith("security."):  # the kernel labels the new directory itself
                continue
            os.setxattr(target_fd, attribute, os.getxattr(source_fd, attribute))
        if times:
            os.utime(target_fd, ns=(source.st_atime_ns, source.st_mtime_ns))
    except OSError as exc:
        raise _NotExchangeable(str(exc)) from exc


def _replicate(source_fd: int, target_fd: int, skip: frozenset[str], device: int, depth: int = 0) -> None:
    """Hard-link every entry of ``source_fd`` but ``skip`` into ``target_fd``, recreating
    subdirectories (with their metadata) and linking what they hold."""
    if depth > _MAX_DEPTH:
        raise _NotExchangeable("nested too deep")
    for name in os.listdir(source_fd):
        if name in skip:
            continue
        info = _lstat_at(source_fd, name)
        if info is None:
            continue
        if info.st_dev != device:
            raise _NotExchangeable("a mount point")
        if not stat.S_ISDIR(info.st_mode):
            os.link(name, name, src_dir_fd=source_fd, dst_dir_fd=target_fd, follow_symlinks=False)
            continue
        if info.st_uid != os.geteuid():
            raise _NotExchangeable("another user's directory")
        os.mkdir(name, 0o700, dir_fd=target_fd)
        inner_source = inner_target = None
        try:
            inner_source = _open_directory_at(source_fd, name)
            inner_target = _open_directory_at(target_fd, name)
            _replicate(inner_source, inner_target, frozenset(), device, depth + 1)
            _copy_directory_metadata(inner_source, inner_target, times=True)
            os.fsync(inner_target)
        finally:
            _close(inner_source)
            _close(inner_target)


def _carry_over(old_fd: int, new_fd: int, skip: frozenset[str], depth: int = 0) -> bool:
    """Bring into the new directory what another program changed in the old one while the
    new one was built (a new file, a replaced one); False if something had to stay behind."""
    whole = True
    for name in os.listdir(old_fd):
        if name in skip:
            continue
        old = _lstat_at(old_fd, name)
        if old is None:
            continue
        new = _lstat_at(new_fd, name)
        if new is None:
            _rename_without_replacing(old_fd, name, new_fd)
        elif _same(old, new):
            continue
        elif stat.S_ISDIR(old.st_mode) and stat.S_ISDIR(new.st_mode):
            if depth >= _MAX_DEPTH:
                whole = False
                continue
            inner_old = inner_new = None
            try:
                inner_old = _open_directory_at(old_fd, name)
                inner_new = _open_directory_at(new_fd, name)
                whole = _carry_over(inner_old, inner_new, frozenset(), depth + 1) and whole
            finally:
                _close(inner_old)
                _close(inner_new)
        elif not stat.S_ISDIR(old.st_mode) and not stat.S_ISDIR(new.st_mode):
            os.replace(name, name, src_dir_fd=old_fd, dst_dir_fd=new_fd)
        else:
            whole = False
    return whole


def _sibling_name(token: str, name: str) -> str:
    return f"{TEMP_PREFIX}{token}.{name}.exchange"


def _working_directory_inside(directory_fd: int) -> bool:
    """Whether this process's working directory is the directory ``directory_fd`` or below it."""
    target = os.fstat(directory_fd)
    path = "."
    try:
        for _ in range(4096):
            here = os.stat(path)
            if _same(here, target):
                return True
            path = os.path.join(path, "..")
            if _same(os.stat(path), here):
                return False
    except OSError:
        return True  # unsure: do not exchange
    return True


# ----------------------------------------------------------------------------- the claim


class _Handle:
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
            self.fd = os.open(self.directory, _DIRECTORY_FLAGS)
        except NotADirectoryError:
            raise OutputError(f"cannot write {self.directory}: not a directory") from None
        except OSError as exc:
            raise _wrap(self.directory, exc) from exc
        parent, name = os.path.split(os.path.abspath(self.directory))
        if not name or name in (".", "..") or _renameat2_function is None:
            return
        try:
            self.parent_fd = os.open(parent or os.sep, _DIRECTORY_FLAGS)
            held = os.fstat(self.fd)
            entry = _lstat_at(self.parent_fd, name)
            self.exchangeable = (_same(entry, held) and stat.S_ISDIR(entry.st_mode)
                                 and held.st_uid == os.geteuid()
                                 and os.fstat(self.parent_fd).st_dev == held.st_dev)
        except OSError:
            self.exchangeable = False
        if self.exchangeable:
            self.name = name
        else:
            _close(self.parent_fd)
            self.parent_fd = None

    def still_here(self) -> bool:
        """Whether the directory's path (and its name in the held parent) still names the
        held directory."""
        try:
            held = os.fstat(self.fd)
            if not _same(os.stat(self.directory), held):
                return False
            return self.parent_fd is None or _same(_lstat_at(self.parent_fd, self.name), held)
        except OSError:
            return False

    def check_still_here(self) -> None:
        if not self.still_here():
            raise OutputError(f"cannot write {self.directory}: the directory was moved or replaced during the run; "
                              "nothing was switched in")

    def close(self) -> None:
        _close(self.lock_fd)
        _close(self.fd)
        _close(self.parent_fd)
        self.lock_fd = self.fd = self.parent_fd = None


class _Busy(OutputError):
    """Another run holds the directory's lock."""


def _lock(handle: _Handle) -> None:
    """Take the lock of the open directory (see :func:`claimed_directory`)."""
    import fcntl

    directory = handle.directory
    flags = os.O_RDWR | os.O_CREAT | _NOFOLLOW | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(LOCK_FILE, flags, 0o666, dir_fd=handle.fd)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputError(f"cannot write {directory}: {LOCK_FILE} is a symbolic link, which contactfem "
                              "does not follow; remove it") from None
        if exc.errno == errno.EISDIR:
            raise OutputError(f"cannot write {directory}: {LOCK_FILE} is not a regular file; remove it") from None
        raise
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OutputError(f"cannot write {directory}: {LOCK_FILE} is not a regular file; remove it")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise _Busy(f"cannot write {directory}: another contactfem run is writing into it; "
                        "wait for it to finish or choose another output directory") from None
    except BaseException:
        os.close(fd)
        raise
    handle.lock_fd = fd


def _claim(directory: Path) -> _Handle:
    """Open ``directory`` and take its lock; retried while a run that just finished swaps
    the directory or removes its lock file under us."""
    for _ in range(20):
        handle = _Handle(directory)
        try:
            handle.open()
            try:
                _lock(handle)
            except FileNotFoundError:  # the directory went away under us (an exchange)
                handle.close()
                continue
            except OSError as exc:
                raise _wrap(directory, exc) from exc
            if _same(_lstat_at(handle.fd, LOCK_FILE), os.fstat(handle.lock_fd)) and handle.still_here():
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


def _release(handle: _Handle, remove_directory: bool) -> bool:
    """Remove the lock file (if it is still ours) and release the lock. Returns whether the
    directory was left empty, with ``remove_directory``, and its path still names it (the
    caller then removes it)."""
    empty = False
    try:
        if handle.fd is not None and handle.lock_fd is not None:
            if _same(_lstat_at(handle.fd, LOCK_FILE), os.fstat(handle.lock_fd)):
                empty = remove_directory and os.listdir(handle.fd) == [LOCK_FILE] and handle.still_here()
                os.unlink(LOCK_FILE, dir_fd=handle.fd)
    except OSError:
        empty = False
    finally:
        handle.close()  # closing the lock's descriptor releases the lock
    return empty


def _recover(handle: _Handle) -> None:
    """Finish or discard what killed runs left (the lock is held, so every staging area and
    exchange here belongs to a run that is gone). Only what this mechanism provably made is
    removed, and a journal is executed only after its names are checked."""
    names = os.listdir(handle.fd)
    if EXCHANGE_FILE in names:
        _recover_exchange(handle)
    if handle.parent_fd is not None:
        _recover_siblings(handle)
    for name in names:
        info = _lstat_at(handle.fd, name)
        if info is None:
            continue
        staging = _STAGING.fullmatch(name)
        if staging is not None and stat.S_ISDIR(info.st_mode):
            _recover_staging(handle, name, f"{staging[1]}-{staging[2]}")
            continue
        temporary = _TEMPORARY.fullmatch(name)
        if temporary is not None and not stat.S_ISDIR(info.st_mode) and not _pid_alive(int(temporary[1])):
            try:
                os.unlink(name, dir_fd=handle.fd)
            except OSError:
                pass


def _recover_staging(handle: _Handle, name: str, token: str) -> None:
    """A staging directory of a run that is gone: a decided switch-over (its journal checked)
    is completed; the directory is removed if it is provably one this mechanism made (its
    marker, or, as earlier versions left them, nothing but regular files in it) and its
    process is gone. Anything else is left alone."""
    try:
        staging_fd = _open_directory_at(handle.fd, name)
    except OSError:
        return
    try:
        decided = False
        if _lstat_at(staging_fd, SWITCH_FILE) is not None:
            plan = _read_journal(staging_fd, SWITCH_FILE)
            decided = plan is not None and plan.token in (None, token) and all(
                (info := _lstat_at(staging_fd, n)) is None or stat.S_ISREG(info.st_mode) for n in plan.files)
            if decided:
                try:
                    _move_in(handle.fd, staging_fd, plan)
                except OSError as exc:
                    raise _wrap(handle.directory, exc) from exc
        gone = decided or not _pid_alive(int(token.split("-")[0]))
        if gone and (_marked(staging_fd, token) or _only_regular_files(staging_fd)):
            _remove_directory_held(handle.fd, name, staging_fd)
    finally:
        os.close(staging_fd)


def _recover_exchange(handle: _Handle) -> None:
    """An exchange was made but its old directory not yet removed: carry over and remove it."""
    plan = _read_journal(handle.fd, EXCHANGE_FILE)
    if handle.parent_fd is not None and plan is not None and plan.token is not None:
        _finish_old(handle, _sibling_name(plan.token, handle.name), plan, f"{TEMP_PREFIX}{plan.token}.staging")
    try:
        os.unlink(EXCHANGE_FILE, dir_fd=handle.fd)
    except OSError:
        pass


def _finish_old(handle: _Handle, sibling: str, plan: _Plan, staging: str) -> None:
    """Carry over from the old directory (at ``sibling``) and remove it, if it is the one
    this exchange put there (its staging directory inside, with the token's marker)."""
    try:
        old_fd = _open_directory_at(handle.parent_fd, sibling)
    except OSError:
        return
    try:
        try:
            inner = _open_directory_at(old_fd, staging)
        except OSError:
            return
        try:
            if not _marked(inner, plan.token):
                return
        finally:
            os.close(inner)
        _finish_old_directory(handle, old_fd, sibling, plan, staging)
    finally:
        os.close(old_fd)


def _recover_siblings(handle: _Handle) -> None:
    """Remove exchange siblings of this directory that were never exchanged (their journal is
    inside, with their own token) and whose process is gone."""
    pattern = re.compile(rf"{re.escape(TEMP_PREFIX)}([0-9]{{1,10}})-([0-9a-f]{{8}})\.{re.escape(handle.name)}"
                         r"\.exchange", re.DOTALL)
    try:
        names = os.listdir(handle.parent_fd)
    except OSError:
        return
    for name in names:
        found = pattern.fullmatch(name)
        if found is None or _pid_alive(int(found[1])):
            continue
        try:
            sibling_fd = _open_directory_at(handle.parent_fd, name)
        except OSError:
            continue
        try:
            plan = _read_journal(sibling_fd, EXCHANGE_FILE)
            if plan is not None and plan.token == f"{found[1]}-{found[2]}":
                _remove_directory_held(handle.parent_fd, name, sibling_fd)
        finally:
            os.close(sibling_fd)


def _is_pattern(name: str) -> bool:
    return any(character in name for character in "*?[")


class ClaimedDirectory:
    """An output directory held by this process (see :func:`claimed_directory`)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self._handle: _Handle | None = None

    def _held(self) -> _Handle:
        if self._handle is None:  # made directly, not by claimed_directory: held, not locked
            handle = _Handle(Path(self.directory))
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
            staging_fd = _open_directory_at(handle.fd, name)
            _write_file_at(staging_fd, STAGING_MARKER, token.encode("ascii"))
        except OSError as exc:
            _close(staging_fd)
            try:
                _remove_tree(handle.fd, name)
            except OSError:
                pass
            if borrowed:
                handle.close()
                self._handle = None
            raise _wrap(staging, exc) from exc
        switched = False
        try:
            yield staging
            plan = self._plan(staging_fd, replaces, last, token)
            # A stop signal whose exception was swallowed on the way (in a finalizer) still
            # stops the run here, before anything is decided.
            interrupts.stop_if_received()
            handle.check_still_here()
            if handle.exchangeable and not _working_directory_inside(handle.fd):
                switched = self._switch_by_exchange(name, staging_fd, plan)
            if not switched:
                interrupts.stop_if_received()
                with _signals_deferred():
                    handle.check_still_here()
                    try:
                        _write_file_at(staging_fd, SWITCH_FILE, plan.dump())
                        os.fsync(staging_fd)
                    except OSError as exc:
                        raise _wrap(staging, exc) from exc
                    switched = True
                    _reached("decided")
                    try:
                        _move_in(handle.fd, staging_fd, plan)
                    except OSError as exc:
                        raise _wrap(Path(self.directory), exc) from exc
                    interrupts.note_switched()
                    _reached("moved in")
                    self._remove_staging(name)
        finally:
            _close(staging_fd)
            if not switched:
                with _signals_deferred():
                    self._remove_staging(name)
            if borrowed:
                handle.close()
                self._handle = None

    def _remove_staging(self, name: str) -> None:
        try:
            _remove_tree(self._handle.fd, name)
        except OSError:
            pass

    def _plan(self, staging_fd: int, replaces: tuple[str, ...], last: str | None, token: str) -> _Plan:
        directory = Path(self.directory)
        handle = self._handle
        names = []
        for name in sorted(os.listdir(staging_fd)):
            if name in (STAGING_MARKER, SWITCH_FILE) or name.startswith(TEMP_PREFIX):
                continue
            info = _lstat_at(staging_fd, name)
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
            info = _lstat_at(handle.fd, name)
            if info is not None and stat.S_ISDIR(info.st_mode):
                raise OutputError(f"cannot write {directory / name}: a directory of that name is in the way")
        # A pattern (a series whose length varies from run to run) names every file of the
        # output directory it matches that a writer could have made; a plain name must be one.
        existing = os.listdir(handle.fd) if any(_is_pattern(r) for r in replaces) else []
        gone = []
        for pattern in replaces:
            if _is_pattern(pattern):
                matches = [n for n in fnmatch.filter(existing, pattern) if is_output_name(n)]
            elif is_output_name(pattern):
                matches = [pattern]
            else:
                raise OutputError(f"cannot write {directory}: {pattern!r} is not the name of a file contactfem writes")
            for name in matches:
                info = _lstat_at(handle.fd, name)
                if name not in names and name not in gone and info is not None and not stat.S_ISDIR(info.st_mode):
                    gone.append(name)
        return _Plan(tuple(names), tuple(gone), token)

    def _switch_by_exchange(self, staging: str, staging_fd: int, plan: _Plan) -> bool:
        """Switch the result in by exchanging the directory with a copy holding it (see the
        module's docstring). False, with nothing changed, where that cannot be done."""
        handle = self._handle
        sibling = _sibling_name(plan.token, handle.name)
        sibling_fd = None
        made = exchanged = False
        try:
            try:
                os.mkdir(sibling, 0o700, dir_fd=handle.parent_fd)
                made = True
                sibling_fd = _open_directory_at(handle.parent_fd, sibling)
                _write_file_at(sibling_fd, EXCHANGE_FILE, plan.dump())
                _reached("sibling made")
                self._fill(sibling_fd, staging, staging_fd, plan)
                _reached("sibling filled")
            except (OSError, _NotExchangeable):
                self._give_up_exchange(sibling, sibling_fd, made)
                return False
            interrupts.stop_if_received()
            with _signals_deferred():
                handle.check_still_here()
                try:
                    _exchange(handle.parent_fd, sibling, handle.name)
                except OSError:
                    self._give_up_exchange(sibling, sibling_fd, made)
                    return False
                exchanged = True
                old_fd = handle.fd
                if not (_same(_lstat_at(handle.parent_fd, sibling), os.fstat(old_fd))
                        and _same(_lstat_at(handle.parent_fd, handle.name), os.fstat(sibling_fd))):
                    # The directory was moved between the check and the exchange: undo it.
                    _exchange(handle.parent_fd, sibling, handle.name)
                    exchanged = False
                    raise OutputError(f"cannot write {self.directory}: the directory was moved or replaced "
                                      "during the run; nothing was switched in")
                handle.fd, sibling_fd = sibling_fd, None
                _fsync_fd(handle.parent_fd)
                interrupts.note_switched()
                _reached("exchanged")
                try:
                    _finish_old_directory(handle, old_fd, sibling, plan, staging)
                finally:
                    os.close(old_fd)
            return True
        except BaseException:
            if not exchanged:  # (if an exchange could not be undone, nothing is removed)
                self._give_up_exchange(sibling, sibling_fd, made)
            raise
        finally:
            _close(sibling_fd)

    def _fill(self, sibling_fd: int, staging: str, staging_fd: int, plan: _Plan) -> None:
        """Make the sibling hold what the directory will: hard links of what stays (the lock
        file too, so that the lock stays held across the exchange) and of the staged files,
        and the directory's own metadata."""
        handle = self._handle
        skip = frozenset((*plan.files, *plan.replaces, staging, EXCHANGE_FILE, SWITCH_FILE))
        _replicate(handle.fd, sibling_fd, skip, os.fstat(handle.fd).st_dev)
        if handle.lock_fd is not None and not _same(_lstat_at(sibling_fd, LOCK_FILE), os.fstat(handle.lock_fd)):
            raise _NotExchangeable("the lock file changed")
        for name in plan.files:
            file_fd = os.open(name, os.O_RDONLY | _NOFOLLOW | getattr(os, "O_CLOEXEC", 0), dir_fd=staging_fd)
            try:
                os.fsync(file_fd)
            finally:
                os.close(file_fd)
            os.link(name, name, src_dir_fd=staging_fd, dst_dir_fd=sibling_fd, follow_symlinks=False)
        _copy_directory_metadata(handle.fd, sibling_fd, times=False)
        os.fsync(sibling_fd)

    def _give_up_exchange(self, sibling: str, sibling_fd: int | None, made: bool) -> None:
        handle = self._handle
        handle.exchangeable = False
        if sibling_fd is not None:
            _remove_directory_held(handle.parent_fd, sibling, sibling_fd)
        elif made:
            try:
                os.rmdir(sibling, dir_fd=handle.parent_fd)  # made, not opened: empty
            except OSError:
                pass


def _finish_old_directory(handle: _Handle, old_fd: int, sibling: str, plan: _Plan, staging: str) -> None:
    """After an exchange: carry over what changed in the old directory meanwhile, remove it,
    then the journal (best effort: what is left is finished by the next claim)."""
    skip = frozenset((*plan.files, *plan.replaces, staging, LOCK_FILE, EXCHANGE_FILE))
    try:
        whole = _carry_over(old_fd, handle.fd, skip)
        _reached("carried over")
        if whole:
            _remove_directory_held(handle.parent_fd, sibling, old_fd)
        _reached("removed the old directory")
        os.unlink(EXCHANGE_FILE, dir_fd=handle.fd)
        _fsync_fd(handle.fd)
        _fsync_fd(handle.parent_fd)
    except OSError:
        pass


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
        handle = _claim(directory)
    except _Busy:
        raise  # the directory is another run's now, whoever made it
    except OutputError:
        _remove_created(created)
        raise
    completed = False
    try:
        probe = f"{TEMP_PREFIX}{os.getpid()}-{secrets.token_hex(4)}.probe"
        try:
            _write_file_at(handle.fd, probe, b"")
            os.unlink(probe, dir_fd=handle.fd)
        except OSError as exc:
            raise _wrap(directory, exc) from exc
        _recover(handle)
        if not overwrite:
            found = [name for name in markers if _lstat_at(handle.fd, name) is not None]
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
        with _signals_deferred():
            if _release(handle, remove_directory=bool(created) and not completed):
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
