"""One evolution: its state, its start and its generation step (ask -> one batched
evaluation -> tell), with invalid (diverged) candidates screened out.

Divergence. A candidate whose fitness is not finite (a simulation that blew up: NaN or
inf features) is *invalid*: it is told to the algorithm with the finite fitness
`INVALID_PENALTY` (ranked after every valid candidate, so no algorithm state turns
NaN), it is never kept as the best, and it is counted (`Evolution.invalid`, the
``invalid`` metric of every generation). The best of an evolution is always a
candidate that was evaluated and finite; until there is one, ``best_fitness`` is inf
and `Evolution.found` is False.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from evosax.algorithms.population_based.base import PopulationBasedAlgorithm
from flax import struct

__all__ = ["INVALID_PENALTY", "Evolution", "FitnessFn", "evolution_ask",
           "evolution_init", "evolution_step", "evolution_tell", "freeze", "screen"]

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
