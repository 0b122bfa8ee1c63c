"""Full Trajectory Evolution (FTE, paper 3.1): one evolution over all N x DoF genes.

Each individual is a whole joint trajectory; it is executed from the start state and its
fitness is the DTW discrepancy (`cgda_jax.dtw`) between the executed and the goal
feature trajectories. The evolution stops after `stagnation` generations without
improvement (paper: 10) or at `max_generations`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.strategies.base import PlanBase, check_config, evolution_init, evolution_step
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import drive, seed_keys


#: Fitness names accepted by ``distance=``.
DISTANCES = ("dtw", "dtw_multi", "euclidean")


def resolve_distance(distance):
    """A fitness ``(executed (N, F), goal (N, F)) -> scalar`` from a name or callable.

    None = "dtw" (the paper's per-dimension DTW). "dtw_multi" is the multi-dimensional
    DTW the authors' C++ execution code used (one warping path for all dimensions, so
    X, Y and Z cannot be warped independently).
    """
    from cgda_jax import distance as d

    if distance is None:
        return d.dtw
    if callable(distance):
        return distance
    if distance not in DISTANCES:
        raise ValueError(f"unknown distance {distance!r}; choose one of {list(DISTANCES)}"
                         " or pass a callable")
    return getattr(d, distance)


class FTEPlan(PlanBase):
    """FTE as a plan for `runner.drive`."""

    name = "fte"

    def __init__(self, sim, goal, *, stagnation, distance=None, **kwargs):
        n_points = goal.shape[0]
        super().__init__(sim, goal, n_points * int(sim.n_dof), **kwargs)
        self.stagnation = int(stagnation)
        self.distance = resolve_distance(distance)

    def _execute(self, u_flat):
        q = self.joints(u_flat.reshape(self.goal.shape[0], self.n_dof))
        return self.sim.rollout(q, self.sim.init_state())[0]

    def _fitness(self, pop):
        feats = jax.vmap(self._execute)(pop)
        return jax.vmap(lambda f: self.distance(f, self.goal))(feats)

    def stop(self, evo):
        return (evo.stall >= self.stagnation) | (evo.generation >= self.max_generations)

    def init(self, key):
        return evolution_init(self.algo, self.params, key, self._fitness, self.n_genes)

    def step(self, evo):
        return evolution_step(self.algo, self.params, evo, self._fitness, self.stop)

    def done(self, evo):
        return evo.done

    def progress(self, evo):
        return {"best_fitness": np.asarray(evo.best_fitness).tolist()}

    def finish(self, evo):
        q = self.joints(evo.best_u.reshape(self.goal.shape[0], self.n_dof))
        return {
            "joints": q,
            "features": self.sim.rollout(q, self.sim.init_state())[0],
            "best_fitness": evo.best_fitness,
            "generation": evo.generation,
            "evaluations": evo.evaluations,
        }

    def to_result(self, final, history, timing):
        goal = np.asarray(self.goal)
        errors = np.linalg.norm(final["features"] - goal, axis=-1)
        gens = int(final["generation"])
        return ExecutionResult(
            strategy=self.name,
            joints=final["joints"],
            features=final["features"],
            goal=goal,
            point_errors=errors,
            fitness_history=history["best_fitness"][:gens].astype(np.float64),
            evaluations=int(final["evaluations"]),
            generations=gens,
            wall_time_s=timing["wall_time_s"],
            compile_time_s=timing["compile_time_s"],
            success=bool(np.all(errors < self.tolerance)),
            tolerance=self.tolerance,
            final_fitness=float(final["best_fitness"]),
            info=self.result_info(timing, stagnation=self.stagnation),
        )


def run_fte(
    sim: Any,
    goal: Any,
    *,
    algorithm: str = "CMA_ES",
    population_size: int = 32,
    tolerance: float = 0.02,
    stagnation: int = 10,
    max_generations: int = 500,
    seed: int = 0,
    chunk_size: int = 10,
    distance: str | Callable[[jax.Array, jax.Array], jax.Array] | None = None,
    algorithm_kwargs: dict | None = None,
    algorithm_params: dict | None = None,
    progress_fn: Callable[[dict], None] | None = None,
) -> ExecutionResult:
    """Full Trajectory Evolution of a goal feature trajectory.

    Args:
        sim: a simulator (see `run_ie`).
        goal: goal feature trajectory (N, F).
        algorithm, population_size, seed, chunk_size, algorithm_kwargs,
            algorithm_params, progress_fn: as in `run_ie`.
        tolerance: success threshold on every point's executed error (FTE itself does
            not stop on it; it stops on stagnation).
        stagnation: stop after this many generations without improvement (paper: 10).
        max_generations: generation budget.
        distance: fitness: "dtw" (default, the paper's per-dimension DTW),
            "dtw_multi" (the authors' C++ fitness), "euclidean", or a callable
            ``(executed (N, F), goal (N, F)) -> scalar``.

    Returns:
        `ExecutionResult`; final_fitness is the best DTW, success = every point's error
        < tolerance.
    """
    goal = check_config(sim, goal, tolerance=tolerance, max_generations=max_generations)
    if int(stagnation) < 1:
        raise ValueError(f"stagnation must be >= 1; got {stagnation}")
    plan = FTEPlan(
        sim, goal, stagnation=stagnation, distance=distance, algorithm=algorithm,
        population_size=population_size, tolerance=tolerance,
        max_generations=max_generations, algorithm_kwargs=algorithm_kwargs,
        algorithm_params=algorithm_params, info={"seed": seed},
    )
    (result,) = drive(plan, seed_keys([seed]), chunk_size=chunk_size,
                      progress_fn=progress_fn)
    return result
