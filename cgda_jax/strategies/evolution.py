"""The evolutionary search every strategy runs: genes, algorithms, one evolution.

Genes. Algorithms search an unbounded, normalized space ``u`` (D,); joint angles
are ``q = mid + half * sin(pi / 2 * u)`` with ``mid, half`` the centre and half-width of
the joint limits. ``u`` in [-1, 1] covers the whole range once; beyond it the sine folds
back, a smooth reflection at the limits (no flat, gradient-free regions as with
clipping, no infeasible postures). ``u = 0`` is the middle of every joint range, the
start mean of distribution-based algorithms, and a step size of about 0.3 moves a joint
by a few tenths of its range.

Algorithms: The evolutionary algorithms: evosax's registry, built by name, class or instance.

One evolution: one evolution: its state, its start and its generation step (ask -> one batched
evaluation -> tell), with invalid (diverged) candidates screened out.

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

import inspect
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from evosax.algorithms import algorithms as _EVOSAX_ALGORITHMS
from evosax.algorithms.population_based.base import PopulationBasedAlgorithm
from flax import struct

from cgda_jax.programs import jit_call

__all__ = ["ALGORITHMS", "INVALID_PENALTY", "Evolution", "FitnessFn", "algorithm_name",
           "default_kwargs", "evolution_ask", "evolution_init", "evolution_step",
           "evolution_tell", "freeze", "from_joints", "make_algorithm", "screen",
           "to_joints"]


# --------------------------------------------------------------------------- genes
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


# --------------------------------------------------------------------------- algorithms
#: Names accepted by ``algorithm=`` (every algorithm shipped with evosax).
ALGORITHMS: dict[str, type] = dict(_EVOSAX_ALGORITHMS)

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
        population_size: individuals per generation (with ``num_populations``, the
            Stein variational ESs' groups, of all groups together: it must divide).
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
            kwargs = dict(algorithm_kwargs or {})
            size = int(population_size)
            if "num_populations" in kwargs:  # Stein variational ESs: size per group
                groups = int(kwargs["num_populations"])
                if groups < 1 or size % groups:
                    raise ValueError(
                        f"population_size={population_size} is not a multiple of "
                        f"num_populations={kwargs['num_populations']} for {name} "
                        "(population_size counts the individuals of all groups)")
                size //= groups
            algo = cls(population_size=size, solution=jnp.zeros((n_genes,)), **kwargs)
        else:  # a configured instance
            algo = cls
            if not (hasattr(algo, "ask") and hasattr(algo, "default_params")):
                raise ValueError(f"{algo!r} is not an evosax algorithm (no ask / "
                                 "default_params)")
            if algorithm_kwargs:
                raise ValueError(f"algorithm_kwargs {sorted(algorithm_kwargs)} given "
                                 f"with an already built {name}; configure it instead")
            size = int(algo.population_size) * int(getattr(algo, "num_populations", 1))
            dims = int(getattr(algo, "num_dims", -1))
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
        missing = _missing_arguments(cls, algorithm_kwargs)
        if missing:
            raise ValueError(
                f"{name} needs constructor argument(s) {missing} that cgda_jax "
                f"cannot choose for it: pass them in algorithm_kwargs, e.g. "
                f"algorithm_kwargs={{{missing[0]!r}: ...}} (see evosax's {name})"
            ) from None
        raise ValueError(f"bad algorithm_kwargs for {name}: {err}") from None
    # evosax computes its default parameters with many small eager ops (each one a
    # compile on first use); tracing them as ONE program costs one compile instead
    # (a few, e.g. LM_MA_ES, need concrete values: computed eagerly then); compiled
    # once per process, not per call (`cgda_jax.programs.jit_call`)
    try:
        params = jit_call(lambda: algo.default_params,
                          name=f"evolution.default_params.{name}")
    except jax.errors.ConcretizationTypeError:
        params = algo.default_params
    overrides = dict(algorithm_params or {})
    unknown = sorted(set(overrides) - set(params.__dataclass_fields__))
    if unknown:
        raise ValueError(
            f"unknown algorithm_params {unknown} for {name}; it has "
            f"{sorted(params.__dataclass_fields__)}"
        )
    params = params.replace(**{k: jnp.asarray(v) for k, v in overrides.items()})
    c_c = np.asarray(getattr(params, "c_c", 0.0), float)
    if np.any(c_c >= 2.0):  # sqrt(c_c (2 - c_c)) of its evolution paths: NaN
        raise ValueError(
            f"{name} with population_size={population_size} and {n_genes} genes has "
            f"evolution-path rates c_c up to {c_c.max():.3g} >= 2 (evosax derives "
            "them from population_size / genes), which turns its state NaN at the "
            "first update: use population_size < 2 x genes, set algorithm_params "
            "c_c, or another algorithm (MA_ES, CMA_ES)")
    # NaN or -inf from a population too small; +inf is a legitimate "no cap" of the
    # *_max fields (MR15_GA's std_max)
    finite = []
    for k in params.__dataclass_fields__:
        for x in jax.tree.leaves(getattr(params, k)):
            x = np.asarray(x, float)
            ok = np.isfinite(x) | ((x == np.inf) if k.endswith("_max") else False)
            finite.append(bool(np.all(ok)))
    if not all(finite):
        raise ValueError(
            f"population_size={population_size} is too small for {name} with "
            f"{n_genes} genes: its default parameters are not finite"
        )
    return algo, params


def _missing_arguments(cls: Any, given: dict[str, Any] | None) -> list[str]:
    """Required constructor arguments of `cls` that neither cgda_jax (population
    size, solution) nor `given` supplies."""
    if not isinstance(cls, type):
        return []
    sig = inspect.signature(cls.__init__)
    return [k for k, p in sig.parameters.items()
            if k not in ("self", "population_size", "solution")
            and p.default is inspect.Parameter.empty
            and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
            and k not in (given or {})]


def default_kwargs(name: str) -> dict[str, Any]:
    """Defaults that fit the normalized gene space (see the module docstring).

    Algorithms with a ``std_schedule`` (SimpleGA, Open_ES, ARS, HillClimbing, ...)
    sample with std 1.0 forever in evosax: in normalized genes that spans the whole
    joint range and never refines; they get a decaying schedule instead (0.3, x0.95
    per generation, down to 0.003).
    """
    cls = ALGORITHMS.get(name)
    if cls is None or "std_schedule" not in inspect.signature(cls.__init__).parameters:
        return {}
    if name == "GuidedES":  # without a surrogate gradient its search needs the width
        return {}
    import optax

    return {
        "std_schedule": optax.exponential_decay(
            0.3, transition_steps=1, decay_rate=0.95, end_value=0.003
        )
    }


# --------------------------------------------------------------------------- one evolution
#: Fitness told to the algorithm for an invalid (non-finite) candidate. A constant,
#: not a figure relative to the generation: population-based algorithms (DE, GA, PSO)
#: compare fitness across generations, and an invalid candidate must lose against
#: every valid one ever seen. Valid fitness is capped at it (ties, never inversions).
#: Float32 keeps its square (1e20) finite, so algorithms that standardize fitness stay
#: finite too.
INVALID_PENALTY = 1e10

FitnessFn = Callable[[jax.Array], jax.Array]
"""Maps joint genes (P, D) -> fitness (P,), minimized; the one batched sim call."""


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
    std_scale: jax.Array | float | None = None,
) -> Evolution:
    """Starts an evolution (jittable, vmappable over `key` and `fitness_u`'s context).

    Distribution-based algorithms start at `mean` (normalized genes (D,); default 0 =
    mid joint ranges), which is not evaluated: the evolution has no best yet
    (``best_fitness`` inf, `Evolution.found` False). Population-based ones get a
    uniform initial population in ``[-1, 1]^D`` that is evaluated here (its best valid
    candidate, if any, is the first best).

    `std_scale` (distribution-based algorithms whose state has a ``std``, e.g.
    CMA_ES, SNES, Open_ES) multiplies the initial search width: a local start around
    a mean already near a solution (a restart from a sampled or neighbouring
    posture). Ignored by the others.
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
        groups = getattr(algo, "num_populations", None)  # (SV_CMA_ES, SV_Open_ES)
        state = algo.init(k_init, mean if groups is None else
                          jnp.broadcast_to(mean, (int(groups), n_genes)), params)
        if std_scale is not None and hasattr(state, "std"):
            state = state.replace(std=state.std * jnp.asarray(std_scale, state.std.dtype))
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


def evolution_ask(algo: Any, params: Any, evo: Evolution) -> tuple[jax.Array, Any]:
    """The candidates of `evo`'s next generation: ``(pop (P, D), algorithm state
    after asking)``; `evolution_tell` takes both with their fitness.  Reads only
    the algorithm state, the key and the generation of `evo`."""
    k_ask, _ = jax.random.split(jax.random.fold_in(evo.key, evo.generation))
    return algo.ask(k_ask, evo.algo, params)


def evolution_tell(
    algo: Any,
    params: Any,
    evo: Evolution,
    pop: jax.Array,
    algo_state: Any,
    fitness: jax.Array,
    stop: Callable[[Evolution], jax.Array],
) -> tuple[Evolution, dict[str, jax.Array]]:
    """Tells `evolution_ask`'s candidates ``pop`` (P, D) their raw ``fitness`` (P,)
    and does the bookkeeping of `evolution_step` (which is ask, one evaluation,
    tell); a done `evo` is returned unchanged.  Its metrics add ``best_index``
    (the generation's best candidate) and ``improved`` (it became the best; False
    when frozen), for a caller keeping something of the best's evaluation."""
    _, k_tell = jax.random.split(jax.random.fold_in(evo.key, evo.generation))
    told, ranked, invalid = screen(fitness)
    algo_state, _ = algo.tell(k_tell, pop, told, algo_state, params)
    i = jnp.argmin(ranked)
    better = ranked[i] < evo.best_fitness
    new = evo.replace(
        algo=algo_state,
        best_u=jnp.where(better, pop[i], evo.best_u),
        best_fitness=jnp.where(better, ranked[i], evo.best_fitness),
        stall=jnp.where(better, 0, evo.stall + 1),
        generation=evo.generation + 1,
        evaluations=evo.evaluations + pop.shape[0],
        invalid=evo.invalid + invalid,
    )
    new = new.replace(done=stop(new))
    out = freeze(evo.done, evo, new)
    metrics = {
        "best_fitness": out.best_fitness,
        "generation_best": jnp.where(evo.done, jnp.inf, ranked[i]),
        "invalid": jnp.where(evo.done, 0, invalid),
        "best_index": i,
        "improved": better & ~evo.done,
    }
    return out, metrics


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
    pop, algo_state = evolution_ask(algo, params, evo)
    return evolution_tell(algo, params, evo, pop, algo_state, fitness_u(pop), stop)
