"""Drives a strategy plan: jitted generation chunks under `lax.scan`, Python only between.

A *plan* (see fte.py, ie.py, iet.py, oet.py) is a small object with pure functions:

- ``init(key) -> carry``
- ``step(carry) -> (carry, metrics)``: one generation; done parts are frozen inside.
- ``done(carry) -> bool``: nothing left to evolve.
- ``progress(carry) -> dict``: host figures for ``progress_fn`` (one entry per trial).
- ``finish(carry) -> dict``: final arrays (best trajectory, its execution, ...).
- ``to_result(final, history, timing) -> ExecutionResult`` on host NumPy arrays.
- ``max_generations_total``: an upper bound on generations (loop guard).
- ``n_points``: goal points (reported to ``progress_fn`` as ``points``).

`run` is the entry every ``run_*`` function and `run_trials` share: it checks the goal and
common settings, builds the plan and drives it for a list of seeds.

`drive` compiles ``init``, a chunk of ``chunk_size`` generations and ``finish`` once each
(timed apart with ``jit(...).lower(...).compile()``), then calls the compiled chunk until
``done``; between chunks it syncs one boolean and calls ``progress_fn``. With several
keys the whole plan is vmapped over them (independent trials in one batched call).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.strategies.base import check_config
from cgda_jax.strategies.result import ExecutionResult

#: Number of times a chunk function was traced, per strategy name (tests use it to
#: prove that IET compiles one step for all of its points).
TRACE_COUNTS: dict[str, int] = {}


def drive(
    plan: Any,
    keys: jax.Array,
    *,
    chunk_size: int = 10,
    progress_fn: Callable[[dict[str, Any]], None] | None = None,
) -> list[Any]:
    """Runs `plan` for each key in `keys` (R,) in one batched call.

    Returns:
        One `ExecutionResult` per key; wall and compile times are those of the whole
        batch (``info["trials_in_batch"]`` says how many shared it).
    """
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size must be >= 1; got {chunk_size}")
    n_trials = keys.shape[0]

    def chunk(carry):
        TRACE_COUNTS[plan.name] = TRACE_COUNTS.get(plan.name, 0) + 1
        return jax.lax.scan(
            lambda c, _: jax.vmap(plan.step)(c), carry, None, length=chunk_size
        )

    def all_done(carry):
        return jnp.all(jax.vmap(plan.done)(carry))

    t0 = time.perf_counter()
    init_c = jax.jit(jax.vmap(plan.init)).lower(keys).compile()
    carry_shape = jax.eval_shape(jax.vmap(plan.init), keys)
    chunk_c = jax.jit(chunk).lower(carry_shape).compile()
    done_c = jax.jit(all_done).lower(carry_shape).compile()
    finish_c = jax.jit(jax.vmap(plan.finish)).lower(carry_shape).compile()
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
    **plan_kwargs: Any,
) -> list[ExecutionResult]:
    """Checks `goal` and the common settings, builds the plan, runs it for `seeds`.

    Args:
        plan_cls: a plan class (e.g. `IEPlan`).
        sim, goal, tolerance, max_generations, chunk_size, progress_fn: as in `run_ie`.
        seeds: R seeds, run as R independent trials in one batched call.
        **plan_kwargs: the rest of the plan's constructor arguments.

    Returns:
        R results, ``info["seed"]`` set to each one's seed.
    """
    goal = check_config(sim, goal, tolerance=tolerance, max_generations=max_generations)
    plan = plan_cls(sim, goal, tolerance=tolerance, max_generations=max_generations,
                    **plan_kwargs)
    results = drive(plan, seed_keys(seeds), chunk_size=chunk_size,
                    progress_fn=progress_fn)
    for seed, res in zip(seeds, results, strict=True):
        res.info["seed"] = seed
    return results
