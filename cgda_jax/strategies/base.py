"""Shared machinery of the execution strategies: the plan base.

Every strategy (FTE, IE, IET, OET) runs one or more evolutions of the same kind: an
`evosax` algorithm (`cgda_jax.strategies.evolution`) asks for a population of gene
vectors, the whole population is executed in ONE batched simulator call, its fitness
against the goal is computed and told back (`cgda_jax.strategies.evolution`, which
also holds the gene bounds and the algorithms). This module holds what the plans
share: `PlanBase`; the names of `cgda_jax.strategies.evolution` and the checks before
a run (`cgda_jax.strategies.settings`) are re-exported here.

Divergence: see `cgda_jax.strategies.evolution`.

References:
    Lange, "evosax: JAX-based Evolution Strategies", GECCO 2023 companion.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from cgda_jax.numerics import exact_matmuls
from cgda_jax.sharding import shard_population
from cgda_jax.sim.description import setup_of
from cgda_jax.sizes import Estimate, sim_estimate
from cgda_jax.strategies.evolution import (
    ALGORITHMS as ALGORITHMS,
    INVALID_PENALTY as INVALID_PENALTY,
    Evolution as Evolution,
    FitnessFn as FitnessFn,
    algorithm_name as algorithm_name,
    default_kwargs,
    evolution_init as evolution_init,
    evolution_step as evolution_step,
    freeze as freeze,
    from_joints as from_joints,
    make_algorithm as make_algorithm,
    screen as screen,
    to_joints as to_joints,
)
from cgda_jax.strategies.fitness import (
    distances,
    judge_best,
    judged_round,
    penalized,
    point_fitness,
)
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.settings import (
    Settings,
    check_config as check_config,
    points_independent as points_independent,
)


#: The algorithms whose update reads only the ranks of a generation's fitness,
#: its best `num_elites` with positive weights (`PlanBase.judge_ranks`).
RANKED_ALGORITHMS = ("CMA_ES",)


def ragged_rows(rows: list[np.ndarray]) -> np.ndarray:
    """Stacks 1-D rows of different lengths into (len(rows), longest or 1), NaN-padded."""
    out = np.full((len(rows), max([len(r) for r in rows] + [1])), np.nan)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


class PlanBase:
    """Shared set-up and pieces of the strategy plans driven by `runner.drive`.

    A plan is built from an already checked goal (`check_config`) and its strategy's
    settings (`cgda_jax.strategies.settings.Settings`, checked when made; the plan
    checks only what needs the simulator); subclasses add the plan functions
    ``init``, ``step``, ``finish``, ``progress`` and ``to_result`` (see `runner`).

    With ``sharding`` (`cgda_jax.sharding.population_sharding`) every fitness
    evaluation, the one batched simulator call of a generation, has its population
    (P, ...) padded to a multiple of the device count and split over the devices
    (`cgda_jax.sharding.shard_population`); the rest of the step is unchanged.
    """

    name = "base"
    #: each goal point evolved on its own (IE, IET): a waypoint, a fitness row and
    #: an error per point; FTE evolves one whole trajectory, OET's rows are its steps
    per_point = False

    def __init__(
        self,
        sim: Any,
        goal: jax.Array,
        n_genes: int,
        settings: Settings,
        *,
        info: dict[str, Any] | None = None,
        sharding: NamedSharding | None = None,
    ):
        exact_matmuls()  # its programs: full float32 products on GPUs too
        self.settings = settings
        self.sim, self.goal = sim, goal
        self.sharding = sharding
        self.n_points = int(goal.shape[0])
        self.lower = jnp.asarray(sim.lower, jnp.float32)
        self.upper = jnp.asarray(sim.upper, jnp.float32)
        self.n_dof = int(sim.n_dof)
        self.n_genes = int(n_genes)
        self.tolerance = float(settings.tolerance)
        aim = float(settings.aim)
        #: what each point's evolution aims for: ``aim * tolerance``; the run is
        #: still judged at ``tolerance`` (the difference is room for a finer
        #: replay, the exported trajectory or a robot to differ a little)
        self.aim_tolerance = self.tolerance * aim
        self.max_generations = int(settings.max_generations)
        self.max_generations_total = self.max_generations
        stagnation = getattr(settings, "stagnation", None)
        self.stagnation = None if stagnation is None else int(stagnation)
        algorithm, population_size = settings.algorithm, settings.population_size
        kwargs = dict(settings.algorithm_kwargs or {})
        if isinstance(algorithm, (str, type)):  # built here: defaults that fit genes
            kwargs = {**default_kwargs(algorithm_name(algorithm)), **kwargs}
        self.algo, self.params = make_algorithm(
            algorithm,
            population_size,
            self.n_genes,
            algorithm_kwargs=kwargs,
            algorithm_params=settings.algorithm_params,
        )
        #: with feasibility and ``judge="ranked"`` (`Settings`): how many of a
        #: generation's best ranks must be exact (CMA-ES: its ``num_elites``, the
        #: candidates with positive weights); only those are sure to be judged
        #: (`ranked_outcome`). None: every candidate is judged.  Kinematic mode
        #: only: in dynamic mode a move's violation includes what the physics
        #: executed (`Feasibility.executed`), known only inside the step.
        self.judge_ranks = None
        if (getattr(settings, "judge", "all") == "ranked"
                and self.feasibility is not None and sharding is None
                and getattr(self.sim, "mode", "kinematic") == "kinematic"
                and algorithm_name(algorithm) in RANKED_ALGORITHMS
                and hasattr(self.sim, "judge")):
            self.judge_ranks = int(self.algo.num_elites)
        self.info = {
            "algorithm": algorithm_name(algorithm),
            "population_size": int(population_size),
            **({"aim": aim, "aim_tolerance": self.aim_tolerance}
               if aim < 1.0 else {}),
            **(info or {}),
        }

    # ---- evolutions and fitness
    def sharded(self, fitness_u: Callable) -> Callable:
        """``fitness_u`` (a function of the population (P, D)) with its batch split
        over the plan's devices (as is without ``sharding``)."""
        if self.sharding is None:
            return fitness_u
        # only the simulator call is split: candidates in and fitness out stay
        # replicated, so ask/tell run as on one device (same reduction order)
        sharded = shard_population(fitness_u, self.sharding)
        replicated = NamedSharding(self.sharding.mesh, PartitionSpec())

        def fitness(pop):
            pop = jax.lax.with_sharding_constraint(pop, replicated)
            return jax.lax.with_sharding_constraint(sharded(pop), replicated)

        return fitness

    def start(
        self, key: jax.Array, fitness_u: FitnessFn, mean: jax.Array | None = None,
        std_scale: jax.Array | float | None = None,
    ) -> Evolution:
        """`evolution_init` with this plan's algorithm and gene count."""
        return evolution_init(self.algo, self.params, key, self.sharded(fitness_u),
                              self.n_genes, mean=mean, std_scale=std_scale)

    def evolve(
        self,
        evo: Evolution,
        fitness_u: FitnessFn,
        stop: Callable[[Evolution], jax.Array] | None = None,
    ) -> tuple[Evolution, dict[str, jax.Array]]:
        """`evolution_step` with this plan's algorithm (default stop: `self.stop`)."""
        return evolution_step(self.algo, self.params, evo, self.sharded(fitness_u),
                              self.stop if stop is None else stop)

    def joints(self, u: jax.Array) -> jax.Array:
        """Normalized genes (..., DoF) -> joint angles."""
        return to_joints(u, self.lower, self.upper)

    def best_joints(self, evo: Evolution) -> jax.Array:
        """Joint angles of `evo`'s best genes (..., D); NaN where nothing valid was
        found (the start mean was never evaluated: it is no posture to report)."""
        q = self.joints(evo.best_u)
        return jnp.where(jnp.expand_dims(evo.found, -1), q, jnp.nan)

    def point_features(self, state: Any, pop_u: jax.Array) -> jax.Array:
        """Features (P, F) after one step from `state` to each posture of `pop_u`
        (P, DoF); the moves are not judged (`advance`)."""
        q = self.joints(pop_u)
        return self.map_population(lambda w: self.advance(state, w)[1], q)

    @property
    def feasibility(self) -> Any:
        """The simulator's `cgda_jax.sim.feasibility.Feasibility`, or None."""
        return getattr(self.sim, "feasibility", None)

    def penalize(self, fitness: jax.Array, violation: Any) -> jax.Array:
        """``fitness`` with the feasibility penalty of ``violation`` added (as is
        without feasibility)."""
        if self.feasibility is None or violation is None:
            return fitness
        return penalized(fitness, violation, self.feasibility.penalty)

    def motion(self, state: Any, pop_u: jax.Array) -> jax.Array:
        """The joint motion (P,) (radians, Euclidean) from the state's posture to
        each posture of ``pop_u`` (P, DoF)."""
        return distances(self.joints(pop_u), state.genes)

    def point_outcome(self, state: Any, pop_u: jax.Array) -> tuple[jax.Array, Any]:
        """Features (P, F) and the move's violation (P,) (None without
        feasibility) after one step from `state` to each posture of `pop_u`."""
        q = self.joints(pop_u)

        def one(w):
            new, feats = self.sim.step(state, w)
            return feats, getattr(new, "move_violation", None)

        return self.map_population(one, q)

    def advance(self, state: Any, waypoint: jax.Array) -> tuple[Any, jax.Array]:
        """``sim.step(state, waypoint)`` without judging the move (with
        feasibility: ``judge=False``), for a move whose violation the caller
        does not use or gets elsewhere: its program then carries no copy of the
        collision check."""
        if self.feasibility is None:
            return self.sim.step(state, waypoint)
        return self.sim.step(state, waypoint, judge=False)

    def map_population(self, fn: Callable, xs: Any) -> Any:
        """``vmap(fn)(xs)`` over the population, through the simulator's
        ``map_population`` when it has one (dynamic MJX mode slices large populations
        there: big batched LAPACK calls deadlock XLA's CPU thread pool)."""
        mapper = getattr(self.sim, "map_population", None)
        return jax.vmap(fn)(xs) if mapper is None else mapper(fn, xs)

    def point_fitness(
        self, state: Any, goal_point: jax.Array, prefix_sq: jax.Array | None = None
    ) -> FitnessFn:
        """Fitness of one posture (P, DoF) -> (P,) stepped to from `state`.

        The Euclidean distance of its features to `goal_point` (F,); with `prefix_sq`
        (the summed squared error of earlier points) ``sqrt(prefix_sq + error^2)``;
        with feasibility below the aim ranked by joint motion (`motion`,
        `cgda_jax.strategies.fitness.least_motion`) and penalized where
        infeasible (`cgda_jax.strategies.fitness.penalized`).
        """

        def fitness_u(pop):
            if self.judge_ranks is not None:
                return self.ranked_outcome(state, pop, goal_point, prefix_sq)[0]
            feats, violation = self.point_outcome(state, pop)
            return self.outcome_fitness(state, pop, feats, violation, goal_point,
                                        prefix_sq)

        return fitness_u

    def outcome_fitness(self, state: Any, pop_u: jax.Array, feats: jax.Array,
                        violation: Any, goal_point: jax.Array,
                        prefix_sq: jax.Array | None = None) -> jax.Array:
        """`point_fitness` (P,) of the postures ``pop_u`` (P, DoF) from their
        `point_outcome` ``(feats, violation)``."""
        feas = self.feasibility
        return point_fitness(
            distances(feats, goal_point), violation,
            None if feas is None else feas.penalty,
            motion=None if feas is None else self.motion(state, pop_u),
            aim=self.aim_tolerance, prefix_sq=prefix_sq)

    def ranked_outcome(self, state: Any, pop_u: jax.Array, goal_point: jax.Array,
                       prefix_sq: jax.Array | None = None
                       ) -> tuple[jax.Array, jax.Array]:
        """`outcome_fitness` (P,) of the postures ``pop_u`` (P, DoF) stepped to
        from `state`, with only the moves whose rank matters judged
        (`judge_ranks` of them at least; `cgda_jax.strategies.fitness.judge_best`
        says why the best ranks are exact), and the moves' violations (P,; NaN
        where not judged).  Every candidate is stepped once, unjudged; the
        judged ones' moves are judged from those steps together
        (`Simulator.judge_moves`)."""
        fitness, violation, _ = self.ranked_outcome_with(state, pop_u, goal_point,
                                                         None, prefix_sq)
        return fitness, violation

    def ranked_outcome_with(self, state: Any, pop_u: jax.Array, goal_point: jax.Array,
                            first_u: jax.Array | None,
                            prefix_sq: jax.Array | None = None,
                            frozen: Any = False
                            ) -> tuple[jax.Array, jax.Array, Any]:
        """`ranked_outcome`, and with ``first_u`` (DoF,) also the move to that
        posture judged, in the same call of the check (``judge_best``'s
        ``lead``: the compiled program carries one copy of it): ``(fitness (P,),
        violations (P,), (its features (F,), its violation))`` (None without).
        ``frozen`` (scalar bool): nothing judged, for a caller that discards
        the fitness and knows the violation (`judge_best`)."""
        lead = 0 if first_u is None else 1
        u = pop_u if first_u is None else jnp.concatenate([first_u[None], pop_u])
        news, feats = self.map_population(lambda w: self.advance(state, w),
                                          self.joints(u))
        fitness = self.outcome_fitness(state, pop_u, feats[lead:], None, goal_point,
                                       prefix_sq)

        def judge(idx, need):
            picked = jax.tree.map(lambda x: x[idx], news)
            return self.sim.judge_moves(state, picked, need)

        fitness, violation = judge_best(
            jnp.concatenate([jnp.zeros((lead,), fitness.dtype), fitness]), judge,
            self.feasibility.penalty, self.judge_ranks, judged_round(self.judge_ranks),
            lead=lead, frozen=frozen)
        first = None if first_u is None else (feats[0], violation[0])
        return fitness[lead:], violation[lead:], first

    def stop(self, evo: Evolution) -> jax.Array:
        """Per-point stop: error below the aim (``aim * tolerance``) or
        generation budget spent."""
        return (evo.best_fitness < self.aim_tolerance) | (
            evo.generation >= self.max_generations
        )

    def stalled(self, evo: Evolution) -> jax.Array:
        """The evolution went `stagnation` generations without improving its best
        (never, when `stagnation` is None)."""
        if self.stagnation is None:
            return jnp.zeros(jnp.shape(evo.stall), bool)
        return evo.stall >= self.stagnation

    # ---- what the drivers of `cgda_jax.strategies.runner` ask of a plan
    @classmethod
    def sampled_postures(cls, settings: Settings, sim: Any) -> tuple[int, str]:
        """Postures a trial of this plan samples once (restart or start means) with
        `settings` on `sim`, and the option that sets them; ``(0, "")``: none.
        The one rule of the plan, of its size (`estimate`) and of a config's checks
        (`cgda_jax.experiment.validate`)."""
        return 0, ""

    def estimate(self, n_trials: int) -> Estimate:
        """What `n_trials` trials of this plan in one batch hold at once
        (`cgda_jax.sizes.sim_estimate`)."""
        return sim_estimate(self.sim, trials=n_trials,
                            population=int(self.info["population_size"]),
                            points=self.n_points, strategy=self.name,
                            samples=self.sampled_postures(self.settings, self.sim)[0])

    def report_progress(self, progress_fn: Callable[[dict[str, Any]], None] | None,
                        generations: int, finished: bool, t1: float,
                        carry: Any) -> None:
        """``progress_fn`` of every driver after a chunk: the strategy, its points,
        the generations run, whether it finished, the seconds since ``t1`` and the
        plan's own figures of ``carry`` (``progress``)."""
        if progress_fn is not None:
            progress_fn({
                "strategy": self.name, "points": self.n_points,
                "generations": generations, "done": finished,
                "elapsed_s": time.perf_counter() - t1, **self.progress(carry),
            })

    def split_results(self, final: Any, histories: list[Any], timing: dict[str, Any],
                      info: dict[str, Any] | None = None) -> list[ExecutionResult]:
        """Every driver's results: trial r's ``to_result`` of its final arrays
        (leaves (R, ...) of ``final``) and history ``histories[r]``, with the
        batch's ``timing`` (wall and compile time of the whole batch,
        ``trials_in_batch``) and ``info`` added to its ``info``."""
        results = []
        for r, history in enumerate(histories):
            f = jax.tree.map(lambda x, r=r: x[r], final)
            res = self.to_result(f, history, timing)
            res.info.update(info or {})
            results.append(res)
        return results

    # ---- plan functions shared by several strategies
    def done(self, carry: Any) -> jax.Array:
        """Every evolution of the carry stopped."""
        return jnp.all(carry.done)

    def execution(self, joints: jax.Array) -> dict[str, jax.Array]:
        """``joints`` (N, DoF) and their ``features`` (N, F) executed from the start
        (with feasibility also its summed ``violation``, 0 = feasible)."""
        features, final = self.sim.rollout(joints, self.sim.init_state())
        out = {"joints": joints, "features": features}
        if getattr(final, "violation", None) is not None:
            out["violation"] = final.violation
        return out

    def rejudge(self, final: dict) -> dict:
        """A finished trial's host arrays with ``violation`` from the judged
        rollout (`cgda_jax.sim.simulator.Simulator.violation`) where its finish
        says the stored one is not the result's (``judged`` False: a run cut
        before its last moves were judged); ``judged`` dropped."""
        final = dict(final)
        if not bool(final.pop("judged", True)):
            joints = jnp.asarray(final["joints"])
            final["violation"] = np.asarray(self.sim.violation(joints))
        return final

    def executed_features(self, joints: jax.Array) -> jax.Array:
        """The ``features`` (N, F) of `execution`, its moves not judged
        (`advance`)."""
        return jax.lax.scan(lambda st, w: self.advance(st, w), self.sim.init_state(),
                            joints)[1]

    def result(
        self,
        final: dict[str, np.ndarray],
        timing: dict[str, Any],
        *,
        fitness_history: np.ndarray,
        evaluations: int,
        generations: int,
        final_fitness: float | None = None,
        point_errors: np.ndarray | None = None,
        complete: bool = True,
        invalid_evaluations: int = 0,
        **info: Any,
    ) -> ExecutionResult:
        """The `ExecutionResult` of a finished run (host arrays).

        ``final`` holds ``joints`` and ``features`` (and ``violation`` with
        feasibility); `point_errors` defaults to each executed point's Euclidean
        error to its goal point (inf where not finite), `final_fitness` to the
        largest of them; success = `complete`, every error < tolerance and (with
        feasibility) a feasible execution (violation 0). `invalid_evaluations`
        counts the diverged evaluations. `info` extends the plan's settings.
        """
        goal = np.asarray(self.goal)
        if point_errors is None:
            point_errors = distances(final["features"], goal)
        point_errors = np.where(np.isfinite(point_errors), point_errors, np.inf)
        if final_fitness is None:
            final_fitness = point_errors.max()
        if np.isnan(final_fitness):  # an execution without finite features
            final_fitness = np.inf
        feasible = True
        if "violation" in final:
            violation = float(np.asarray(final["violation"]))
            feasible = violation == 0.0
            info = {"feasible": feasible, "violation": violation, **info}
        return ExecutionResult(
            strategy=self.name,
            joints=final["joints"],
            features=final["features"],
            goal=goal,
            point_errors=point_errors,
            fitness_history=fitness_history,
            evaluations=int(evaluations),
            generations=int(generations),
            wall_time_s=timing["wall_time_s"],
            compile_time_s=timing["compile_time_s"],
            success=bool(complete and feasible
                         and np.all(point_errors < self.tolerance)),
            tolerance=self.tolerance,
            final_fitness=float(final_fitness),
            info={**self.info, "trials_in_batch": timing["trials_in_batch"], **info},
            invalid_evaluations=int(invalid_evaluations),
            setup=setup_of(self.sim),
        )
