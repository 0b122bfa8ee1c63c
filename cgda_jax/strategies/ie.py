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
import jax.numpy as jnp
import numpy as np

from cgda_jax.strategies.base import PlanBase, points_independent, ragged_rows
from cgda_jax.strategies.refine import REFINE, polish, reachability
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import run


def point_keys(key: jax.Array, n_points: int) -> jax.Array:
    """The per-point keys (N,) IE derives from a run's key: ``fold_in(key, i)``."""
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(n_points))


class IEPlan(PlanBase):
    """IE as a plan for `runner.drive` (see there).

    Args (beyond `PlanBase`'s):
        keys: optional explicit per-point keys (N,) replacing those of the run's key.
        refine: "none", "adam" or "lbfgs": polish each point's best posture by
            gradient descent afterwards (`cgda_jax.strategies.refine.polish`).
        refine_steps: optimiser steps of the polish.
        reach_check: sample the reachable features first and freeze the points no
            posture brings within tolerance (`refine.reachability`).
    Both need independent points (kinematic mode, stateless scene).
    """

    name = "ie"

    def __init__(self, sim, goal, *, keys=None, refine="none", refine_steps=100,
                 reach_check=False, **kwargs):
        if keys is not None and keys.shape[0] != goal.shape[0]:
            raise ValueError(
                f"keys has {keys.shape[0]} entries for {goal.shape[0]} points"
            )
        if refine not in REFINE:
            raise ValueError(f"refine={refine!r}; expected one of {REFINE}")
        self.sequential = not points_independent(sim)
        if self.sequential and (refine != "none" or reach_check):
            raise ValueError(
                "refine and reach_check need independent points: kinematic mode and a "
                "scene without state (e.g. the marker); this simulator is "
                f"{getattr(sim, 'mode', '?')} with {type(sim.scene).__name__}")
        info = {**(kwargs.pop("info", None) or {}),
                "sequential_context": self.sequential, "refine": refine}
        super().__init__(sim, goal, int(sim.n_dof), info=info, **kwargs)
        self.keys = keys
        self.refine, self.refine_steps = refine, int(refine_steps)
        self.unreachable = np.zeros(self.n_points, bool)
        self.reach_genes = np.zeros((self.n_points, self.n_dof), np.float32)
        self.reach_nearest = np.full(self.n_points, np.inf, np.float32)
        if reach_check:
            reach = reachability(sim, goal, self.tolerance)
            self.unreachable[reach["unreachable"]] = True
            self.reach_genes = reach["genes"].astype(np.float32)
            self.reach_nearest = reach["nearest"].astype(np.float32)
            self.info["reach_check_s"] = reach["seconds"]
            self.info["unreachable_points"] = [
                {"index": i, "nearest_approach": float(reach["nearest"][i])}
                for i in reach["unreachable"]]

    def _contexts(self, best_u: jax.Array) -> tuple[Any, jax.Array]:
        """Start states of every point (stacked, N) and each point's error (N,)
        when the postures ``joints(best_u)`` (N, DoF) are executed in order."""
        start = self.sim.init_state()
        if not self.sequential:
            states = jax.tree.map(
                lambda x: jnp.broadcast_to(x, (self.n_points, *jnp.shape(x))), start)
            return states, jnp.full((self.n_points,), jnp.inf)

        def body(state, w):
            new, feats = self.sim.step(state, w)
            return new, (state, feats)

        _, (states, feats) = jax.lax.scan(body, start, self.joints(best_u))
        errors = jnp.linalg.norm(feats - self.goal, axis=-1)
        return states, jnp.where(jnp.isfinite(errors), errors, jnp.inf)

    def init(self, key):
        keys = point_keys(key, self.n_points) if self.keys is None else self.keys
        states, _ = self._contexts(jnp.zeros((self.n_points, self.n_dof)))
        evo = jax.vmap(
            lambda k, g, st: self.start(k, self.point_fitness(st, g))
        )(keys, self.goal, states)
        if not self.unreachable.any():
            return evo
        # no posture reaches these points: keep the nearest approach, spend nothing
        off = jnp.asarray(self.unreachable)
        return evo.replace(
            done=evo.done | off,
            best_u=jnp.where(off[:, None], jnp.asarray(self.reach_genes), evo.best_u),
            best_fitness=jnp.where(off, jnp.asarray(self.reach_nearest),
                                   evo.best_fitness))

    def step(self, evo):
        states, errors = self._contexts(evo.best_u)
        if self.sequential:  # re-score each best where the others now leave it
            fresh = evo.replace(
                best_fitness=jnp.where(jnp.isfinite(evo.best_fitness), errors,
                                       evo.best_fitness))
            evo = fresh.replace(done=jax.vmap(self.stop)(fresh))
        return jax.vmap(
            lambda e, g, st: self.evolve(e, self.point_fitness(st, g))
        )(evo, self.goal, states)

    def progress(self, evo):
        return {
            "points_done": np.asarray(evo.done).sum(axis=-1).tolist(),
            "worst_error": np.asarray(evo.best_fitness).max(axis=-1).tolist(),
        }

    def finish(self, evo):
        joints = self.best_joints(evo)
        if self.refine != "none":
            u, _ = polish(self.sim, evo.best_u, self.goal, method=self.refine,
                          steps=self.refine_steps)
            joints = jnp.where(evo.found[:, None], self.joints(u), joints)
        return {
            **self.execution(joints),
            "generation": evo.generation,
            "evaluations": evo.evaluations,
            "invalid": evo.invalid,
            "found": evo.found,
        }

    def to_result(self, final, history, timing):
        gens = final["generation"]
        hist = history["best_fitness"].astype(np.float64)  # (G, N)
        return self.result(
            final, timing,
            fitness_history=ragged_rows([hist[:g, i] for i, g in enumerate(gens)]),
            evaluations=final["evaluations"].sum(),
            generations=gens.max(),
            point_generations=gens.tolist(),
            invalid_evaluations=final["invalid"].sum(),
            point_invalid=final["invalid"].tolist(),
            points_without_valid=np.flatnonzero(~final["found"]).tolist(),
        )


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
        progress_fn: called with a dict after each chunk.
        devices: None (default: one device, the unsharded program), "all" or a
            device count: each generation's batched simulator call (N points x
            population) has its population axis split over these devices (padded
            to a multiple of their count by repeating the last candidate, whose
            results are dropped); same results as unsharded. Multi-host: see
            `cgda_jax.sharding`.

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
        progress_fn=progress_fn, devices=devices,
    )
    return result
