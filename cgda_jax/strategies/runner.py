"""Drives a strategy plan: jitted generation chunks under `lax.scan`, Python only between.

A *plan* (see fte.py, ie.py, iet.py, oet.py) is a small object with pure functions:

- ``init(key) -> carry``
- ``step(carry) -> (carry, metrics)``: one generation; done parts are frozen inside.
- ``done(carry) -> bool``: nothing left to evolve.
- ``progress(carry) -> dict``: host figures for ``progress_fn`` (one entry per trial),
  ``generations`` among them: the count its result reports (IE: the slowest point's;
  IET, OET: summed over points; restarts included), not the chunks driven.
- ``finish(carry) -> dict``: final arrays (best trajectory, its execution, ...).
- ``to_result(final, history, timing) -> ExecutionResult`` on host NumPy arrays.
- ``max_generations_total``: an upper bound on generations (loop guard).
- ``n_points``: goal points (reported to ``progress_fn`` as ``points``).

and, from `cgda_jax.strategies.base.PlanBase`, what every driver asks of it:
``report_progress`` (``progress_fn`` after a chunk), ``split_results`` (a batch's
results per trial) and ``estimate`` (what a batch holds, checked before compiling).

`run_plan` is the entry every run shares (`cgda_jax.strategies.run`): it checks the goal,
builds the plan from its settings and drives it for a list of seeds.

`drive` compiles ``init``, a chunk of ``chunk_size`` generations and ``finish`` once each
(`compile_plan`, timed apart with ``jit(...).lower(...).compile()``), then calls the
compiled chunk until ``done``; between chunks it syncs one boolean and calls
``progress_fn``. With several keys the whole plan is vmapped over them (independent
trials in one batched call); with one, it runs on that trial directly, so that its
``lax.cond`` branches stay real (see `over_trials_fn`).

Several devices (``devices=`` of the ``run_*`` functions and `run_trials`, see
`cgda_jax.sharding`): `run_trials` splits the trials axis over them (`drive` with a
sharding), a single run splits the population of each generation's batched simulator
call (`PlanBase` with a sharding). Without ``devices`` the programs are unchanged.

Batched trials that shrink as they finish (`drive_repacked`, `drive_ie_points`;
``batching=`` of `cgda_jax.strategies.run_trials`, `driver`):

`drive` runs R trials in lock-step until the slowest one stops: every
generation costs R trials' work however many are still running. On a CPU, where a
generation's work grows about linearly with the batch, that wasted most of the batch.
The two drivers here drop finished work between chunks instead and re-pack what is
left into a smaller batch whose size comes from a short, fixed ladder (the full size
halved, rounded up, down to ``min_size``), so at most ``log2`` of it programs are
compiled:

- `drive_repacked` (every strategy): the batch holds the trials still running.
- `drive_ie_points` (IE with independent points: kinematic mode, stateless scene):
  the batch holds the (trial, point) evolutions still running, pooled over all the
  trials. IE points finish at very different generations (a trial's slowest point
  sets its length), so this drops about half of the work a per-trial run does.

A trial's result does not depend on the batch it runs in: the vmapped programs of
two or more trials give each trial the same bits whatever the batch size and the
other seeds (measured: batches of 2, 3, 4 and 8 holding seed 2, the shrinking
driver, the lock-step one and IE's pooled points; tests/test_trials_batching.py),
so the batch never shrinks below 2 (a lock-step "batch" of one, `drive` with
one key, is the single run). A single run (``run_fte(seed=s)``, one key through `drive`)
is the unbatched program: XLA fuses and rounds it differently in the last bits
(from about the second generation, 1e-6 in the fitness), and the rank-based
selection of an evolution strategy can turn that into another search path, so a
trial and the single run of its seed end equal to about 1e-4 on most seeds but on
another path on some (measured: 2 of 8 seeds of an FTE run on the tiny arm, final
errors 288 vs 227 mm and 402 vs 440 mm; issue 25 reports seed 3 of 10 on a 7-joint
arm in physics, 38.5 mm batched and 18.9 mm alone). Success rates are rates of the
same search; compare seeds one to one between batched runs. A trial's history is what its single run
records (its chunks until it stopped). ``info["batching"]`` says which driver ran and
``info["batch_sizes"]`` the batch of each chunk (trials, or point evolutions).

Divergence (see `cgda_jax.strategies.base`): after a run, `run_plan` logs ONE warning
through the ``cgda_jax`` logger when some candidate evaluations were invalid, and
raises `SimulationDiverged` when none was valid (`check_divergence`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from cgda_jax.programs import compile_ahead, compile_jit
from cgda_jax.sharding import axis_shardings, resolve_devices, shard_leading
from cgda_jax.sizes import check_estimate
from cgda_jax.strategies.base import check_config
from cgda_jax.strategies.result import ExecutionResult, SimulationDiverged

log = logging.getLogger("cgda_jax")

#: Number of times a chunk function was traced, per strategy name (tests use it to
#: prove that IET compiles one step for all of its points).
TRACE_COUNTS: dict[str, int] = {}


def _replicated(sharding: NamedSharding) -> NamedSharding:
    return NamedSharding(sharding.mesh, PartitionSpec())


def over_trials_fn(n_trials: int, sharding: NamedSharding | None) -> Callable:
    """How a plan function is applied over the trials axis (R, ...) of its inputs:
    `jax.vmap`, or for a single unsharded trial a call on the trial itself (its
    outputs given back a leading axis of 1). Under `vmap` a `lax.cond` whose
    predicate differs per trial runs both branches every time (a select); a single
    trial keeps the plans' conditionals (a restart, a point's end, a re-execution)
    real, run only when taken."""
    if n_trials != 1 or sharding is not None:
        return jax.vmap

    def single(fn: Callable) -> Callable:
        def one(x):
            out = fn(jax.tree.map(lambda a: a[0], x))
            return jax.tree.map(lambda a: jnp.expand_dims(a, 0), out)
        return one

    return single


def compile_plan(
    plan: Any,
    keys: jax.Array,
    *,
    chunk_size: int = 10,
    sharding: NamedSharding | None = None,
) -> tuple[Any, Any, Any, Any]:
    """Compiled ``(init, chunk, done, finish)`` of `plan` over `keys` (R,): vmapped,
    or for one unsharded key run on that trial directly (`over_trials_fn`).

    With `sharding` (see `cgda_jax.sharding.population_sharding`) the trials axis of
    the keys, the carry (R, ...) and the chunk's metrics (G, R, ...) is split over its
    devices (R must be a multiple of the device count); each device then runs R / K
    trials of the same per-trial program. Without it, a plan whose own ``sharding``
    splits the population keeps its keys and carry replicated over that mesh.
    """

    over_trials = over_trials_fn(int(keys.shape[0]), sharding)

    def chunk(carry):
        TRACE_COUNTS[plan.name] = TRACE_COUNTS.get(plan.name, 0) + 1
        return jax.lax.scan(
            lambda c, _: over_trials(plan.step)(c), carry, None, length=chunk_size
        )

    def all_done(carry):
        return jnp.all(over_trials(plan.done)(carry))

    carry_shape = jax.eval_shape(over_trials(plan.init), keys)
    init_kw: dict[str, Any] = {}
    chunk_kw: dict[str, Any] = {}
    carry_kw: dict[str, Any] = {}
    if sharding is not None:  # trials split over the mesh
        cs = axis_shardings(carry_shape, sharding)
        metric_shape = jax.eval_shape(chunk, carry_shape)[1]
        ms = axis_shardings(metric_shape, sharding, axis=1)
    elif getattr(plan, "sharding", None) is not None:  # only the population is split
        sharding = cs = ms = _replicated(plan.sharding)
    if sharding is not None:
        init_kw = {"in_shardings": sharding, "out_shardings": cs}
        chunk_kw = {"in_shardings": (cs,), "out_shardings": (cs, ms)}
        carry_kw = {"in_shardings": (cs,)}
    parts = [(f"runner.{plan.name}.{part}.{chunk_size}", f, x, kw)
             for part, f, kw, x in (
                 ("init", over_trials(plan.init), init_kw, keys),
                 ("chunk", chunk, chunk_kw, carry_shape),
                 ("done", all_done, carry_kw, carry_shape),
                 ("finish", over_trials(plan.finish), carry_kw, carry_shape))]
    for rank, (name, f, x, kw) in enumerate((parts[1], parts[0], *parts[2:])):
        # each in a thread (in a scope), traced one at a time, the chunk (the
        # longest to compile) first, so that its compile starts soonest
        compile_ahead(name, f, x, rank=min(rank, 1), **kw)
    # a program compiled before is reused (`cgda_jax.programs`)
    return tuple(compile_jit(name, f, x, **kw) for name, f, x, kw in parts)


def drive(
    plan: Any,
    keys: jax.Array,
    *,
    chunk_size: int = 10,
    progress_fn: Callable[[dict[str, Any]], None] | None = None,
    sharding: NamedSharding | None = None,
) -> list[Any]:
    """Runs `plan` for each key in `keys` (R,) in one batched call.

    Args:
        plan, keys, chunk_size, progress_fn: see the module docstring.
        sharding: split the R trials over the devices of this sharding (see
            `compile_plan`). When R is not a multiple of the device count the keys
            are padded by repeating the last one (the extra trials duplicate the last
            trial, so they do not change when the batch stops) and their results
            are dropped.

    Returns:
        One `ExecutionResult` per key; wall and compile times are those of the whole
        batch (``info["trials_in_batch"]`` says how many shared it).
    """
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size must be >= 1; got {chunk_size}")
    n_trials = keys.shape[0]
    if sharding is not None:
        keys = shard_leading(keys, sharding, pad=True)
    elif getattr(plan, "sharding", None) is not None:
        keys = jax.device_put(keys, _replicated(plan.sharding))

    t0 = time.perf_counter()
    init_c, chunk_c, done_c, finish_c = compile_plan(
        plan, keys, chunk_size=chunk_size, sharding=sharding
    )
    compile_time = time.perf_counter() - t0

    t1 = time.perf_counter()
    carry = init_c(keys)
    histories = []
    generations = 0
    while True:
        carry, metrics = chunk_c(carry)
        histories.append(metrics)
        generations += chunk_size
        finished = bool(done_c(carry))
        plan.report_progress(progress_fn, generations, finished, t1, carry)
        if finished or generations >= plan.max_generations_total:
            break
    final = jax.block_until_ready(finish_c(carry))
    wall = time.perf_counter() - t1

    history = jax.tree.map(lambda *xs: np.concatenate(xs, axis=0), *histories)
    final = jax.tree.map(np.asarray, final)
    timing = {
        "wall_time_s": wall,
        "compile_time_s": compile_time,
        "trials_in_batch": int(n_trials),
    }
    # history leaves are (G, R, ...), final leaves (R, ...)
    return plan.split_results(final, [jax.tree.map(lambda x, r=r: x[:, r], history)
                                       for r in range(n_trials)], timing)


def check_divergence(results: list[ExecutionResult]) -> None:
    """Reports diverged (invalid) candidate evaluations of a run's results.

    Logs one warning line (logger ``cgda_jax``; the CLI prints it as ``cgda:
    warning: ...``) when some evaluations were invalid.

    Raises:
        SimulationDiverged: no evaluation of any result was valid (every candidate of
            every evolution diverged): there is no posture to report.
    """
    invalid = sum(int(r.invalid_evaluations) for r in results)
    if invalid == 0:
        return
    total = sum(int(r.evaluations) for r in results)
    name = results[0].strategy.upper()
    run = (f"{name} run" if len(results) == 1
           else f"{name} runs ({len(results)} trials)")
    if invalid >= total:
        raise SimulationDiverged(
            f"every one of the {total} candidate evaluations of the {run} diverged "
            "(non-finite features): no posture could be evaluated. Check the "
            "simulation: actuator gains (kp) too high for the timestep, a timestep "
            "too large, or a model that is unstable from its initial state"
        )
    without = [(i, r.info.get("points_without_valid", [])) for i, r in
               enumerate(results)]
    without = [(i, p) for i, p in without if p]
    detail = ""
    if without:
        where = "; ".join(
            (f"trial {i}: " if len(results) > 1 else "") + f"points {p}"
            for i, p in without
        )
        detail = (f"; no valid candidate at all for {where}: no posture there, "
                  "goal not met")
    log.warning(
        "%d of %d candidate evaluations diverged (non-finite features): the %s ranked "
        "them last and never reported one as the best%s. If many diverge, check the "
        "simulation (actuator gains, timestep)", invalid, total, run, detail,
    )


def check_seeds(seeds: Any) -> list[int]:
    """`seeds` as ints in 0 .. 2**32 - 1 (JAX keys are 32-bit).

    Raises:
        ValueError: an empty list, or a seed out of range (named with its place).
    """
    out = []
    for i, s in enumerate(seeds):
        if isinstance(s, bool) or int(s) != s or not 0 <= int(s) <= 2**32 - 1:
            raise ValueError(f"seed {s!r} (trial {i}) is not an integer in 0 .. "
                             f"{2**32 - 1}; JAX keys are 32-bit")
        out.append(int(s))
    if not out:
        raise ValueError("seeds is empty: give at least one")
    return out


def seed_keys(seeds: Any) -> jax.Array:
    """Typed keys (R,) from integer seeds (R,)."""
    return jax.vmap(jax.random.key)(jnp.asarray(seeds, dtype=jnp.uint32))


def run_plan(
    plan_cls: type,
    sim: Any,
    goal: Any,
    settings: Any,
    seeds: list[int],
    *,
    progress_fn: Callable[[dict[str, Any]], None] | None = None,
    shard: str = "population",
    driver: Callable[..., list[ExecutionResult]] | None = None,
) -> list[ExecutionResult]:
    """Checks `goal`, builds the plan from its `settings`, runs it for `seeds`.

    Args:
        plan_cls: a plan class (e.g. `IEPlan`).
        sim, goal: the simulator and the goal (N, F) (`check_config`).
        settings: the plan's settings (`cgda_jax.strategies.settings.Settings`;
            already checked); its ``chunk_size`` and ``devices`` are the run's:
            None (one device, no sharding), "all", a device count or a sharding
            (see `cgda_jax.sharding.resolve_devices`).
        seeds: R seeds, run as R independent trials in one batched call.
        progress_fn: called with a dict after each chunk (see `drive`).
        shard: which axis `devices` splits: "population" (the candidates of each
            generation's batched simulator call, see `PlanBase`) or "trials" (the R
            runs, see `drive`).
        driver: runs the plan instead of `drive` (same call, no sharding), e.g.
            the shrinking batches of `cgda_jax.strategies.runner`.

    Returns:
        R results, ``info["seed"]`` set to each one's seed and ``info["devices"]``
        to the number of devices the run was split over. Invalid (diverged)
        evaluations are reported by one warning (see `check_divergence`).

    Raises:
        SimulationDiverged: every candidate evaluation of the run diverged.
        cgda_jax.sizes.SizeError: the run would not fit (XLA's 32-bit sizes or the
            memory; see `PlanBase.estimate`), before anything is compiled.
        ValueError: a seed outside 0 .. 2**32 - 1.
    """
    chunk_size, devices = settings.chunk_size, settings.devices
    if shard not in ("population", "trials"):
        raise ValueError(f"shard must be 'population' or 'trials'; got {shard!r}")
    seeds = check_seeds(seeds)
    sharding = resolve_devices(devices)
    goal = check_config(sim, goal)
    plan = plan_cls(sim, goal, settings,
                    sharding=sharding if shard == "population" else None)
    # before any program is compiled: XLA aborts on 32-bit overflows
    est = plan.estimate(len(seeds))
    sampled = plan.sampled_postures(settings, sim)[1] or "population_size"
    check_estimate(est, sampled if est.part != "generation" and len(seeds) == 1
                   else "n_trials" if len(seeds) > 1 else "population_size")
    if driver is not None and sharding is None:
        results = driver(plan, seed_keys(seeds), chunk_size=chunk_size,
                         progress_fn=progress_fn)
    else:
        results = drive(plan, seed_keys(seeds), chunk_size=chunk_size,
                        progress_fn=progress_fn,
                        sharding=sharding if shard == "trials" else None)
    n_devices = 1 if sharding is None else int(sharding.mesh.size)
    for seed, res in zip(seeds, results, strict=True):
        res.info["seed"] = seed
        res.info["devices"] = n_devices
    check_divergence(results)
    return results


# --------------------------------------------------------------------------- batches
def ladder(n: int, min_size: int = 1) -> list[int]:
    """Batch sizes ``n, ceil(n / 2), ceil(n / 4), ...`` while not below `min_size`."""
    sizes = [int(n)]
    while sizes[-1] > 1 and -(-sizes[-1] // 2) >= max(int(min_size), 1):
        sizes.append(-(-sizes[-1] // 2))
    return sorted(sizes)


def _bucket(sizes: list[int], n: int) -> int:
    return next(s for s in sizes if s >= n)


def _pad(idx: np.ndarray, size: int) -> np.ndarray:
    """`idx` padded to `size` by repeating its last entry."""
    return np.concatenate([idx, np.full(size - idx.size, idx[-1], idx.dtype)])


def _take(tree: Any, idx: jax.Array) -> Any:
    return jax.tree.map(lambda x: x[idx], tree)


def _put(tree: Any, sub: Any, idx: jax.Array) -> Any:
    """``tree[idx] = sub`` leaf-wise; indices out of range (padding) are dropped."""
    return jax.tree.map(lambda x, s: x.at[idx].set(s, mode="drop"), tree, sub)


class _Programs:
    """Compiled programs per batch size, compiled on first use; compile time summed."""

    def __init__(self):
        self.cache: dict[Any, Any] = {}
        self.compile_s = 0.0

    def get(self, name: str, fn: Callable, *args: Any) -> Any:
        key = (name, *[jax.tree.map(lambda x: (x.shape, x.dtype), a) for a in args])
        key = (name, str(key))
        if key not in self.cache:
            t0 = time.perf_counter()
            self.cache[key] = compile_jit(f"runner.trials.{name}", fn, *args)
            self.compile_s += time.perf_counter() - t0
        return self.cache[key]

    def __call__(self, name: str, fn: Callable, *args: Any) -> Any:
        return self.get(name, fn, *args)(*args)


# --------------------------------------------------------------------------- trials
def drive_repacked(
    plan: Any,
    keys: jax.Array,
    *,
    chunk_size: int = 10,
    progress_fn: Callable[[dict[str, Any]], None] | None = None,
    min_size: int = 2,
) -> list[Any]:
    """Like `drive` (same arguments and results), but finished trials leave
    the batch between chunks and the rest are re-packed into the smallest size of
    `ladder` (R) that holds them (padding repeats the last running trial; its copy
    is dropped).

    The batch never shrinks below 2 trials (`min_size`; a single trial runs with a
    copy of itself): XLA rounds a batch of one like an unbatched program, not like
    the batches of two or more, whose programs give each trial the same bits
    whatever the batch's size and other seeds (see the module docstring)."""
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size must be >= 1; got {chunk_size}")
    n = int(keys.shape[0])
    if n == 1:  # the batched program, run with a copy: the same bits as in a batch
        results = drive_repacked(plan, jnp.concatenate([keys, keys]),
                                 chunk_size=chunk_size, progress_fn=progress_fn,
                                 min_size=min_size)[:1]
        results[0].info["trials_in_batch"] = 1
        return results
    sizes = ladder(n, max(int(min_size), 2))
    progs = _Programs()

    def chunk(carry):
        carry, metrics = jax.lax.scan(
            lambda c, _: jax.vmap(plan.step)(c), carry, None, length=chunk_size)
        return carry, metrics, jax.vmap(plan.done)(carry)

    init_c = progs.get("init", jax.vmap(plan.init), keys)
    carry_shape = jax.eval_shape(jax.vmap(plan.init), keys)
    finish_c = progs.get("finish", jax.vmap(plan.finish), carry_shape)
    t1, compiled_before = time.perf_counter(), progs.compile_s
    carry = init_c(keys)
    active = np.arange(n)
    per_trial: list[list[Any]] = [[] for _ in range(n)]
    batch_sizes: list[int] = []
    generations = 0
    while active.size:
        size = _bucket(sizes, active.size)
        idx = jnp.asarray(_pad(active, size))
        sub = progs("take", _take, carry, idx)
        sub, metrics, done = progs("chunk", chunk, sub)
        drop = jnp.asarray(np.where(np.arange(size) < active.size, _pad(active, size),
                                    n))
        carry = progs("put", _put, carry, sub, drop)
        metrics, done = jax.device_get((metrics, done))
        for j, r in enumerate(active):
            per_trial[r].append(jax.tree.map(lambda x, j=j: x[:, j], metrics))
        batch_sizes.append(size)
        generations += chunk_size
        active = active[~np.asarray(done[: active.size], bool)]
        if generations >= plan.max_generations_total:
            active = active[:0]
        plan.report_progress(progress_fn, generations, not active.size, t1, carry)
    final = jax.device_get(jax.block_until_ready(finish_c(carry)))
    wall = time.perf_counter() - t1 - (progs.compile_s - compiled_before)
    histories = [jax.tree.map(lambda *xs: np.concatenate(xs, axis=0), *h)
                 for h in per_trial]
    timing = {"wall_time_s": wall, "compile_time_s": progs.compile_s,
              "trials_in_batch": n}
    return plan.split_results(final, histories, timing,
                         {"batching": "trials", "batch_sizes": batch_sizes})


# --------------------------------------------------------------------------- IE points
def _blocked_size(size: int, block: int | None) -> int:
    """`size` rounded up to a multiple of its block count (see `IEPlan.pool_step`)."""
    if not block or size <= block:
        return size
    n_blocks = -(-size // block)
    return n_blocks * -(-size // n_blocks)


def drive_ie_points(
    plan: Any,
    keys: jax.Array,
    *,
    chunk_size: int = 10,
    progress_fn: Callable[[dict[str, Any]], None] | None = None,
    min_size: int = 8,
    block_evaluations: int | None = -1,
) -> list[Any]:
    """Like `drive` for an IE plan with independent points, but the batch is
    the pool of (trial, point) evolutions still running, re-packed between chunks
    into the smallest size of `ladder` (R * N) that holds them.

    `block_evaluations`: evaluate the pool in blocks of about this many candidates
    (see `IEPlan.pool_step`); -1 (default): 2048 on a CPU, one batch on other devices;
    None: one batch.
    """
    if plan.sequential:
        raise ValueError("drive_ie_points needs independent points (kinematic mode, "
                         "stateless scene); use drive_repacked")
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size must be >= 1; got {chunk_size}")
    n, n_pts = int(keys.shape[0]), plan.n_points
    total = n * n_pts
    sizes = ladder(total, min(min_size, total))
    progs = _Programs()
    pts = np.arange(total) % n_pts
    prev_g = jnp.asarray(np.where(pts > 0, np.arange(total) - 1, -1))
    next_g = jnp.asarray(np.where(pts < n_pts - 1, np.arange(total) + 1, -1))
    goal = jnp.tile(plan.goal, (n, 1))

    if block_evaluations == -1:
        block_evaluations = 2048 if jax.default_backend() == "cpu" else None
    block = (None if not block_evaluations else
             max(1, int(block_evaluations) // int(plan.info["population_size"])))

    def chunk(p):
        p, metrics = jax.lax.scan(lambda c, _: plan.pool_step(c, block), p, None,
                                  length=chunk_size)
        return p, metrics

    def flatten(carry):
        return jax.tree.map(lambda x: x.reshape((total, *x.shape[2:])), carry)

    def unflatten(flat):
        return jax.tree.map(lambda x: x.reshape((n, n_pts, *x.shape[1:])), flat)

    def frozen(flat):
        return (flat.best_fitness, flat.tries, flat.done,
                flat.generations + flat.evo.generation)

    init_c = progs.get("init", jax.vmap(plan.init), keys)
    carry_shape = jax.eval_shape(jax.vmap(plan.init), keys)
    flat_shape = jax.eval_shape(flatten, carry_shape)
    flatten_c = progs.get("flatten", flatten, carry_shape)
    finish_c = progs.get("finish", lambda f: jax.vmap(plan.finish)(unflatten(f)),
                         flat_shape)
    t1, compiled_before = time.perf_counter(), progs.compile_s
    flat = flatten_c(init_c(keys))
    best_f, tries, done, gens = jax.device_get(progs("frozen", frozen, flat))
    active = np.flatnonzero(~done)
    chunks: list[dict[str, np.ndarray]] = []
    batch_sizes: list[int] = []
    generations = 0
    while active.size:
        size = _blocked_size(_bucket(sizes, active.size), block)
        idx = _pad(active, size)
        pos = np.full(total, -1)
        pos[active] = np.arange(active.size)
        prev_pos = np.where(np.asarray(prev_g)[idx] >= 0, pos[np.asarray(prev_g)[idx]],
                            -1)
        next_pos = np.where(np.asarray(next_g)[idx] >= 0, pos[np.asarray(next_g)[idx]],
                            -1)
        pool = progs("gather", plan.gather_pool, flat, goal, jnp.asarray(idx), prev_g,
                     next_g, jnp.asarray(prev_pos), jnp.asarray(next_pos))
        pool, metrics = progs("chunk", chunk, pool)
        drop = jnp.asarray(np.where(np.arange(size) < active.size, idx, total))
        flat = progs("put", _put, flat, pool.s, drop)
        metrics = jax.device_get(metrics)
        # points outside the pool are frozen: their metrics are constant
        full = {"best_fitness": np.broadcast_to(best_f, (chunk_size, total)).copy(),
                "invalid": np.zeros((chunk_size, total), np.int32),
                "try": np.broadcast_to(tries - 1, (chunk_size, total)).copy()}
        for k, v in full.items():
            v[:, active] = metrics[k][:, : active.size]
        chunks.append(full)
        batch_sizes.append(size)
        generations += chunk_size
        best_f, tries, done, gens = jax.device_get(progs("frozen", frozen, flat))
        active = np.flatnonzero(~done)
        if generations >= plan.max_generations_total:
            active = active[:0]
        plan.report_progress(progress_fn, generations, not active.size, t1,
                  SimpleNamespace(  # the fields IEPlan.progress reads, per trial
                      done=done.reshape((n, n_pts)),
                      best_fitness=best_f.reshape((n, n_pts)),
                      generations=gens.reshape((n, n_pts)),
                      evo=SimpleNamespace(generation=np.zeros((n, n_pts), int))))
    final = jax.device_get(jax.block_until_ready(finish_c(flat)))
    wall = time.perf_counter() - t1 - (progs.compile_s - compiled_before)
    history = {k: np.concatenate([c[k] for c in chunks] or [np.zeros((0, total))],
                                 axis=0).reshape((-1, n, n_pts))
               for k in ("best_fitness", "invalid", "try")}
    histories = [{k: v[:, r] for k, v in history.items()} for r in range(n)]
    timing = {"wall_time_s": wall, "compile_time_s": progs.compile_s,
              "trials_in_batch": n}
    return plan.split_results(final, histories, timing,
                         {"batching": "points", "batch_sizes": batch_sizes})


#: ``batching=`` values of `run_trials`.
BATCHING = ("auto", "trials", "lockstep")


def driver(batching: str) -> Callable[..., list[Any]] | None:
    """The drive function of a ``batching`` mode (None: `drive`, lock-step).

    "auto": IE points pooled when the plan's points are independent, else trials
    re-packed; "trials": trials re-packed; "lockstep": `drive`.
    """
    if batching not in BATCHING:
        raise ValueError(f"batching must be one of {list(BATCHING)}; got {batching!r}")
    if batching == "lockstep":
        return None
    if batching == "trials":
        return drive_repacked

    def drive_auto(plan, keys, **kw):
        if hasattr(plan, "pool_step") and not plan.sequential:  # IE's points
            return drive_ie_points(plan, keys, **kw)
        return drive_repacked(plan, keys, **kw)

    return drive_auto
