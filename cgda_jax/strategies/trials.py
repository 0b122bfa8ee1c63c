"""R independent trials of a strategy in ONE batched call (vmap over seeds)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from cgda_jax.strategies import ie, iet
from cgda_jax.strategies.fte import FTEPlan
from cgda_jax.strategies.ie import IEPlan
from cgda_jax.strategies.iet import IETPlan
from cgda_jax.strategies.oet import OETPlan
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import run

#: Strategy name -> (plan class, defaults of its extra settings).
STRATEGIES: dict[str, tuple[type, dict[str, Any]]] = {
    "fte": (FTEPlan, {"stagnation": 10, "distance": None}),
    "ie": (IEPlan, {"restarts": ie.RESTARTS, "stagnation": ie.STAGNATION,
                    "refine": "none", "reach_check": False,
                    "restart_samples": ie.RESTART_SAMPLES}),
    "iet": (IETPlan, {"restarts": iet.RESTARTS, "backtracks": iet.BACKTRACKS,
                      "warm_start": False, "restart_samples": iet.RESTART_SAMPLES}),
    "oet": (OETPlan, {"max_steps": None, "lookahead": 1}),
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
    **strategy_kwargs: Any,
) -> list[ExecutionResult]:
    """Runs `n_trials` independent trials of a strategy at once.

    Trial r uses seed ``seed + r`` and gives the same result as the single run with that
    seed; the batch runs until every trial stopped (finished trials are frozen).

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
            `cgda_jax.sharding`.
        **strategy_kwargs: the strategy's own settings (FTE: stagnation, distance; IE: restarts,
            stagnation, refine, reach_check,
            restart_samples; IET: restarts, backtracks, warm_start,
            restart_samples;
            OET: max_steps, lookahead).

    Returns:
        R `ExecutionResult`s; their wall/compile times are those of the whole batch.
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown strategy {strategy!r}; choose one of {sorted(STRATEGIES)}")
    if int(n_trials) < 1:
        raise ValueError(f"n_trials must be >= 1; got {n_trials}")
    plan_cls, defaults = STRATEGIES[strategy]
    unknown = sorted(set(strategy_kwargs) - set(defaults))
    if unknown:
        raise ValueError(f"unknown settings {unknown} for strategy {strategy!r}")
    return run(
        plan_cls, sim, goal, [seed + r for r in range(int(n_trials))],
        algorithm=algorithm, population_size=population_size, tolerance=tolerance,
        max_generations=max_generations, chunk_size=chunk_size,
        algorithm_kwargs=algorithm_kwargs, algorithm_params=algorithm_params,
        progress_fn=progress_fn, devices=devices, shard="trials",
        **{**defaults, **strategy_kwargs},
    )
