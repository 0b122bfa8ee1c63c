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
from the same pool; `cgda_jax.strategies.seeding`), "reach" (the 8 nearest samples of
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
    points_independent,
)
from cgda_jax.strategies.fte_starts import first_mean, restart_mean, start_pool
from cgda_jax.strategies.refine import REFINE, polish_trajectory
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import run

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
    done: jax.Array


class FTEPlan(PlanBase):
    """FTE as a plan for `runner.drive`.

    Args (beyond `PlanBase`'s):
        stagnation: a try stops after this many generations without improvement.
        distance: fitness name or callable (see `resolve_distance`).
        restarts, min_improvement, init, init_samples, init_std, refine,
            refine_steps, refine_gamma: see `run_fte`.
    """

    name = "fte"

    def __init__(self, sim, goal, *, stagnation=10, distance=None, restarts=0,
                 min_improvement=0.0, init="middle", init_samples=INIT_SAMPLES,
                 init_std=INIT_STD, refine="none", refine_steps=100,
                 refine_gamma=REFINE_GAMMA, **kwargs):
        if stagnation is None:
            raise ValueError("FTE needs stagnation (a whole number >= 1); got None")
        if int(restarts) < 0:
            raise ValueError(f"restarts must be >= 0; got {restarts}")
        if not 0 <= float(min_improvement) < 1:
            raise ValueError(f"min_improvement must be in [0, 1); got {min_improvement}")
        if init not in INITS:
            raise ValueError(f"init={init!r}; expected one of {list(INITS)}")
        if init == "auto":
            init = "reach" if points_independent(sim) else "sampled"
        if init == "reach" and not points_independent(sim):
            raise ValueError(
                "init='reach' needs a differentiable execution: kinematic mode and a "
                f"scene without state (e.g. the marker); this simulator is "
                f"{getattr(sim, 'mode', '?')} with {type(sim.scene).__name__}; use "
                "init='sampled'")
        if int(init_samples) < 1:
            raise ValueError(f"init_samples must be >= 1; got {init_samples}")
        if init_std is not None and not float(init_std) > 0:
            raise ValueError(f"init_std must be > 0 or None; got {init_std}")
        if refine not in REFINE:
            raise ValueError(f"refine={refine!r}; expected one of {list(REFINE)}")
        if refine != "none" and not points_independent(sim):
            raise ValueError(
                "refine needs a differentiable execution: kinematic mode and a scene "
                f"without state (e.g. the marker); this simulator is "
                f"{getattr(sim, 'mode', '?')} with {type(sim.scene).__name__}")
        if not float(refine_gamma) > 0 or int(refine_steps) < 1:
            raise ValueError(f"refine_gamma must be > 0 and refine_steps >= 1; got "
                             f"{refine_gamma}, {refine_steps}")
        user_params = dict(kwargs.get("algorithm_params") or {})
        info = {**(kwargs.pop("info", None) or {}), "init": init, "refine": refine}
        super().__init__(sim, goal, goal.shape[0] * int(sim.n_dof), info=info,
                         stagnation=stagnation, **kwargs)
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

    # ---- fitness and execution
    def _trajectory(self, u_flat):
        return self.joints(u_flat.reshape(self.n_points, self.n_dof))

    def _fitness(self, pop):
        out = self.map_population(lambda u: self.execution(self._trajectory(u)), pop)
        f = jax.vmap(lambda f: self.distance(f, self.goal))(out["features"])
        return self.penalize(f, out.get("violation"))

    def _errors(self, u_flat):
        """(N,) pointwise errors of executing `u_flat` (inf where not finite)."""
        feats = self.executed_features(self._trajectory(u_flat))
        e = jnp.linalg.norm(feats - self.goal, axis=-1)
        return jnp.where(jnp.isfinite(e), e, jnp.inf)

    # ---- tries
    def _start(self, key, mean, params):
        """A try from `mean`; a mean other than the middle is evaluated too (one
        more evaluation) and is the try's first best when valid."""
        fitness = self.sharded(self._fitness)
        evo = evolution_init(self.algo, params, key, fitness, self.n_genes, mean=mean)
        if mean is None:
            return evo
        # one execution, not a population (no batched simulator call)
        out = self.execution(self._trajectory(mean))
        f = self.penalize(self.distance(out["features"], self.goal),
                          out.get("violation"))
        take = jnp.isfinite(f) & (f < evo.best_fitness)
        return evo.replace(
            best_u=jnp.where(take, mean, evo.best_u),
            best_fitness=jnp.where(take, f, evo.best_fitness).astype(jnp.float32),
            evaluations=evo.evaluations + 1,
            invalid=evo.invalid + (~jnp.isfinite(f)).astype(jnp.int32))

    def _restart(self, s: FTEState) -> Evolution:
        mean, key = restart_mean(self, s)
        return self._start(key, mean, self.try_params)

    def _met(self, errors):
        return jnp.all(errors < self.aim_tolerance)

    # ---- plan functions
    def init(self, key):
        pool_u, pool_f, cand_u, cand_err, evals, bad = start_pool(self, key)
        zero = jnp.zeros((), jnp.int32)
        s = FTEState(
            evo=None, key=key, tries=zero + 1, ref=None, stall=zero, best_u=None,
            best_fitness=None, best_errors=None, generations=zero,
            evaluations=evals, invalid=bad, pool_u=pool_u, pool_f=pool_f,
            cand_u=cand_u, cand_err=cand_err, done=jnp.asarray(False))
        mean = first_mean(self, s)
        evo = self._start(key, mean, self.params if mean is None else self.try_params)
        errors = jnp.where(evo.found, self._errors(evo.best_u), jnp.inf)
        errors = jnp.broadcast_to(errors, (self.n_points,))
        return s.replace(evo=evo, ref=jnp.max(errors), best_u=evo.best_u,
                         best_fitness=evo.best_fitness, best_errors=errors,
                         done=(self.restarts > 0) & self._met(errors))

    def step(self, s: FTEState):
        left = self.max_generations - s.generations
        evo, metrics = self.evolve(s.evo, self._fitness,
                                   lambda e: e.generation >= left)
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
                        done=done)

        def restart(n: FTEState) -> FTEState:
            return n.replace(
                evo=self._restart(n), tries=n.tries + 1,
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


def run_fte(
    sim: Any,
    goal: Any,
    *,
    algorithm: Any = "CMA_ES",
    population_size: int = 32,
    tolerance: float = 0.02,
    stagnation: int = 10,
    aim: float = 1.0,
    max_generations: int = 500,
    seed: int = 0,
    chunk_size: int = 10,
    distance: str | Callable[[jax.Array, jax.Array], jax.Array] | None = None,
    restarts: int = RESTARTS,
    min_improvement: float = MIN_IMPROVEMENT,
    init: str = INIT,
    init_samples: int = INIT_SAMPLES,
    init_std: float | None = INIT_STD,
    refine: str = "none",
    refine_steps: int = 100,
    refine_gamma: float = REFINE_GAMMA,
    algorithm_kwargs: dict | None = None,
    algorithm_params: dict | None = None,
    progress_fn: Callable[[dict], None] | None = None,
    devices: int | str | None = None,
) -> ExecutionResult:
    """Full Trajectory Evolution of a goal feature trajectory.

    The paper's FTE is ``restarts=0, min_improvement=0, init="middle"``; the defaults
    add restarts and a sampled start (see the module docstring).

    Args:
        sim: a simulator (see `run_ie`).
        goal: goal feature trajectory (N, F).
        algorithm, population_size, seed, chunk_size, algorithm_kwargs,
            algorithm_params, progress_fn, devices: as in `run_ie`.
        tolerance: success threshold on every point's executed error. Without
            restarts FTE does not stop on it (it stops on stagnation); with restarts
            the run ends once the best trajectory meets it at every point, and a try
            that stagnated short of it is restarted.
        stagnation: a try stops after this many generations without improvement
            (paper: 10).
        max_generations: generation budget, shared by all tries.
        distance: fitness: "dtw" (default, the paper's per-dimension DTW),
            "dtw_multi" (the authors' C++ fitness), "euclidean", or a callable
            ``(executed (N, F), goal (N, F)) -> scalar``.
        restarts: tries after the first (inside the compiled step): odd ones repair
            the best trajectory's missed points with fresh postures, even ones start
            wholly fresh; ``info["tries"]`` says how many ran.
        min_improvement: with restarts, a try also stops after `stagnation`
            generations in which the worst point error of its best trajectory did
            not drop by more than this fraction (the DTW fitness may keep creeping
            down while one point sits in a local minimum).
        init: first mean: "middle" (the paper), "start" (the start posture at
            every point) or "sampled" (nearest of `init_samples` random postures to
            each goal point; these evaluations count in ``evaluations``).
        init_samples: random postures sampled per sampled start.
        init_std: initial step size of tries that start elsewhere than the middle
            (algorithms with ``std_init``, unless `algorithm_params` sets it).
            None: 0.01 after init "reach" (the mean is already near a solution),
            else 0.08.
        refine: "none", "adam" or "lbfgs": polish the best trajectory by descending
            the soft-DTW to the goal through the kinematic chain, keeping the
            iterate with the lowest true `distance` (never worse). Needs kinematic
            mode and a stateless scene. ``info["evolved_fitness"]`` is the fitness
            before the polish.
        refine_steps: optimiser steps of the polish.
        refine_gamma: soft-DTW smoothing of the polish (feature units).
        aim: the share of the tolerance each point's evolution aims for, in
            (0, 1]: it stops, restarts and ranks by least motion at
            ``aim * tolerance``; the run is still judged at ``tolerance``.  Below 1
            it leaves room for a finer replay, the exported trajectory or a robot
            to differ a little (1: the paper's rule, anything within tolerance).

    Returns:
        `ExecutionResult`; final_fitness is the best fitness (`distance`), success =
        every point's error < tolerance.
    """
    (result,) = run(
        FTEPlan, sim, goal, [seed], algorithm=algorithm,
        population_size=population_size, tolerance=tolerance,
        max_generations=max_generations, chunk_size=chunk_size,
        algorithm_kwargs=algorithm_kwargs, algorithm_params=algorithm_params,
        stagnation=stagnation, distance=distance, restarts=restarts,
        min_improvement=min_improvement, init=init, init_samples=init_samples,
        init_std=init_std, refine=refine, refine_steps=refine_steps,
        refine_gamma=refine_gamma, aim=aim, progress_fn=progress_fn,
        devices=devices,
    )
    return result
