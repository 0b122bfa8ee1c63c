"""Full Trajectory Evolution (FTE, paper 3.1): one evolution over all N x DoF genes.

Each individual is a whole joint trajectory; it is executed from the start state and its
fitness is the DTW discrepancy (`cgda_jax.dtw`) between the executed and the goal
feature trajectories. With the paper's settings (``restarts=0, init="middle",
min_improvement=0``) the evolution starts at the middle of the joint ranges and stops
after `stagnation` generations without improvement (paper: 10) or at
`max_generations`.

Restarts (IPOP-like, new means; all inside the compiled step, traced counters). With
restarts a try also stops when the worst point error of its best trajectory has not
improved by more than `min_improvement` (relative) for `stagnation` generations (the
DTW fitness keeps creeping down while one point sits in a wrong inverse-kinematics
basin). If the best trajectory so far misses the tolerance at
some point, a new try starts with a fresh key, while tries and the generation budget
(`max_generations`, shared by all tries) are left. Odd tries *repair* the best
trajectory (its points that miss the tolerance get a freshly sampled posture, the
others keep theirs); even tries start from a wholly fresh sampled trajectory. A
sampled posture for a missed point is taken away (in gene space) from the posture it
stuck at, so the restart leaves that basin. The best
over every try is kept; with restarts the run ends as soon as it meets the tolerance
at every point (the pointwise success test, one rollout of the best per generation).
The population size stays fixed: evosax algorithms build their recombination weights
and state shapes for one population size, so a growing population would need several
compiled algorithms or masked weights that distort CMA-ES's update; new means with a
fresh step size keep every shape static and, on these goals, are what escapes a
wrong inverse-kinematics branch.

Initialisation (``init``): "middle" (u = 0, the paper), "start" (the start posture at
every point), "sampled" (for every goal point the nearest of `init_samples` random
postures, executed once per run in batches of the population size; restarts draw
from the same pool; `cgda_jax.strategies.refine`), "reach" (the 8 nearest samples of
every point descended by gradient on its error, as `refine.reachability` does; the
best candidate per point is the first mean, restarts draw other candidates; needs a
differentiable execution: kinematic mode, stateless scene) or "auto" (default:
"reach" where possible, else "sampled"). A start mean other than the middle is
evaluated (one execution), so a sound start is already a candidate.
Means other than the middle start with step size `init_std` (distribution-based
algorithms; population-based ones draw their own uniform population).

Polish (``refine``): "adam" or "lbfgs" descend the soft-DTW (`cgda_jax.soft_dtw`,
`refine_gamma`) between executed features and goal through the differentiable
kinematic chain from the best trajectory, keeping the iterate with the lowest true
FTE distance (never worse; `cgda_jax.strategies.refine.polish_trajectory`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from cgda_jax.strategies.base import (
    Evolution,
    PlanBase,
    evolution_init,
    freeze,
    from_joints,
    points_independent,
)
from cgda_jax.strategies.evolution import evolution_ask, evolution_tell
from cgda_jax.strategies.fitness import (
    distances,
    judge_best,
    judged_round,
    polish_loss,
    polish_penalty,
)
from cgda_jax.strategies.refine import (
    REFINE,
    descended_candidates,
    nearest_in_pool,
    pick_candidate,
    polish_trajectory,
    sample_pool,
)
from cgda_jax.strategies.settings import Settings, option

#: Sampled postures descended per goal point (init "reach").
REACH_STARTS = 8
#: Adam steps of that descent (redundant 6-7 joint arms need more than 60).
REACH_STEPS = 200
_SAMPLE_SALT = 0x5EED  # key of the pool: fold_in(key, salt)


#: Fitness names accepted by ``distance=``.
DISTANCES = ("dtw", "dtw_multi", "euclidean")
#: Start means accepted by ``init=``.
INITS = ("auto", "middle", "start", "sampled", "reach")
#: Defaults of `run_fte` beyond the paper's (see the module docstring).
RESTARTS = 8
MIN_IMPROVEMENT = 0.05
INIT = "auto"
INIT_SAMPLES = 2048
INIT_STD = None
#: Step size of tries from a mean other than the middle, per init mode (init_std None).
MODE_STD = {"start": 0.08, "sampled": 0.08, "reach": 0.01}
REFINE_GAMMA = 1e-3



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


@struct.dataclass
class FTEState:
    """Carry of an FTE run.

    Attributes:
        evo: the current try.
        key: the run's key; try t > 0 uses ``fold_in(key, t)``.
        tries: tries started (1 + restarts used).
        ref, stall: the worst point error of the try's best at its last
            improvement by more than `min_improvement` (relative), and the
            generations since (with restarts a try also stops on this stall).
        best_u, best_fitness: the best over every try (inf: nothing valid yet).
        best_errors: (N,) pointwise errors of the best trajectory's execution.
        generations, evaluations, invalid: spent by the finished tries (and the
            sampled pool).
        pool_u, pool_f: the sampled postures (S, D) and their features (S, F)
            (init "sampled"; else empty).
        cand_u, cand_err: per point, the descended candidate postures (N, K, D)
            and their errors (N, K) (init "reach"; else empty).
        pending: the try's start mean (its ``evo.best_u``) is not evaluated
            yet: it is, with the try's first generation (`FTEPlan.mean_later`).
        done: the run is finished.
    """

    evo: Evolution
    key: jax.Array
    tries: jax.Array
    ref: jax.Array
    stall: jax.Array
    best_u: jax.Array
    best_fitness: jax.Array
    best_errors: jax.Array
    generations: jax.Array
    evaluations: jax.Array
    invalid: jax.Array
    pool_u: jax.Array
    pool_f: jax.Array
    cand_u: jax.Array
    cand_err: jax.Array
    pending: jax.Array
    done: jax.Array


@dataclasses.dataclass(frozen=True, kw_only=True)
class FTESettings(Settings):
    """FTE's settings (beyond `Settings`'s; its own defaults: population_size 32,
    max_generations 500, the budget shared by all tries). The paper's FTE is
    ``restarts=0, min_improvement=0, init="middle"``; the defaults add restarts
    and a sampled start (see the module docstring).

    ``tolerance``: success threshold on every point's executed error. Without
    restarts FTE does not stop on it (it stops on stagnation); with restarts the
    run ends once the best trajectory meets it at every point, and a try that
    stagnated short of it is restarted.

    Attributes:
        stagnation: a try stops after this many generations without improvement
            (paper: 10).
        distance: fitness (`resolve_distance`): "dtw" (None, the default: the
            paper's per-dimension DTW), "dtw_multi" (the authors' C++ fitness),
            "euclidean", or (Python callers) a callable
            ``(executed (N, F), goal (N, F)) -> scalar``.
        restarts: tries after the first (inside the compiled step): odd ones repair
            the best trajectory's missed points with fresh postures, even ones start
            wholly fresh; ``info["tries"]`` says how many ran.
        min_improvement: with restarts, a try also stops after `stagnation`
            generations in which the worst point error of its best trajectory did
            not drop by more than this fraction (the DTW fitness may keep creeping
            down while one point sits in a local minimum).
        init: first mean (`INITS`): "middle" (the paper), "start" (the start
            posture at every point), "sampled" (nearest of `init_samples` random
            postures to each goal point; these evaluations count in
            ``evaluations``), "reach" (the nearest samples descended by gradient;
            kinematic mode, stateless scene) or "auto" ("reach" where possible,
            else "sampled").
        init_samples: random postures sampled per sampled start.
        init_std: initial step size of tries that start elsewhere than the middle
            (algorithms with ``std_init``, unless `algorithm_params` sets it).
            None: 0.01 after init "reach" (the mean is already near a solution),
            else 0.08 (`MODE_STD`).
        refine: "none", "adam" or "lbfgs": polish the best trajectory by descending
            the soft-DTW to the goal through the kinematic chain, keeping the
            iterate with the lowest true `distance` (never worse). Needs kinematic
            mode and a stateless scene. ``info["evolved_fitness"]`` is the fitness
            before the polish.
        refine_steps: optimiser steps of the polish.
        refine_gamma: soft-DTW smoothing of the polish (feature units).
    """

    population_size: int = option(32, "int", 1)
    max_generations: int = option(500, "int", 1)
    stagnation: int = option(10, "int", 1)
    distance: str | Callable | None = option(None, "choice", DISTANCES, none=True,
                                             callables=True)
    restarts: int = option(RESTARTS, "int", 0)
    min_improvement: float = option(MIN_IMPROVEMENT, "number", "in [0, 1)")
    init: str = option(INIT, "choice", INITS)
    init_samples: int = option(INIT_SAMPLES, "int", 1)
    init_std: float | None = option(INIT_STD, "number", "> 0", none=True)
    refine: str = option("none", "choice", REFINE)
    refine_steps: int = option(100, "int", 1)
    refine_gamma: float = option(REFINE_GAMMA, "number", "> 0")


class FTEPlan(PlanBase):
    """FTE as a plan for `runner.drive`, built from `FTESettings` (or its fields
    as keywords, changing the defaults); ``info``, ``sharding``: see `PlanBase`.
    """

    name = "fte"

    def __init__(self, sim, goal, settings: FTESettings | None = None, *,
                 info=None, sharding=None, **changes):
        st = FTESettings.of(settings, **changes)
        refine, distance = st.refine, st.distance
        init = self.start_mode(st.init, sim)
        if init == "reach" and not points_independent(sim):
            raise ValueError(
                "init='reach' needs a differentiable execution: kinematic mode and a "
                f"scene without state (e.g. the marker); this simulator is "
                f"{getattr(sim, 'mode', '?')} with {type(sim.scene).__name__}; use "
                "init='sampled'")
        if refine != "none" and not points_independent(sim):
            raise ValueError(
                "refine needs a differentiable execution: kinematic mode and a scene "
                f"without state (e.g. the marker); this simulator is "
                f"{getattr(sim, 'mode', '?')} with {type(sim.scene).__name__}")
        user_params = dict(st.algorithm_params or {})
        info = {**(info or {}), "init": init, "refine": refine}
        super().__init__(sim, goal, goal.shape[0] * int(sim.n_dof), st, info=info,
                         sharding=sharding)
        restarts, min_improvement = st.restarts, st.min_improvement
        init_samples, init_std = st.init_samples, st.init_std
        refine_steps, refine_gamma = st.refine_steps, st.refine_gamma
        self.distance_name = distance if isinstance(distance, str) else None
        self.distance = resolve_distance(distance)
        self.restarts = int(restarts)
        self.min_improvement = float(min_improvement)
        self.init_mode, self.init_samples = init, int(init_samples)
        self.refine, self.refine_steps = refine, int(refine_steps)
        self.refine_gamma = float(refine_gamma)
        # a mean that is not the middle: a smaller first step size, unless set
        self.try_params = self.params
        fields = getattr(self.params, "__dataclass_fields__", {})
        std = MODE_STD.get(init, 0.08) if init_std is None else float(init_std)
        if "std_init" in fields and "std_init" not in user_params:
            self.try_params = self.params.replace(std_init=jnp.asarray(std))

    @staticmethod
    def start_mode(init: str, sim) -> str:
        """``init`` with "auto" resolved: "reach" with independent points, else
        "sampled"."""
        if init == "auto":
            return "reach" if points_independent(sim) else "sampled"
        return init

    @classmethod
    def sampled_postures(cls, settings: FTESettings, sim) -> tuple[int, str]:
        """``init_samples`` when the start samples postures ("sampled", "reach"),
        else none (see `PlanBase.sampled_postures`)."""
        sampled = cls.start_mode(settings.init, sim) in ("sampled", "reach")
        return int(settings.init_samples) if sampled else 0, "init_samples"

    # ---- fitness and execution
    def _trajectory(self, u_flat):
        return self.joints(u_flat.reshape(self.n_points, self.n_dof))

    def _fitness(self, pop, lead: int = 0):
        """Fitness (P,) of the trajectories ``pop`` (P, N * D); with ``lead``
        (judged apart only) the first is a move set judged whatever its rank
        (`judge_best`'s lead: a restart's mean)."""
        if not self.moves_apart:
            out = self.map_population(lambda u: self.execution(self._trajectory(u)),
                                      pop)
            f = jax.vmap(lambda f: self.distance(f, self.goal))(out["features"])
            return self.penalize(f, out.get("violation"))
        (before, after), feats = self.map_population(self._moves, pop)
        f = jax.vmap(lambda f: self.distance(f, self.goal))(feats)

        def judge(idx, need):
            # the picked trajectories' moves, judged together
            v = jax.vmap(self.sim.judge_moves)(
                jax.tree.map(lambda x: x[idx], before),
                jax.tree.map(lambda x: x[idx], after),
                jnp.broadcast_to(need[:, None], (need.shape[0], self.n_points)))
            # summed move by move, in order, as the judged rollout sums them
            return jax.lax.scan(lambda c, x: (c + x, None),
                                jnp.zeros(v.shape[:1], v.dtype), v.T)[0]

        if self.judge_ranks is None:
            every = jnp.arange(f.shape[0], dtype=jnp.int32)
            return self.penalize(f, judge(every, jnp.ones(every.shape, bool)))
        return judge_best(f, judge, self.feasibility.penalty, self.judge_ranks,
                          judged_round(self.judge_ranks), lead=lead)[0]

    @property
    def mean_later(self) -> bool:
        """A restart's start mean is evaluated with its try's first generation,
        in the same call of the check (`judge_best`'s lead), not at the restart
        (a second copy of the check in the generation program): judged apart,
        unsharded."""
        return self.moves_apart and self.sharding is None

    @property
    def moves_apart(self) -> bool:
        """A generation's moves judged apart from their execution, together
        (`Simulator.judge_moves`; with ``judge = "ranked"`` only the
        trajectories whose rank matters, `judge_best`): kinematic mode with
        feasibility.  Else every candidate's execution judges its moves."""
        return (self.feasibility is not None and hasattr(self.sim, "judge_moves")
                and getattr(self.sim, "mode", "kinematic") == "kinematic")

    def _moves(self, u_flat):
        """The trajectory's moves, unjudged: the states before and after each
        (N stacked each) and the features (N, F)."""

        def one(state, w):
            new, feats = self.advance(state, w)
            return new, (state, new, feats)

        _, (before, after, feats) = jax.lax.scan(one, self.sim.init_state(),
                                                 self._trajectory(u_flat))
        return (before, after), feats

    def _errors(self, u_flat):
        """(N,) pointwise errors of executing `u_flat` (inf where not finite)."""
        feats = self.executed_features(self._trajectory(u_flat))
        e = distances(feats, self.goal)
        return jnp.where(jnp.isfinite(e), e, jnp.inf)

    # ---- tries
    def _start(self, key, mean, params, evaluate: bool = True):
        """A try from `mean`; a mean other than the middle is evaluated too (one
        more evaluation; ``evaluate=False``: later, `took`) and is the try's
        first best when valid."""
        fitness = self.sharded(self._fitness)
        evo = evolution_init(self.algo, params, key, fitness, self.n_genes, mean=mean)
        if mean is None or not evaluate:
            return evo
        # one execution, not a population (no batched simulator call)
        out = self.execution(self._trajectory(mean))
        f = self.penalize(self.distance(out["features"], self.goal),
                          out.get("violation"))
        return self.took(evo, mean, f)

    @staticmethod
    def took(evo: Evolution, mean, f) -> Evolution:
        """``evo`` with its start ``mean``'s fitness ``f`` told: the first best
        when valid, one more evaluation."""
        take = jnp.isfinite(f) & (f < evo.best_fitness)
        return evo.replace(
            best_u=jnp.where(take, mean, evo.best_u),
            best_fitness=jnp.where(take, f, evo.best_fitness).astype(jnp.float32),
            evaluations=evo.evaluations + 1,
            invalid=evo.invalid + (~jnp.isfinite(f)).astype(jnp.int32))

    def _restart(self, s: FTEState) -> Evolution:
        mean, key = self.restart_mean(s)
        return self._start(key, mean, self.try_params, evaluate=not self.mean_later)

    def _met(self, errors):
        return jnp.all(errors < self.aim_tolerance)

    # ---- start means: the sampled pool, the descended candidates, restart means
    def start_pool(self, key: jax.Array) -> tuple:
        """The sampled postures of a run and, for init "reach", the descended
        candidates of every point (empty arrays where unused), and the
        evaluations spent (count, invalid)."""
        zero = jnp.zeros((), jnp.int32)
        f_dim = self.goal.shape[1]
        empty = (jnp.zeros((0, self.n_dof)), jnp.zeros((0, f_dim)),
                 jnp.zeros((self.n_points, 0, self.n_dof)),
                 jnp.zeros((self.n_points, 0)))
        if self.init_mode not in ("sampled", "reach"):
            return (*empty, zero, zero)
        state = self.sim.init_state()
        u, f, bad = sample_pool(
            jax.random.fold_in(key, _SAMPLE_SALT),
            lambda x: self.point_features(state, x), self.n_dof, self.init_samples,
            batch=self.algo.population_size)
        evals = jnp.asarray(u.shape[0], jnp.int32)
        if self.init_mode == "sampled":
            return (u, f, *empty[2:], evals, bad)
        # the moves' penalties taken after the descent, every iterate's at once
        penalty = polish_penalty(self.sim, state, self.lower, self.upper)
        cand_u, cand_err = descended_candidates(
            u, f, self.goal,
            lambda g: polish_loss(self.sim, state, g, self.lower, self.upper,
                                  judge=penalty is None),
            n_starts=REACH_STARTS, steps=REACH_STEPS, penalty=penalty)
        return (*empty[:2], cand_u, cand_err, evals, bad)


    def first_mean(self, s: FTEState) -> jax.Array | None:
        """The first try's mean (N * D,) of the plan's init mode (None: the middle)."""
        if self.init_mode == "middle":
            return None
        if self.init_mode == "start":
            q0 = self.sim.init_state().genes
            u0 = from_joints(jnp.asarray(q0, jnp.float32), self.lower, self.upper)
            return jnp.tile(u0, self.n_points)
        if self.init_mode == "reach":
            i = jnp.argmin(s.cand_err, axis=1)
            return jnp.take_along_axis(s.cand_u, i[:, None, None], axis=1).reshape(-1)
        genes, _ = nearest_in_pool(s.pool_u, s.pool_f, self.goal)
        return genes.reshape(-1)


    def restart_mean(self, s: FTEState) -> tuple[jax.Array, jax.Array]:
        """The mean (N * D,) and key of try ``s.tries``.

        Odd tries repair the best trajectory (its points that miss the tolerance get
        fresh postures), even ones start wholly fresh. Fresh postures: init "reach", a
        random descended candidate within tolerance, away from the posture the point
        stuck at (`pick_candidate`); "sampled", the nearest of a random half of the
        pool, away from it (`nearest_in_pool`); otherwise uniform random.
        """
        t = s.tries
        k_mean, k_evo = jax.random.split(jax.random.fold_in(s.key, t))
        best = s.best_u.reshape(self.n_points, self.n_dof)
        miss = ~(s.best_errors < self.aim_tolerance)
        avoid = jnp.where((miss & jnp.isfinite(s.best_fitness))[:, None], best,
                          jnp.nan)
        if self.init_mode == "reach":
            fresh = pick_candidate(k_mean, s.cand_u, s.cand_err, self.aim_tolerance,
                                   avoid)
        elif self.init_mode == "sampled":
            fresh, _ = nearest_in_pool(s.pool_u, s.pool_f, self.goal, key=k_mean,
                                       avoid=avoid)
        else:
            fresh = jax.random.uniform(k_mean, (self.n_points, self.n_dof),
                                       minval=-1.0, maxval=1.0)
        repair = jnp.where(miss[:, None], fresh, best)
        use = (t % 2 == 1) & jnp.isfinite(s.best_fitness)
        mean = jnp.where(use, repair, fresh).reshape(-1)
        return mean, k_evo

    # ---- plan functions
    def init(self, key):
        pool_u, pool_f, cand_u, cand_err, evals, bad = self.start_pool(key)
        zero = jnp.zeros((), jnp.int32)
        s = FTEState(
            evo=None, key=key, tries=zero + 1, ref=None, stall=zero, best_u=None,
            best_fitness=None, best_errors=None, generations=zero,
            evaluations=evals, invalid=bad, pool_u=pool_u, pool_f=pool_f,
            cand_u=cand_u, cand_err=cand_err, pending=jnp.asarray(False),
            done=jnp.asarray(False))
        mean = self.first_mean(s)
        evo = self._start(key, mean, self.params if mean is None else self.try_params)
        errors = jnp.where(evo.found, self._errors(evo.best_u), jnp.inf)
        errors = jnp.broadcast_to(errors, (self.n_points,))
        return s.replace(evo=evo, ref=jnp.max(errors), best_u=evo.best_u,
                         best_fitness=evo.best_fitness, best_errors=errors,
                         done=(self.restarts > 0) & self._met(errors))

    def step(self, s: FTEState):
        left = self.max_generations - s.generations
        stop = lambda e: e.generation >= left  # noqa: E731
        if self.mean_later:  # the try's pending start mean judged with it
            pop, algo_state = evolution_ask(self.algo, self.params, s.evo)
            f = self._fitness(jnp.concatenate([s.evo.best_u[None], pop]), lead=1)
            evo = jax.tree.map(lambda a, b: jnp.where(s.pending, a, b),
                               self.took(s.evo, s.evo.best_u, f[0]), s.evo)
            evo, metrics = evolution_tell(self.algo, self.params, evo, pop,
                                          algo_state, f[1:], stop)
        else:
            evo, metrics = self.evolve(s.evo, self._fitness, stop)
        better = evo.best_fitness < s.best_fitness
        errors = jax.lax.cond(better, lambda: self._errors(evo.best_u),
                              lambda: s.best_errors)
        best_u = jnp.where(better, evo.best_u, s.best_u)
        best_f = jnp.where(better, evo.best_fitness, s.best_fitness)
        # progress of this try on what success needs: the worst point error of its
        # best (relative; min_improvement = 0: any improvement)
        worst = jnp.max(jax.lax.cond(evo.best_fitness == best_f, lambda: errors,
                                     lambda: self._errors(evo.best_u)))
        gain = worst < s.ref * (1.0 - self.min_improvement)
        gain = gain | (jnp.isfinite(worst) & ~jnp.isfinite(s.ref))
        stall = jnp.where(gain, 0, s.stall + 1)
        ref = jnp.where(gain, worst, s.ref)
        met = self._met(errors) & (self.restarts > 0)
        try_end = evo.done | self.stalled(evo)
        if self.restarts > 0:
            try_end = try_end | (stall >= self.stagnation)
        spent = s.generations + evo.generation >= self.max_generations
        done = met | spent | (try_end & (s.tries > self.restarts))
        again = try_end & ~done
        new = s.replace(evo=evo.replace(done=evo.done | done), ref=ref, stall=stall,
                        best_u=best_u, best_fitness=best_f, best_errors=errors,
                        pending=jnp.asarray(False), done=done)

        def restart(n: FTEState) -> FTEState:
            return n.replace(
                evo=self._restart(n), tries=n.tries + 1,
                pending=jnp.asarray(self.mean_later),
                ref=jnp.asarray(jnp.inf, jnp.float32), stall=jnp.zeros_like(n.stall),
                generations=n.generations + n.evo.generation,
                evaluations=n.evaluations + n.evo.evaluations,
                invalid=n.invalid + n.evo.invalid)

        new = jax.lax.cond(again, restart, lambda n: n, new)
        new = freeze(s.done, s, new)
        return new, {"best_fitness": new.best_fitness, "invalid": metrics["invalid"],
                     "try": new.tries - 1}

    def done(self, s):
        return s.done

    def progress(self, s):
        return {"generations": np.asarray(s.generations + s.evo.generation).tolist(),
                "best_fitness": np.asarray(s.best_fitness).tolist(),
                "tries": np.asarray(s.tries).tolist()}

    def finish(self, s):
        found = jnp.isfinite(s.best_fitness)
        u, fitness = s.best_u, s.best_fitness
        if self.refine != "none":
            u, fitness = polish_trajectory(
                self.sim, u, self.goal, self.distance, method=self.refine,
                steps=self.refine_steps, gamma=self.refine_gamma,
                multi=self.distance_name == "dtw_multi")
            u = jnp.where(found, u, s.best_u)
            fitness = jnp.where(found, fitness, s.best_fitness)
        return {
            # NaN when nothing valid was found (the start mean was never evaluated)
            **self.execution(jnp.where(found, self._trajectory(u), jnp.nan)),
            "best_fitness": fitness,
            "evolved_fitness": s.best_fitness,
            "generation": s.generations + s.evo.generation,
            "evaluations": s.evaluations + s.evo.evaluations,
            "invalid": s.invalid + s.evo.invalid,
            "tries": s.tries,
        }

    def to_result(self, final, history, timing):
        gens = int(final["generation"])
        info = {}
        if self.refine != "none":
            info["evolved_fitness"] = float(final["evolved_fitness"])
        return self.result(
            final, timing,
            fitness_history=history["best_fitness"][:gens].astype(np.float64),
            evaluations=final["evaluations"],
            generations=gens,
            final_fitness=final["best_fitness"],
            stagnation=self.stagnation,
            restarts=self.restarts,
            tries=int(final["tries"]),
            min_improvement=self.min_improvement,
            invalid_evaluations=final["invalid"],
            points_without_valid=(
                [] if np.isfinite(final["best_fitness"]) else list(range(self.n_points))
            ),
            **info,
        )
