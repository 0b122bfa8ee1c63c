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

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from cgda_jax.strategies.base import (
    Evolution,
    PlanBase,
    check_config,
    evolution_init,
    evolution_step,
    freeze,
)
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import drive, seed_keys


@struct.dataclass
class IETState:
    """Carry of an IET run.

    Attributes:
        evo: evolution of the current point.
        key: the run's key (point i's evolution uses ``fold_in(key, i)``).
        point: index of the point being evolved (N once finished).
        sim_state: simulator state after executing the frozen prefix.
        prefix_sq: summed squared feature error of the frozen prefix.
        joints: frozen postures (N, DoF); features: their features (N, F).
        point_fitness, point_generations, point_evaluations: per point (N,).
    """

    evo: Evolution
    key: jax.Array
    point: jax.Array
    sim_state: Any
    prefix_sq: jax.Array
    joints: jax.Array
    features: jax.Array
    point_fitness: jax.Array
    point_generations: jax.Array
    point_evaluations: jax.Array


class IETPlan(PlanBase):
    """IET as a plan for `runner.drive`."""

    name = "iet"

    def __init__(self, sim, goal, **kwargs):
        super().__init__(sim, goal, int(sim.n_dof), **kwargs)
        self.n_points = int(goal.shape[0])
        self.max_generations_total = self.n_points * self.max_generations

    def _fitness(self, sim_state, prefix_sq, point):
        goal_point = self.goal[jnp.minimum(point, self.n_points - 1)]

        def fitness_u(pop):
            feats = self.point_features(sim_state, pop)
            sq = jnp.sum((feats - goal_point) ** 2, axis=-1)
            return jnp.sqrt(prefix_sq + sq)

        return fitness_u

    def _start(self, key, sim_state, prefix_sq, point):
        return evolution_init(
            self.algo, self.params, jax.random.fold_in(key, point),
            self._fitness(sim_state, prefix_sq, point), self.n_dof,
        )

    def init(self, key):
        n, f = self.n_points, self.goal.shape[1]
        sim_state = self.sim.init_state()
        zero = jnp.zeros((), jnp.float32)
        point = jnp.zeros((), jnp.int32)
        return IETState(
            evo=self._start(key, sim_state, zero, point),
            key=key,
            point=point,
            sim_state=sim_state,
            prefix_sq=zero,
            joints=jnp.zeros((n, self.n_dof), jnp.float32),
            features=jnp.zeros((n, f), jnp.float32),
            point_fitness=jnp.full((n,), jnp.inf, jnp.float32),
            point_generations=jnp.zeros((n,), jnp.int32),
            point_evaluations=jnp.zeros((n,), jnp.int32),
        )

    def _commit(self, s: IETState) -> IETState:
        i = s.point
        q = self.joints(s.evo.best_u)
        sim_state, feats = self.sim.step(s.sim_state, q)
        prefix_sq = s.prefix_sq + jnp.sum((feats - self.goal[i]) ** 2)
        nxt = i + 1
        return s.replace(
            evo=self._start(s.key, sim_state, prefix_sq, nxt),
            point=nxt,
            sim_state=sim_state,
            prefix_sq=prefix_sq,
            joints=s.joints.at[i].set(q),
            features=s.features.at[i].set(feats),
            point_fitness=s.point_fitness.at[i].set(s.evo.best_fitness),
            point_generations=s.point_generations.at[i].set(s.evo.generation),
            point_evaluations=s.point_evaluations.at[i].set(s.evo.evaluations),
        )

    def step(self, s: IETState):
        finished = self.done(s)
        fit = self._fitness(s.sim_state, s.prefix_sq, s.point)
        evo, metrics = evolution_step(self.algo, self.params, s.evo, fit, self.stop)
        new = s.replace(evo=evo)
        new = jax.lax.cond(evo.done, self._commit, lambda x: x, new)
        new = freeze(finished, s, new)
        metrics = {"best_fitness": metrics["best_fitness"],
                   "point": jnp.where(finished, -1, s.point)}
        return new, metrics

    def done(self, s):
        return s.point >= self.n_points

    def progress(self, s):
        return {"point": np.asarray(s.point).tolist()}

    def finish(self, s):
        features, _ = self.sim.rollout(s.joints, self.sim.init_state())
        return {
            "joints": s.joints,
            "features": features,
            "carried_features": s.features,
            "point": s.point,
            "point_fitness": s.point_fitness,
            "point_generations": s.point_generations,
            "point_evaluations": s.point_evaluations,
        }

    def to_result(self, final, history, timing):
        goal = np.asarray(self.goal)
        errors = np.linalg.norm(final["features"] - goal, axis=-1)
        gens = final["point_generations"]
        hist = np.full((self.n_points, max(int(gens.max()), 1)), np.nan)
        for i in range(self.n_points):
            h = history["best_fitness"][history["point"] == i]
            hist[i, : len(h)] = h
        complete = int(final["point"]) >= self.n_points
        return ExecutionResult(
            strategy=self.name,
            joints=final["joints"],
            features=final["features"],
            goal=goal,
            point_errors=errors,
            fitness_history=hist,
            evaluations=int(final["point_evaluations"].sum()),
            generations=int(gens.sum()),
            wall_time_s=timing["wall_time_s"],
            compile_time_s=timing["compile_time_s"],
            success=bool(complete and np.all(final["point_fitness"] < self.tolerance)),
            tolerance=self.tolerance,
            final_fitness=float(final["point_fitness"][-1]),
            info=self.result_info(
                timing,
                point_generations=gens.tolist(),
                point_evaluations=final["point_evaluations"].tolist(),
                point_fitness=final["point_fitness"].tolist(),
                carried_matches_rollout=bool(
                    np.allclose(final["carried_features"], final["features"],
                                atol=1e-4)
                ),
            ),
        )


def run_iet(
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
    progress_fn: Callable[[dict], None] | None = None,
) -> ExecutionResult:
    """Incrementally Evolved Trajectories (paper Algorithm 1).

    Args:
        sim: a simulator (see `run_ie`).
        goal: goal feature trajectory (N, F).
        tolerance: epsilon of Algorithm 1: point i stops when the Euclidean distance of
            executed features 0..i to goal 0..i is below it (feature units, e.g. percent
            painted).
        max_generations: generation budget per point.
        algorithm, population_size, seed, chunk_size, algorithm_kwargs,
            algorithm_params, progress_fn: as in `run_ie`.

    Returns:
        `ExecutionResult`; success = every point met epsilon; final_fitness = the whole
        trajectory's Euclidean fitness.
    """
    goal = check_config(sim, goal, tolerance=tolerance, max_generations=max_generations)
    plan = IETPlan(
        sim, goal, algorithm=algorithm, population_size=population_size,
        tolerance=tolerance, max_generations=max_generations,
        algorithm_kwargs=algorithm_kwargs, algorithm_params=algorithm_params,
        info={"seed": seed},
    )
    (result,) = drive(plan, seed_keys([seed]), chunk_size=chunk_size,
                      progress_fn=progress_fn)
    return result
