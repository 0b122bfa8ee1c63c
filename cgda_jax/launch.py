"""Start a multi-process job on this machine: N copies of a command, one job.

`launch` gives each copy the variables `cgda_jax.distributed.initialize` reads
(``CGDA_COORDINATOR=127.0.0.1:<free port>``, ``CGDA_NUM_PROCESSES``,
``CGDA_PROCESS_ID``), streams their output prefixed ``[p0]``, ``[p1]``, ..., stops
them all when one fails, on a timeout or on Ctrl-C, and returns the job's status.
From a shell::

    python -m cgda_jax.launch -n 4 [--timeout S] -- python my_trials.py ...

(the script calls ``cgda_jax.distributed.initialize()`` first). On a cluster the
scheduler starts the processes instead (README, "Several processes and machines").
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterable, Sequence
from typing import TextIO

from cgda_jax.job import (
    ENV_CLUSTER,
    ENV_COORDINATOR,
    ENV_NUM_PROCESSES,
    ENV_PROCESS_ID,
)

__all__ = ["free_port", "launch", "main", "without_option"]




def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on `host` right now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def _pump(pipe, out: TextIO, prefix: str, lock: threading.Lock) -> None:
    for raw in iter(pipe.readline, b""):
        line = raw.decode(errors="replace").rstrip("\r\n")
        with lock:
            out.write(f"{prefix}{line}\n")
            out.flush()
    pipe.close()


def _stop(procs: Iterable[subprocess.Popen], grace_s: float = 5.0) -> None:
    """SIGTERM each running worker's process group, SIGKILL what is left after
    `grace_s`."""
    procs = [p for p in procs if p.poll() is None]
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for p in procs:
            try:
                os.killpg(p.pid, sig)
            except (ProcessLookupError, PermissionError):
                pass
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline and any(p.poll() is None for p in procs):
            time.sleep(0.05)
        procs = [p for p in procs if p.poll() is None]
        if not procs:
            return


def _status(code: int) -> int:
    return 128 - code if code < 0 else code  # killed by signal n: 128 + n


class _Terminated(Exception):
    pass


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
    (SIGTERM, then SIGKILL after 5 s), as on `timeout_s` and on Ctrl-C / SIGTERM
    to the launcher: no worker outlives it.

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
            ENV_NUM_PROCESSES: str(n), "PYTHONUNBUFFERED": "1"}
    base.pop(ENV_CLUSTER, None)
    lock = threading.Lock()
    procs: list[subprocess.Popen] = []
    pumps: list[threading.Thread] = []
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
                t = threading.Thread(target=_pump, args=(pipe, stream, tag, lock),
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
                _stop(procs)
                _join(pumps)  # their last lines (a traceback) come first
                _note(err, lock, f"process {i} exited with status {_status(c)}; "
                      "stopped the others")
                return _status(c) or 1
            if all(c is not None for c in codes):
                return _status(codes[0])
            if deadline is not None and time.monotonic() > deadline:
                _stop(procs)
                _join(pumps)
                _note(err, lock, f"timed out after {timeout_s:g} s; stopped all "
                      f"{n} processes")
                return 124
            time.sleep(0.05)
    except KeyboardInterrupt:
        _stop(procs)
        _note(err, lock, "interrupted (SIGINT); stopped all processes")
        return 130
    except _Terminated:
        _stop(procs)
        _note(err, lock, "interrupted (SIGTERM); stopped all processes")
        return 143
    finally:
        _stop(procs)
        _join(pumps)
        if in_main:
            signal.signal(signal.SIGTERM, old_term)


def _join(pumps: list[threading.Thread]) -> None:
    for t in pumps:
        t.join(timeout=2.0)


def _note(stream: TextIO, lock: threading.Lock, text: str) -> None:
    with lock:
        stream.write(f"launch: {text}\n")
        stream.flush()


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
