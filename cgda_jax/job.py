"""The environment of a multi-process job: the ``CGDA_*`` variable names that
`cgda_jax.launch` sets for its workers and `cgda_jax.distributed` reads, and their
parsing (`job_from_env`). Both modules import it; it imports neither.
"""

from __future__ import annotations

import os
from typing import Any

ENV_COORDINATOR = "CGDA_COORDINATOR"
ENV_NUM_PROCESSES = "CGDA_NUM_PROCESSES"
ENV_PROCESS_ID = "CGDA_PROCESS_ID"
ENV_LOCAL_DEVICE_IDS = "CGDA_LOCAL_DEVICE_IDS"
ENV_CLUSTER = "CGDA_CLUSTER"


def _env_int(name: str, env: dict[str, str]) -> int:
    if name not in env:
        raise ValueError(
            f"{ENV_COORDINATOR} is set but {name} is not: set {ENV_COORDINATOR}, "
            f"{ENV_NUM_PROCESSES} and {ENV_PROCESS_ID} together"
        )
    try:
        return int(env[name])
    except ValueError:
        raise ValueError(f"{name}={env[name]!r} is not an integer") from None


def job_from_env(env: dict[str, str] | None = None) -> dict[str, Any] | None:
    """The keyword arguments of ``jax.distributed.initialize`` the environment asks
    for, or None when it describes no job (see the module docstring).

    Raises:
        ValueError: an incomplete or malformed explicit form (names the variable).
    """
    env = dict(os.environ if env is None else env)
    ids = env.get(ENV_LOCAL_DEVICE_IDS, "").strip()
    try:
        local = [int(i) for i in ids.split(",")] if ids else None
    except ValueError:
        raise ValueError(f"{ENV_LOCAL_DEVICE_IDS}={ids!r}: use e.g. 0 or 0,1") from None
    if env.get(ENV_COORDINATOR, "").strip():
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
    cluster = env.get(ENV_CLUSTER, "").strip().lower()
    if cluster:
        method = None if cluster == "auto" else cluster
        return {"cluster_detection_method": method, "local_device_ids": local}
    return None
