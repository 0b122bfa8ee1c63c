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

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from cgda_jax.strategies.base import (
    Evolution,
    PlanBase,
    freeze,
    from_joints,
    points_independent,
    ragged_rows,
)
from cgda_jax.strategies.evolution import evolution_ask, evolution_tell
from cgda_jax.strategies.fitness import squared_error, total_error
from cgda_jax.strategies.ie import (
    BACKTRACKS,
    LOCAL_STD,
    RESTART_SAMPLES,
    STAGNATION,
    IEPlan,
    backtrack_to,
)
from cgda_jax.strategies.refine import nearest_samples
from cgda_jax.strategies.settings import Settings, option

__all__ = ["BACKTRACKS", "LOCAL_STD", "RESTARTS", "RESTART_SAMPLES", "STAGNATION",
           "IETPlan", "IETSettings", "IETState", "tree_at", "tree_set"]

#: Default restarts of a point that missed its tolerance.  (Backtracks per run,
#: their rule, restart samples and their local search width: IE's,
#: `cgda_jax.strategies.ie`.)
RESTARTS = 6


@struct.dataclass
class IETState:
    """Carry of an IET run.

    Attributes:
        evo: evolution of the current point (one restart of it).
        key: the run's key; evolution ``t`` of point i uses
            ``fold_in(fold_in(key, i), t)``.
        point: index of the point being evolved (N once finished).
        tries: evolutions started so far per point (N,) (restarts and revisits after a
            backtrack); the next one of point i is number ``tries[i]``.
        restart: restarts of the current point since it was (re)entered.
        backtracks: backtracks spent.
        stuck, depth: the point that made the last backtrack and how many points
            back it went (a point that keeps missing goes back further each time).
        best_u, best_fitness: best genes / fitness over the tries of the current
            point since it was (re)entered (its restarts); the committed posture.
        sim_states: simulator state before each point (stacked, N + 1).
        prefix_sq: summed squared feature error of the frozen prefix before each point
            (N + 1,).
        joints: frozen postures (N, DoF); features: their features (N, F).
        point_fitness: fitness (Euclidean over points 0..i) at commit (N,).
        point_generations, point_evaluations: spent per point (N,), restarts and
            revisits included.
        point_invalid: how many of those evaluations were invalid (N,).
        stopped: the run stopped at `point`: none of its evolutions (restarts,
            backtracks) found a valid candidate, so there is no posture to commit.
        samples: (N, K, D) the sampled postures nearest each goal point (K = 0
            without restart samples), restart means.
        evo_violation, best_violation, violations: with feasibility, the move
            violations of ``evo``'s best, of ``best_u`` and of the committed
            postures (N,), from the evaluations that found them (NaN: not
            known, e.g. an initial population's best); None otherwise.
    """

    evo: Evolution
    key: jax.Array
    point: jax.Array
    tries: jax.Array
    restart: jax.Array
    backtracks: jax.Array
    stuck: jax.Array
    depth: jax.Array
    best_u: jax.Array
    best_fitness: jax.Array
    sim_states: Any
    prefix_sq: jax.Array
    joints: jax.Array
    features: jax.Array
    point_fitness: jax.Array
    point_generations: jax.Array
    point_evaluations: jax.Array
    point_invalid: jax.Array
    stopped: jax.Array
    samples: jax.Array
    evo_violation: jax.Array | None = None
    best_violation: jax.Array | None = None
    violations: jax.Array | None = None


def tree_at(tree: Any, i: jax.Array) -> Any:
    """Entry ``i`` of every leaf of a stacked pytree."""
    return jax.tree.map(lambda x: x[i], tree)


def tree_set(tree: Any, i: jax.Array, value: Any) -> Any:
    """A stacked pytree with entry ``i`` of every leaf replaced by ``value``'s."""
    return jax.tree.map(lambda x, v: x.at[i].set(v), tree, value)



@dataclasses.dataclass(frozen=True, kw_only=True)
class IETSettings(Settings):
    """IET's settings (beyond `Settings`'s; ``tolerance`` is epsilon of Algorithm 1,
    in feature units, e.g. percent painted; ``max_generations`` the budget of one
    evolution of a point).

    The evolution of point i minimizes the paper's fitness, the Euclidean distance
    of executed features 0..i to goal 0..i; it stops when point i's OWN error is
    below the aim (the frozen prefix adds a constant the point cannot change; with
    the whole-prefix rule one miss would make every later point spend its whole
    budget).

    Attributes:
        restarts: a point that missed epsilon after `max_generations` is evolved
            again with a fresh key, up to this many times: from the sampled
            postures nearest the goal point in turn (see `restart_samples`, with a
            local search width `LOCAL_STD`) or, without samples, a random start
            mean; the best over all restarts is kept.
        backtracks: a point that still missed after its restarts makes the run
            re-evolve the previous point (fresh key) and try again, up to this many
            times per run; the k-th backtrack in a row from the same point
            re-evolves the k previous points (`cgda_jax.strategies.ie.backtrack_to`,
            IE's rule too; escapes prefixes that leave no way to the goal, e.g.
            every remaining square only reachable by sweeping across another
            one). 0 restarts and 0 backtracks give the paper's plain
            Algorithm 1.
        warm_start: start each point's first evolution at the previous point's
            posture (point 0: the start posture) instead of the middle of the joint
            ranges; for goals reached by small continuous moves (pushing an object).
        restart_samples: postures sampled once per run (kinematic mode, stateless
            scene; one batched call inside the compiled init) whose nearest to each
            goal point seed its restarts t = 1..`restarts`; later tries (revisits
            after a backtrack) from random means. 0: random means.
        stagnation: an evolution of a point also stops after this many
            generations without improvement (None: only at `max_generations`), so
            a point stuck where it cannot meet epsilon restarts or backtracks
            early instead of spending its whole budget.
    """

    restarts: int = option(RESTARTS, "int", 0)
    backtracks: int = option(BACKTRACKS, "int", 0)
    warm_start: bool = option(False, "bool")
    restart_samples: int = option(RESTART_SAMPLES, "int", 0)
    stagnation: int | None = option(STAGNATION, "int", 1, none=True)


class IETPlan(PlanBase):
    """IET as a plan for `runner.drive`, built from `IETSettings` (or its fields
    as keywords, changing the defaults); ``info``, ``sharding``: see `PlanBase`.

    A point whose every evolution (restarts and backtracks included) found no valid
    candidate (every simulation diverged) is not committed: the run stops there
    (``info["points_without_valid"]``; it and the later points have NaN joints).
    """

    name = "iet"
    per_point = True

    def __init__(self, sim, goal, settings: IETSettings | None = None, *,
                 info=None, sharding=None, **changes):
        st = IETSettings.of(settings, **changes)
        super().__init__(sim, goal, int(sim.n_dof), st, info=info, sharding=sharding)
        restarts = st.restarts
        self.restart_samples = self.sampled_postures(st, sim)[0]
        self.n_nearest = min(self.restart_samples, int(restarts))
        self.restarts = int(restarts)
        self.backtracks = int(st.backtracks)
        self.warm_start = bool(st.warm_start)
        evolutions = self.n_points * (1 + self.restarts) * (1 + self.backtracks)
        self.max_generations_total = evolutions * self.max_generations

    @classmethod
    def sampled_postures(cls, settings: IETSettings, sim) -> tuple[int, str]:
        """IE's rule (`IEPlan.sampled_postures`)."""
        return IEPlan.sampled_postures(settings, sim)

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
        own_sq = squared_error(feats, self.goal[i])
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
            first, depth = backtrack_to(i, s.stuck, s.depth)
            s = s.replace(backtracks=s.backtracks + 1, stuck=i, depth=depth)
            return self._start(s, first, jnp.zeros_like(i))

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
        if self.judge_ranks is None:
            feats, violation = self.sharded(lambda u: self.point_outcome(state, u))(pop)
            fitness = self.outcome_fitness(state, pop, feats, violation,
                                           self._goal(s.point), prefix_sq)
        else:  # the best's move is judged (`ranked_outcome`)
            fitness, violation = self.ranked_outcome(state, pop, self._goal(s.point),
                                                     prefix_sq)
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
            final_fitness=total_error(final["features"], np.asarray(self.goal)),
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
