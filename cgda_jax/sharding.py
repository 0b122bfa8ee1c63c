"""Split the population (or trials) axis across all devices with `jax.sharding`.

Every hot path in cgda_jax is a function of a leading batch axis (candidates of a
population, independent trials) that is embarrassingly parallel.  These helpers put
that axis on a 1-D device mesh so XLA's partitioner (GSPMD) runs each device's slice
of the batch on that device, with no change to the kernels:

- `population_mesh` / `population_sharding`: a 1-D ``Mesh`` over ``jax.devices()``
  (axis ``"pop"``) and the ``NamedSharding`` that splits an array's leading axis
  over it (the other axes are replicated).
- `pad_leading`: pad the leading axis to a multiple of the device count by repeating
  the last row (a valid candidate, so padding never simulates garbage or NaN).
- `shard_leading`: place a pytree of host arrays with that sharding (padding, or a
  ``ValueError`` naming the sizes when the axis does not divide evenly).
- `shard_population`: wrap ``fn(pop (P, ...)) -> pytree of (P, ...)`` so that, inside
  or outside ``jit``, the population is padded, constrained to the sharding, evaluated
  and cut back to P rows.  Use it in a strategy's fitness evaluation.
- `sharded_execute`: one jitted, sharded call of e.g. ``sim.execute_population``.

The strategies expose this as ``devices=None | K | "all"`` (`resolve_devices`):
``run_trials(..., devices=...)`` splits the trials axis (R padded to a multiple of K
by repeating the last trial), ``run_ie/run_fte/run_iet/run_oet(..., devices=...)``
the population of each generation's simulator call (P padded likewise).

Results are the same as unsharded evaluation (each candidate is computed by the same
per-candidate program; tests/test_sharding.py checks this on 4 forced host devices).

Several processes or machines: `cgda_jax.distributed` is the code path.
`cgda_jax.distributed.initialize` joins the job described by the environment
(``CGDA_COORDINATOR`` / ``CGDA_NUM_PROCESSES`` / ``CGDA_PROCESS_ID``, or
``CGDA_CLUSTER=auto`` for JAX's own SLURM / Open MPI / Kubernetes detection) before
anything else touches JAX; `cgda_jax.distributed.launch` starts N such processes on
one machine; `cgda_jax.distributed.distributed_trials` runs each process's share of
the trials with `run_trials` over that process's *local* devices (a
`population_sharding` of ``jax.local_devices()``) and gathers the per-seed results to
every process. No array spans processes there (trials are independent), so the
kernels and the shardings above are unchanged; only process 0 writes files
(`cgda_jax.distributed.is_writer`).

After ``jax.distributed.initialize``, ``jax.devices()`` lists the devices of *all*
processes, so `population_mesh()` / ``devices="all"`` would build a mesh spanning
every process, to split ONE population over every machine (not exercised by the
tests; every process must then make the same calls with identical host arrays, or
build global arrays with ``jax.make_array_from_process_local_data``). For many
trials, `distributed_trials` needs no cross-machine traffic inside a generation.

On one machine, ``XLA_FLAGS=--xla_force_host_platform_device_count=K`` (set before
JAX is imported) splits the CPU into K devices, which is how the tests run this.
"""

from __future__ import annotations

import functools
import numbers
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
from jax.sharding import Mesh, NamedSharding, PartitionSpec

__all__ = [
    "AXIS",
    "axis_shardings",
    "pad_leading",
    "population_mesh",
    "population_sharding",
    "resolve_devices",
    "shard_leading",
    "shard_population",
    "sharded_execute",
]

#: Name of the mesh axis the population / trials axis is split over.
AXIS = "pop"


def population_mesh(
    n_devices: int | None = None, devices: Sequence[jax.Device] | None = None
) -> Mesh:
    """A 1-D mesh (axis ``"pop"``) over the first ``n_devices`` devices.

    Args:
        n_devices: how many devices; default all of ``jax.devices()`` (every host's,
            after ``jax.distributed.initialize``).
        devices: the devices to use instead of ``jax.devices()``.

    Raises:
        ValueError: ``n_devices`` < 1 or more than there are.
    """
    available = list(jax.devices() if devices is None else devices)
    n = len(available) if n_devices is None else int(n_devices)
    if not 1 <= n <= len(available):
        raise ValueError(
            f"n_devices={n_devices} but {len(available)} device(s) are available "
            f"({available[0].platform if available else 'none'})"
        )
    return Mesh(available[:n], (AXIS,))


def population_sharding(
    n_devices: int | None = None, mesh: Mesh | None = None
) -> NamedSharding:
    """Sharding that splits an array's leading axis over a 1-D device mesh.

    Args:
        n_devices: see `population_mesh` (ignored when ``mesh`` is given).
        mesh: a mesh with an axis named ``"pop"``; default `population_mesh`.
    """
    mesh = population_mesh(n_devices) if mesh is None else mesh
    return NamedSharding(mesh, PartitionSpec(AXIS))


def resolve_devices(
    devices: int | str | NamedSharding | None,
) -> NamedSharding | None:
    """The sharding a ``devices=`` option of the strategies asks for.

    Args:
        devices: None (no sharding: today's single-device program), ``"all"`` (every
            device of ``jax.devices()``), an int K (the first K devices) or a
            ``NamedSharding`` from `population_sharding` (used as is).

    Returns:
        None or a `population_sharding`.

    Raises:
        ValueError: anything else, or more devices than there are.
    """
    if devices is None or isinstance(devices, NamedSharding):
        return devices
    if isinstance(devices, str):
        if devices != "all":
            raise ValueError(f"devices={devices!r}: use None, 'all' or a device count")
        return population_sharding()
    if isinstance(devices, bool) or not isinstance(devices, numbers.Integral):
        raise ValueError(f"devices={devices!r}: use None, 'all' or a device count")
    return population_sharding(devices)


def _n_shards(sharding: NamedSharding) -> int:
    return int(sharding.mesh.shape[AXIS])


def _leading_size(tree: Any) -> int:
    sizes = {leaf.shape[0] if leaf.ndim else None for leaf in jax.tree.leaves(tree)}
    if len(sizes) != 1 or None in sizes:
        raise ValueError(
            f"every leaf needs the same leading (population) axis; got sizes {sizes}"
        )
    return sizes.pop()


def pad_leading(tree: Any, multiple: int) -> Any:
    """Pad every leaf's leading axis up to a multiple by repeating its last row.

    Works on traced values (inside ``jit``/``vmap``); a no-op when it already divides.

    Args:
        tree: pytree of arrays (P, ...), all with the same P >= 1.
        multiple: the device count.

    Returns:
        The same pytree with leaves (ceil(P / multiple) * multiple, ...).
    """
    size = _leading_size(tree)
    extra = -size % int(multiple)
    if extra == 0:
        return tree

    def pad(x):
        return jnp.concatenate([x, jnp.repeat(x[-1:], extra, axis=0)], axis=0)

    return jax.tree.map(pad, tree)


def axis_shardings(tree: Any, sharding: NamedSharding, axis: int = 0) -> Any:
    """Per-leaf shardings that split axis ``axis`` of every leaf over the mesh.

    For ``jax.jit(..., in_shardings=..., out_shardings=...)`` of functions whose
    inputs/outputs are batched over trials or candidates: leaves with fewer than
    ``axis + 1`` dimensions are replicated.  E.g. a strategy runner that vmaps a
    plan over R trials can keep its carry split over devices with
    ``axis_shardings(carry_shapes, s)`` and its per-chunk metrics (G, R, ...) with
    ``axis_shardings(metric_shapes, s, axis=1)``; the whole loop then runs R/K
    trials per device with no change to the plan (tests/test_sharding.py).

    Args:
        tree: pytree of arrays or ``jax.ShapeDtypeStruct`` (e.g. ``jax.eval_shape``).
        sharding: from `population_sharding` (its mesh and axis name are used).
        axis: the batch axis.

    Returns:
        A pytree of ``NamedSharding`` with the structure of ``tree``.
    """
    mesh = sharding.mesh

    def one(leaf):
        if len(leaf.shape) <= axis:
            return NamedSharding(mesh, PartitionSpec())
        return NamedSharding(mesh, PartitionSpec(*([None] * axis), AXIS))

    return jax.tree.map(one, tree)


def shard_leading(tree: Any, sharding: NamedSharding, *, pad: bool = False) -> Any:
    """Place a pytree on the devices, its leading axis split by ``sharding``.

    Args:
        tree: pytree of arrays (P, ...), host or device; typed PRNG keys work too.
        sharding: from `population_sharding`.
        pad: pad to a multiple of the device count (see `pad_leading`) instead of
            raising; the caller then drops the extra rows of the results.

    Raises:
        ValueError: P is not a multiple of the device count and ``pad`` is False.
    """
    size, n = _leading_size(tree), _n_shards(sharding)
    if size % n:
        if not pad:
            raise ValueError(
                f"leading (population/trials) axis of size {size} is not divisible "
                f"by the {n} devices of the mesh; choose a multiple of {n} or pass "
                "pad=True"
            )
        tree = pad_leading(tree, n)
    return jax.device_put(tree, sharding)


def shard_population(
    fn: Callable[[Any], Any], sharding: NamedSharding | None = None
) -> Callable[[Any], Any]:
    """Wrap a population function so that its batch is split across devices.

    Args:
        fn: ``fn(pop) -> out`` where ``pop`` and every leaf of ``out`` have the same
            leading population axis P (e.g. ``sim.execute_population`` or a fitness).
        sharding: default `population_sharding` over all devices.

    Returns:
        ``wrapped(pop) -> out``, same values as ``fn``; pads P to a multiple of the
        device count, constrains inputs and outputs to ``sharding`` and drops the
        padded rows.  Usable inside ``jit`` (and under an outer ``vmap``); on one
        device it is ``fn`` plus a no-op constraint.
    """
    sharding = population_sharding() if sharding is None else sharding
    n = _n_shards(sharding)

    def constrain(tree):
        return jax.tree.map(
            lambda x: jax.lax.with_sharding_constraint(x, sharding), tree
        )

    def wrapped(pop):
        size = _leading_size(pop)
        out = constrain(fn(constrain(pad_leading(pop, n))))
        return jax.tree.map(lambda x: x[:size], out)

    return wrapped


@functools.lru_cache(maxsize=32)
def _jitted(sim_fn: Callable[[Any], Any], sharding: NamedSharding) -> Callable:
    return jax.jit(shard_population(sim_fn, sharding))


def sharded_execute(
    sim_fn: Callable[[Any], Any], pop: Any, sharding: NamedSharding | None = None
) -> Any:
    """Evaluate a whole population in one jitted call split across devices.

    The jitted wrapper is cached per ``(sim_fn, sharding)``, so repeated calls with
    the same shapes do not recompile.

    Args:
        sim_fn: ``(P, ...) -> (P, ...)``, e.g. ``sim.execute_population`` with
            ``pop`` (P, N, DoF) giving features (P, N, F). Must be hashable.
        pop: the population (pytree with leading axis P; any P >= 1).
        sharding: default `population_sharding` over all devices.

    Returns:
        ``sim_fn(pop)``, computed with each device evaluating its slice; the
        outputs stay sharded over the devices.
    """
    sharding = population_sharding() if sharding is None else sharding
    return _jitted(sim_fn, sharding)(pop)
