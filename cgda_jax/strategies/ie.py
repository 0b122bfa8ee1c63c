"""Individual Evolution (IE, paper 3.2): every goal point evolved on its own, all at once.

Each point i has its own evolution of DoF genes; its fitness is the Euclidean distance
between the features reached by moving from the start state to the candidate posture
and goal point i. The N evolutions are independent, so they run as ONE batched
evolution (`vmap` over points); each point stops when its error drops below
`tolerance` (or at `max_generations`) and is frozen from then on.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.strategies.base import (
    PlanBase,
    check_config,
    evolution_init,
    evolution_step,
)
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import drive, seed_keys


def point_keys(key: jax.Array, n_points: int) -> jax.Array:
    """The per-point keys (N,) IE derives from a run's key: ``fold_in(key, i)``."""
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(n_points))


class IEPlan(PlanBase):
    """IE as a plan for `runner.drive` (see there)."""

    name = "ie"

    def __init__(self, sim, goal, *, keys_fn=None, **kwargs):
        super().__init__(sim, goal, int(sim.n_dof), **kwargs)
        self.keys_fn = keys_fn or (lambda key: point_keys(key, goal.shape[0]))

    def _fitness(self, goal_point: jax.Array) -> Callable[[jax.Array], jax.Array]:
        start = self.sim.init_state()

        def fitness_u(pop):
            feats = self.point_features(start, pop)
            return jnp.linalg.norm(feats - goal_point, axis=-1)

        return fitness_u

    def init(self, key):
        return jax.vmap(
            lambda k, g: evolution_init(
                self.algo, self.params, k, self._fitness(g), self.n_dof
            )
        )(self.keys_fn(key), self.goal)

    def step(self, evo):
        return jax.vmap(
            lambda e, g: evolution_step(
                self.algo, self.params, e, self._fitness(g), self.stop
            )
        )(evo, self.goal)

    def done(self, evo):
        return jnp.all(evo.done)

    def progress(self, evo):
        return {
            "points_done": np.asarray(evo.done).sum(axis=-1).tolist(),
            "worst_error": np.asarray(evo.best_fitness).max(axis=-1).tolist(),
        }

    def finish(self, evo):
        joints = self.joints(evo.best_u)
        features, _ = self.sim.rollout(joints, self.sim.init_state())
        return {
            "joints": joints,
            "features": features,
            "best_fitness": evo.best_fitness,
            "generation": evo.generation,
            "evaluations": evo.evaluations,
        }

    def to_result(self, final, history, timing):
        goal = np.asarray(self.goal)
        errors = np.linalg.norm(final["features"] - goal, axis=-1)
        gens = final["generation"]
        hist = history["best_fitness"].T.astype(np.float64)  # (N, G)
        hist = hist[:, : int(gens.max())]
        hist[np.arange(hist.shape[1])[None, :] >= gens[:, None]] = np.nan
        return ExecutionResult(
            strategy=self.name,
            joints=final["joints"],
            features=final["features"],
            goal=goal,
            point_errors=errors,
            fitness_history=hist,
            evaluations=int(final["evaluations"].sum()),
            generations=int(gens.max()),
            wall_time_s=timing["wall_time_s"],
            compile_time_s=timing["compile_time_s"],
            success=bool(np.all(errors < self.tolerance)),
            tolerance=self.tolerance,
            final_fitness=float(errors.max()),
            info=self.result_info(timing, point_generations=gens.tolist()),
        )


def run_ie(
    sim: Any,
    goal: Any,
    *,
    algorithm: str = "CMA_ES",
    population_size: int = 16,
    tolerance: float = 0.02,
    max_generations: int = 100,
    seed: int = 0,
    chunk_size: int = 10,
    algorithm_kwargs: dict | None = None,
    algorithm_params: dict | None = None,
    keys: jax.Array | None = None,
    progress_fn: Callable[[dict], None] | None = None,
) -> ExecutionResult:
    """Individual Evolution of every goal point, all points in one batched evolution.

    Args:
        sim: a simulator (`n_dof`, `n_features`, `lower`, `upper`, `init_state`,
            `step`, `rollout`).
        goal: goal feature trajectory (N, F).
        algorithm: evosax algorithm name (see `ALGORITHMS`).
        population_size: individuals per generation and point.
        tolerance: a point is done when its error is below this (feature units; the
            paper used 20 mm).
        max_generations: generation budget per point.
        seed: random seed; point i uses ``fold_in(key(seed), i)`` (see `point_keys`).
        chunk_size: generations per compiled `lax.scan` chunk.
        algorithm_kwargs, algorithm_params: see `make_algorithm`.
        keys: optional explicit per-point keys (N,) replacing the seed's (to re-run
            one point of a batched run alone).
        progress_fn: called with a dict after each chunk.

    Returns:
        `ExecutionResult`; success = every point's executed error < tolerance.

    Examples:
        >>> res = run_ie(sim, goal, tolerance=0.02)  # doctest: +SKIP
        >>> res.point_errors.max() < 0.02  # doctest: +SKIP
    """
    goal = check_config(sim, goal, tolerance=tolerance, max_generations=max_generations)
    if keys is not None and keys.shape[0] != goal.shape[0]:
        raise ValueError(f"keys has {keys.shape[0]} entries for {goal.shape[0]} points")
    plan = IEPlan(
        sim, goal, algorithm=algorithm, population_size=population_size,
        tolerance=tolerance, max_generations=max_generations,
        algorithm_kwargs=algorithm_kwargs, algorithm_params=algorithm_params,
        keys_fn=None if keys is None else (lambda _key: keys),
        info={"seed": seed},
    )
    (result,) = drive(plan, seed_keys([seed]), chunk_size=chunk_size,
                      progress_fn=progress_fn)
    return result
