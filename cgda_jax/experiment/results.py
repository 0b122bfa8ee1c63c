"""A run's results folder: chosen, locked, written aside, moved into place at the end.

A run never writes into its results folder directly. It writes into a temporary folder
beside it (``.<name>.tmp-XXXX``) and, once everything is written, moves that folder into
place with one rename (an atomic exchange on Linux when an older folder is replaced).
So the folder always holds the files of ONE complete run, or the previous run's
untouched, or nothing:

- an existing non-empty folder is refused (`FolderError`) unless ``overwrite=True``,
  which replaces it whole, and only when it is a results folder (holds a
  ``result.json``); with ``fresh=True`` (no folder given by the user) the first free
  name of ``<base>``, ``<base>-2``, ``<base>-3``, ... is taken instead;
- a lock file beside the folder (``.<name>.lock``, ``flock``: released by the kernel
  even when the process is killed) stops two runs sharing a folder: the second gets
  `FolderBusy`;
- a run that fails or is interrupted (SIGINT, SIGTERM) removes its temporary folder:
  the previous results stay as they were, no partial work is kept; leftovers of a
  killed run (SIGKILL) are removed by the next run of the same folder.

``report.md`` links only files of its own run, since every run starts from an empty
folder.
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
import tempfile

#: A folder counts as a previous run's results (replaceable with ``overwrite``) when
#: it holds this file.
MARKER = "result.json"

_MAX_FRESH = 1000


class FolderError(ValueError):
    """The results folder cannot be used: not empty, not a folder, not writable."""


class FolderBusy(FolderError):
    """Another run holds the results folder's lock."""


def expand(path: str | os.PathLike) -> pathlib.Path:
    """``path`` with ``~`` expanded."""
    return pathlib.Path(path).expanduser()


def _is_empty_dir(p: pathlib.Path) -> bool:
    return p.is_dir() and not any(p.iterdir())


def _hidden(target: pathlib.Path, what: str) -> str:
    return f".{target.name}.{what}"


def check_writable(folder: pathlib.Path, what: str | None = None) -> None:
    """``folder`` exists or can be created, and can be written: checked by creating
    and removing a temporary folder in it or in its nearest existing ancestor.

    Raises:
        FolderError: naming ``what`` (default: the folder) and the reason.
    """
    folder = pathlib.Path(folder)
    what = what or f"folder {folder}"
    probe_in = folder
    while not probe_in.exists() and probe_in != probe_in.parent:
        probe_in = probe_in.parent
    if not probe_in.is_dir():
        raise FolderError(f"{what} cannot be created: {probe_in} is not a folder")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".cgda-probe-", dir=probe_in))
    except OSError as err:
        raise FolderError(
            f"{what} cannot be written: {probe_in}: {err.strerror or err}"
        ) from None


def _check_target(target: pathlib.Path, overwrite: bool) -> None:
    if not target.exists():
        return
    if not target.is_dir():
        raise FolderError(f"results folder {target} exists and is not a folder")
    if _is_empty_dir(target):
        return
    if not overwrite:
        raise FolderError(
            f"results folder {target} is not empty; replace it with --overwrite "
            f"(overwrite=True), or choose another folder"
        )
    if not (target / MARKER).is_file():
        raise FolderError(
            f"results folder {target} is not empty and holds no {MARKER} (not a "
            f"results folder): refusing to replace it; choose another folder"
        )


def plan_folder(
    target: str | os.PathLike, *, overwrite: bool = False, fresh: bool = False
) -> pathlib.Path:
    """The folder a run would write to, checked, with nothing created or locked.

    Args:
        target: the folder asked for; with ``fresh`` the base of the names tried.
        overwrite: an existing results folder may be replaced.
        fresh: take the first of ``target``, ``target-2``, ... that is missing or
            empty (``overwrite`` then replaces ``target`` itself).

    Raises:
        FolderError: the folder cannot be used (the message says why and what to do).
    """
    target = expand(target)
    check_writable(target.parent, f"results folder {target}")
    if fresh and not overwrite:
        for cand in _candidates(target):
            if not cand.exists() or _is_empty_dir(cand):
                return cand
    _check_target(target, overwrite)
    return target


def _candidates(base: pathlib.Path):
    yield base
    for k in range(2, _MAX_FRESH + 1):
        yield base.with_name(f"{base.name}-{k}")
    raise FolderError(f"no free results folder among {base}, {base}-2, ... "
                      f"{base}-{_MAX_FRESH}")


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
    (interrupt included) it is removed and ``rf.path`` is left as it was.

    Args:
        target: the results folder (``~`` expanded); with ``fresh`` the base name.
        overwrite: replace an existing results folder whole.
        fresh: choose the first free one of ``target``, ``target-2``, ...

    Raises (on entering):
        FolderBusy: another run holds the lock of the folder.
        FolderError: the folder is not empty (without ``overwrite``), not a results
            folder, not a folder, or cannot be written.
    """

    def __init__(self, target: str | os.PathLike, *, overwrite: bool = False,
                 fresh: bool = False):
        self.target = expand(target)
        self.overwrite = overwrite
        self.fresh = fresh
        self.path: pathlib.Path = self.target
        self.work: pathlib.Path | None = None
        self.committed = False
        self._lock: _Lock | None = None

    # ---- entering: lock, check, clean leftovers, make the temporary folder
    def _lock_for(self, folder: pathlib.Path) -> _Lock:
        return _Lock(folder.parent / _hidden(folder, "lock"))

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
            for cand in _candidates(self.target):
                if cand.exists() and not _is_empty_dir(cand):
                    continue
                lock = self._lock_for(cand)
                if not lock.acquire():
                    continue
                if cand.exists() and not _is_empty_dir(cand):  # finished meanwhile
                    lock.release()
                    continue
                self.path, self._lock = cand, lock
                return
        lock = self._lock_for(self.target)
        if not lock.acquire():
            raise FolderBusy(
                f"results folder {self.target} is in use by another run"
                f"{lock.holder()}; wait for it to finish or choose another folder"
            )
        try:
            _check_target(self.target, self.overwrite)
        except BaseException:
            lock.release()
            raise
        self.path, self._lock = self.target, lock

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
            self.work = _make_dir(self.path.parent, _hidden(self.path, "tmp-"))
        except BaseException:
            self._lock.release()
            raise
        return self

    # ---- leaving: commit or discard, then unlock
    def _commit(self) -> None:
        work, path = self.work, self.path
        if not path.exists():
            os.rename(work, path)
        elif _is_empty_dir(path):
            os.rename(work, path)  # a directory may replace an empty one
        elif _exchange(work, path):
            shutil.rmtree(work)  # the previous results, now at the temporary name
        else:
            old = path.parent / _hidden(path, f"old-{secrets.token_hex(4)}")
            os.rename(path, old)
            os.rename(work, path)
            shutil.rmtree(old)
        self.work = None
        self.committed = True

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            with _signals_held():
                if exc_type is None:
                    self._commit()
                elif self.work is not None:
                    shutil.rmtree(self.work, ignore_errors=True)
                    self.work = None
        finally:
            if self._lock is not None:
                self._lock.release()
                self._lock = None
