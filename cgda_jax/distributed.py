"""Several processes (one machine or many) on JAX's own distributed runtime.

Independent trials are embarrassingly parallel, so the multi-process path is plain:
every process runs its share of the trial seeds on its own devices (the same
`run_trials` as one process) and the per-seed results are then gathered to every
process with one collective (``jax.experimental.multihost_utils.process_allgather``;
on CPU through gloo). No array ever spans processes, so no kernel changes.

- `initialize`: join the job. Reads the environment (see below) and calls
  ``jax.distributed.initialize`` before anything else touches JAX; a no-op returning
  False when no job is described (a plain single-process run). JAX's preemption
  notifier (which takes SIGTERM for itself) stays off unless asked for, and a
  launched worker dies with its launcher (`follow_launcher`).
- `launch` (`cgda_jax.launch`; ``python -m cgda_jax.launch -n N -- CMD``): start N
  copies of a command on this machine (a localhost coordinator on a free port),
  stream their output prefixed ``[p0]``, ``[p1]``, ..., stop them all when one
  fails, on a timeout or on Ctrl-C; returns the job's exit status.
- `distributed_trials`: `run_trials` split over every process's devices, gathered
  to every process; the same results as a single-process `run_trials` with the
  same seeds (tests/test_distributed.py).
- `share`, `allgather_objects`: the two pieces `distributed_trials` is made of, for
  other per-seed work (e.g. the CLI's trials of an experiment config).
- `is_writer`: True on process 0 only. **Rule: only process 0 writes files**
  (results folders, reports, plots); every process holds the gathered results, the
  others only compute.

Environment (read by `initialize`; `launch` sets the first three)::

    CGDA_COORDINATOR=host:port   process 0's address and a free port (required for
                                 the explicit form; process 0 listens there)
    CGDA_NUM_PROCESSES=N         processes in the job
    CGDA_PROCESS_ID=i            this process, 0 .. N-1
    CGDA_LOCAL_DEVICE_IDS=0,1    optional: the local accelerators this process
                                 uses (e.g. one GPU per process on a GPU node)
    CGDA_JOIN_TIMEOUT=300        optional: seconds to wait for every process to
                                 join; then the process ends (status 3, one line)
    CGDA_CLUSTER=auto            instead of the three above: JAX's own detection
                                 (SLURM ``srun``, Open MPI ``mpirun``, Kubernetes,
                                 Cloud TPU); or name one: slurm, ompi, mpi4py, ...

On CPU the collectives go through gloo (``jax_cpu_collectives_implementation``), set
by `initialize`; on GPU through NCCL, on TPU through the interconnect, unchanged.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import pickle
import signal
import sys
import threading
from collections.abc import Sequence
from typing import Any

from cgda_jax.job import (
    ENV_CLUSTER,
    ENV_COORDINATOR,
    ENV_JOIN_TIMEOUT,
    ENV_LAUNCHER_PID,
    ENV_LOCAL_DEVICE_IDS,
    ENV_NUM_PROCESSES,
    ENV_PROCESS_ID,
    job_from_env,
    join_timeout,
)

__all__ = [
    "ENV_CLUSTER",
    "ENV_COORDINATOR",
    "ENV_LOCAL_DEVICE_IDS",
    "ENV_NUM_PROCESSES",
    "ENV_PROCESS_ID",
    "allgather_objects",
    "distributed_trials",
    "follow_launcher",
    "initialize",
    "is_writer",
    "launch",
    "share",
]

#: Status of a process that ended because its job did not join in time.
JOIN_FAILED = 3


def _watch_join(timeout_s: float, where: str, waiting, on_timeout) -> threading.Event:
    """A thread that says ``waiting(text)`` after a few seconds and, unless the
    returned event is set within ``timeout_s``, calls ``on_timeout(line)`` and ends
    the process (`os._exit`: JAX's own end of the wait aborts it, SIGABRT with a
    C++ stack)."""
    done = threading.Event()

    def watch():
        if not done.wait(min(5.0, timeout_s / 2)) and waiting is not None:
            waiting(f"waiting for every process of the job to join at {where} (up to "
                    f"{timeout_s:g} s, {ENV_JOIN_TIMEOUT})")
        if done.wait(max(0.0, timeout_s - min(5.0, timeout_s / 2))):
            return
        with contextlib.suppress(Exception):
            on_timeout(f"the multi-process job at {where} did not join within "
                       f"{timeout_s:g} s (a process that never started or cannot "
                       f"reach it? {ENV_JOIN_TIMEOUT} sets the wait)")
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(JOIN_FAILED)

    threading.Thread(target=watch, name="cgda-join", daemon=True).start()
    return done


def _stderr_line(line: str) -> None:
    sys.stderr.write(f"cgda_jax: error: {line}\n")


def initialize(*, timeout_s: float | None = None, heartbeat_timeout_s: int = 100,
               preemption_service: bool = False, waiting=None,
               on_timeout=_stderr_line) -> bool:
    """Join the multi-process job the environment describes (module docstring).

    Call it first, before any JAX computation (``jax.distributed.initialize`` must
    precede the backends). Also selects gloo for CPU collectives. A worker started
    by `cgda_jax.launch` also ends when its launcher ends, even by SIGKILL (Linux:
    the parent-death signal), so no worker outlives its job.

    Args:
        timeout_s: how long to wait for every process to connect (default
            ``$CGDA_JOIN_TIMEOUT``, else 300 s); then ``on_timeout(line)`` is called
            and the process ends with status `JOIN_FAILED` (3).
        waiting: called with a line after a few seconds of waiting (None: quiet).
        on_timeout: says the line (default: on stderr).
        heartbeat_timeout_s: how soon the others notice a process that died.
        preemption_service: keep JAX's preemption service, whose notifier takes
            SIGTERM for itself (it reports "SIGTERM caught" and the process goes
            on); off by default, so that SIGTERM reaches the program's own handler
            (``cgda`` ends the process and cleans its results folder up).

    Returns:
        True when a job was joined (``jax.process_count()`` processes), False when
        the environment describes none (single process; nothing done) or this
        process already joined.

    Raises:
        ValueError: malformed or incomplete CGDA_* variables (named).
        RuntimeError: JAX already ran a computation in this process, or the job
            could not be joined (the message names the coordinator).
    """
    import jax

    job = job_from_env()
    if job is None or jax.distributed.is_initialized():
        return False
    timeout_s = join_timeout() if timeout_s is None else float(timeout_s)
    follow_launcher()
    if "jax_cpu_collectives_implementation" in jax.config.values:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    if "jax_enable_preemption_service" in jax.config.values:
        jax.config.update("jax_enable_preemption_service", bool(preemption_service))
    where = job.get("coordinator_address") or (
        f"{ENV_CLUSTER}={os.environ.get(ENV_CLUSTER)}")
    done = _watch_join(timeout_s, where, waiting, on_timeout)
    try:
        jax.distributed.initialize(
            **job,  # JAX's own wait ends later: the watch speaks first
            initialization_timeout=int(timeout_s) + 60,
            heartbeat_timeout_seconds=int(heartbeat_timeout_s),
        )
    except Exception as err:
        raise RuntimeError(
            f"could not join the multi-process job ({where}): "
            f"{str(err).strip().splitlines()[0] if str(err).strip() else err!r}"
        ) from err
    finally:
        done.set()
    return True


def follow_launcher() -> bool:
    """When this process is a worker of `cgda_jax.launch` (``CGDA_LAUNCHER_PID``),
    have the kernel kill it when the launcher dies (Linux ``PR_SET_PDEATHSIG``;
    strictly: when the launcher's thread that started it ends, so call `launch`
    from a thread that outlives the job); exits at once when the launcher is
    already gone. True when set up."""
    pid = os.environ.get(ENV_LAUNCHER_PID, "").strip()
    if not pid.isdigit() or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        if libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):  # pragma: no cover - no prctl
        return False
    if os.getppid() != int(pid):  # the launcher died before prctl
        os._exit(128 + int(signal.SIGKILL))
    return True


def process_index() -> int:
    """This process's index (0 when single-process; see `is_writer`)."""
    import jax

    if jax.distributed.is_initialized():
        return int(jax.process_index())
    return int(os.environ.get(ENV_PROCESS_ID, "0") or 0)


def is_writer() -> bool:
    """True on the one process that writes files: process 0.

    After `initialize`, ``jax.process_index() == 0``; before it (or without a job),
    the ``CGDA_PROCESS_ID`` variable decides, so a worker that has not joined yet
    still does not write.
    """
    return process_index() == 0


# ---------------------------------------------------------------------------
# Splitting work and gathering results
# ---------------------------------------------------------------------------


def _device_counts() -> list[int]:
    import jax

    counts = [0] * jax.process_count()
    for d in jax.devices():
        counts[d.process_index] += 1
    return counts


def share(n_items: int, counts: Sequence[int] | None = None,
          index: int | None = None) -> range:
    """This process's contiguous slice of ``range(n_items)``.

    Items are dealt evenly over all devices of all processes (the first
    ``n_items % D`` devices get one more), so a process gets as many as its local
    devices take. Contiguous, in process order: the slices of processes 0, 1, ...
    concatenate to ``range(n_items)``.

    Args:
        n_items: how many (trials).
        counts: devices per process (default: from ``jax.devices()``).
        index: the process (default: this one).
    """
    import jax

    counts = list(_device_counts() if counts is None else counts)
    index = int(jax.process_index() if index is None else index)
    total = sum(counts)
    per_device = [n_items // total + (d < n_items % total) for d in range(total)]
    first = sum(counts[:index])
    start = sum(per_device[:first])
    return range(start, start + sum(per_device[first:first + counts[index]]))


#: How long `allgather_objects` waits for the slowest process (seconds).
GATHER_TIMEOUT_S = 24 * 3600
_GATHERS = [0]  # calls so far: names each call's barrier (same on every process)


def _barrier(timeout_s: float) -> None:
    """Wait on the coordination service (no collective) until every process is
    here. The first CPU collective sets up gloo with a fixed 30 s limit for all
    processes to arrive, so the collectives must start together even when one
    process's share took minutes longer."""
    from jax._src import distributed as jax_distributed

    client = getattr(jax_distributed.global_state, "client", None)
    if client is None:  # pragma: no cover - only without a job
        return
    _GATHERS[0] += 1
    client.wait_at_barrier(f"cgda_allgather_{_GATHERS[0]}",
                           timeout_in_ms=int(timeout_s * 1000))


def allgather_objects(obj: Any, timeout_s: float | None = None) -> list[Any]:
    """Every process's ``obj`` (picklable), in process order, on every process.

    A barrier (waits up to `timeout_s`, default `GATHER_TIMEOUT_S`, for the
    slowest process), then ``process_allgather`` of the sizes and of the pickled
    bytes padded to the longest. Every process must call it, the same number of
    times. Single process: ``[obj]``.
    """
    import jax
    import numpy as np

    if jax.process_count() == 1:
        return [obj]
    from jax.experimental import multihost_utils

    _barrier(GATHER_TIMEOUT_S if timeout_s is None else timeout_s)
    data = np.frombuffer(pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL),
                         dtype=np.uint8)
    sizes = np.asarray(multihost_utils.process_allgather(
        np.array([data.size], np.int64))).reshape(-1)
    padded = np.zeros(int(sizes.max()), np.uint8)
    padded[:data.size] = data
    rows = np.asarray(multihost_utils.process_allgather(padded))
    return [pickle.loads(rows[k, :int(sizes[k])].tobytes())
            for k in range(rows.shape[0])]


def _portable(err: BaseException) -> BaseException:
    try:
        pickle.loads(pickle.dumps(err))
        return err
    except Exception:  # noqa: BLE001 - an unpicklable error travels as text
        return RuntimeError(f"{type(err).__name__}: {err}")


def _local_sharding(n_trials: int):
    import jax

    from cgda_jax.sharding import population_mesh, population_sharding

    local = jax.local_devices()[:max(1, n_trials)]
    if len(local) == 1:
        return None  # the unsharded single-device program
    return population_sharding(mesh=population_mesh(devices=local))


def distributed_trials(strategy: str, sim: Any, goal: Any, n_trials: int, *,
                       seed: int = 0, **kwargs: Any) -> list:
    """`run_trials` over all processes of the job; every process gets all results.

    Trial r (seed ``seed + r``) runs on the process whose `share` holds r, inside
    one `run_trials` call per process over its local devices (its ``devices``
    argument: a sharding of ``jax.local_devices()``), then the results are
    gathered (`allgather_objects`). Without a job (one process) it is `run_trials`
    on the local devices.

    Args:
        strategy, sim, goal, n_trials, seed: as in `run_trials`.
        **kwargs: the rest of `run_trials`' arguments except ``devices`` (decided
            here); ``progress_fn`` reports this process's trials only.

    Returns:
        ``n_trials`` `ExecutionResult`s in seed order, the same per seed as
        ``run_trials(strategy, sim, goal, n_trials, seed=seed, **kwargs)``;
        ``info["process"]``/``info["processes"]`` say where each ran, and its
        wall/compile times are those of that process's batch.

    Raises:
        Exception: the first failing process's exception, raised on every process
            (so none waits forever), with a note naming that process.
    """
    import jax

    from cgda_jax.strategies.trials import run_trials

    if "devices" in kwargs:
        raise ValueError("distributed_trials decides `devices` itself (each "
                         "process uses its local devices); do not pass it")
    if int(n_trials) < 1:
        raise ValueError(f"n_trials must be >= 1; got {n_trials}")
    mine = share(int(n_trials))
    me, n_proc = int(jax.process_index()), int(jax.process_count())
    payload: tuple[str, Any]
    try:
        results = []
        if len(mine):
            results = run_trials(strategy, sim, goal, len(mine),
                                 seed=seed + mine.start,
                                 devices=_local_sharding(len(mine)), **kwargs)
        for res in results:
            res.info["process"], res.info["processes"] = me, n_proc
        payload = ("ok", results)
    except Exception as err:  # noqa: BLE001 - sent to the others, raised below
        payload = ("error", _portable(err))
    gathered = allgather_objects(payload)
    for k, (status, value) in enumerate(gathered):
        if status == "error":
            value.add_note(f"(raised on process {k} of {n_proc})")
            raise value
    return [res for _, part in gathered for res in part]


def launch(n_processes: int, argv: Sequence[str], **kwargs: Any) -> int:
    """`cgda_jax.launch.launch`: run N copies of `argv` as one job on this machine."""
    from cgda_jax.launch import launch as _launch

    return _launch(n_processes, argv, **kwargs)
