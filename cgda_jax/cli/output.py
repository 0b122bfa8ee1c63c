"""What the ``cgda`` commands share: progress lines on stderr (`say`), the JAX
compilation cache, exit statuses and failures: which errors are bad input
(status 2) and which are failures (3, their traceback saved to a log file), signals
(130 / 143, the results folder cleaned up) and library warnings as one line each.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import pathlib
import signal
import socket
import sys
import tempfile
import threading
import traceback
from typing import Any

from cgda_jax.job import ENV_LAUNCHER_PID

#: Errors that mean bad input while a config is read and checked (status 2).
USER_ERRORS = (ValueError, FileNotFoundError, KeyError, NotADirectoryError)

#: Exit statuses: goal met, goal not met, usage or config error (bad key, value or
#: file; results folder not empty, in use or not writable), any other failure (a
#: diverged simulation, or an unexpected error whose traceback goes to a log file).
EXIT_MET, EXIT_NOT_MET, EXIT_USAGE, EXIT_FAILURE = 0, 1, 2, 3
#: A simulation diverged (`cgda_jax.SimulationDiverged`): one of the failures.
EXIT_DIVERGED = EXIT_FAILURE
#: Interrupted by a signal: 128 + its number.
EXIT_SIGNAL = {signal.SIGINT: 130, signal.SIGTERM: 143}
#: ``0`` turns off the store of a run's compiled programs in the cache folder (on
#: by default).
PROGRAM_STORE_ENV = "CGDA_JAX_PROGRAM_STORE"


@dataclasses.dataclass
class Session:
    """What one ``cgda`` process holds besides its arguments (``args`` stays what
    the user typed): `~cgda_jax.cli.app.main` makes one and hands it to the
    command.

    Attributes:
        argv: the command line (a ``--processes P`` job starts its workers with it).
        quiet: no progress lines on stderr (`say`): ``--quiet``, or a process of a
            multi-process job other than process 0 (`cgda_jax.cli.trials.join_job`).
        run_folder: the results folder this process holds once it took it (a
            `~cgda_jax.results_folder.writing.RunFolder`, or a
            `~cgda_jax.cli.trials.FolderElsewhere` where another process of its job
            holds it); None before. Until then a failure is bad input
            (`user_error`); an interrupt abandons it (`SignalWatcher`) and names it
            (`interrupted_text`).
        job_open: a process of a multi-process job before the step all its
            processes take together: ending alone, it exits at once (`leave_job`).
    """

    argv: list[str] = dataclasses.field(default_factory=list)
    quiet: bool = False
    run_folder: Any = None
    job_open: bool = False


def diverged(err: BaseException) -> bool:
    """`err` is a `cgda_jax.SimulationDiverged` (its module is loaded if it is one)."""
    mod = sys.modules.get("cgda_jax.strategies.result")
    return mod is not None and isinstance(err, mod.SimulationDiverged)


class _StderrHandler(logging.StreamHandler):
    """A stream handler on whatever ``sys.stderr`` is at each write (a plain
    `logging.StreamHandler` keeps the stderr of when it was made: called again in
    one process, e.g. under pytest's capture, it wrote to a closed stream and
    printed a "Logging error" report instead of the warning)."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:  # set by StreamHandler.__init__: ignored
        pass


def log_warnings() -> None:
    """Library warnings (logger ``cgda_jax``) as ``cgda: warning: ...`` lines."""
    logger = logging.getLogger("cgda_jax")
    if not any(isinstance(h, _StderrHandler) for h in logger.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("cgda: warning: %(message)s"))
        logger.addHandler(handler)
        logger.propagate = False


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM received while ``cgda`` was working."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class Signals:
    """While active, SIGINT and SIGTERM raise `Interrupted` in the main thread (so
    the results folder is cleaned up); afterwards they are only remembered."""

    def __init__(self):
        self.received: int | None = None
        self.active = False
        self.old: dict[int, object] = {}

    def _handle(self, signum, frame):
        self.received = signum
        if self.active:
            raise Interrupted(signum)

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in EXIT_SIGNAL:
                self.old[sig] = signal.signal(sig, self._handle)
        self.active = True
        return self

    def __exit__(self, *exc):
        self.active = False
        for sig, handler in self.old.items():
            signal.signal(sig, handler)

    def default(self) -> None:
        """SIGINT and SIGTERM end the process at once, the system's way (a process
        of a multi-process job until its `SignalWatcher` runs: it holds nothing to
        clean up yet, and a Python exception in the middle of joining the job
        could leave JAX's runtime threads to crash the exit)."""
        if threading.current_thread() is threading.main_thread():
            for sig in EXIT_SIGNAL:
                signal.signal(sig, signal.SIG_DFL)


def save_traceback() -> str:
    """The current exception's traceback in a temporary log file; its path (or why
    it could not be written)."""
    try:
        fd, path = tempfile.mkstemp(prefix="cgda-error-", suffix=".log")
        with os.fdopen(fd, "w") as f:
            f.write(f"cgda {' '.join(sys.argv[1:])}\n\n{traceback.format_exc()}")
        return f"traceback in {path}"
    except OSError as err:
        return f"traceback not saved: {err.strerror or err}"


def first_line(err: BaseException) -> str:
    text = str(err.args[0]) if isinstance(err, KeyError) and err.args else str(err)
    return text.strip().splitlines()[0] if text.strip() else type(err).__name__


def interrupted_text(session: Session | None, signum: int) -> str:
    """The line that says ``cgda`` was interrupted, and what became of the folder
    (``session``: None before the arguments were read)."""
    name = signal.Signals(signum).name
    rf = None if session is None else session.run_folder
    if rf is None or rf.path is None:
        where = ""
    elif rf.committed:
        where = f" after the results were written to {rf.path}"
    else:
        where = f"; nothing written ({rf.path} left as it was)"
    return f"cgda: interrupted ({name}){where}"


def launched_worker() -> bool:
    """This process is a worker of `cgda_jax.launch` (its launcher says what ended
    the job, so the worker does not)."""
    return bool(os.environ.get(ENV_LAUNCHER_PID, "").strip())


def interrupted(session: Session | None, signum: int) -> int:
    if not launched_worker():
        print(interrupted_text(session, signum), file=sys.stderr)
    return EXIT_SIGNAL.get(signum, 128 + signum)


class JobFailed(Exception):
    """A multi-process job ends with ``status``: ``line`` says why on this process,
    or is None where another process said it (or the launcher did)."""

    def __init__(self, status: int, line: str | None = None):
        super().__init__(line or f"status {status}")
        self.status, self.line = status, line


def failure(session: Session, err: Exception) -> tuple[int, str]:
    """The exit status and the one line for ``err`` (an unexpected one's traceback
    saved to a log file named on the line)."""
    if user_error(session, err):
        return EXIT_USAGE, f"cgda: error: {first_line(err)}"
    if diverged(err):
        return EXIT_DIVERGED, f"cgda: error: {first_line(err)}"
    where = save_traceback()
    return EXIT_FAILURE, f"cgda: error: {type(err).__name__}: {first_line(err)} ({where})"


class SignalWatcher:
    """SIGINT and SIGTERM in a process of a multi-process job: they end it at once,
    from a thread of its own, even while the main thread waits inside JAX (a
    collective, a compile), where a Python handler would run only once it returns.

    The thread is woken through `signal.set_wakeup_fd` (the Python handlers left
    do nothing); it abandons the results folder this process holds
    (`Session.run_folder`: `~cgda_jax.results_folder.writing.RunFolder.abandon`),
    says the one line unless ``quiet`` (a launched worker: its launcher speaks) and
    exits with 130 / 143 through `os._exit`, skipping JAX's exit-time shutdown,
    which would wait for the other processes.
    """

    def __init__(self, session: Session, quiet: bool = False):
        self.session, self.quiet = session, quiet
        self._recv, self._send = socket.socketpair()

    def start(self) -> None:
        """Install (main thread only)."""
        self._send.setblocking(False)
        for sig in EXIT_SIGNAL:
            signal.signal(sig, _noted)
        signal.set_wakeup_fd(self._send.fileno(), warn_on_full_buffer=False)
        threading.Thread(target=self._watch, name="cgda-signals", daemon=True).start()

    def _watch(self) -> None:
        while True:
            data = self._recv.recv(1)
            if not data:  # pragma: no cover - closed
                return
            if data[0] in EXIT_SIGNAL:
                break
        signum = data[0]
        rf = self.session.run_folder
        if rf is not None:
            rf.abandon()
        if not self.quiet:
            with contextlib.suppress(Exception):
                sys.stderr.write(interrupted_text(self.session, signum) + "\n")
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(EXIT_SIGNAL[signum])


def leave_job(session: Session, status: int) -> int:
    """``status``; but a process of a multi-process job that ends alone, before
    the step all its processes take together (`Session.job_open`), exits here and
    now (`os._exit`): JAX's exit-time shutdown would wait for the others, who wait
    at that step for it. Its launcher (or scheduler) then stops the others."""
    if session.job_open:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(status)
    return status


def _noted(signum, frame) -> None:
    """A Python-level handler that does nothing: `SignalWatcher` acts."""


def user_error(session: Session, err: Exception) -> bool:
    """Bad input (status 2): before the run starts, any of `USER_ERRORS`; once it
    runs (everything was checked), only config and file errors, the rest is a
    failure (status 3, with its traceback)."""
    from cgda_jax.experiment.config import ConfigError

    rf = session.run_folder
    if rf is None or rf.committed:
        return isinstance(err, USER_ERRORS)
    from cgda_jax.sizes import SizeError  # refused before it allocates

    return isinstance(err, (ConfigError, FileNotFoundError, NotADirectoryError,
                            SizeError))


def check_out_file(path: pathlib.Path, flag: str = "--out",
                   folder: pathlib.Path | None = None, own: tuple = ()) -> None:
    """A file a command will write (``cgda export``), checked before any work: not a
    folder, in a folder that exists and can be written, and not a file of the
    results folder ``folder`` other than the names ``own`` (those the command
    itself writes there).

    Raises:
        FolderError: naming ``flag``, the path and the problem (status 2).
    """
    from cgda_jax.results_folder.rules import FolderError, check_writable

    path = pathlib.Path(path)
    if path.is_dir():
        raise FolderError(f"{flag} {path} is a folder; name a file")
    if not path.parent.is_dir():
        raise FolderError(f"{flag} {path}: folder {path.parent} not found")
    if folder is not None and path.exists() and path.name not in own:
        inside = path.resolve().is_relative_to(pathlib.Path(folder).resolve())
        if inside:
            raise FolderError(f"{flag} {path} is a file of the results folder "
                              f"{folder}; it would be overwritten (name another file)")
    if path.exists() and not os.access(path, os.W_OK):
        raise FolderError(f"{flag} {path} cannot be written: permission denied")
    check_writable(path.parent, f"{flag} {path}: its folder")


def say(session: Session, text: str) -> None:
    """``text`` as a line on stderr, unless quiet (`Session.quiet`)."""
    if not session.quiet:
        print(text, file=sys.stderr, flush=True)


def say_chosen(session: Session, label: str, rf) -> None:
    """Say where the results go when it is not the folder asked for (taken, or a
    symbolic link followed)."""
    if rf.note:
        say(session, f"[{label}] {rf.note}")


def _cache_dir() -> pathlib.Path:
    env = os.environ.get("CGDA_JAX_CACHE")
    return pathlib.Path(env).expanduser() if env else (
        pathlib.Path.home() / ".cache" / "cgda_jax" / "jax")


def enable_compilation_cache(path: pathlib.Path | None = None) -> pathlib.Path:
    """Turn on JAX's persistent compilation cache, small programs included, and
    keep the programs of a run, found without tracing, in its ``programs/``
    (`cgda_jax.programs.set_program_store`; ``$CGDA_JAX_PROGRAM_STORE=0`` keeps
    them in memory only).

    Raises:
        FolderError: the folder cannot be created or written (names it and
            $CGDA_JAX_CACHE).
    """
    import jax

    from cgda_jax.programs import set_program_store
    from cgda_jax.results_folder.rules import FolderError, check_writable

    path = path or _cache_dir()
    what = f"compilation cache folder {path} ($CGDA_JAX_CACHE)"
    try:
        check_writable(path, what)
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise FolderError(f"{what} cannot be created: {err.strerror or err}") from None
    except FolderError as err:
        raise FolderError(f"{err}; point CGDA_JAX_CACHE at a writable folder or "
                          "pass --no-cache") from None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    # The store keeps only programs XLA compiled in this process: on the CPU (jax
    # 0.10.2) an executable that XLA's compile took from JAX's persistent cache
    # serializes into one that fails in a new process ("Function ... not found";
    # `cgda_jax.programs`, tests/test_program_store.py).
    if os.environ.get(PROGRAM_STORE_ENV, "1") != "0":
        set_program_store(path / "programs")  # found there without tracing
    else:
        set_program_store(None)
    return path
