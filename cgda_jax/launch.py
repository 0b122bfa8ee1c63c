"""Start a multi-process job on this machine: N copies of a command, one job.

`launch` gives each copy the variables `cgda_jax.distributed.initialize` reads
(``CGDA_COORDINATOR=127.0.0.1:<free port>``, ``CGDA_NUM_PROCESSES``,
``CGDA_PROCESS_ID``), streams their output prefixed ``[p0]``, ``[p1]``, ..., stops
them all when one fails, on a timeout or on Ctrl-C, and returns the job's status
(`start_job`: the same, saying how it ended as a `JobEnd`).
From a shell::

    python -m cgda_jax.launch -n 4 [--timeout S] -- python my_trials.py ...

(the script calls ``cgda_jax.distributed.initialize()`` first). On a cluster the
scheduler starts the processes instead (README, "Several processes and machines").
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import TextIO

from cgda_jax.job import (
    ENV_CLUSTER,
    ENV_COORDINATOR,
    ENV_LAUNCHER_PID,
    ENV_NUM_PROCESSES,
    ENV_PROCESS_ID,
)

__all__ = ["JobEnd", "free_port", "launch", "main", "start_job", "without_option"]


#: Exit statuses of a process that caught SIGINT / SIGTERM and ended (128 + signal).
_SIGNAL_EXITS = (128 + int(signal.SIGINT), 128 + int(signal.SIGTERM))


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on `host` right now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


class _Lines:
    """The workers' lines on their way to our streams: written at once, or (with
    ``hold_s``) each held that long first, so that lines printed by a process in
    the moments before the job ends can still be dropped (`mute`)."""

    def __init__(self, hold_s: float = 0.0,
                 drop: Callable[[str], bool] | None = None,
                 keep: Callable[[str], bool] | None = None):
        self.hold_s, self.drop, self.keep = hold_s, drop, keep
        self.lock = threading.Lock()
        self.muted: set[int] = set()
        self.pending: collections.deque = collections.deque()
        self.wake = threading.Event()
        if hold_s > 0:
            threading.Thread(target=self._forward, daemon=True).start()

    def add(self, i: int, stream: TextIO, line: str, prefix: str) -> None:
        if self.drop is not None and self.drop(line):
            return
        text = f"{prefix}{line}\n"
        kept = self.keep is not None and self.keep(line)
        with self.lock:
            if i in self.muted and not kept:
                return
            if self.hold_s <= 0:
                stream.write(text)
                stream.flush()
            else:
                self.pending.append(
                    (time.monotonic() + self.hold_s, i, stream, text, kept))

    def mute(self, keep: int | None, n: int) -> None:
        with self.lock:
            self.muted |= {i for i in range(n) if i != keep}

    def flush(self, until: float | None = None) -> None:
        """Write the lines due by ``until`` (all without it), muted ones dropped."""
        with self.lock:
            while self.pending and (until is None or self.pending[0][0] <= until):
                _, i, stream, text, kept = self.pending.popleft()
                if kept or i not in self.muted:
                    stream.write(text)
                    stream.flush()

    def _forward(self) -> None:
        while not self.wake.wait(0.05):
            self.flush(time.monotonic())


def _pump(pipe, out: TextIO, prefix: str, i: int, lines: _Lines) -> None:
    for raw in iter(pipe.readline, b""):
        line = raw.decode(errors="replace").rstrip("\r\n")
        lines.add(i, out, line, prefix)  # read on when muted: no full pipe
    pipe.close()


def _signal_all(procs: Iterable[subprocess.Popen], sig: int) -> None:
    """`sig` to each worker's process group: the worker and what it started (a
    worker that already ended may have left children behind in its group, which
    would otherwise run on and write to its pipes)."""
    for p in procs:
        try:
            os.killpg(p.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass


def _wait(procs: list[subprocess.Popen], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while any(p.poll() is None for p in procs):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def _stop(procs: Sequence[subprocess.Popen], grace_s: float = 3.0) -> None:
    """Stop every worker's process group: SIGTERM, then SIGKILL what is left after
    `grace_s`. Processes 1 .. N-1 first, process 0 (which hosts JAX's coordination
    service) once they are gone: a worker whose coordinator vanished first would
    abort with a C++ stack of its own. Last, SIGKILL to every group: what the
    workers started and left behind (a helper of a killed worker)."""
    procs = list(procs)
    for group in (procs[1:], procs[:1]):
        _signal_all(group, signal.SIGTERM)
        if not _wait(group, grace_s):
            _signal_all(group, signal.SIGKILL)
            _wait(group, grace_s)
    _signal_all(procs, signal.SIGKILL)  # what the workers left in their groups


def _status(code: int) -> int:
    return 128 - code if code < 0 else code  # killed by signal n: 128 + n


class _Terminated(Exception):
    pass


@dataclasses.dataclass(frozen=True)
class JobEnd:
    """How a job started by `start_job` ended.

    Attributes:
        status: the job's exit status (as `launch` returns it).
        reason: ``"ok"`` (every process ended with an ok status), ``"failed"``
            (a process did not), ``"timeout"`` or ``"interrupted"`` (the launcher
            got SIGINT or SIGTERM).
        process: the failed process (``"failed"``), else None.
        code: its raw exit code (negative: killed by that signal), else None.
        signum: the signal that interrupted the launcher (``"interrupted"``).
        message: what happened, in words (`launch` prints it after ``launch:``).
    """

    status: int
    reason: str
    process: int | None = None
    code: int | None = None
    signum: int | None = None
    message: str = ""


def launch(n_processes: int, argv: Sequence[str], *,
           timeout_s: float | None = None, ok_codes: Iterable[int] = (0,),
           env: dict[str, str] | None = None, host: str = "127.0.0.1",
           stdout: TextIO | None = None, stderr: TextIO | None = None,
           prefix: bool = True) -> int:
    """Run `n_processes` copies of the command `argv` as one job on this machine.

    Each copy gets ``CGDA_COORDINATOR=host:<free port>``, ``CGDA_NUM_PROCESSES``
    and ``CGDA_PROCESS_ID`` (its script calls `initialize`). Their stdout and
    stderr go to ours line by line, prefixed ``[p<i>] ``. When one exits with a
    status not in `ok_codes` (or is killed), the others are stopped at once
    (SIGTERM, then SIGKILL after 3 s), as on `timeout_s` and on Ctrl-C / SIGTERM
    to the launcher: no worker outlives it (nor a SIGKILL of the launcher: each
    worker's `initialize` asks the kernel to end it with its launcher).

    Args:
        n_processes: N >= 1.
        argv: the command, e.g. ``[sys.executable, "script.py", ...]``.
        timeout_s: stop everything after this many seconds (None: no limit).
        ok_codes: exit statuses that are not failures (e.g. ``(0, 1)`` for a
            command whose 1 means "goal not met").
        env: extra environment for the workers.
        host: the coordinator's address (this machine).
        stdout, stderr: where the workers' lines go (default ours).
        prefix: prefix each line with ``[p<i>] ``.

    Returns:
        Process 0's exit status when every process ended with an ok status;
        otherwise the first failure's status (a signal n as 128 + n), 124 on the
        timeout, 130 / 143 when the launcher was interrupted (SIGINT / SIGTERM).
    """
    err = stderr or sys.stderr
    end = start_job(n_processes, argv, timeout_s=timeout_s, ok_codes=ok_codes,
                    env=env, host=host, stdout=stdout, stderr=stderr, prefix=prefix)
    if end.message:
        err.write(f"launch: {end.message}\n")
        err.flush()
    return end.status


def start_job(n_processes: int, argv: Sequence[str], *,
              timeout_s: float | None = None, ok_codes: Iterable[int] = (0,),
              env: dict[str, str] | None = None, host: str = "127.0.0.1",
              stdout: TextIO | None = None, stderr: TextIO | None = None,
              prefix: bool = True, mute_on_end: bool = False,
              hold_s: float = 0.0, drop: Callable[[str], bool] | None = None,
              keep: Callable[[str], bool] | None = None) -> JobEnd:
    """`launch`, saying nothing itself: how the job ended, as a `JobEnd`.

    The arguments not listed below are those of `launch`.

    Args:
        mute_on_end: once the job is decided to end (a failure, the timeout, an
            interrupt), drop the lines of the processes being stopped (the failed
            one's last lines still come): what they print while dying (a JAX
            runtime's complaint that its coordinator left) is noise.
        hold_s: hold each line that long before writing it, so that with
            `mute_on_end` the lines a process printed just before the end (as the
            others noticed a process die) are dropped too.
        drop: ``drop(line)`` True: the line is not shown (e.g. a library's
            chatter on stdout).
        keep: ``keep(line)`` True: the line is shown even from a muted process
            (e.g. the program's own error line, printed by a process that ended
            just after another one failed).
    """
    n = int(n_processes)
    if n < 1:
        raise ValueError(f"n_processes must be >= 1; got {n_processes}")
    if not argv:
        raise ValueError("argv is empty: give the command to run")
    ok = set(ok_codes)
    out = stdout or sys.stdout
    err = stderr or sys.stderr
    address = f"{host}:{free_port(host)}"
    base = {**os.environ, **(env or {}), ENV_COORDINATOR: address,
            ENV_NUM_PROCESSES: str(n), ENV_LAUNCHER_PID: str(os.getpid()),
            "PYTHONUNBUFFERED": "1"}
    base.pop(ENV_CLUSTER, None)
    lines = _Lines(hold_s, drop, keep)
    procs: list[subprocess.Popen] = []
    pumps: list[threading.Thread] = []

    def end_all(keep: int | None = None) -> None:
        """Stop the job; `keep`: the failed process, whose last lines still come."""
        if mute_on_end:
            lines.mute(keep, n)
        _stop(procs)
        _join(pumps)  # the failed one's last lines (its error) come first
        lines.flush()

    old_term = None
    in_main = threading.current_thread() is threading.main_thread()
    if in_main:
        def on_term(signum, frame):
            raise _Terminated()
        old_term = signal.signal(signal.SIGTERM, on_term)
    try:
        for i in range(n):
            p = subprocess.Popen(list(argv), env={**base, ENV_PROCESS_ID: str(i)},
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 stdin=subprocess.DEVNULL, start_new_session=True)
            procs.append(p)
            tag = f"[p{i}] " if prefix else ""
            for pipe, stream in ((p.stdout, out), (p.stderr, err)):
                t = threading.Thread(target=_pump,
                                     args=(pipe, stream, tag, i, lines),
                                     daemon=True)
                t.start()
                pumps.append(t)
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            codes = [p.poll() for p in procs]
            failed = [(i, c) for i, c in enumerate(codes)
                      if c is not None and c not in ok]
            if failed:
                i, c = failed[0]
                # killed by a signal, or ended by one it caught (status 128 +
                # SIGINT / SIGTERM), the process itself has nothing more to say:
                # what comes on its pipes now is from what it started (a helper's
                # complaint that its parent vanished), noise like the others'
                signalled = c < 0 or c in _SIGNAL_EXITS
                end_all(keep=None if signalled else i)
                return JobEnd(_status(c) or 1, "failed", i, c, message=(
                    f"process {i} exited with status {_status(c)}; stopped the "
                    "others"))
            if all(c is not None for c in codes):
                _join(pumps)
                lines.flush()
                return JobEnd(_status(codes[0]), "ok")
            if deadline is not None and time.monotonic() > deadline:
                end_all()
                return JobEnd(124, "timeout", message=(
                    f"timed out after {timeout_s:g} s; stopped all {n} processes"))
            time.sleep(0.05)
    except KeyboardInterrupt:
        end_all()
        return JobEnd(130, "interrupted", signum=int(signal.SIGINT),
                      message="interrupted (SIGINT); stopped all processes")
    except _Terminated:
        end_all()
        return JobEnd(143, "interrupted", signum=int(signal.SIGTERM),
                      message="interrupted (SIGTERM); stopped all processes")
    finally:
        _stop(procs)
        _join(pumps)
        lines.flush()
        lines.wake.set()
        if in_main:
            signal.signal(signal.SIGTERM, old_term)


def _join(pumps: list[threading.Thread]) -> None:
    for t in pumps:
        t.join(timeout=2.0)


def without_option(argv: Sequence[str], option: str) -> list[str]:
    """`argv` without ``option VALUE`` / ``option=VALUE`` (e.g. a CLI re-running
    itself in each worker without ``--processes N``)."""
    out, skip = [], False
    for arg in argv:
        if skip:
            skip = False
        elif arg == option:
            skip = True
        elif not arg.startswith(option + "="):
            out.append(arg)
    return out


def main(argv: list[str] | None = None) -> int:
    """``python -m cgda_jax.launch -n N [--timeout S] [--ok-codes 0 1] -- CMD ...``"""
    p = argparse.ArgumentParser(
        prog="python -m cgda_jax.launch",
        description="Run N copies of a command as one multi-process JAX job on this "
        "machine (each calls cgda_jax.distributed.initialize()).")
    p.add_argument("-n", "--processes", type=int, required=True, metavar="N")
    p.add_argument("--timeout", type=float, metavar="S",
                   help="stop every process after S seconds (status 124)")
    p.add_argument("--ok-codes", type=int, nargs="+", default=[0], metavar="CODE",
                   help="exit statuses that are not failures (default 0)")
    p.add_argument("command", nargs=argparse.REMAINDER,
                   help="the command, after --")
    args = p.parse_args(argv)
    cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not cmd:
        p.error("give the command to run after --")
    if args.processes < 1:
        p.error(f"-n must be >= 1; got {args.processes}")
    return launch(args.processes, cmd, timeout_s=args.timeout,
                  ok_codes=args.ok_codes)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
