"""Reading what a case names on disk, bounded: the case file itself, profile and outline
files, a mesh file's digest; and path checks done as text, before anything is opened."""

from __future__ import annotations

import hashlib
import os
import stat
from pathlib import Path
from typing import Any

from contactfem.case import limits
from contactfem.case.messages import error_reason, shortened
from contactfem.case.reader import Reader
from contactfem.errors import CaseError


def read_text_file(path: str | os.PathLike[str], what: str = "case") -> str:
    """A YAML input (a case or a sweep file) as text: its path checked as text, a regular
    file, at most :data:`~contactfem.case.limits.MAX_CASE_BYTES` read, UTF-8; refusals say which ``what`` file."""
    path = Path(path)
    shown = shortened(str(path))
    problem = path_problem(path)
    if problem is not None:
        raise CaseError(f"{shown}: the {what} file's path {problem}")
    data = _read_bounded(path, shown, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise CaseError(f"{shortened(path.name)}: {_not_utf8(data, error)}") from None


def path_problem(path: str | os.PathLike[str], *, name_reserve: int = 0, path_reserve: int = 0) -> str | None:
    """Why the file system would refuse ``path`` before looking at it, or None.

    Checked as text only (nothing is opened or looked up): no NUL character, encodable as
    a file name, every component at most :data:`~contactfem.case.limits.NAME_MAX` bytes (the last one at most
    ``limits.NAME_MAX - name_reserve``) and the whole at most ``limits.PATH_MAX - 1 - path_reserve``
    bytes. The result completes "the path ...", e.g. "contains a NUL character".
    """
    text = os.fspath(path)
    if isinstance(text, bytes):
        raw = text
    else:
        if "\x00" in text:
            return "contains a NUL character"
        try:
            raw = os.fsencode(text)
        except UnicodeEncodeError:
            return "cannot be encoded as a file name (it holds a lone surrogate)"
    if b"\x00" in raw:
        return "contains a NUL character"
    separators = {os.sep, os.altsep} - {None}
    for separator in separators - {"/"}:
        raw = raw.replace(os.fsencode(separator), b"/")
    parts = raw.split(b"/")
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        limit = limits.NAME_MAX - (name_reserve if last else 0)
        if len(part) > limit:
            kept = f" ({limits.NAME_MAX} less {name_reserve} kept for the names made from it)" if last and name_reserve else ""
            return (f"has a component of {len(part)} bytes ({shortened(os.fsdecode(part), 40)!r}); "
                    f"expected at most {limit} bytes per file or directory name{kept}")
    limit = limits.PATH_MAX - 1 - path_reserve
    if len(raw) > limit:
        kept = f" ({limits.PATH_MAX - 1} less {path_reserve} kept for the files written under it)" if path_reserve else ""
        return f"is {len(raw)} bytes long; expected at most {limit} bytes{kept}"
    return None


def _read_bounded(path: Path, shown: str, what: str = "case") -> bytes:
    """The bytes of a regular file of at most limits.MAX_CASE_BYTES, reading no more than one byte past it."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError) as error:
        raise CaseError(f"{shown}: cannot read the {what} file ({error_reason(error)})") from None
    _refuse_special(mode, shown, what)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except (OSError, ValueError) as error:
        raise CaseError(f"{shown}: cannot read the {what} file ({error_reason(error)})") from None
    chunks, size = [], 0
    try:
        info = os.fstat(fd)  # the file opened, which may differ from the one looked at
        _refuse_special(info.st_mode, shown, what)
        if info.st_size > limits.MAX_CASE_BYTES:
            size = info.st_size
        while size <= limits.MAX_CASE_BYTES:
            chunk = os.read(fd, limits.MAX_CASE_BYTES + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as error:
        raise CaseError(f"{shown}: cannot read the {what} file ({error_reason(error)})") from None
    finally:
        os.close(fd)
    if size > limits.MAX_CASE_BYTES:
        raise CaseError(f"{shown}: the {what} file is larger than {limits.MAX_CASE_BYTES} bytes (1 MiB); "
                        f"expected a YAML {what} file of a few kB" +
                        (" (long outlines and profiles go in files of their own: geometry.polygon.file, "
                         "geometry.profile.file)" if what == "case" else ""))
    return b"".join(chunks)


def _refuse_special(mode: int, shown: str, what: str = "case") -> None:
    if stat.S_ISDIR(mode):
        raise CaseError(f"{shown}: is a directory; expected a YAML {what} file")
    if not stat.S_ISREG(mode):
        kinds = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                 (stat.S_ISSOCK, "a socket"))
        kind = next((name for test, name in kinds if test(mode)), "not a regular file")
        raise CaseError(f"{shown}: is {kind}, not a regular file; expected a YAML {what} file")


def _not_utf8(data: bytes, error: UnicodeDecodeError) -> str:
    for bom, encoding in ((b"\xff\xfe\x00\x00", "UTF-32"), (b"\x00\x00\xfe\xff", "UTF-32"),
                          (b"\xff\xfe", "UTF-16"), (b"\xfe\xff", "UTF-16")):
        if data.startswith(bom):
            return f"the case file is {encoding} (it starts with a {encoding} byte order mark); expected UTF-8"
    line = data.count(b"\n", 0, error.start) + 1
    column = error.start - (data.rfind(b"\n", 0, error.start) + 1) + 1
    return (f"byte 0x{data[error.start]:02x} at line {line}, column {column} is not UTF-8 ({error.reason}); "
            "expected a UTF-8 text file")


def file_mode(r: Reader, key: str, spec: Any, path: Path) -> int:
    """``os.stat(path).st_mode`` of a file a case names, or a one-line refusal naming ``key``."""
    try:
        return os.stat(path).st_mode
    except FileNotFoundError:
        raise r.fail(key, spec, f"no such file ({shortened(str(path))})") from None
    except (OSError, ValueError) as error:
        raise r.fail(key, spec, f"cannot read {shortened(str(path))} ({error_reason(error)})") from None


def data_file_lines(r: Reader, fkey: str, text: Any, source: Path, expected: str) -> list[str]:
    """The lines of the data file a case names at ``fkey`` (a profile, an outline), read
    within :data:`~contactfem.case.limits.MAX_DATA_FILE_BYTES` and recorded for the case's hash."""
    if not isinstance(text, str) or not text:
        raise r.fail(fkey, text, f"expected the path of {expected}")
    path = Path(text)
    if not path.is_absolute():
        path = source.parent / path
    shown = shortened(str(path))
    problem = path_problem(path)
    if problem is not None:
        raise r.fail(fkey, text, f"the path {'' if path == Path(text) else f'{shown} '}{problem}")
    data = _read_data_bytes(r, fkey, text, path)
    r.inputs.append(hashlib.sha256(data).digest())
    r.input_paths.append(path)
    try:
        content = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise r.fail(fkey, text, f"byte 0x{data[error.start]:02x} on line {line} is not UTF-8; expected "
                     "a text file") from None
    return content.splitlines()


def case_digest(text: bytes, inputs: list[bytes]) -> str:
    """SHA-256 of the case text followed by the SHA-256 of each data file it reads
    (``inputs``, in the order read), so that a changed profile, outline or mesh file changes
    the case's hash; the text's alone when it reads none."""
    digest = hashlib.sha256(text)
    for file_digest in inputs:
        digest.update(file_digest)
    return digest.hexdigest()


def file_digest(r: Reader, key: str, spec: Any, path: Path) -> bytes:
    """SHA-256 of a file, read in blocks (a mesh file may be large)."""
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as stream:
            for block in iter(lambda: stream.read(1 << 20), b""):
                digest.update(block)
    except OSError as error:
        raise r.fail(key, spec, f"cannot read {shortened(str(path))} ({error_reason(error)})") from None
    return digest.digest()


def _read_data_bytes(r: Reader, fkey: str, text: str, path: Path) -> bytes:
    """A regular file within what is left of the case's :data:`~contactfem.case.limits.MAX_DATA_FILE_BYTES` for all
    its data files (a polygon and its holes each from a file share it), reading no more than
    one byte past that."""
    shown = shortened(str(path))
    budget = limits.MAX_DATA_FILE_BYTES - r.data_bytes
    mode = file_mode(r, fkey, text, path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    chunks, size = [], 0
    fd = None
    try:
        if stat.S_ISREG(mode):
            fd = os.open(path, flags)
            mode = os.fstat(fd).st_mode  # the file opened, which may differ from the one looked at
        if not stat.S_ISREG(mode):
            kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file"
            raise r.fail(fkey, text, f"{shown} is {kind}; expected a CSV file")
        while size <= budget:
            chunk = os.read(fd, min(budget + 1 - size, 1 << 24))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as error:
        raise r.fail(fkey, text, f"cannot read {shown} ({error_reason(error)})") from None
    finally:
        if fd is not None:
            os.close(fd)
    if size > budget:
        bound = f"{limits.MAX_DATA_FILE_BYTES} bytes (64 MiB) all of a case's data files may hold"
        room = bound if budget == limits.MAX_DATA_FILE_BYTES else f"the {budget} bytes left of the {bound}"
        raise r.fail(fkey, text, f"{shown} is larger than {room}; expected at most {limits.MAX_POLYGON_VERTICES} lines "
                     "of points in all")
    r.data_bytes += size
    return b"".join(chunks)
