"""Incrementally Evolved Trajectories (IET, paper 3.3, Algorithm 1).

Point i is evolved with points 0..i-1 frozen; the fitness of a candidate posture is the
Euclidean distance between the executed features 0..i and goal 0..i. The simulation is
deterministic, so the simulator state reached by the frozen prefix is carried and each
candidate is executed with ONE `sim.step` from it: every point costs the same (the
paper's cost grew linearly with i). The frozen prefix contributes its squared error, so
the fitness is exactly the paper's ``|execute(M[0..i]) - X[0..i]|``.

All points share one compiled generation step: a (N, DoF) buffer of frozen postures and
a traced point index. When the current point's evolution stops (fitness < tolerance or
`max_generations`), the same step commits it (steps the carried state, stores the
posture and features) and starts the next point's evolution; the run is one sequence of
`lax.scan` chunks, so R independent trials vmap over seeds.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from cgda_jax.strategies.ie_plan import LOCAL_STD, RESTART_SAMPLES, STAGNATION
from cgda_jax.strategies.iet_plan import BACKTRACKS, RESTARTS, IETPlan
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import run

# the plan and its defaults live in iet_plan (names kept importable from here)
__all__ = ["BACKTRACKS", "LOCAL_STD", "RESTARTS", "RESTART_SAMPLES", "STAGNATION",
           "IETPlan", "run_iet"]

def run_iet(
    sim: Any,
    goal: Any,
    *,
    algorithm: Any = "CMA_ES",
    population_size: int = 16,
    tolerance: float = 0.02,
    max_generations: int = 100,
    seed: int = 0,
    chunk_size: int = 10,
    restarts: int = RESTARTS,
    backtracks: int = BACKTRACKS,
    warm_start: bool = False,
    restart_samples: int = RESTART_SAMPLES,
    stagnation: int | None = STAGNATION,
    aim: float = 1.0,
    algorithm_kwargs: dict | None = None,
    algorithm_params: dict | None = None,
    progress_fn: Callable[[dict], None] | None = None,
    devices: int | str | None = None,
) -> ExecutionResult:
    """Incrementally Evolved Trajectories (paper Algorithm 1).

    Args:
        sim: a simulator (see `run_ie`).
        goal: goal feature trajectory (N, F).
        tolerance: epsilon of Algorithm 1 (feature units, e.g. percent painted). The
            evolution of point i minimizes the paper's fitness, the Euclidean distance
            of executed features 0..i to goal 0..i; it stops when point i's OWN error
            is below epsilon (the frozen prefix adds a constant the point cannot
            change; with the whole-prefix rule one miss would make every later point
            spend its whole budget).
        max_generations: generation budget of one evolution of a point.
        restarts: a point that missed epsilon after `max_generations` is evolved
            again with a fresh key, up to this many times: from the sampled
            postures nearest the goal point in turn (see `restart_samples`) or,
            without samples, a random start mean.
        backtracks: a point that still missed after its restarts makes the run
            re-evolve the previous point (fresh key) and try again, up to this many
            times per run; the k-th backtrack in a row from the same point
            re-evolves the k previous points. 0 and 0 give the paper's plain
            Algorithm 1.
        warm_start: start each point's first evolution at the previous point's
            posture (point 0: the start posture) instead of the middle of the joint
            ranges; for goals reached by small continuous moves (pushing an object).
        restart_samples: postures sampled once per run (kinematic mode, stateless
            scene; one batched call inside the compiled init) whose nearest to each
            goal point seed its restarts with a local search; 0: off.
        stagnation: an evolution of a point also stops after this many
            generations without improvement (None: only at `max_generations`), so
            a point stuck where it cannot meet epsilon restarts or backtracks
            early instead of spending its whole budget.
        algorithm, population_size, seed, chunk_size, algorithm_kwargs,
            algorithm_params, progress_fn, devices: as in `run_ie`.
        aim: the share of the tolerance each point's evolution aims for, in
            (0, 1]: it stops, restarts and ranks by least motion at
            ``aim * tolerance``; the run is still judged at ``tolerance``.  Below 1
            it leaves room for a finer replay, the exported trajectory or a robot
            to differ a little (1: the paper's rule, anything within tolerance).

    Returns:
        `ExecutionResult`; success = every executed point's error < epsilon;
        final_fitness = the whole trajectory's Euclidean fitness. ``info`` holds
        per-point generations / evaluations / tries, each try's best fitness
        (``try_best_fitness[i][t]``) and the backtracks used; fitness_history row i
        is point i's last evolution. The committed posture of a point is the best
        over its restarts (``point_fitness[i]``), also when every one missed epsilon.
    """
    (result,) = run(
        IETPlan, sim, goal, [seed], algorithm=algorithm,
        population_size=population_size, tolerance=tolerance,
        max_generations=max_generations, chunk_size=chunk_size,
        algorithm_kwargs=algorithm_kwargs, algorithm_params=algorithm_params,
        restarts=restarts, backtracks=backtracks, warm_start=warm_start,
        restart_samples=restart_samples, stagnation=stagnation,
        aim=aim, progress_fn=progress_fn, devices=devices,
    )
    return result
