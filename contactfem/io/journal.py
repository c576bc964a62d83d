"""The names a switch-over trusts, and its journals (:mod:`contactfem.io.atomic`).

A name read from disk (a journal's, a directory listing's) is acted on only if it is one of
this mechanism's own: a plain name that one of contactfem's writers produces, or a
leftover's full name with its process id and random token.
"""

from __future__ import annotations

import errno
import fnmatch
import json
import os
import re
import stat
from dataclasses import dataclass

from contactfem.io import dirfd

#: Every temporary file starts with this, so leftovers of a killed process are easy to spot.
TEMP_PREFIX = ".tmp-"

#: A temporary made here: ``.tmp-<pid>-<8 hex digits>.<the final name>``.
TEMPORARY = re.compile(r"\.tmp-([0-9]{1,10})-([0-9a-f]{8})\.(.+)", re.DOTALL)
#: A staging directory: ``.tmp-<pid>-<8 hex digits>.staging``.
STAGING = re.compile(r"\.tmp-([0-9]{1,10})-([0-9a-f]{8})\.staging")
#: A run's token: ``<pid>-<8 hex digits>``.
TOKEN = re.compile(r"[0-9]{1,10}-[0-9a-f]{8}")

#: The names contactfem's writers give their files (glob patterns for series whose length
#: varies). Only such names are moved in or deleted on the word of a journal read from disk.
OUTPUT_NAMES = (
    "report.json", "contact.csv",
    "solution.vtu", "contact.vtu", "solution.pvd", "solution.pvtu", "solution_*.vtu", "solution.h5", "solution.xdmf", "solution-xdmf.h5",
    "path.pvd", "path.h5", "path.csv", "path.png", "path-*.vtu",
    "deformed.png", "contact_profile.png",
    "compare.json", "compare.png", "compare.pvd", "compare-*.vtu",
    "convergence.json", "convergence.csv", "convergence_h.png", "convergence_time.png",
    "convergence-*.pvd", "convergence-*.vtu",
    "adapt.json", "adapt.png",
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


def is_pattern(name: str) -> bool:
    return any(character in name for character in "*?[")


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


@dataclass(frozen=True)
class Plan:
    """The files a switch-over moves in (the last one last) and the files it removes."""

    files: tuple[str, ...]
    replaces: tuple[str, ...]
    token: str | None = None

    def dump(self) -> bytes:
        return json.dumps({"token": self.token, "files": list(self.files),
                           "replaces": list(self.replaces)}).encode("utf-8")


def read_journal(directory_fd: int, name: str) -> Plan | None:
    """The plan in the journal ``name``, or None if it is not one this mechanism wrote: not
    JSON, a name that is not a plain output name (:func:`is_output_name`), a token that is
    not ``<pid>-<8 hex digits>``. A journal read from disk is never trusted further than
    that; the caller checks that its token is the one it expects."""
    data = dirfd.read_file_at(directory_fd, name)
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
    if token is not None and not (isinstance(token, str) and TOKEN.fullmatch(token)):
        return None
    names = files + replaces
    if not all(is_output_name(n) for n in names) or len(set(names)) != len(names):
        return None
    return Plan(tuple(files), tuple(replaces), token)


def marked(staging_fd: int, token: str) -> bool:
    return dirfd.read_file_at(staging_fd, STAGING_MARKER, 64) == token.encode("ascii")


def only_regular_files(directory_fd: int) -> bool:
    for name in os.listdir(directory_fd):
        info = dirfd.lstat_at(directory_fd, name)
        if info is not None and not stat.S_ISREG(info.st_mode):
            return False
    return True


def move_in(directory_fd: int, staging_fd: int, plan: Plan) -> None:
    """Move the plan's files from the staging directory into the output directory, then
    remove the files it replaces (idempotent: a file already moved is skipped)."""
    for name in plan.files:
        info = dirfd.lstat_at(staging_fd, name)
        if info is None:
            continue
        if not stat.S_ISREG(info.st_mode):
            raise OSError(errno.EINVAL, f"{name} in the staging area is not a regular file")
        os.replace(name, name, src_dir_fd=staging_fd, dst_dir_fd=directory_fd)
        dirfd.reached(f"moved {name}")
    for name in plan.replaces:
        info = dirfd.lstat_at(directory_fd, name)
        if info is not None and not stat.S_ISDIR(info.st_mode):
            os.unlink(name, dir_fd=directory_fd)
    dirfd.fsync_fd(directory_fd)
