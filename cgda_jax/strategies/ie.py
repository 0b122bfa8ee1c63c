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

from cgda_jax.strategies.base import (
    Evolution,
    PlanBase,
    from_joints,
    points_independent,
    ragged_rows,
)
from cgda_jax.strategies.ie_state import IEState, point_keys
from cgda_jax.strategies.refine import REFINE, nearest_samples, polish, reachability
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import run

#: Default restarts of a point and generations without improvement that stop a try.
RESTARTS = 9
STAGNATION = 40
#: Initial search width of a local restart (from a sampled or a neighbour's
#: posture), relative to the algorithm's own (distribution-based algorithms).
LOCAL_STD = 0.15
#: Postures sampled (one batched kinematics call per run) to seed the restarts.
RESTART_SAMPLES = 4096


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
        restarts: tries of a point that stopped above tolerance are restarted (fresh
            key; see `_try` for the start means), up to this many times; the best is
            kept.
        restart_samples: postures sampled once per run (independent points only)
            whose nearest to each goal point seed its restarts; 0: none.
        stagnation: a try also stops after this many generations without
            improvement (None: only at `max_generations`).
        warm_start: every point's first try is a local search (initial width
            `LOCAL_STD`) around the start posture (where the arm is before the
            approach) instead of a full-width search around the middle of the
            joint ranges; restarts are as without it.  All points then start in
            the same branch of the arm's inverse kinematics, so in dynamic mode
            each point's posture is a short move from its neighbour's, within
            the speed limits (a 7-joint arm's clean circle: 13-19 generations
            against 74-120 without).
    """

    name = "ie"

    def __init__(self, sim, goal, *, keys=None, refine="none", refine_steps=100,
                 reach_check=False, restarts=0, stagnation=None,
                 restart_samples=RESTART_SAMPLES, warm_start=False, **kwargs):
        if keys is not None and keys.shape[0] != goal.shape[0]:
            raise ValueError(
                f"keys has {keys.shape[0]} entries for {goal.shape[0]} points"
            )
        if refine not in REFINE:
            raise ValueError(f"refine={refine!r}; expected one of {REFINE}")
        # with feasibility the moves between points count: point i is evolved from
        # where points 0..i-1 leave the arm, like the final execution
        feasible_moves = getattr(sim, "feasibility", None) is not None
        self.sequential = not points_independent(sim) or feasible_moves
        if not points_independent(sim) and (refine != "none" or reach_check):
            raise ValueError(
                "refine and reach_check need independent points: kinematic mode and a "
                "scene without state (e.g. the marker); this simulator is "
                f"{getattr(sim, 'mode', '?')} with {type(sim.scene).__name__}")
        info = {**(kwargs.pop("info", None) or {}),
                "sequential_context": self.sequential, "refine": refine}
        super().__init__(sim, goal, int(sim.n_dof), info=info, stagnation=stagnation,
                         **kwargs)
        self.keys = keys
        self.warm_start = bool(warm_start)
        self.info["warm_start"] = self.warm_start
        self.refine, self.refine_steps = refine, int(refine_steps)
        if int(restarts) < 0:
            raise ValueError(f"restarts must be >= 0; got {restarts}")
        self.restarts = int(restarts)
        if int(restart_samples) < 0:
            raise ValueError(f"restart_samples must be >= 0; got {restart_samples}")
        # sampled restart means need postures whose features do not depend on the
        # context (independent features; with feasibility the move to them is still
        # judged in context) and at least one restart to use them
        self.restart_samples = (0 if not points_independent(sim) or self.restarts == 0
                                else int(restart_samples))
        self.n_nearest = min(self.restart_samples, max(1, (self.restarts + 1) // 2))
        self.max_generations_total = self.max_generations * (1 + self.restarts)
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
            return new, (state, feats, new.move_violation)

        _, (states, feats, violation) = jax.lax.scan(body, start,
                                                     self.joints(best_u))
        errors = self.penalize(jnp.linalg.norm(feats - self.goal, axis=-1), violation)
        return states, jnp.where(jnp.isfinite(errors), errors, jnp.inf)

    def _stop(self, evo: Evolution) -> jax.Array:
        """One try of a point stops: tolerance met, its budget spent, or stalled."""
        return self.stop(evo) | self.stalled(evo)

    def _try(self, key, goal_point, state, t, neighbour_u=None, samples=None):
        """Try ``t`` of a point. Try 0 starts from the mid-range mean (with
        `warm_start`: a local search at the start posture) with the point key;
        restart ``t > 0`` uses key ``fold_in(key, t)``. With restart samples,
        odd restarts start from the sampled postures nearest the goal point in turn
        (restart t from the (t-1)//2-th nearest: each near the goal, in whichever
        basin, whatever the previous tries converged to) and even restarts
        alternate between a solved neighbour's best genes (the goal curve is
        continuous, so a neighbour's posture is often in the right basin) and a
        random mean; without samples: neighbour, random, alternately.
        Without a solved neighbour a random mean replaces it. Sample and neighbour
        restarts search locally (initial std scaled by `LOCAL_STD`)."""
        k_mean, k_evo = jax.random.split(jax.random.fold_in(key, t))
        mean = jax.random.uniform(k_mean, (self.n_dof,), minval=-1.0, maxval=1.0)
        k = 0 if samples is None else samples.shape[0]
        restart = t > 0
        if k:  # odd restarts: the samples in turn; even: neighbour, random, ...
            use_sample = restart & ((t - 1) % 2 == 0)
            use_neighbour = restart & ((t - 1) % 4 == 1)
        else:  # alternate: neighbour, random
            use_sample, use_neighbour = jnp.bool_(False), restart & ((t - 1) % 2 == 0)
        if neighbour_u is None:
            use_neighbour = jnp.bool_(False)
        else:
            use_neighbour = use_neighbour & jnp.all(jnp.isfinite(neighbour_u))
            mean = jnp.where(use_neighbour, jnp.nan_to_num(neighbour_u), mean)
        if k:
            mean = jnp.where(use_sample, samples[jnp.clip((t - 1) // 2, 0, k - 1)],
                             mean)
        # a sampled or neighbouring posture is near a solution: search locally there
        local = use_sample | use_neighbour
        first = 0.0
        if self.warm_start:  # try 0: a local search from where the arm starts
            first = from_joints(self.sim.init_state().genes, self.lower, self.upper)
            local = local | ~restart
        mean = jnp.where(restart, mean, first)
        return self.start(jnp.where(restart, k_evo, key),
                          self.point_fitness(state, goal_point), mean=mean,
                          std_scale=jnp.where(local, LOCAL_STD, 1.0))

    def _neighbours(self, best_u, best_fitness):
        """(N, D) the best genes of each point's better-solved neighbour (i-1 or
        i+1, the one with the lower error); NaN where neither has a valid one."""
        inf = jnp.full((1,), jnp.inf)
        nan = jnp.full((1, self.n_dof), jnp.nan)
        prev_f = jnp.concatenate([inf, best_fitness[:-1]])
        next_f = jnp.concatenate([best_fitness[1:], inf])
        prev_u = jnp.concatenate([nan, best_u[:-1]])
        next_u = jnp.concatenate([best_u[1:], nan])
        u = jnp.where((prev_f <= next_f)[:, None], prev_u, next_u)
        ok = jnp.isfinite(jnp.minimum(prev_f, next_f))
        return jnp.where(ok[:, None], u, jnp.nan)

    def init(self, key):
        keys = point_keys(key, self.n_points) if self.keys is None else self.keys
        states, _ = self._contexts(jnp.zeros((self.n_points, self.n_dof)))
        zero = jnp.zeros((self.n_points,), jnp.int32)
        if self.restart_samples:  # one batched kinematics call (points independent)
            start = self.sim.init_state()
            samples, _ = nearest_samples(
                lambda u: self.point_features(start, u), self.goal,
                jax.random.fold_in(key, 2**31 - 1), self.n_dof, self.restart_samples,
                self.n_nearest)
        else:
            samples = jnp.zeros((self.n_points, 0, self.n_dof))
        evo = jax.vmap(self._try)(keys, self.goal, states, zero)
        # no posture reaches the unreachable points: keep the nearest approach
        off = jnp.asarray(self.unreachable)
        best_u = jnp.where(off[:, None], jnp.asarray(self.reach_genes), evo.best_u)
        best_f = jnp.where(off, jnp.asarray(self.reach_nearest), evo.best_fitness)
        return IEState(
            evo=evo.replace(done=evo.done | off), keys=keys, samples=samples,
            tries=zero + 1,
            best_u=best_u, best_fitness=best_f,
            done=(best_f < self.aim_tolerance) | off,
            generations=zero, evaluations=zero, invalid=zero)

    def step(self, s: IEState):
        states, errors = self._contexts(s.best_u)
        evo = s.evo
        if self.sequential:  # re-score the bests where the others now leave them
            fresh = jnp.where(jnp.isfinite(s.best_fitness), errors, s.best_fitness)
            same = jnp.all(evo.best_u == s.best_u, axis=-1)
            evo = evo.replace(best_fitness=jnp.where(
                same & jnp.isfinite(evo.best_fitness), fresh, evo.best_fitness))
            evo = evo.replace(done=jax.vmap(self._stop)(evo))
            s = s.replace(best_fitness=fresh, done=(fresh < self.aim_tolerance)
                          | (evo.done & (s.tries > self.restarts)))
        evo, metrics = jax.vmap(
            lambda e, g, st: self.evolve(e, self.point_fitness(st, g), self._stop)
        )(evo, self.goal, states)
        s = self.settle(s, evo, self.goal, states, self._neighbours)
        return s, {"best_fitness": s.best_fitness, "invalid": metrics["invalid"],
                   "try": s.tries - 1}

    def settle(self, s, evo, goal, states, neighbours_of):
        """After a generation: keep each point's best over its tries, restart the
        tries that stopped short of the tolerance while tries are left (`_try`,
        starting from ``neighbours_of(best_u, best_fitness)`` or the sampled
        postures), and mark the points done. Shared by `step` and the pooled
        points of `cgda_jax.strategies.batching` (``goal``, ``states``: per point)."""
        better = evo.best_fitness < s.best_fitness
        best_u = jnp.where(better[:, None], evo.best_u, s.best_u)
        best_f = jnp.where(better, evo.best_fitness, s.best_fitness)
        met = best_f < self.aim_tolerance
        # a try that stopped short of the tolerance restarts while tries are left
        again = evo.done & ~met & (s.tries <= self.restarts) & ~s.done
        if self.restarts == 0:  # never restarts (tries >= 1): nothing to trace
            fresh = evo
        else:
            neighbours = neighbours_of(best_u, best_f)
            fresh = jax.lax.cond(  # (population-based algorithms evaluate at start)
                jnp.any(again), lambda: jax.vmap(self._try)(
                    s.keys, goal, states, s.tries, neighbours,
                    s.samples if self.restart_samples else None),
                lambda: evo)
        s = s.replace(
            generations=s.generations + jnp.where(again, evo.generation, 0),
            evaluations=s.evaluations + jnp.where(again, evo.evaluations, 0),
            invalid=s.invalid + jnp.where(again, evo.invalid, 0),
            evo=jax.tree.map(
                lambda f, e: jnp.where(again.reshape((-1,) + (1,) * (e.ndim - 1)),
                                       f, e), fresh, evo),
            tries=s.tries + again, best_u=best_u, best_fitness=best_f)
        return s.replace(done=met | (evo.done & ~again))

    def progress(self, s):
        return {
            "points_done": np.asarray(s.done).sum(axis=-1).tolist(),
            "worst_error": np.asarray(s.best_fitness).max(axis=-1).tolist(),
        }

    def finish(self, s):
        found = jnp.isfinite(s.best_fitness)
        joints = jnp.where(found[:, None], self.joints(s.best_u), jnp.nan)
        executed = self.execution(joints)
        if self.refine != "none":
            u, _ = polish(self.sim, s.best_u, self.goal, method=self.refine,
                          steps=self.refine_steps)
            polished = self.execution(jnp.where(found[:, None], self.joints(u),
                                                joints))
            if "violation" in executed:  # kept only if the motion stays as feasible
                better = polished["violation"] <= executed["violation"]
                polished = jax.tree.map(lambda a, b: jnp.where(better, a, b),
                                        polished, executed)
            executed = polished
        return {
            **executed,
            "generation": s.generations + s.evo.generation,
            "evaluations": s.evaluations + s.evo.evaluations,
            "invalid": s.invalid + s.evo.invalid,
            "found": found,
            "tries": s.tries,
        }

    def to_result(self, final, history, timing):
        gens = final["generation"]
        hist = history["best_fitness"].astype(np.float64)  # (G, N)
        rows = [hist[: int(g), i] for i, g in enumerate(gens)]
        return self.result(
            final, timing,
            fitness_history=ragged_rows(rows),
            evaluations=final["evaluations"].sum(),
            generations=gens.max(),
            point_generations=gens.tolist(),
            point_tries=final["tries"].tolist(),
            restarts=self.restarts, stagnation=self.stagnation,
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
