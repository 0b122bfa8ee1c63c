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

from cgda_jax.strategies.base import PlanBase
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import run

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
    """FTE as a plan for `runner.drive`.

    Args (beyond `PlanBase`'s):
        stagnation: stop after this many generations without improvement.
        distance: fitness name or callable (see `resolve_distance`).
    """

    name = "fte"

    def __init__(self, sim, goal, *, stagnation=10, distance=None, **kwargs):
        if int(stagnation) < 1:
            raise ValueError(f"stagnation must be >= 1; got {stagnation}")
        super().__init__(sim, goal, goal.shape[0] * int(sim.n_dof), **kwargs)
        self.stagnation = int(stagnation)
        self.distance = resolve_distance(distance)

    def _trajectory(self, u_flat):
        return self.joints(u_flat.reshape(self.n_points, self.n_dof))

    def _fitness(self, pop):
        feats = self.map_population(
            lambda u: self.execution(self._trajectory(u))["features"], pop
        )
        return jax.vmap(lambda f: self.distance(f, self.goal))(feats)

    def stop(self, evo):
        return (evo.stall >= self.stagnation) | (evo.generation >= self.max_generations)

    def init(self, key):
        return self.start(key, self._fitness)

    def step(self, evo):
        return self.evolve(evo, self._fitness)

    def progress(self, evo):
        return {"best_fitness": np.asarray(evo.best_fitness).tolist()}

    def finish(self, evo):
        return {
            # NaN when nothing valid was found (the start mean was never evaluated)
            **self.execution(
                jnp.where(evo.found, self._trajectory(evo.best_u), jnp.nan)
            ),
            "best_fitness": evo.best_fitness,
            "generation": evo.generation,
            "evaluations": evo.evaluations,
            "invalid": evo.invalid,
        }

    def to_result(self, final, history, timing):
        gens = int(final["generation"])
        return self.result(
            final, timing,
            fitness_history=history["best_fitness"][:gens].astype(np.float64),
            evaluations=final["evaluations"],
            generations=gens,
            final_fitness=final["best_fitness"],
            stagnation=self.stagnation,
            invalid_evaluations=final["invalid"],
            points_without_valid=(
                [] if np.isfinite(final["best_fitness"]) else list(range(self.n_points))
            ),
        )


def run_fte(
    sim: Any,
    goal: Any,
    *,
    algorithm: Any = "CMA_ES",
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
    devices: int | str | None = None,
) -> ExecutionResult:
    """Full Trajectory Evolution of a goal feature trajectory.

    Args:
        sim: a simulator (see `run_ie`).
        goal: goal feature trajectory (N, F).
        algorithm, population_size, seed, chunk_size, algorithm_kwargs,
            algorithm_params, progress_fn, devices: as in `run_ie`.
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
    (result,) = run(
        FTEPlan, sim, goal, [seed], algorithm=algorithm,
        population_size=population_size, tolerance=tolerance,
        max_generations=max_generations, chunk_size=chunk_size,
        algorithm_kwargs=algorithm_kwargs, algorithm_params=algorithm_params,
        stagnation=stagnation, distance=distance,
        progress_fn=progress_fn, devices=devices,
    )
    return result
