"""The IE plan (`IEPlan`, driven by `cgda_jax.strategies.runner`): every goal
point's evolution, its restarts and the result; `cgda_jax.strategies.ie` runs it
(`run_ie`, the method itself is described there)."""

from __future__ import annotations

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
from cgda_jax.strategies.evolution import evolution_tell
from cgda_jax.strategies.ie_context import (
    contexts,
    fresh,
    judged_execution,
    judged_generation,
    rescore,
)
from cgda_jax.strategies.ie_state import IEState, point_keys
from cgda_jax.strategies.refine import REFINE, nearest_samples, polish, reachability

__all__ = ["LOCAL_STD", "RESTARTS", "RESTART_SAMPLES", "STAGNATION", "IEPlan"]

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

    def point_stop(self, evo: Evolution) -> jax.Array:
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
        states, _ = contexts(self, jnp.zeros((self.n_points, self.n_dof)))
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
            generations=zero, evaluations=zero, invalid=zero,
            **({} if not self.judges_in_step else {
                "judged_u": jnp.full_like(best_u, jnp.nan),
                "judged_violation": jnp.full((self.n_points,), jnp.nan)}))

    @property
    def judges_in_step(self) -> bool:
        """Feasibility with the sequential context: the bests' moves are judged
        with the candidates each generation (`ie_context.judged_generation`)."""
        return self.sequential and self.feasibility is not None

    @property
    def finish_takes_judged(self) -> bool:
        """`judges_in_step` and no polish: the result's execution takes the
        kept judgements (`ie_context.judged_execution`); a polish judges its
        postures in the finish."""
        return self.judges_in_step and self.refine == "none"

    def done(self, s: IEState) -> jax.Array:
        """Every point finished (and, `finish_takes_judged`, its move judged as
        executed: `ie_context.fresh`)."""
        if not self.finish_takes_judged:
            return jnp.all(s.done)
        return jnp.all(s.done) & fresh(s)

    def step(self, s: IEState):
        states, errors = contexts(self, s.best_u)
        asked = None
        if self.judges_in_step:  # the bests' moves judged with the candidates
            errors, violation, asked = judged_generation(self, s.evo, s.best_u, states)
            s = s.replace(judged_u=s.best_u, judged_violation=violation)
        if self.sequential:  # re-score the bests where the others now leave them
            s, evo = rescore(self, s, errors)
        else:
            evo = s.evo
        if asked is None:
            evo, metrics = jax.vmap(
                lambda e, g, st: self.evolve(e, self.point_fitness(st, g),
                                             self.point_stop)
            )(evo, self.goal, states)
        else:
            evo, metrics = jax.vmap(
                lambda e, pop, a, f: evolution_tell(self.algo, self.params, e, pop,
                                                    a, f, self.point_stop)
            )(evo, *asked)
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
        gens = np.asarray(s.generations + s.evo.generation)
        return {  # generations: the slowest point's, as the result's
            "generations": gens.max(axis=-1).tolist(),
            "points_done": np.asarray(s.done).sum(axis=-1).tolist(),
            "points_met": (np.asarray(s.best_fitness) < self.tolerance
                           ).sum(axis=-1).tolist(),
            "worst_error": np.asarray(s.best_fitness).max(axis=-1).tolist(),
        }

    def finish(self, s):
        found = jnp.isfinite(s.best_fitness)
        joints = jnp.where(found[:, None], self.joints(s.best_u), jnp.nan)
        if self.finish_takes_judged:
            executed = judged_execution(self, s, joints)
        else:
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
        final = self.rejudge(final)
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
