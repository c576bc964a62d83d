"""The switch-over in one step: the output directory exchanged with a sibling holding the
new result (:mod:`contactfem.io.atomic` describes it, and where it cannot be made).

``handle`` below is the claim's held directory (:class:`contactfem.io.held.Held`): its
descriptor ``fd``, its parent's ``parent_fd``, its ``name`` there and its ``lock_fd``.
"""

from __future__ import annotations

import errno
import os
import re
import stat
from pathlib import Path
from typing import TYPE_CHECKING

from contactfem import interrupts
from contactfem.errors import OutputError
from contactfem.io import dirfd, journal

if TYPE_CHECKING:
    from contactfem.io.held import Held

#: How deep the subdirectories of an output directory may be nested for it to be exchanged.
MAX_DEPTH = 64


class NotExchangeable(Exception):
    """The output directory cannot be rebuilt beside itself (see the module's docstring)."""


def copy_directory_metadata(source_fd: int, target_fd: int, times: bool) -> None:
    """Give the directory ``target_fd`` the group, mode and extended attributes of
    ``source_fd`` (and its times, ``times``); NotExchangeable where that cannot be done."""
    source = os.fstat(source_fd)
    try:
        if os.fstat(target_fd).st_gid != source.st_gid:
            os.fchown(target_fd, -1, source.st_gid)
        os.fchmod(target_fd, stat.S_IMODE(source.st_mode))
        if stat.S_IMODE(os.fstat(target_fd).st_mode) != stat.S_IMODE(source.st_mode):
            raise NotExchangeable("mode")
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
        raise NotExchangeable(str(exc)) from exc


def replicate(source_fd: int, target_fd: int, skip: frozenset[str], device: int, depth: int = 0) -> None:
    """Hard-link every entry of ``source_fd`` but ``skip`` into ``target_fd``, recreating
    subdirectories (with their metadata) and linking what they hold."""
    if depth > MAX_DEPTH:
        raise NotExchangeable("nested too deep")
    for name in os.listdir(source_fd):
        if name in skip:
            continue
        info = dirfd.lstat_at(source_fd, name)
        if info is None:
            continue
        if info.st_dev != device:
            raise NotExchangeable("a mount point")
        if not stat.S_ISDIR(info.st_mode):
            os.link(name, name, src_dir_fd=source_fd, dst_dir_fd=target_fd, follow_symlinks=False)
            continue
        if info.st_uid != os.geteuid():
            raise NotExchangeable("another user's directory")
        os.mkdir(name, 0o700, dir_fd=target_fd)
        inner_source = inner_target = None
        try:
            inner_source = dirfd.open_directory_at(source_fd, name)
            inner_target = dirfd.open_directory_at(target_fd, name)
            replicate(inner_source, inner_target, frozenset(), device, depth + 1)
            copy_directory_metadata(inner_source, inner_target, times=True)
            os.fsync(inner_target)
        finally:
            dirfd.close_quietly(inner_source)
            dirfd.close_quietly(inner_target)


def carry_over(old_fd: int, new_fd: int, skip: frozenset[str], depth: int = 0) -> bool:
    """Bring into the new directory what another program changed in the old one while the
    new one was built (a new file, a replaced one); False if something had to stay behind."""
    whole = True
    for name in os.listdir(old_fd):
        if name in skip:
            continue
        old = dirfd.lstat_at(old_fd, name)
        if old is None:
            continue
        new = dirfd.lstat_at(new_fd, name)
        if new is None:
            dirfd.rename_without_replacing(old_fd, name, new_fd)
        elif dirfd.same_file(old, new):
            continue
        elif stat.S_ISDIR(old.st_mode) and stat.S_ISDIR(new.st_mode):
            if depth >= MAX_DEPTH:
                whole = False
                continue
            inner_old = inner_new = None
            try:
                inner_old = dirfd.open_directory_at(old_fd, name)
                inner_new = dirfd.open_directory_at(new_fd, name)
                whole = carry_over(inner_old, inner_new, frozenset(), depth + 1) and whole
            finally:
                dirfd.close_quietly(inner_old)
                dirfd.close_quietly(inner_new)
        elif not stat.S_ISDIR(old.st_mode) and not stat.S_ISDIR(new.st_mode):
            os.replace(name, name, src_dir_fd=old_fd, dst_dir_fd=new_fd)
        else:
            whole = False
    return whole


def sibling_name(token: str, name: str) -> str:
    return f"{journal.TEMP_PREFIX}{token}.{name}.exchange"


def working_directory_inside(directory_fd: int) -> bool:
    """Whether this process's working directory is the directory ``directory_fd`` or below it."""
    target = os.fstat(directory_fd)
    path = "."
    try:
        for _ in range(4096):
            here = os.stat(path)
            if dirfd.same_file(here, target):
                return True
            path = os.path.join(path, "..")
            if dirfd.same_file(os.stat(path), here):
                return False
    except OSError:
        return True  # unsure: do not exchange
    return True


def switch_by_exchange(handle: Held, directory: Path, staging: str, staging_fd: int,
                       plan: journal.Plan) -> bool:
    """Switch the result in by exchanging the directory with a copy holding it (see the
    module's docstring). False, with nothing changed, where that cannot be done."""
    sibling = sibling_name(plan.token, handle.name)
    sibling_fd = None
    made = exchanged = False
    try:
        try:
            os.mkdir(sibling, 0o700, dir_fd=handle.parent_fd)
            made = True
            sibling_fd = dirfd.open_directory_at(handle.parent_fd, sibling)
            dirfd.write_file_at(sibling_fd, journal.EXCHANGE_FILE, plan.dump())
            dirfd.reached("sibling made")
            _fill(handle, sibling_fd, staging, staging_fd, plan)
            dirfd.reached("sibling filled")
        except (OSError, NotExchangeable):
            _give_up(handle, sibling, sibling_fd, made)
            return False
        interrupts.stop_if_received()
        with interrupts.deferred():
            handle.check_still_here()
            try:
                dirfd.exchange(handle.parent_fd, sibling, handle.name)
            except OSError:
                _give_up(handle, sibling, sibling_fd, made)
                return False
            exchanged = True
            old_fd = handle.fd
            if not (dirfd.same_file(dirfd.lstat_at(handle.parent_fd, sibling), os.fstat(old_fd))
                    and dirfd.same_file(dirfd.lstat_at(handle.parent_fd, handle.name), os.fstat(sibling_fd))):
                # The directory was moved between the check and the exchange: undo it.
                dirfd.exchange(handle.parent_fd, sibling, handle.name)
                exchanged = False
                raise OutputError(f"cannot write {directory}: the directory was moved or replaced "
                                  "during the run; nothing was switched in")
            handle.fd, sibling_fd = sibling_fd, None
            dirfd.fsync_fd(handle.parent_fd)
            interrupts.note_switched()
            dirfd.reached("exchanged")
            try:
                finish_old_directory(handle, old_fd, sibling, plan, staging)
            finally:
                os.close(old_fd)
        return True
    except BaseException:
        if not exchanged:  # (if an exchange could not be undone, nothing is removed)
            _give_up(handle, sibling, sibling_fd, made)
        raise
    finally:
        dirfd.close_quietly(sibling_fd)


def _fill(handle: Held, sibling_fd: int, staging: str, staging_fd: int, plan: journal.Plan) -> None:
    """Make the sibling hold what the directory will: hard links of what stays (the lock
    file too, so that the lock stays held across the exchange) and of the staged files,
    and the directory's own metadata."""
    skip = frozenset((*plan.files, *plan.replaces, staging, journal.EXCHANGE_FILE, journal.SWITCH_FILE))
    replicate(handle.fd, sibling_fd, skip, os.fstat(handle.fd).st_dev)
    lock = dirfd.lstat_at(sibling_fd, journal.LOCK_FILE)
    if handle.lock_fd is not None and not dirfd.same_file(lock, os.fstat(handle.lock_fd)):
        raise NotExchangeable("the lock file changed")
    for name in plan.files:
        file_fd = os.open(name, os.O_RDONLY | dirfd.NOFOLLOW | getattr(os, "O_CLOEXEC", 0), dir_fd=staging_fd)
        try:
            os.fsync(file_fd)
        finally:
            os.close(file_fd)
        os.link(name, name, src_dir_fd=staging_fd, dst_dir_fd=sibling_fd, follow_symlinks=False)
    copy_directory_metadata(handle.fd, sibling_fd, times=False)
    os.fsync(sibling_fd)


def _give_up(handle: Held, sibling: str, sibling_fd: int | None, made: bool) -> None:
    """Remove the sibling (if it is still the one made) and switch by moves from now on."""
    handle.exchangeable = False
    if sibling_fd is not None:
        dirfd.remove_directory_held(handle.parent_fd, sibling, sibling_fd)
    elif made:
        try:
            os.rmdir(sibling, dir_fd=handle.parent_fd)  # made, not opened: empty
        except OSError:
            pass


def finish_old_directory(handle: Held, old_fd: int, sibling: str, plan: journal.Plan, staging: str) -> None:
    """After an exchange: carry over what changed in the old directory meanwhile, remove it,
    then the journal (best effort: what is left is finished by the next claim)."""
    skip = frozenset((*plan.files, *plan.replaces, staging, journal.LOCK_FILE, journal.EXCHANGE_FILE))
    try:
        whole = carry_over(old_fd, handle.fd, skip)
        dirfd.reached("carried over")
        if whole:
            dirfd.remove_directory_held(handle.parent_fd, sibling, old_fd)
        dirfd.reached("removed the old directory")
        os.unlink(journal.EXCHANGE_FILE, dir_fd=handle.fd)
        dirfd.fsync_fd(handle.fd)
        dirfd.fsync_fd(handle.parent_fd)
    except OSError:
        pass


def finish_old(handle: Held, sibling: str, plan: journal.Plan, staging: str) -> None:
    """Carry over from the old directory (at ``sibling``) and remove it, if it is the one
    this exchange put there (its staging directory inside, with the token's marker)."""
    try:
        old_fd = dirfd.open_directory_at(handle.parent_fd, sibling)
    except OSError:
        return
    try:
        try:
            inner = dirfd.open_directory_at(old_fd, staging)
        except OSError:
            return
        try:
            if not journal.marked(inner, plan.token):
                return
        finally:
            os.close(inner)
        finish_old_directory(handle, old_fd, sibling, plan, staging)
    finally:
        os.close(old_fd)


def recover_exchange(handle: Held) -> None:
    """An exchange was made but its old directory not yet removed: carry over and remove it."""
    plan = journal.read_journal(handle.fd, journal.EXCHANGE_FILE)
    if handle.parent_fd is not None and plan is not None and plan.token is not None:
        staging = f"{journal.TEMP_PREFIX}{plan.token}.staging"
        finish_old(handle, sibling_name(plan.token, handle.name), plan, staging)
    try:
        os.unlink(journal.EXCHANGE_FILE, dir_fd=handle.fd)
    except OSError:
        pass


def recover_siblings(handle: Held) -> None:
    """Remove exchange siblings of this directory that were never exchanged (their journal is
    inside, with their own token) and whose process is gone."""
    pattern = re.compile(rf"{re.escape(journal.TEMP_PREFIX)}([0-9]{{1,10}})-([0-9a-f]{{8}})"
                         rf"\.{re.escape(handle.name)}\.exchange", re.DOTALL)
    try:
        names = os.listdir(handle.parent_fd)
    except OSError:
        return
    for name in names:
        found = pattern.fullmatch(name)
        if found is None or dirfd.pid_alive(int(found[1])):
            continue
        try:
            sibling_fd = dirfd.open_directory_at(handle.parent_fd, name)
        except OSError:
            continue
        try:
            plan = journal.read_journal(sibling_fd, journal.EXCHANGE_FILE)
            if plan is not None and plan.token == f"{found[1]}-{found[2]}":
                dirfd.remove_directory_held(handle.parent_fd, name, sibling_fd)
        finally:
            os.close(sibling_fd)
