"""The environment of a multi-process job: the ``CGDA_*`` variable names that
`cgda_jax.launch` sets for its workers and `cgda_jax.distributed` reads, and their
parsing (`job_from_env`). Both modules import it; it imports neither.

A job is described in one of two forms, never half of one: the explicit form
(``CGDA_COORDINATOR``, ``CGDA_NUM_PROCESSES`` and ``CGDA_PROCESS_ID``, all three),
or ``CGDA_CLUSTER`` (JAX's own detection; then none of the three). A process id or
a process count without a coordinator, or either form mixed with the other, is an
error that names the variables (a process that took itself for a worker would run
every seed and write nothing).
"""

from __future__ import annotations

import os
from typing import Any

ENV_COORDINATOR = "CGDA_COORDINATOR"
ENV_NUM_PROCESSES = "CGDA_NUM_PROCESSES"
ENV_PROCESS_ID = "CGDA_PROCESS_ID"
ENV_LOCAL_DEVICE_IDS = "CGDA_LOCAL_DEVICE_IDS"
ENV_CLUSTER = "CGDA_CLUSTER"
#: Set by `cgda_jax.launch` for its workers: the launcher's process id (a worker
#: ends when the launcher does, `cgda_jax.distributed.initialize`).
ENV_LAUNCHER_PID = "CGDA_LAUNCHER_PID"
#: Set by ``cgda run --trials N --processes P`` for its workers: the temporary
#: results folder the launching process holds (process 0 writes into it; the
#: launcher moves it into place) and the folder it becomes.
ENV_JOB_WORK = "CGDA_JOB_WORK"
ENV_JOB_FOLDER = "CGDA_JOB_FOLDER"

#: Seconds a process waits for every process of its job to join (default
#: `JOIN_TIMEOUT_S`); then it ends with one line (`cgda_jax.distributed.initialize`).
ENV_JOIN_TIMEOUT = "CGDA_JOIN_TIMEOUT"
JOIN_TIMEOUT_S = 300.0

_EXPLICIT = (ENV_COORDINATOR, ENV_NUM_PROCESSES, ENV_PROCESS_ID)


def join_timeout(env: dict[str, str] | None = None) -> float:
    """`ENV_JOIN_TIMEOUT` in seconds (default `JOIN_TIMEOUT_S`).

    Raises:
        ValueError: not a number > 0 (named).
    """
    env = os.environ if env is None else env
    text = env.get(ENV_JOIN_TIMEOUT, "").strip()
    if not text:
        return JOIN_TIMEOUT_S
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 < value < 1e6:
        raise ValueError(f"{ENV_JOIN_TIMEOUT}={text!r}: use seconds > 0 (default "
                         f"{JOIN_TIMEOUT_S:g}), less than 1e6")
    return value


def _env_int(name: str, env: dict[str, str]) -> int:
    try:
        return int(env[name])
    except ValueError:
        raise ValueError(f"{name}={env[name]!r} is not an integer") from None


def _set(env: dict[str, str], name: str) -> bool:
    return bool(env.get(name, "").strip())


def job_from_env(env: dict[str, str] | None = None) -> dict[str, Any] | None:
    """The keyword arguments of ``jax.distributed.initialize`` the environment asks
    for, or None when it describes no job (see the module docstring).

    Raises:
        ValueError: an incomplete, mixed or malformed form (names the variables).
    """
    env = dict(os.environ if env is None else env)
    ids = env.get(ENV_LOCAL_DEVICE_IDS, "").strip()
    try:
        local = [int(i) for i in ids.split(",")] if ids else None
    except ValueError:
        raise ValueError(f"{ENV_LOCAL_DEVICE_IDS}={ids!r}: use e.g. 0 or 0,1") from None
    given = [name for name in _EXPLICIT if _set(env, name)]
    cluster = env.get(ENV_CLUSTER, "").strip().lower()
    if cluster and given:
        raise ValueError(
            f"{ENV_CLUSTER}={env[ENV_CLUSTER].strip()} and {', '.join(given)} are "
            f"both set: describe the job by {ENV_CLUSTER} alone or by "
            f"{', '.join(_EXPLICIT)}, not both")
    if given and len(given) < len(_EXPLICIT):
        missing = [name for name in _EXPLICIT if name not in given]
        raise ValueError(
            f"{' and '.join(given)} {'is' if len(given) == 1 else 'are'} set but "
            f"{' and '.join(missing)} {'is' if len(missing) == 1 else 'are'} not: "
            f"set {', '.join(_EXPLICIT)} together (or none of them: one process)")
    if given:
        address = env[ENV_COORDINATOR].strip()
        host, _, port = address.rpartition(":")
        if not host or not port.isdigit():
            raise ValueError(f"{ENV_COORDINATOR}={address!r}: use host:port")
        n = _env_int(ENV_NUM_PROCESSES, env)
        i = _env_int(ENV_PROCESS_ID, env)
        if n < 1 or not 0 <= i < n:
            raise ValueError(
                f"{ENV_PROCESS_ID}={i} with {ENV_NUM_PROCESSES}={n}: need "
                f"{ENV_NUM_PROCESSES} >= 1 and 0 <= {ENV_PROCESS_ID} < it"
            )
        return {"coordinator_address": address, "num_processes": n, "process_id": i,
                "local_device_ids": local}
    if cluster:
        method = None if cluster == "auto" else cluster
        return {"cluster_detection_method": method, "local_device_ids": local}
    return None
