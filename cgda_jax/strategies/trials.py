"""R independent trials of a strategy in ONE batched call (vmap over seeds)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from cgda_jax.strategies import fte, ie, iet
from cgda_jax.strategies.batching import driver as batching_driver
from cgda_jax.strategies.fte import FTEPlan
from cgda_jax.strategies.ie import IEPlan
from cgda_jax.strategies.iet import IETPlan
from cgda_jax.strategies.oet import OETPlan
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import run

#: Settings every strategy takes (`cgda_jax.strategies.base.PlanBase`).
SHARED = {"aim": 1.0}
#: Strategy name -> (plan class, defaults of its extra settings).
STRATEGIES: dict[str, tuple[type, dict[str, Any]]] = {
    "fte": (FTEPlan, {"stagnation": 10, "distance": None,
                      "restarts": fte.RESTARTS, "min_improvement": fte.MIN_IMPROVEMENT,
                      "init": fte.INIT, "init_samples": fte.INIT_SAMPLES,
                      "init_std": fte.INIT_STD, "refine": "none", "refine_steps": 100,
                      "refine_gamma": fte.REFINE_GAMMA, **SHARED}),
    "ie": (IEPlan, {"restarts": ie.RESTARTS, "stagnation": ie.STAGNATION,
                    "refine": "none", "reach_check": False,
                    "restart_samples": ie.RESTART_SAMPLES, "warm_start": False,
                    **SHARED}),
    "iet": (IETPlan, {"restarts": iet.RESTARTS, "backtracks": iet.BACKTRACKS,
                      "warm_start": False, "restart_samples": iet.RESTART_SAMPLES,
                      "stagnation": iet.STAGNATION, **SHARED}),
    "oet": (OETPlan, {"max_steps": None, "lookahead": 1, "restarts": 0,
                      "stagnation": None, "warm_start": False, **SHARED}),
}


def run_trials(
    strategy: str,
    sim: Any,
    goal: Any,
    n_trials: int,
    *,
    seed: int = 0,
    algorithm: Any = "CMA_ES",
    population_size: int = 16,
    tolerance: float = 0.02,
    max_generations: int = 100,
    chunk_size: int = 10,
    algorithm_kwargs: dict | None = None,
    algorithm_params: dict | None = None,
    progress_fn: Callable[[dict], None] | None = None,
    devices: int | str | None = None,
    batching: str = "auto",
    **strategy_kwargs: Any,
) -> list[ExecutionResult]:
    """Runs `n_trials` independent trials of a strategy at once.

    Trial r uses seed ``seed + r``; its result is the same bits in any batch of
    trials (any size, any other seeds). The single run with that seed is the
    unbatched program, rounded differently in the last bits; most seeds end within
    about 1e-4 of it, some on another search path (see
    `cgda_jax.strategies.batching`).
    By default the batch shrinks as trials finish (`cgda_jax.strategies.batching`):
    finished trials, or for IE with independent points finished points, leave it
    between chunks, so a trial that stops early costs no more than its own run.

    Args:
        strategy: "fte", "ie", "iet" or "oet".
        sim, goal, algorithm, population_size, tolerance, max_generations, chunk_size,
            algorithm_kwargs, algorithm_params, progress_fn: as in the `run_*`
            functions.
        n_trials: R.
        seed: first seed.
        devices: None (default: one device, the unsharded program), "all" or a
            device count K: the R trials are split over K devices, R / K per device
            (R is padded up to a multiple of K by repeating the last trial, whose
            copies are dropped; choose R a multiple of K to waste nothing). Each
            trial gives the same result as unsharded. Multi-host: see
            `cgda_jax.sharding`. Sharded batches run in lock-step.
        batching: "auto" (default: IE points pooled over the trials where points
            are independent, else finished trials dropped), "trials" or
            "lockstep" (every trial runs until the slowest stops; one compiled
            chunk); see `cgda_jax.strategies.batching.driver`.
        **strategy_kwargs: the strategy's own settings (FTE: stagnation, distance,
            restarts, min_improvement, init, init_samples, init_std, refine,
            refine_steps, refine_gamma; IE: restarts, stagnation, refine,
            reach_check, restart_samples, warm_start; IET: restarts, backtracks,
            warm_start, restart_samples, stagnation; OET: max_steps, lookahead,
            restarts, stagnation, warm_start; every one: aim).

    Returns:
        R `ExecutionResult`s; their wall/compile times are those of the whole batch;
        ``info["batching"]`` and ``info["batch_sizes"]`` (batch of each chunk) say
        how it shrank.
    """
    if int(n_trials) < 1:
        raise ValueError(f"n_trials must be >= 1; got {n_trials}")
    return run_seeds(
        strategy, sim, goal, [seed + r for r in range(int(n_trials))],
        algorithm=algorithm, population_size=population_size, tolerance=tolerance,
        max_generations=max_generations, chunk_size=chunk_size,
        algorithm_kwargs=algorithm_kwargs, algorithm_params=algorithm_params,
        progress_fn=progress_fn, devices=devices, batching=batching,
        **strategy_kwargs)


def run_seeds(
    strategy: str,
    sim: Any,
    goal: Any,
    seeds: list[int],
    *,
    devices: int | str | None = None,
    batching: str = "auto",
    **kwargs: Any,
) -> list[ExecutionResult]:
    """`run_trials` for an explicit list of seeds (one trial each, in one batch).

    `kwargs`: the other arguments of `run_trials` and the strategy's settings.
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown strategy {strategy!r}; choose one of {sorted(STRATEGIES)}")
    seeds = [int(x) for x in seeds]
    if not seeds:
        raise ValueError("seeds is empty: give at least one")
    drive_fn = batching_driver(batching)
    plan_cls, defaults = STRATEGIES[strategy]
    common = ("algorithm", "population_size", "tolerance", "max_generations",
              "chunk_size", "algorithm_kwargs", "algorithm_params", "progress_fn")
    run_kw = {k: kwargs.pop(k) for k in common if k in kwargs}
    run_kw = {"algorithm": "CMA_ES", "population_size": 16, "tolerance": 0.02,
              "max_generations": 100, "chunk_size": 10, **run_kw}
    unknown = sorted(set(kwargs) - set(defaults))
    if unknown:
        raise ValueError(f"unknown settings {unknown} for strategy {strategy!r}")
    return run(plan_cls, sim, goal, seeds, devices=devices, shard="trials",
               driver=drive_fn, **run_kw, **{**defaults, **kwargs})
