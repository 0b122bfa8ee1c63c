"""The evolutionary algorithms: evosax's registry, built by name, class or instance.

References:
    Lange, "evosax: JAX-based Evolution Strategies", GECCO 2023 companion.
"""

from __future__ import annotations

import inspect
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from evosax.algorithms import algorithms as _EVOSAX_ALGORITHMS

__all__ = ["ALGORITHMS", "algorithm_name", "default_kwargs", "make_algorithm"]

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
    # (a few, e.g. LM_MA_ES, need concrete values: computed eagerly then).
    try:
        params = jax.jit(lambda: algo.default_params)()
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
