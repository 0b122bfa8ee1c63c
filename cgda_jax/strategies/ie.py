"""Individual Evolution (IE, paper 3.2): every goal point evolved on its own, all at once.

Each point i has its own evolution of DoF genes; its fitness is the Euclidean distance
between the features reached by moving from the start state to the candidate posture
and goal point i. The N evolutions are independent, so they run as ONE batched
evolution (`vmap` over points); each point stops when its error drops below
`tolerance` (or at `max_generations`) and is frozen from then on.

Points are only independent when a step's features do not depend on where it starts:
kinematic mode with a scene that carries no state (the marker).  Otherwise (dynamic
mode: the arm moves from the previous posture and may not have settled; a scene with
state, e.g. a painted wall) every generation first executes the current best
postures of all points in order, from the start (one sequential rollout of N
waypoints), and evaluates point i's candidates from the state reached after points
0..i-1, the way the final sequential execution will run them; each point's best is
re-scored in that context before the stop test.  ``info["sequential_context"]`` says
which variant ran.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax

from cgda_jax.strategies.ie_plan import (
    LOCAL_STD,
    RESTART_SAMPLES,
    RESTARTS,
    STAGNATION,
    IEPlan,
)
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import run

# the plan and its defaults live in ie_plan (names kept importable from here)
__all__ = ["LOCAL_STD", "RESTARTS", "RESTART_SAMPLES", "STAGNATION", "IEPlan",
           "run_ie"]

def run_ie(
    sim: Any,
    goal: Any,
    *,
    algorithm: Any = "CMA_ES",
    population_size: int = 16,
    tolerance: float = 0.02,
    max_generations: int = 100,
    seed: int = 0,
    chunk_size: int = 10,
    algorithm_kwargs: dict | None = None,
    algorithm_params: dict | None = None,
    keys: jax.Array | None = None,
    refine: str = "none",
    refine_steps: int = 100,
    reach_check: bool = False,
    restarts: int = RESTARTS,
    stagnation: int | None = STAGNATION,
    aim: float = 1.0,
    restart_samples: int = RESTART_SAMPLES,
    warm_start: bool = False,
    progress_fn: Callable[[dict], None] | None = None,
    devices: int | str | None = None,
) -> ExecutionResult:
    """Individual Evolution of every goal point, all points in one batched evolution.

    Args:
        sim: a simulator (`n_dof`, `n_features`, `lower`, `upper`, `init_state`,
            `step`, `rollout`).
        goal: goal feature trajectory (N, F).
        algorithm: an evosax algorithm: a name (see `ALGORITHMS`), a class, or a
            configured instance (its population and solution sizes must match; see
            `cgda_jax.strategies.base.make_algorithm`).
        population_size: individuals per generation and point.
        tolerance: a point is done when its error is below this (feature units; the
            paper used 20 mm).
        max_generations: generation budget per point.
        seed: random seed; point i uses ``fold_in(key(seed), i)`` (see `point_keys`).
        chunk_size: generations per compiled `lax.scan` chunk.
        algorithm_kwargs, algorithm_params: see `make_algorithm`.
        keys: optional explicit per-point keys (N,) replacing the seed's (to re-run
            one point of a batched run alone).
        refine: "none" (default), "adam" or "lbfgs": after evolution, polish every
            point's best posture by gradient descent through the differentiable
            kinematic simulator (optax), keeping the best iterate (never worse).
        refine_steps: optimiser steps of the polish.
        reach_check: before evolving, sample 2,048 postures (one batched kinematics
            call) and descend from the nearest ones; points no posture brings
            within `tolerance` are not evolved (no budget spent) and listed in
            ``info["unreachable_points"]`` with their nearest approach.
            `refine` and `reach_check` need kinematic mode and a stateless scene.
        restarts: a point whose try stopped above `tolerance` (budget spent or
            stalled) is tried again with a fresh key, up to this many times (inside
            the compiled step), starting alternately from its better-solved
            neighbour's best posture and from a random mean; the best over its tries
            is kept and ``info["point_tries"]`` says how many it took. Restart t
            starts (cycling) from the sampled posture nearest the goal point (see
            `restart_samples`), a better-solved neighbour's best posture, or a
            random mean (without samples: neighbour and random alternately).
        stagnation: a try stops after this many generations without improvement
            (None: only at `max_generations`), so a stuck point restarts early.
        restart_samples: with independent points (kinematic mode, stateless
            scene) and restarts > 0, this many postures drawn uniformly in the joint
            limits are evaluated once per run (one batched kinematics call, inside
            the compiled init) and the nearest to each goal point is a restart mean:
            a point stuck in a local minimum restarts in the goal's basin. 0: off.
        warm_start: every point's first try searches locally around the start
            posture instead of over the whole joint ranges from their middle
            (restarts as without it); see `IEPlan`.
        progress_fn: called with a dict after each chunk.
        devices: None (default: one device, the unsharded program), "all" or a
            device count: each generation's batched simulator call (N points x
            population) has its population axis split over these devices (padded
            to a multiple of their count by repeating the last candidate, whose
            results are dropped); same results as unsharded. Multi-host: see
            `cgda_jax.sharding`.
        aim: the share of the tolerance each point's evolution aims for, in
            (0, 1]: it stops, restarts and ranks by least motion at
            ``aim * tolerance``; the run is still judged at ``tolerance``.  Below 1
            it leaves room for a finer replay, the exported trajectory or a robot
            to differ a little (1: the paper's rule, anything within tolerance).

    Returns:
        `ExecutionResult`; success = every point's executed error < tolerance.

    Examples:
        >>> res = run_ie(sim, goal, tolerance=0.02)  # doctest: +SKIP
        >>> res.point_errors.max() < 0.02  # doctest: +SKIP
    """
    (result,) = run(
        IEPlan, sim, goal, [seed], algorithm=algorithm,
        population_size=population_size, tolerance=tolerance,
        max_generations=max_generations, chunk_size=chunk_size,
        algorithm_kwargs=algorithm_kwargs, algorithm_params=algorithm_params,
        keys=keys, refine=refine, refine_steps=refine_steps, reach_check=reach_check,
        restarts=restarts, stagnation=stagnation, restart_samples=restart_samples,
        warm_start=warm_start,
        aim=aim, progress_fn=progress_fn, devices=devices,
    )
    return result
