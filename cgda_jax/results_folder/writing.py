"""`RunFolder`: one run's results folder, locked, written aside and moved into place
when complete (the rules: `cgda_jax.results_folder.rules`).

A lock file beside the folder (``.<name>.lock``, ``flock``: released by the kernel
even when the process is killed) stops two runs sharing a folder; the run writes
into ``.<name>.tmp-XXXX`` beside it, and the commit is one rename (an atomic
exchange on Linux when an older folder is replaced), never cut in half by SIGINT
or SIGTERM.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import glob
import os
import pathlib
import secrets
import shutil
import signal
import threading

from cgda_jax.results_folder.rules import (
    FolderBusy,
    FolderError,
    candidates,
    check_target,
    check_writable,
    expand,
    follow_link,
    followable,
    hidden_name,
    is_empty_dir,
)

__all__ = ["RunFolder", "check_free"]


def check_free(folder: pathlib.Path) -> None:
    """Refuse ``folder`` when another run holds its lock, creating nothing (what a
    ``--dry-run`` checks; the run itself takes the lock).

    Raises:
        FolderBusy: naming the folder and the holder's pid.
    """
    lock = _Lock(folder.parent / hidden_name(folder, "lock"))
    try:
        fd = os.open(lock.path, os.O_RDONLY)
    except OSError:  # no lock file: nobody holds it
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError as err:
        if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            raise FolderBusy(f"results folder {folder} is in use by another run"
                             f"{lock.holder()}; wait for it to finish or choose "
                             "another folder") from None
        raise
    finally:
        os.close(fd)


class _Lock:
    """An exclusive, non-blocking ``flock`` on ``path`` (removed when released)."""

    def __init__(self, path: pathlib.Path):
        self.path = path
        self.fd: int | None = None

    def acquire(self) -> bool:
        """True when taken; False when another process holds it."""
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as err:
                os.close(fd)
                if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    return False
                raise
            # the holder before us may have removed the file after we opened it:
            # then we locked an orphan; try again on the file now at `path`
            try:
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
                self.fd = fd
                return True
            os.close(fd)

    def holder(self) -> str:
        try:
            pid = self.path.read_text().strip()
        except OSError:
            return ""
        return f" (pid {pid})" if pid.isdigit() else ""

    def release(self) -> None:
        if self.fd is None:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.path)
        os.close(self.fd)
        self.fd = None


def _exchange(a: pathlib.Path, b: pathlib.Path) -> bool:
    """Atomically swap two paths (Linux ``renameat2(RENAME_EXCHANGE)``); False where
    the system or the file system cannot."""
    fn = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)
    if fn is None:
        return False
    at_fdcwd, rename_exchange = -100, 2
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


@contextlib.contextmanager
def _signals_held():
    """SIGINT and SIGTERM wait until the block is done (a commit or a clean-up is
    never cut in half by them)."""
    sigs = {signal.SIGINT, signal.SIGTERM}
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    except (AttributeError, OSError, ValueError):  # pragma: no cover - no sigmask
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _make_dir(parent: pathlib.Path, prefix: str) -> pathlib.Path:
    """A new folder ``parent/<prefix><random>`` with the usual (umask) permissions."""
    while True:
        path = parent / f"{prefix}{secrets.token_hex(4)}"
        try:
            path.mkdir()
            return path
        except FileExistsError:  # pragma: no cover - 32 random bits
            continue


class RunFolder:
    """Context manager that owns one run's results folder (see the module docstring).

    ``with RunFolder(target) as rf:`` write everything into ``rf.work``; on a normal
    exit it becomes ``rf.path`` (``rf.committed`` is then True); on an exception
    (interrupt included) it is removed and ``rf.path`` is left as it was. Another
    thread may `abandon` it meanwhile (a signal watcher).

    Args:
        target: the results folder (``~`` expanded); with ``fresh`` the base name.
        overwrite: replace an existing results folder whole.
        fresh: choose the first free one of ``target``, ``target-2``, ...

    Attributes:
        target: the folder asked for; ``path``: the one written (a free name, or
            the folder a link names); ``note``: that difference in words, or None.

    Raises (on entering):
        FolderBusy: another run holds the lock of the folder.
        FolderError: the folder is not empty (without ``overwrite``), not a results
            folder, not a folder, a dangling link, or cannot be written.
    """

    def __init__(self, target: str | os.PathLike, *, overwrite: bool = False,
                 fresh: bool = False):
        self.target = expand(target)
        self.overwrite = overwrite
        self.fresh = fresh
        self.path: pathlib.Path = self.target
        self.chosen: pathlib.Path = self.target  # the name taken, before a link
        self.work: pathlib.Path | None = None
        self.committed = False
        self._lock: _Lock | None = None
        self._mutex = threading.Lock()
        self._abandoned = False

    @property
    def note(self) -> str | None:
        """Where the results go when it is not the folder asked for, or None."""
        parts = []
        if self.chosen != self.target:
            parts.append(f"{self.target} is taken: results go to {self.chosen}")
        if self.path != self.chosen:
            parts.append(f"{self.chosen} is a symbolic link, followed: results go to "
                         f"{self.path}")
        return "; ".join(parts) or None

    # ---- entering: lock, check, clean leftovers, make the temporary folder
    def _lock_for(self, folder: pathlib.Path) -> _Lock:
        return _Lock(folder.parent / hidden_name(folder, "lock"))

    def _take(self) -> None:
        parent = self.target.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise FolderError(
                f"results folder {self.target} cannot be created "
                f"({err.strerror or err})"
            ) from None
        check_writable(parent, f"results folder {self.target}")
        if self.fresh and not self.overwrite:
            for cand in candidates(self.target):
                real = followable(cand)
                if real is None or (real.exists() and not is_empty_dir(real)):
                    continue
                lock = self._lock_for(real)
                if not lock.acquire():
                    continue
                if real.exists() and not is_empty_dir(real):  # finished meanwhile
                    lock.release()
                    continue
                self.chosen, self.path, self._lock = cand, real, lock
                self._check_parent()
                return
        real = follow_link(self.target)
        lock = self._lock_for(real)
        if not lock.acquire():
            raise FolderBusy(
                f"results folder {real} is in use by another run"
                f"{lock.holder()}; wait for it to finish or choose another folder"
            )
        self.path, self._lock = real, lock
        self._check_parent()
        try:
            check_target(real, self.overwrite)
        except BaseException:
            self._release()
            raise

    def _check_parent(self) -> None:
        if self.path.parent != self.target.parent:  # a link's folder, elsewhere
            try:
                check_writable(self.path.parent, f"results folder {self.path}")
            except BaseException:
                self._release()
                raise

    def _clean_leftovers(self) -> None:
        """Temporary folders of earlier runs of this folder that were killed."""
        parent, stem = self.path.parent, glob.escape(self.path.name)
        olds = sorted(parent.glob(f".{stem}.old-*"))
        if olds and not self.path.exists():  # killed between the two renames
            os.rename(olds.pop(), self.path)
        for p in [*parent.glob(f".{stem}.tmp-*"), *olds]:
            shutil.rmtree(p, ignore_errors=True)

    def __enter__(self) -> RunFolder:
        self._take()
        try:
            self._clean_leftovers()
            self.work = _make_dir(self.path.parent, hidden_name(self.path, "tmp-"))
        except BaseException:
            self._release()
            raise
        return self

    # ---- leaving: commit or discard, then unlock
    def _commit(self) -> None:
        work, path = self.work, self.path
        if not path.exists():
            os.rename(work, path)
        elif is_empty_dir(path):
            os.rename(work, path)  # a directory may replace an empty one
        elif _exchange(work, path):
            shutil.rmtree(work)  # the previous results, now at the temporary name
        else:
            old = path.parent / hidden_name(path, f"old-{secrets.token_hex(4)}")
            os.rename(path, old)
            os.rename(work, path)
            shutil.rmtree(old)
        self.work = None
        self.committed = True

    def _discard(self) -> None:
        if self.work is not None:
            for _ in range(3):  # a file written meanwhile by another thread
                shutil.rmtree(self.work, ignore_errors=True)
                if not os.path.lexists(self.work):
                    break
            self.work = None

    def _release(self) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def abandon(self) -> bool:
        """Discard the temporary folder and release the lock now, from any thread,
        unless the run was committed already (a commit under way is waited for);
        the context's exit then does nothing. Returns ``committed``."""
        with self._mutex:
            if not self.committed:
                self._discard()
            self._release()
            self._abandoned = True
            return self.committed

    def __exit__(self, exc_type, exc, tb) -> None:
        with self._mutex:
            if self._abandoned:
                return
            try:
                with _signals_held():
                    if exc_type is None:
                        self._commit()
                    else:
                        self._discard()
            finally:
                self._release()
