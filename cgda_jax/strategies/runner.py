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

`run` is the entry every ``run_*`` function and `run_trials` share: it checks the goal and
common settings, builds the plan and drives it for a list of seeds.

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

Divergence (see `cgda_jax.strategies.base`): after a run, `run` logs ONE warning
through the ``cgda_jax`` logger when some candidate evaluations were invalid, and
raises `SimulationDiverged` when none was valid (`check_divergence`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from cgda_jax.sharding import axis_shardings, resolve_devices, shard_leading
from cgda_jax.sizes import Estimate, check_estimate, dynamic_width, run_estimate
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
    return (
        jax.jit(over_trials(plan.init), **init_kw).lower(keys).compile(),
        jax.jit(chunk, **chunk_kw).lower(carry_shape).compile(),
        jax.jit(all_done, **carry_kw).lower(carry_shape).compile(),
        jax.jit(over_trials(plan.finish), **carry_kw).lower(carry_shape).compile(),
    )


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
        if progress_fn is not None:
            progress_fn(
                {
                    "strategy": plan.name,
                    "points": plan.n_points,
                    "generations": generations,
                    "done": finished,
                    "elapsed_s": time.perf_counter() - t1,
                    **plan.progress(carry),
                }
            )
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
    results = []
    for r in range(n_trials):
        # history leaves are (G, R, ...), final leaves (R, ...)
        h = jax.tree.map(lambda x, r=r: x[:, r], history)
        f = jax.tree.map(lambda x, r=r: x[r], final)
        results.append(plan.to_result(f, h, timing))
    return results


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


def plan_estimate(plan: Any, n_trials: int) -> Estimate:
    """What `n_trials` trials of `plan` in one batch hold at once
    (`cgda_jax.sizes.run_estimate`)."""
    sim = plan.sim
    robot = getattr(sim, "robot", None)
    model = getattr(robot, "mj_model", None)
    samples = int(getattr(plan, "restart_samples", 0) or 0)
    if getattr(plan, "init_mode", None) in ("sampled", "reach"):
        samples = max(samples, int(plan.init_samples))
    backend = getattr(getattr(sim, "backend", None), "name", None)
    return run_estimate(
        trials=n_trials, population=int(plan.info["population_size"]),
        points=plan.n_points, features=int(sim.n_features), dof=plan.n_dof,
        bodies=int(model.nbody) if model is not None else 1, strategy=plan.name,
        samples=samples,
        dynamic_width=(dynamic_width(model) if backend == "mjx" and model is not None
                       else 0))


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


def run(
    plan_cls: type,
    sim: Any,
    goal: Any,
    seeds: list[int],
    *,
    tolerance: float,
    max_generations: int,
    chunk_size: int = 10,
    progress_fn: Callable[[dict[str, Any]], None] | None = None,
    devices: int | str | NamedSharding | None = None,
    shard: str = "population",
    driver: Callable[..., list[ExecutionResult]] | None = None,
    **plan_kwargs: Any,
) -> list[ExecutionResult]:
    """Checks `goal` and the common settings, builds the plan, runs it for `seeds`.

    Args:
        plan_cls: a plan class (e.g. `IEPlan`).
        sim, goal, tolerance, max_generations, chunk_size, progress_fn: as in `run_ie`.
        seeds: R seeds, run as R independent trials in one batched call.
        devices: None (one device, no sharding), "all", a device count or a
            sharding (see `cgda_jax.sharding.resolve_devices`).
        shard: which axis `devices` splits: "population" (the candidates of each
            generation's batched simulator call, see `PlanBase`) or "trials" (the R
            runs, see `drive`).
        driver: runs the plan instead of `drive` (same call, no sharding), e.g.
            the shrinking batches of `cgda_jax.strategies.batching`.
        **plan_kwargs: the rest of the plan's constructor arguments.

    Returns:
        R results, ``info["seed"]`` set to each one's seed and ``info["devices"]``
        to the number of devices the run was split over. Invalid (diverged)
        evaluations are reported by one warning (see `check_divergence`).

    Raises:
        SimulationDiverged: every candidate evaluation of the run diverged.
        cgda_jax.sizes.SizeError: the run would not fit (XLA's 32-bit sizes or the
            memory; see `plan_estimate`), before anything is compiled.
        ValueError: a seed outside 0 .. 2**32 - 1.
    """
    if shard not in ("population", "trials"):
        raise ValueError(f"shard must be 'population' or 'trials'; got {shard!r}")
    seeds = check_seeds(seeds)
    sharding = resolve_devices(devices)
    goal = check_config(sim, goal, tolerance=tolerance, max_generations=max_generations)
    plan = plan_cls(sim, goal, tolerance=tolerance, max_generations=max_generations,
                    sharding=sharding if shard == "population" else None,
                    **plan_kwargs)
    # before any program is compiled: XLA aborts on 32-bit overflows
    est = plan_estimate(plan, len(seeds))
    sampled = "init_samples" if plan.name == "fte" else "restart_samples"
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
