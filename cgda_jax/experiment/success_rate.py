"""Success rate of an execution experiment over N seeds (``cgda run CONFIG --trials N``).

Seeds ``strategy.seed, strategy.seed + 1, ...`` run as ONE batched call
(`cgda_jax.strategies.run_seeds`: each trial gives the same bits in any batch;
`cgda_jax.strategies.runner` says how it can differ from the single run). Three
steps, usable apart (e.g. seeds split over processes and their records joined before
writing):

- `trial_records` (cfg, seeds) -> one plain dict per seed (JSON-ready);
- `summarize` (records) -> the success count, rate and its Wilson 95% interval;
- `write_trials` writes the results folder: ``config.toml``, ``trials.json`` (the
  summary and every record), ``result.json`` (the summary) and ``report.md`` (the
  rate and a table per seed).

`run_trials_experiment` does all three. A seed's ``run_time_s`` is its share of the
batch (the batch's run time / its trial count; compile apart): trials of one batch
have no run time of their own.
"""

from __future__ import annotations

import json
import math
import pathlib
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from cgda_jax.experiment.build import BuiltExecution, build_execution
from cgda_jax.experiment.config import ConfigError, ExperimentConfig, dump_config

__all__ = ["run_trials_experiment", "summarize", "trial_records", "wilson_interval",
           "write_trials"]


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a success rate (default 95%)."""
    if n < 1:
        raise ValueError(f"n must be >= 1; got {n}")
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return lo, hi


def check_trials(cfg: ExperimentConfig, n_trials: Any) -> int:
    """`n_trials` as an int >= 1 for an execution config.

    Raises:
        ConfigError: a recognition config, or a bad trial count.
    """
    if cfg.kind != "execution":
        raise ConfigError(
            f"--trials needs an execution experiment; {cfg.name!r} is a "
            f"{cfg.kind} experiment (its result does not depend on a seed)")
    try:
        n = int(n_trials)
    except (TypeError, ValueError):
        n = None
    if n is None or n != n_trials or n < 1:
        raise ConfigError(f"--trials must be a whole number >= 1; got {n_trials!r}")
    return n


def trial_records(
    cfg: ExperimentConfig,
    seeds: list[int],
    progress_fn: Callable[[dict], None] | None = None,
    built: BuiltExecution | None = None,
) -> list[dict[str, Any]]:
    """Runs `cfg`'s strategy once per seed, all seeds in one batched call, on the
    goal and simulator of ``built`` (those its checks built; default: built here
    unchecked, `build_execution`: a worker of a job its launcher checked).

    Returns:
        One dict per seed: ``seed``, ``success``, ``max_point_error``,
        ``final_fitness``, ``generations``, ``evaluations``, ``run_time_s`` (its
        share of the batch), ``batch_run_time_s``, ``compile_time_s`` (the
        batch's) and ``trials_in_batch``.
    """
    from cgda_jax.strategies import run_seeds

    built = built if built is not None else build_execution(cfg)
    goal, sim = built.goal, built.sim
    s = cfg.strategy
    results = run_seeds(
        s.name, sim, goal, list(seeds), algorithm=s.algorithm,
        population_size=s.population_size, tolerance=s.tolerance,
        max_generations=s.max_generations, chunk_size=s.chunk_size,
        progress_fn=progress_fn, **s.options,
    )
    n = len(results)
    return [{
        "seed": int(r.info["seed"]),
        "success": bool(r.success),
        "max_point_error": float(np.max(r.point_errors)),
        "final_fitness": float(r.final_fitness),
        "generations": int(r.generations),
        "evaluations": int(r.evaluations),
        "run_time_s": float(r.wall_time_s) / n,
        "batch_run_time_s": float(r.wall_time_s),
        "compile_time_s": float(r.compile_time_s),
        "trials_in_batch": int(r.info.get("trials_in_batch", n)),
    } for r in results]


def summarize(records: list[dict[str, Any]], tolerance: float | None = None
              ) -> dict[str, Any]:
    """Success count and rate of `records` with their Wilson 95% interval."""
    n = len(records)
    k = sum(bool(r["success"]) for r in records)
    lo, hi = wilson_interval(k, n)
    errors = [r["max_point_error"] for r in records]
    return {
        "kind": "trials",
        "trials": n,
        "successes": k,
        "success_rate": k / n,
        "wilson95": [lo, hi],
        "seeds": [r["seed"] for r in records],
        "median_max_point_error": float(np.median(errors)),
        "median_generations": float(np.median([r["generations"] for r in records])),
        "tolerance": tolerance,
    }


def _report(cfg: ExperimentConfig, summary: dict[str, Any],
            records: list[dict[str, Any]]) -> str:
    lo, hi = summary["wilson95"]
    s = cfg.strategy
    lines = [
        f"# {cfg.name}: success rate over {summary['trials']} seeds", "",
        cfg.description, "",
        (f"{s.name.upper()} ({s.algorithm}, population {s.population_size}, tolerance "
        f"{s.tolerance:g}, at most {s.max_generations} generations), seeds "
        f"{records[0]['seed']}..{records[-1]['seed']}, all in one batched call."), "",
        "| trials | successes | success rate | Wilson 95% interval |",
        "|---|---|---|---|",
        (f"| {summary['trials']} | {summary['successes']} | "
        f"{summary['success_rate']:.1%} | {lo:.1%} to {hi:.1%} |"), "",
        (f"Batch run time {summary['batch_run_time_s']:.2f} s (compile "
        f"{summary['compile_time_s']:.1f} s apart); a seed's run time below is its "
        "share of the batch."), "",
        "| seed | success | max point error | generations | evaluations | run time (s) |",
        "|---|---|---|---|---|---|",
    ]
    for r in records:
        lines.append(
            f"| {r['seed']} | {'yes' if r['success'] else '**no**'} | "
            f"{r['max_point_error']:.4g} | {r['generations']} | {r['evaluations']} | "
            f"{r['run_time_s']:.3f} |")
    lines += ["", ("Per-seed figures: [trials.json](trials.json); the config: "
              "[config.toml](config.toml)."), ""]
    return "\n".join(lines)


def write_trials(cfg: ExperimentConfig, records: list[dict[str, Any]],
                 folder: pathlib.Path, extra: dict[str, Any] | None = None
                 ) -> dict[str, Any]:
    """Writes the trials results into the existing, empty `folder`; returns the
    summary (as in ``result.json``)."""
    folder = pathlib.Path(folder)
    records = sorted(records, key=lambda r: r["seed"])
    summary = {**summarize(records, cfg.strategy.tolerance), "name": cfg.name,
               "strategy": cfg.strategy.name,
               "batch_run_time_s": max(r["batch_run_time_s"] for r in records),
               "compile_time_s": max(r["compile_time_s"] for r in records),
               **(extra or {})}
    (folder / "config.toml").write_text(dump_config(cfg))
    (folder / "trials.json").write_text(
        json.dumps({**summary, "records": records}, indent=2))
    (folder / "result.json").write_text(json.dumps(summary, indent=2))
    (folder / "report.md").write_text(_report(cfg, summary, records))
    return summary


def run_trials_experiment(
    cfg: ExperimentConfig,
    n_trials: int,
    folder: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
) -> dict[str, Any]:
    """Runs `n_trials` seeds of `cfg` (from ``strategy.seed``) in one batched call
    and writes their success-rate table into `folder` (existing, empty).

    Returns:
        The summary: ``trials``, ``successes``, ``success_rate``, ``wilson95``, ...

    Raises:
        ConfigError: a recognition config, a bad `n_trials` (`check_trials`) or
            anything `cgda_jax.experiment.check_experiment` refuses (the seed range,
            the batch's size, ...).
    """
    from cgda_jax.experiment.validate import check_and_build

    n = check_trials(cfg, n_trials)
    _, built = check_and_build(cfg, trials=n)  # seeds, sizes, options: first
    t0 = time.perf_counter()
    seeds = [cfg.strategy.seed + i for i in range(n)]
    records = trial_records(cfg, seeds, progress_fn, built)
    return write_trials(cfg, records, folder,
                        {"total_time_s": time.perf_counter() - t0})
