"""Batched trials that shrink as trials (or IE points) finish.

`runner.drive` runs R trials in lock-step until the slowest one stops: every
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
so the batch never shrinks below 2 (a lock-step "batch" of one, `runner.drive` with
one key, is the single run). A single run (``run_fte(seed=s)``, one key through `runner.drive`)
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
"""

from __future__ import annotations

import time
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from cgda_jax.strategies.ie import IEPlan
from cgda_jax.strategies.ie_state import IEState

__all__ = ["drive_ie_points", "drive_repacked", "ladder"]


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
            self.cache[key] = jax.jit(fn).lower(*args).compile()
            self.compile_s += time.perf_counter() - t0
        return self.cache[key]

    def __call__(self, name: str, fn: Callable, *args: Any) -> Any:
        return self.get(name, fn, *args)(*args)


def _results(plan, final, histories, n_trials, timing, info):
    results = []
    for r in range(n_trials):
        f = jax.tree.map(lambda x, r=r: x[r], final)
        res = plan.to_result(f, histories[r], timing)
        res.info.update(info)
        results.append(res)
    return results


def _progress(progress_fn, plan, generations, finished, t1, carry):
    if progress_fn is not None:
        progress_fn({
            "strategy": plan.name, "points": plan.n_points, "generations": generations,
            "done": finished, "elapsed_s": time.perf_counter() - t1,
            **plan.progress(carry),
        })


# --------------------------------------------------------------------------- trials
def drive_repacked(
    plan: Any,
    keys: jax.Array,
    *,
    chunk_size: int = 10,
    progress_fn: Callable[[dict[str, Any]], None] | None = None,
    min_size: int = 2,
) -> list[Any]:
    """Like `runner.drive` (same arguments and results), but finished trials leave
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
        _progress(progress_fn, plan, generations, not active.size, t1, carry)
    final = jax.device_get(jax.block_until_ready(finish_c(carry)))
    wall = time.perf_counter() - t1 - (progs.compile_s - compiled_before)
    histories = [jax.tree.map(lambda *xs: np.concatenate(xs, axis=0), *h)
                 for h in per_trial]
    timing = {"wall_time_s": wall, "compile_time_s": progs.compile_s,
              "trials_in_batch": n}
    return _results(plan, final, histories, n, timing,
                    {"batching": "trials", "batch_sizes": batch_sizes})


# --------------------------------------------------------------------------- IE points
@struct.dataclass
class _Pool:
    """IE points gathered from several trials: IEState fields (P, ...) plus each
    point's goal and its neighbours (position in the pool, or -1 and their frozen
    best genes and fitness; inf / NaN where there is no neighbour)."""

    s: IEState
    goal: jax.Array
    prev_pos: jax.Array
    next_pos: jax.Array
    prev_u: jax.Array
    prev_f: jax.Array
    next_u: jax.Array
    next_f: jax.Array


def _blocked_size(size: int, block: int | None) -> int:
    """`size` rounded up to a multiple of its block count (see `_pool_step`)."""
    if not block or size <= block:
        return size
    n_blocks = -(-size // block)
    return n_blocks * -(-size // n_blocks)


def _pool_step(plan: IEPlan, p: _Pool, block: int | None
               ) -> tuple[_Pool, dict[str, jax.Array]]:
    """`IEPlan.step` (independent points) on a pool of points from several trials.

    With `block`, the evolutions (ask, evaluate, tell) run in ``ceil(P / block)``
    equal blocks one after the other (`lax.map`), not as one batch: on a CPU a
    simulator call of many thousand candidates outgrows the caches and costs about
    twice as much per candidate (measured, benchmarks/bench_trials.py).
    """
    s = p.s
    size = s.done.shape[0]
    start = plan.sim.init_state()
    states = jax.tree.map(lambda x: jnp.broadcast_to(x, (size, *jnp.shape(x))), start)

    def evolve(e, g, st):
        return jax.vmap(
            lambda e, g, st: plan.evolve(e, plan.point_fitness(st, g), plan.point_stop)
        )(e, g, st)

    n_blocks = 1 if not block or size <= block else -(-size // block)
    if n_blocks == 1:
        evo, metrics = evolve(s.evo, p.goal, states)
    else:
        split = (lambda t: jax.tree.map(
            lambda x: x.reshape((n_blocks, size // n_blocks, *x.shape[1:])), t))
        evo, metrics = jax.lax.map(lambda a: evolve(*a),
                                   (split(s.evo), split(p.goal), split(states)))
        evo, metrics = jax.tree.map(lambda x: x.reshape((size, *x.shape[2:])),
                                    (evo, metrics))

    def neighbours_of(best_u, best_f):
        # the neighbours of `IEPlan._neighbours`: in the pool, or frozen outside it
        prev_f = jnp.where(p.prev_pos >= 0, best_f[jnp.maximum(p.prev_pos, 0)],
                           p.prev_f)
        next_f = jnp.where(p.next_pos >= 0, best_f[jnp.maximum(p.next_pos, 0)],
                           p.next_f)
        prev_u = jnp.where((p.prev_pos >= 0)[:, None],
                           best_u[jnp.maximum(p.prev_pos, 0)], p.prev_u)
        next_u = jnp.where((p.next_pos >= 0)[:, None],
                           best_u[jnp.maximum(p.next_pos, 0)], p.next_u)
        u = jnp.where((prev_f <= next_f)[:, None], prev_u, next_u)
        ok = jnp.isfinite(jnp.minimum(prev_f, next_f))
        return jnp.where(ok[:, None], u, jnp.nan)

    s = plan.settle(s, evo, p.goal, states, neighbours_of)
    return p.replace(s=s), {"best_fitness": s.best_fitness,
                            "invalid": metrics["invalid"], "try": s.tries - 1}


def _gather_pool(flat: IEState, goal, idx, prev_g, next_g, prev_pos, next_pos):
    def nb(g):
        ok = g >= 0
        f = jnp.where(ok, flat.best_fitness[jnp.maximum(g, 0)], jnp.inf)
        u = jnp.where(ok[:, None], flat.best_u[jnp.maximum(g, 0)], jnp.nan)
        return u, f

    (pu, pf), (nu, nf) = nb(prev_g[idx]), nb(next_g[idx])
    return _Pool(s=_take(flat, idx), goal=goal[idx], prev_pos=prev_pos,
                 next_pos=next_pos, prev_u=pu, prev_f=pf, next_u=nu, next_f=nf)


def drive_ie_points(
    plan: IEPlan,
    keys: jax.Array,
    *,
    chunk_size: int = 10,
    progress_fn: Callable[[dict[str, Any]], None] | None = None,
    min_size: int = 8,
    block_evaluations: int | None = -1,
) -> list[Any]:
    """Like `runner.drive` for an IE plan with independent points, but the batch is
    the pool of (trial, point) evolutions still running, re-packed between chunks
    into the smallest size of `ladder` (R * N) that holds them.

    `block_evaluations`: evaluate the pool in blocks of about this many candidates
    (see `_pool_step`); -1 (default): 2048 on a CPU, one batch on other devices;
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
        p, metrics = jax.lax.scan(lambda c, _: _pool_step(plan, c, block), p, None,
                                  length=chunk_size)
        return p, metrics

    def flatten(carry):
        return jax.tree.map(lambda x: x.reshape((total, *x.shape[2:])), carry)

    def unflatten(flat):
        return jax.tree.map(lambda x: x.reshape((n, n_pts, *x.shape[1:])), flat)

    def frozen(flat):
        return flat.best_fitness, flat.tries, flat.done

    init_c = progs.get("init", jax.vmap(plan.init), keys)
    carry_shape = jax.eval_shape(jax.vmap(plan.init), keys)
    flat_shape = jax.eval_shape(flatten, carry_shape)
    flatten_c = progs.get("flatten", flatten, carry_shape)
    finish_c = progs.get("finish", lambda f: jax.vmap(plan.finish)(unflatten(f)),
                         flat_shape)
    t1, compiled_before = time.perf_counter(), progs.compile_s
    flat = flatten_c(init_c(keys))
    best_f, tries, done = jax.device_get(progs("frozen", frozen, flat))
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
        pool = progs("gather", _gather_pool, flat, goal, jnp.asarray(idx), prev_g,
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
        best_f, tries, done = jax.device_get(progs("frozen", frozen, flat))
        active = np.flatnonzero(~done)
        if generations >= plan.max_generations_total:
            active = active[:0]
        _progress(progress_fn, plan, generations, not active.size, t1,
                  SimpleNamespace(done=done.reshape((n, n_pts)),
                                  best_fitness=best_f.reshape((n, n_pts))))
    final = jax.device_get(jax.block_until_ready(finish_c(flat)))
    wall = time.perf_counter() - t1 - (progs.compile_s - compiled_before)
    history = {k: np.concatenate([c[k] for c in chunks] or [np.zeros((0, total))],
                                 axis=0).reshape((-1, n, n_pts))
               for k in ("best_fitness", "invalid", "try")}
    histories = [{k: v[:, r] for k, v in history.items()} for r in range(n)]
    timing = {"wall_time_s": wall, "compile_time_s": progs.compile_s,
              "trials_in_batch": n}
    return _results(plan, final, histories, n, timing,
                    {"batching": "points", "batch_sizes": batch_sizes})


#: ``batching=`` values of `run_trials`.
BATCHING = ("auto", "trials", "lockstep")


def driver(batching: str) -> Callable[..., list[Any]] | None:
    """The drive function of a ``batching`` mode (None: `runner.drive`, lock-step).

    "auto": IE points pooled when the plan's points are independent, else trials
    re-packed; "trials": trials re-packed; "lockstep": `runner.drive`.
    """
    if batching not in BATCHING:
        raise ValueError(f"batching must be one of {list(BATCHING)}; got {batching!r}")
    if batching == "lockstep":
        return None
    if batching == "trials":
        return drive_repacked

    def drive_auto(plan, keys, **kw):
        if isinstance(plan, IEPlan) and not plan.sequential:
            return drive_ie_points(plan, keys, **kw)
        return drive_repacked(plan, keys, **kw)

    return drive_auto
