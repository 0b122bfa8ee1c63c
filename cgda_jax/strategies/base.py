"""Shared machinery of the execution strategies: algorithms, gene bounds, one evolution.

Every strategy (FTE, IE, IET, OET) runs one or more evolutions of the same kind: an
`evosax` algorithm asks for a population of gene vectors, the whole population is
executed in ONE batched simulator call, its fitness against the goal is computed and
told back. This module holds that generation step (`evolution_step`), the start of an
evolution (`evolution_init`), the name -> algorithm registry and the gene bounds.

Gene bounds. Algorithms search an unbounded, normalized space ``u`` (D,); joint angles
are ``q = mid + half * sin(pi / 2 * u)`` with ``mid, half`` the centre and half-width of
the joint limits. ``u`` in [-1, 1] covers the whole range once; beyond it the sine folds
back, a smooth reflection at the limits (no flat, gradient-free regions as with
clipping, no infeasible postures). ``u = 0`` is the middle of every joint range, the
start mean of distribution-based algorithms, and a step size of about 0.3 moves a joint
by a few tenths of its range.

Divergence. A candidate whose fitness is not finite (a simulation that blew up: NaN or
inf features) is *invalid*: it is told to the algorithm with the finite fitness
`INVALID_PENALTY` (ranked after every valid candidate, so no algorithm state turns
NaN), it is never kept as the best, and it is counted (`Evolution.invalid`, the
``invalid`` metric of every generation). The best of an evolution is always a
candidate that was evaluated and finite; until there is one, ``best_fitness`` is inf
and `Evolution.found` is False.

References:
    Lange, "evosax: JAX-based Evolution Strategies", GECCO 2023 companion.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from evosax.algorithms import algorithms as _EVOSAX_ALGORITHMS
from evosax.algorithms.population_based.base import PopulationBasedAlgorithm
from flax import struct
from jax.sharding import NamedSharding, PartitionSpec

from cgda_jax.sharding import shard_population
from cgda_jax.strategies.result import ExecutionResult

#: Names accepted by ``algorithm=`` (every algorithm shipped with evosax).
ALGORITHMS: dict[str, type] = dict(_EVOSAX_ALGORITHMS)

#: Fitness told to the algorithm for an invalid (non-finite) candidate. A constant,
#: not a figure relative to the generation: population-based algorithms (DE, GA, PSO)
#: compare fitness across generations, and an invalid candidate must lose against
#: every valid one ever seen. Valid fitness is capped at it (ties, never inversions).
#: Float32 keeps its square (1e20) finite, so algorithms that standardize fitness stay
#: finite too.
INVALID_PENALTY = 1e10

FitnessFn = Callable[[jax.Array], jax.Array]
"""Maps joint genes (P, D) -> fitness (P,), minimized; the one batched sim call."""


# --------------------------------------------------------------------------- algorithms
def algorithm_name(algorithm: Any) -> str:
    """The name of an algorithm given by name, evosax class or configured instance."""
    if isinstance(algorithm, str):
        return algorithm
    cls = algorithm if isinstance(algorithm, type) else type(algorithm)
    return cls.__name__


def make_algorithm(
    algorithm: Any,
    population_size: int,
    n_genes: int,
    *,
    algorithm_kwargs: dict[str, Any] | None = None,
    algorithm_params: dict[str, Any] | None = None,
) -> tuple[Any, Any]:
    """Builds an evosax algorithm and its parameters.

    Args:
        algorithm: as users of evosax pass it: a name (a key of `ALGORITHMS`, e.g.
            "CMA_ES", "SimpleGA", "DifferentialEvolution"), an algorithm class
            (e.g. ``evosax.algorithms.CMA_ES``, built here), or a configured instance
            (``CMA_ES(population_size=32, solution=jnp.zeros(3), ...)``, used as it
            is: its population size and solution size must match).
        population_size: individuals per generation.
        n_genes: genes per individual (D).
        algorithm_kwargs: extra constructor arguments (e.g. ``std_schedule`` of SimpleGA).
        algorithm_params: fields of the algorithm's ``default_params`` to override
            (e.g. ``{"std_init": 0.3}`` for CMA_ES).

    Returns:
        ``(algorithm, params)``.

    Raises:
        ValueError: unknown name, unknown parameter, or a population too small for the
            algorithm (its constructor refuses it or its default parameters are not
            finite).
    """
    name = algorithm_name(algorithm)
    if isinstance(algorithm, str) and name not in ALGORITHMS:
        raise ValueError(
            f"unknown algorithm {name!r}; choose one of {sorted(ALGORITHMS)}"
        )
    if int(population_size) < 2:
        raise ValueError(
            f"population_size={population_size} is too small for {name}: need >= 2"
        )
    cls = ALGORITHMS[name] if isinstance(algorithm, str) else algorithm
    if isinstance(cls, type) and not hasattr(cls, "ask"):
        raise ValueError(f"algorithm {name!r} is not an evosax algorithm class")
    try:
        if isinstance(cls, type):
            algo = cls(
                population_size=int(population_size),
                solution=jnp.zeros((n_genes,)),
                **(algorithm_kwargs or {}),
            )
        else:  # a configured instance
            algo = cls
            if not (hasattr(algo, "ask") and hasattr(algo, "default_params")):
                raise ValueError(f"{algo!r} is not an evosax algorithm (no ask / "
                                 "default_params)")
            if algorithm_kwargs:
                raise ValueError(f"algorithm_kwargs {sorted(algorithm_kwargs)} given "
                                 f"with an already built {name}; configure it instead")
            size, dims = int(algo.population_size), int(getattr(algo, "num_dims", -1))
            if size != int(population_size) or dims != int(n_genes):
                raise ValueError(
                    f"the {name} instance has population_size={size} and "
                    f"{dims} genes; this run needs population_size="
                    f"{population_size} and {n_genes} genes (one per evolved joint"
                    " and waypoint)")
    except AssertionError as err:
        raise ValueError(
            f"population_size={population_size} is not allowed for {name}: {err}"
        ) from None
    except TypeError as err:
        raise ValueError(f"bad algorithm_kwargs for {name}: {err}") from None
    # evosax computes its default parameters with many small eager ops (each one a
    # compile on first use); tracing them as ONE program costs one compile instead.
    params = jax.jit(lambda: algo.default_params)()
    overrides = dict(algorithm_params or {})
    unknown = sorted(set(overrides) - set(params.__dataclass_fields__))
    if unknown:
        raise ValueError(
            f"unknown algorithm_params {unknown} for {name}; it has "
            f"{sorted(params.__dataclass_fields__)}"
        )
    params = params.replace(**{k: jnp.asarray(v) for k, v in overrides.items()})
    finite = [np.all(np.isfinite(np.asarray(x, float))) for x in jax.tree.leaves(params)]
    if not all(finite):
        raise ValueError(
            f"population_size={population_size} is too small for {name} with "
            f"{n_genes} genes: its default parameters are not finite"
        )
    return algo, params


# --------------------------------------------------------------------------- gene bounds
def to_joints(u: jax.Array, lower: jax.Array, upper: jax.Array) -> jax.Array:
    """Maps normalized genes (..., DoF) to joint angles inside [lower, upper]."""
    mid = 0.5 * (upper + lower)
    half = 0.5 * (upper - lower)
    return mid + half * jnp.sin(0.5 * jnp.pi * u)


def from_joints(q: jax.Array, lower: jax.Array, upper: jax.Array) -> jax.Array:
    """Inverse of `to_joints` on [-1, 1] (angles are clipped into the limits first)."""
    mid = 0.5 * (upper + lower)
    half = jnp.maximum(0.5 * (upper - lower), 1e-12)
    s = jnp.clip((q - mid) / half, -1.0, 1.0)
    return jnp.arcsin(s) * (2.0 / jnp.pi)


def points_independent(sim: Any) -> bool:
    """Whether a step's features depend only on its waypoint, not on where it starts:
    kinematic mode (``sim.mode``, default kinematic) and a scene state with no arrays
    (the marker; a paint wall remembers what was painted)."""
    if getattr(sim, "mode", "kinematic") != "kinematic":
        return False
    scene = getattr(sim, "scene", None)
    return scene is None or not jax.tree.leaves(scene.init_state())


# --------------------------------------------------------------------------- validation
def check_config(
    sim: Any,
    goal: Any,
    *,
    tolerance: float | None = None,
    max_generations: int | None = None,
    min_points: int = 1,
) -> jax.Array:
    """Checks a goal (N, F) against a simulator and common settings; returns it f32.

    The checks run in NumPy on the host (eager JAX ops would each compile once).
    """
    from cgda_jax.checks import check_float32

    g64 = np.asarray(goal, dtype=np.float64)
    if np.all(np.isfinite(g64)):  # NaN/inf: the per-point message below
        check_float32(g64, "goal")
    g = g64.astype(np.float32)
    if g.ndim == 1 and sim.n_features == 1:
        g = g[:, None]
    if g.ndim != 2:
        raise ValueError(f"goal must have shape (N, F); got shape {tuple(g.shape)}")
    if g.shape[1] != sim.n_features:
        names = getattr(sim, "feature_names", None)
        raise ValueError(
            f"goal has {g.shape[1]} features per point but the simulator's scene has "
            f"{sim.n_features}" + (f" ({', '.join(names)})" if names else "")
        )
    if g.shape[0] < min_points:
        raise ValueError(f"goal needs at least {min_points} point(s); got {g.shape[0]}")

    if not np.all(np.isfinite(g)):
        bad = int(np.argmax(~np.all(np.isfinite(g), axis=1)))
        raise ValueError(f"goal has a non-finite value at point {bad}")
    if tolerance is not None and not tolerance > 0:
        raise ValueError(f"tolerance must be > 0; got {tolerance}")
    if max_generations is not None and int(max_generations) < 1:
        raise ValueError(f"max_generations must be >= 1; got {max_generations}")
    return jnp.asarray(g)


# --------------------------------------------------------------------------- one evolution
@struct.dataclass
class Evolution:
    """State of one evolution (one point of IE/IET/OET, or the whole FTE trajectory).

    Attributes:
        algo: the evosax algorithm state.
        key: this evolution's key; generation g uses ``fold_in(key, g)``.
        best_u: best normalized genes so far (D,).
        best_fitness: its fitness (scalar).
        stall: generations since the best fitness last improved.
        generation: generations run.
        evaluations: fitness evaluations spent.
        invalid: how many of them were invalid (non-finite fitness).
        done: True once a stop condition held; the state is then frozen.
    """

    algo: Any
    key: jax.Array
    best_u: jax.Array
    best_fitness: jax.Array
    stall: jax.Array
    generation: jax.Array
    evaluations: jax.Array
    invalid: jax.Array
    done: jax.Array

    @property
    def found(self) -> jax.Array:
        """True once a valid candidate was evaluated (`best_u` is one); bool array."""
        return jnp.isfinite(self.best_fitness)


def screen(fitness: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Splits a population's raw fitness (P,) into what is told and what is ranked.

    Returns:
        ``(told, ranked, n_invalid)``: `told` (P,) is finite (invalid candidates get
        `INVALID_PENALTY`, valid ones are capped at it), for the algorithm; `ranked`
        (P,) is the fitness with inf for invalid candidates, for the best; `n_invalid`
        is the int32 count of invalid candidates (traced, no host sync).
    """
    valid = jnp.isfinite(fitness)
    told = jnp.where(valid, jnp.minimum(fitness, INVALID_PENALTY), INVALID_PENALTY)
    ranked = jnp.where(valid, fitness, jnp.inf)
    return told, ranked, jnp.sum(~valid).astype(jnp.int32)


def evolution_init(
    algo: Any,
    params: Any,
    key: jax.Array,
    fitness_u: FitnessFn,
    n_genes: int,
    mean: jax.Array | None = None,
) -> Evolution:
    """Starts an evolution (jittable, vmappable over `key` and `fitness_u`'s context).

    Distribution-based algorithms start at `mean` (normalized genes (D,); default 0 =
    mid joint ranges), which is not evaluated: the evolution has no best yet
    (``best_fitness`` inf, `Evolution.found` False). Population-based ones get a
    uniform initial population in ``[-1, 1]^D`` that is evaluated here (its best valid
    candidate, if any, is the first best).
    """
    key, k_init, k_pop = jax.random.split(key, 3)
    if isinstance(algo, PopulationBasedAlgorithm):
        pop = jax.random.uniform(
            k_pop, (algo.population_size, n_genes), minval=-1.0, maxval=1.0
        )
        told, ranked, invalid = screen(fitness_u(pop))
        state = algo.init(k_init, pop, told, params)
        i = jnp.argmin(ranked)
        best_u, best_f, evals = pop[i], ranked[i], algo.population_size
    else:
        mean = jnp.zeros((n_genes,)) if mean is None else mean
        state = algo.init(k_init, mean, params)
        best_u, best_f, evals = mean, jnp.asarray(jnp.inf), 0
        invalid = jnp.zeros((), jnp.int32)
    return Evolution(
        algo=state,
        key=key,
        best_u=best_u,
        best_fitness=jnp.asarray(best_f, jnp.float32),
        stall=jnp.asarray(0, jnp.int32),
        generation=jnp.asarray(0, jnp.int32),
        evaluations=jnp.asarray(evals, jnp.int32),
        invalid=invalid,
        done=jnp.asarray(False),
    )


def freeze(done: jax.Array, old: Any, new: Any) -> Any:
    """Keeps `old` where `done` (a scalar bool) holds, else `new` (pytree-wise)."""
    return jax.tree.map(lambda o, n: jnp.where(done, o, n), old, new)


def evolution_step(
    algo: Any,
    params: Any,
    evo: Evolution,
    fitness_u: FitnessFn,
    stop: Callable[[Evolution], jax.Array],
) -> tuple[Evolution, dict[str, jax.Array]]:
    """One generation: ask -> one batched evaluation -> tell -> bookkeeping -> stop test.

    A done evolution is returned unchanged (its computation still runs, masked, so that
    batched evolutions stay in lock-step).

    Args:
        algo, params: from `make_algorithm`.
        evo: the evolution state.
        fitness_u: normalized genes (P, D) -> fitness (P,).
        stop: Evolution -> bool, evaluated after the update.

    Returns:
        ``(evo, metrics)`` with metrics ``best_fitness`` (best so far),
        ``generation_best`` (this generation's best valid fitness; inf when frozen or
        when none was valid) and ``invalid`` (invalid candidates of this generation;
        0 when frozen). Invalid candidates are told `INVALID_PENALTY` (see `screen`).
    """
    k = jax.random.fold_in(evo.key, evo.generation)
    k_ask, k_tell = jax.random.split(k)
    pop, algo_state = algo.ask(k_ask, evo.algo, params)
    told, ranked, invalid = screen(fitness_u(pop))
    algo_state, _ = algo.tell(k_tell, pop, told, algo_state, params)
    i = jnp.argmin(ranked)
    better = ranked[i] < evo.best_fitness
    new = evo.replace(
        algo=algo_state,
        best_u=jnp.where(better, pop[i], evo.best_u),
        best_fitness=jnp.where(better, ranked[i], evo.best_fitness),
        stall=jnp.where(better, 0, evo.stall + 1),
        generation=evo.generation + 1,
        evaluations=evo.evaluations + algo.population_size,
        invalid=evo.invalid + invalid,
    )
    new = new.replace(done=stop(new))
    out = freeze(evo.done, evo, new)
    metrics = {
        "best_fitness": out.best_fitness,
        "generation_best": jnp.where(evo.done, jnp.inf, ranked[i]),
        "invalid": jnp.where(evo.done, 0, invalid),
    }
    return out, metrics


# --------------------------------------------------------------------------- plans
def _default_kwargs(name: str) -> dict[str, Any]:
    """Defaults that fit the normalized gene space (see the module docstring)."""
    if name == "SimpleGA":
        import optax

        # evosax's SimpleGA mutates with std 1.0 forever: in normalized genes that spans
        # the whole joint range and never refines; decay it instead.
        return {
            "std_schedule": optax.exponential_decay(
                0.3, transition_steps=1, decay_rate=0.95, end_value=0.003
            )
        }
    return {}


def ragged_rows(rows: list[np.ndarray]) -> np.ndarray:
    """Stacks 1-D rows of different lengths into (len(rows), longest or 1), NaN-padded."""
    out = np.full((len(rows), max([len(r) for r in rows] + [1])), np.nan)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


class PlanBase:
    """Shared set-up and pieces of the strategy plans driven by `runner.drive`.

    A plan is built from an already checked goal (`check_config`); subclasses add their
    own settings (checked in their ``__init__``) and the plan functions ``init``,
    ``step``, ``finish``, ``progress`` and ``to_result`` (see `runner`).

    With ``sharding`` (`cgda_jax.sharding.population_sharding`) every fitness
    evaluation, the one batched simulator call of a generation, has its population
    (P, ...) padded to a multiple of the device count and split over the devices
    (`cgda_jax.sharding.shard_population`); the rest of the step is unchanged.
    """

    name = "base"

    def __init__(
        self,
        sim: Any,
        goal: jax.Array,
        n_genes: int,
        *,
        algorithm: Any,
        population_size: int,
        tolerance: float,
        max_generations: int,
        algorithm_kwargs: dict[str, Any] | None = None,
        algorithm_params: dict[str, Any] | None = None,
        info: dict[str, Any] | None = None,
        sharding: NamedSharding | None = None,
    ):
        self.sim, self.goal = sim, goal
        self.sharding = sharding
        self.n_points = int(goal.shape[0])
        self.lower = jnp.asarray(sim.lower, jnp.float32)
        self.upper = jnp.asarray(sim.upper, jnp.float32)
        self.n_dof = int(sim.n_dof)
        self.n_genes = int(n_genes)
        self.tolerance = float(tolerance)
        self.max_generations = int(max_generations)
        self.max_generations_total = self.max_generations
        kwargs = dict(algorithm_kwargs or {})
        if isinstance(algorithm, str):
            kwargs = {**_default_kwargs(algorithm), **kwargs}
        self.algo, self.params = make_algorithm(
            algorithm,
            population_size,
            self.n_genes,
            algorithm_kwargs=kwargs,
            algorithm_params=algorithm_params,
        )
        self.info = {
            "algorithm": algorithm_name(algorithm),
            "population_size": int(population_size),
            **(info or {}),
        }

    # ---- evolutions and fitness
    def _sharded(self, fitness_u: FitnessFn) -> FitnessFn:
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
        self, key: jax.Array, fitness_u: FitnessFn, mean: jax.Array | None = None
    ) -> Evolution:
        """`evolution_init` with this plan's algorithm and gene count."""
        return evolution_init(self.algo, self.params, key, self._sharded(fitness_u),
                              self.n_genes, mean=mean)

    def evolve(
        self,
        evo: Evolution,
        fitness_u: FitnessFn,
        stop: Callable[[Evolution], jax.Array] | None = None,
    ) -> tuple[Evolution, dict[str, jax.Array]]:
        """`evolution_step` with this plan's algorithm (default stop: `self.stop`)."""
        return evolution_step(self.algo, self.params, evo, self._sharded(fitness_u),
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
        """Features (P, F) after one step from `state` to each posture of `pop_u` (P, DoF)."""
        q = self.joints(pop_u)
        return self.map_population(lambda w: self.sim.step(state, w)[1], q)

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
        (the summed squared error of earlier points) ``sqrt(prefix_sq + error^2)``.
        """

        def fitness_u(pop):
            feats = self.point_features(state, pop)
            if prefix_sq is None:
                return jnp.linalg.norm(feats - goal_point, axis=-1)
            return jnp.sqrt(prefix_sq + jnp.sum((feats - goal_point) ** 2, axis=-1))

        return fitness_u

    def stop(self, evo: Evolution) -> jax.Array:
        """Per-point stop: error below tolerance or generation budget spent."""
        return (evo.best_fitness < self.tolerance) | (
            evo.generation >= self.max_generations
        )

    # ---- plan functions shared by several strategies
    def done(self, carry: Any) -> jax.Array:
        """Every evolution of the carry stopped."""
        return jnp.all(carry.done)

    def execution(self, joints: jax.Array) -> dict[str, jax.Array]:
        """``joints`` (N, DoF) and their ``features`` (N, F) executed from the start."""
        features, _ = self.sim.rollout(joints, self.sim.init_state())
        return {"joints": joints, "features": features}

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

        ``final`` holds ``joints`` and ``features``; `point_errors` defaults to each
        executed point's Euclidean error to its goal point (inf where not finite),
        `final_fitness` to the largest of them; success = `complete` and every error
        < tolerance. `invalid_evaluations` counts the diverged evaluations. `info`
        extends the plan's settings.
        """
        goal = np.asarray(self.goal)
        if point_errors is None:
            point_errors = np.linalg.norm(final["features"] - goal, axis=-1)
        point_errors = np.where(np.isfinite(point_errors), point_errors, np.inf)
        if final_fitness is None:
            final_fitness = point_errors.max()
        if np.isnan(final_fitness):  # an execution without finite features
            final_fitness = np.inf
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
            success=bool(complete and np.all(point_errors < self.tolerance)),
            tolerance=self.tolerance,
            final_fitness=float(final_fitness),
            info={**self.info, "trials_in_batch": timing["trials_in_batch"], **info},
            invalid_evaluations=int(invalid_evaluations),
        )
