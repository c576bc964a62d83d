"""File operations relative to a held directory, for the output directory's claim
(:mod:`contactfem.io.atomic`): nothing here follows a symbolic link it is not told to, and
the Linux ``renameat2`` system call, reached through ctypes, exchanges two names in one step.
"""

from __future__ import annotations

import ctypes
import errno
import os
import platform
import shutil
import stat
import sys
from pathlib import Path

from contactfem.errors import OutputError

#: Open a directory (never for writing, never inherited by a child process).
DIRECTORY_FLAGS = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0)
NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
#: The largest file read back (a journal lists file names only).
READ_LIMIT = 1 << 20


def reason(exc: OSError) -> str:
    # strerror is the short human reason ("Permission denied"); libraries such as
    # h5py raise OSError with only a message, which str() gives.
    return exc.strerror or str(exc)


def cannot_write(final: Path, exc: OSError) -> OutputError:
    return OutputError(f"cannot write {final}: {reason(exc)}")


def reached(step: str) -> None:
    """Called as each step of a switch-over is done (the tests stop a run here)."""


def lstat_at(directory_fd: int, name: str) -> os.stat_result | None:
    try:
        return os.stat(name, dir_fd=directory_fd, follow_symlinks=False)
    except FileNotFoundError:
        return None


def same_file(a: os.stat_result | None, b: os.stat_result | None) -> bool:
    return a is not None and b is not None and (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def open_directory_at(directory_fd: int, name: str) -> int:
    """The directory ``name`` in ``directory_fd``, never through a symbolic link."""
    return os.open(name, DIRECTORY_FLAGS | NOFOLLOW, dir_fd=directory_fd)


def close_quietly(fd: int | None) -> None:
    if fd is not None:
        try:
            os.close(fd)
        except OSError:
            pass


def write_file_at(directory_fd: int, name: str, data: bytes) -> None:
    """Create ``name`` (it must not exist) in ``directory_fd`` with ``data``, synced."""
    fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o666,
                 dir_fd=directory_fd)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        os.close(fd)


def read_file_at(directory_fd: int, name: str, limit: int = READ_LIMIT) -> bytes | None:
    """The content of the regular file ``name`` (not through a link), or None."""
    try:
        fd = os.open(name, os.O_RDONLY | NOFOLLOW | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0),
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


def remove_tree(directory_fd: int, name: str) -> None:
    """Remove ``name`` in ``directory_fd`` and all it holds, following no symbolic link."""
    info = lstat_at(directory_fd, name)
    if info is None:
        return
    if stat.S_ISDIR(info.st_mode):
        shutil.rmtree(name, dir_fd=directory_fd)
    else:
        os.unlink(name, dir_fd=directory_fd)


def remove_directory_held(parent_fd: int, name: str, held_fd: int) -> None:
    """Remove the directory ``name`` of ``parent_fd`` and all it holds, if it is still the
    directory held by ``held_fd`` (never whatever was put in its place)."""
    if same_file(lstat_at(parent_fd, name), os.fstat(held_fd)):
        try:
            shutil.rmtree(name, dir_fd=parent_fd)
        except OSError:
            pass


def fsync_fd(fd: int) -> None:
    try:
        os.fsync(fd)
    except OSError:
        pass


def pid_alive(pid: int) -> bool:
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


RENAME_NOREPLACE = 1
RENAME_EXCHANGE = 2
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


renameat2_function = _load_renameat2()


def renameat2(old_fd: int, old: str, new_fd: int, new: str, flags: int) -> None:
    """Linux renameat2(2); OSError(ENOSYS) where it cannot be called."""
    if renameat2_function is None:
        raise OSError(errno.ENOSYS, os.strerror(errno.ENOSYS))
    if renameat2_function(old_fd, os.fsencode(old), new_fd, os.fsencode(new), flags) != 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code))


def exchange(directory_fd: int, first: str, second: str) -> None:
    """Swap the entries ``first`` and ``second`` of ``directory_fd`` in one step."""
    renameat2(directory_fd, first, directory_fd, second, RENAME_EXCHANGE)


def rename_without_replacing(source_fd: int, name: str, target_fd: int) -> None:
    try:
        renameat2(source_fd, name, target_fd, name, RENAME_NOREPLACE)
    except OSError as exc:
        if exc.errno not in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP, errno.ENOTSUP):
            raise
        if lstat_at(target_fd, name) is not None:
            raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST)) from None
        os.rename(name, name, src_dir_fd=source_fd, dst_dir_fd=target_fd)
