"""The IET plan (`IETPlan`, driven by `cgda_jax.strategies.runner`): one point's
evolution at a time, its commit, restarts and backtracks, and the result;
`cgda_jax.strategies.iet` runs it (`run_iet`, the method itself is described
there)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.strategies.base import (
    PlanBase,
    freeze,
    from_joints,
    points_independent,
    ragged_rows,
)
from cgda_jax.strategies.evolution import evolution_ask, evolution_tell
from cgda_jax.strategies.ie_plan import LOCAL_STD, RESTART_SAMPLES
from cgda_jax.strategies.iet_state import IETState, tree_at, tree_set
from cgda_jax.strategies.refine import nearest_samples

__all__ = ["BACKTRACKS", "RESTARTS", "IETPlan"]

#: Default restarts of a point that missed its tolerance, and backtracks per run.
#: (Restart samples and their local search width: IE's, `ie_plan`.)
RESTARTS = 6
BACKTRACKS = 8


class IETPlan(PlanBase):
    """IET as a plan for `runner.drive`.

    Args (beyond `PlanBase`'s):
        restarts: evolutions of a point that missed its tolerance after
            `max_generations` are restarted (fresh key, random start mean) up to this
            many times; the best over all restarts is kept.
        backtracks: when a point still misses after its restarts, the previous point
            is re-evolved (fresh key) and the point tried again, up to this many times
            per run; the k-th backtrack in a row from the same point goes k points
            back (escapes prefixes that leave no way to the goal, e.g. every
            remaining square only reachable by sweeping across another one).
        warm_start: the first evolution of each point starts at the previous
            point's committed posture (point 0: the start posture) instead of the
            middle of the joint ranges.
        restart_samples: with independent points (kinematic mode, stateless scene)
            this many postures are sampled once per run (one batched call in the
            compiled init); restart t = 1..`restarts` of a point starts from its
            t-th nearest sample with a local search width (`LOCAL_STD`); later
            tries (revisits after a backtrack) from random means. 0: random means.

    A point whose every evolution (restarts and backtracks included) found no valid
    candidate (every simulation diverged) is not committed: the run stops there
    (``info["points_without_valid"]``; it and the later points have NaN joints).
    """

    name = "iet"

    def __init__(self, sim, goal, *, restarts=0, backtracks=0, warm_start=False,
                 restart_samples=RESTART_SAMPLES, stagnation=None, **kwargs):
        super().__init__(sim, goal, int(sim.n_dof), stagnation=stagnation, **kwargs)
        if int(restart_samples) < 0:
            raise ValueError(f"restart_samples must be >= 0; got {restart_samples}")
        self.restart_samples = (int(restart_samples) if points_independent(sim)
                                and int(restarts) > 0 else 0)
        self.n_nearest = min(self.restart_samples, int(restarts))
        self.restarts = int(restarts)
        self.backtracks = int(backtracks)
        self.warm_start = bool(warm_start)
        evolutions = self.n_points * (1 + self.restarts) * (1 + self.backtracks)
        self.max_generations_total = evolutions * self.max_generations

    def _goal(self, point):
        return self.goal[jnp.clip(point, 0, self.n_points - 1)]

    def _fitness(self, sim_state, prefix_sq, point):
        return self.point_fitness(sim_state, self._goal(point), prefix_sq)

    def _stop(self, prefix_sq):
        # the frozen prefix adds a constant the point cannot change: stop on the
        # point's own error (fitness^2 - prefix), same ranking as the paper's fitness
        tol_sq = self.aim_tolerance**2

        def stop(evo):
            own_sq = evo.best_fitness**2 - prefix_sq
            return ((own_sq < tol_sq) | (evo.generation >= self.max_generations)
                    | self.stalled(evo))

        return stop

    def _start(self, s: IETState, point, restart) -> IETState:
        """Starts evolution number ``tries[point]`` of `point` (a restart when > 0)."""
        p = jnp.clip(point, 0, self.n_points - 1)
        t = s.tries[p]
        key = jax.random.fold_in(jax.random.fold_in(s.key, point), t)
        k_mean, k_evo = jax.random.split(key)
        first = 0.0
        if self.warm_start:  # the posture the point starts from
            before = jnp.where(p > 0, s.joints[jnp.maximum(p - 1, 0)],
                               s.sim_states.genes[0])
            first = from_joints(before, self.lower, self.upper)
        mean = jnp.where(
            t > 0,
            jax.random.uniform(k_mean, (self.n_dof,), minval=-1.0, maxval=1.0),
            first,
        )
        local = jnp.bool_(False)
        if self.restart_samples:  # restarts: the nearest samples in turn
            local = (t > 0) & (t <= self.n_nearest)
            nearest = s.samples[p, jnp.clip(t - 1, 0, self.n_nearest - 1)]
            mean = jnp.where(local, nearest, mean)
        prefix_sq = s.prefix_sq[p]
        evo = self.start(
            k_evo, self._fitness(tree_at(s.sim_states, p), prefix_sq, point), mean=mean,
            std_scale=jnp.where(local, LOCAL_STD, 1.0))
        # a restart keeps the best of the point's earlier tries (same prefix); a new
        # point or a revisit after a backtrack (new prefix) starts from this try's
        keep = restart > 0
        s = s.replace(
            evo=evo, point=point, restart=restart, tries=s.tries.at[p].add(1),
            best_u=jnp.where(keep, s.best_u, evo.best_u),
            best_fitness=jnp.where(keep, s.best_fitness, evo.best_fitness),
        )
        if self.feasibility is None:
            return s
        unknown = jnp.float32(jnp.nan)  # an evaluated initial population's best
        return s.replace(evo_violation=unknown, best_violation=jnp.where(
            keep, s.best_violation, unknown))

    def init(self, key):
        n, f = self.n_points, self.goal.shape[1]
        state0 = self.sim.init_state()
        zero_i = jnp.zeros((), jnp.int32)
        if self.restart_samples:
            samples, _ = nearest_samples(
                lambda u: self.point_features(state0, u), self.goal,
                jax.random.fold_in(key, 2**31 - 1), self.n_dof, self.restart_samples,
                self.n_nearest)
        else:
            samples = jnp.zeros((n, 0, self.n_dof))
        s = IETState(
            evo=None, key=key, point=zero_i, tries=jnp.zeros((n,), jnp.int32),
            restart=zero_i, backtracks=zero_i, stuck=zero_i - 1, depth=zero_i,
            best_u=jnp.zeros((self.n_dof,), jnp.float32),
            best_fitness=jnp.asarray(jnp.inf, jnp.float32),
            sim_states=jax.tree.map(
                lambda x: jnp.broadcast_to(x, (n + 1, *jnp.shape(x))), state0),
            prefix_sq=jnp.zeros((n + 1,), jnp.float32),
            joints=jnp.zeros((n, self.n_dof), jnp.float32),
            features=jnp.zeros((n, f), jnp.float32),
            point_fitness=jnp.full((n,), jnp.inf, jnp.float32),
            point_generations=jnp.zeros((n,), jnp.int32),
            point_evaluations=jnp.zeros((n,), jnp.int32),
            point_invalid=jnp.zeros((n,), jnp.int32),
            stopped=jnp.asarray(False), samples=samples,
        )
        if self.feasibility is not None:
            nan = jnp.float32(jnp.nan)
            s = s.replace(evo_violation=nan, best_violation=nan,
                          violations=jnp.full((n,), jnp.nan, jnp.float32))
        return self._start(s, zero_i, zero_i)

    def _end_evolution(self, s: IETState) -> IETState:
        """The current evolution stopped: commit the point, restart it, or backtrack."""
        i = s.point
        better = s.evo.best_fitness < s.best_fitness
        best_u = jnp.where(better, s.evo.best_u, s.best_u)
        best_f = jnp.where(better, s.evo.best_fitness, s.best_fitness)
        if self.feasibility is not None:
            s = s.replace(best_violation=jnp.where(better, s.evo_violation,
                                                   s.best_violation))
        s = s.replace(
            best_u=best_u, best_fitness=best_f,
            point_generations=s.point_generations.at[i].add(s.evo.generation),
            point_evaluations=s.point_evaluations.at[i].add(s.evo.evaluations),
            point_invalid=s.point_invalid.at[i].add(s.evo.invalid),
        )
        q = self.joints(best_u)
        # the move was judged in the evaluation that found it (best_f)
        sim_state, feats = self.advance(tree_at(s.sim_states, i), q)
        own_sq = jnp.sum((feats - self.goal[i]) ** 2)
        met = own_sq < self.aim_tolerance**2
        found = jnp.isfinite(best_f)  # best_u was evaluated (valid) in some try
        can_restart = s.restart < self.restarts
        can_backtrack = (i > 0) & (s.backtracks < self.backtracks)

        def commit(s):
            nxt = i + 1
            s = s.replace(
                sim_states=tree_set(s.sim_states, nxt, sim_state),
                prefix_sq=s.prefix_sq.at[nxt].set(s.prefix_sq[i] + own_sq),
                joints=s.joints.at[i].set(q),
                features=s.features.at[i].set(feats),
                point_fitness=s.point_fitness.at[i].set(best_f),
            )
            if self.feasibility is not None:
                s = s.replace(violations=s.violations.at[i].set(s.best_violation))
            return jax.lax.cond(nxt < self.n_points,
                                lambda s: self._start(s, nxt, jnp.zeros_like(i)),
                                lambda s: s.replace(point=nxt), s)

        def restart(s):
            return self._start(s, i, s.restart + 1)

        def backtrack(s):
            # the k-th backtrack in a row from the same point goes k points back:
            # re-evolving only the previous point rarely changes what is left
            # (which squares remain unpainted, where the arm stands)
            depth = jnp.where(s.stuck == i, s.depth + 1, 1)
            s = s.replace(backtracks=s.backtracks + 1, stuck=i, depth=depth)
            return self._start(s, jnp.maximum(i - depth, 0), jnp.zeros_like(i))

        def stop(s):  # nothing valid to commit: every candidate diverged
            return s.replace(stopped=jnp.asarray(True))

        fallback = jnp.where(found, 0, 3)
        branch = jnp.where(met, 0, jnp.where(can_restart, 1,
                                             jnp.where(can_backtrack, 2, fallback)))
        return jax.lax.switch(branch, [commit, restart, backtrack, stop], s)

    def step(self, s: IETState):
        finished = self.done(s)
        p = jnp.minimum(s.point, self.n_points - 1)
        prefix_sq = s.prefix_sq[p]
        if self.feasibility is None:
            fit = self._fitness(tree_at(s.sim_states, p), prefix_sq, s.point)
            evo, metrics = self.evolve(s.evo, fit, self._stop(prefix_sq))
            new = s.replace(evo=evo)
        else:  # keep the move violation of the evolution's best
            new, metrics = self._judged_step(s, p, prefix_sq)
            evo = new.evo
        new = jax.lax.cond(evo.done, self._end_evolution, lambda x: x, new)
        new = freeze(finished, s, new)
        # which evolution (point, try) this generation belongs to
        metrics = {"best_fitness": metrics["best_fitness"],
                   "invalid": metrics["invalid"],
                   "point": jnp.where(finished, -1, s.point),
                   "try": s.tries[p] - 1}
        return new, metrics

    def _judged_step(self, s: IETState, p, prefix_sq):
        """With feasibility: one generation (ask, one batched evaluation, tell)
        that also keeps its best's move violation (``evo_violation``)."""
        state = tree_at(s.sim_states, p)
        pop, algo_state = evolution_ask(self.algo, self.params, s.evo)
        feats, violation = self.sharded(lambda u: self.point_outcome(state, u))(pop)
        fitness = self.outcome_fitness(state, pop, feats, violation,
                                       self._goal(s.point), prefix_sq)
        evo, metrics = evolution_tell(self.algo, self.params, s.evo, pop, algo_state,
                                      fitness, self._stop(prefix_sq))
        kept = jnp.where(metrics["improved"], violation[metrics["best_index"]],
                         s.evo_violation)
        return s.replace(evo=evo, evo_violation=kept), metrics

    def done(self, s):
        return (s.point >= self.n_points) | s.stopped

    def progress(self, s):
        running = np.where(np.asarray(self.done(s)), 0, np.asarray(s.evo.generation))
        return {  # generations: summed over the points, as the result's
            "generations": (np.asarray(s.point_generations).sum(-1) + running).tolist(),
            "point": np.asarray(s.point).tolist(),
                "backtracks": np.asarray(s.backtracks).tolist()}

    def finish(self, s):
        # points never committed (a stopped run) have no posture: NaN
        committed = jnp.arange(self.n_points) < s.point
        joints = jnp.where(committed[:, None], s.joints, jnp.nan)
        if self.feasibility is None:
            executed = self.execution(joints)
        else:  # the committed moves' violations, judged when they were evaluated
            done = jnp.all(committed)
            executed = {
                "joints": joints, "features": self.executed_features(joints),
                "violation": jnp.where(done, jnp.sum(s.violations), jnp.nan),
                "judged": ~done | jnp.all(jnp.isfinite(s.violations))}
        return {
            **executed,
            "carried_features": s.features,
            "point": s.point,
            "tries": s.tries,
            "backtracks": s.backtracks,
            "point_fitness": s.point_fitness,
            "point_generations": s.point_generations,
            "point_evaluations": s.point_evaluations,
            "point_invalid": s.point_invalid,
            "stopped": s.stopped,
        }

    def to_result(self, final, history, timing):
        final = self.rejudge(final)
        # each point's history: the generations of its last (committed) evolution
        last_try = final["tries"] - 1
        hist = ragged_rows([
            history["best_fitness"][(history["point"] == i) & (history["try"] == t)]
            for i, t in enumerate(last_try)
        ])
        gens = final["point_generations"]
        n_done = min(int(final["point"]), self.n_points)
        return self.result(
            final, timing,
            fitness_history=hist,
            evaluations=final["point_evaluations"].sum(),
            generations=gens.sum(),
            final_fitness=np.linalg.norm(final["features"] - np.asarray(self.goal)),
            complete=int(final["point"]) >= self.n_points,
            invalid_evaluations=final["point_invalid"].sum(),
            point_invalid=final["point_invalid"].tolist(),
            points_without_valid=[n_done] if bool(final["stopped"]) else [],
            restarts=self.restarts,
            warm_start=self.warm_start,
            stagnation=self.stagnation,
            backtracks=self.backtracks,
            backtracks_used=int(final["backtracks"]),
            point_tries=final["tries"].tolist(),
            point_generations=gens.tolist(),
            point_evaluations=final["point_evaluations"].tolist(),
            point_fitness=final["point_fitness"].tolist(),
            try_best_fitness=[
                [float(np.min(history["best_fitness"][(history["point"] == i)
                                                      & (history["try"] == t)],
                              initial=np.inf))
                 for t in range(n_tries)]
                for i, n_tries in enumerate(final["tries"])
            ],
            carried_matches_rollout=bool(
                np.allclose(final["carried_features"][:n_done],
                            final["features"][:n_done], atol=1e-4)
            ),
        )
