"""What an IE run carries from generation to generation (`IEState`), and the
per-point keys it derives from a run's key (`point_keys`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from cgda_jax.strategies.evolution import Evolution

__all__ = ["IEState", "point_keys"]


def point_keys(key: jax.Array, n_points: int) -> jax.Array:
    """The per-point keys (N,) IE derives from a run's key: ``fold_in(key, i)``."""
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(n_points))


@struct.dataclass
class IEState:
    """Carry of an IE run (every field stacked over the N points).

    Attributes:
        evo: the current try of each point.
        keys: the point keys; try t > 0 uses ``fold_in(key, t)``.
        samples: (N, K, D) the K sampled postures nearest each goal point (nearest
            first; K = 0 without restart samples), restart means.
        tries: tries started per point (1 + restarts used).
        best_u, best_fitness: the best over every try (inf: nothing valid yet).
        done: the point is finished (tolerance met, or out of tries).
        generations, evaluations, invalid: spent by the finished tries.
        judged_u, judged_violation: with feasibility (sequential context): the
            bests the last generation judged in context and their moves'
            violations (`cgda_jax.strategies.ie_context`); None otherwise.
    """

    evo: Evolution
    keys: jax.Array
    samples: jax.Array
    tries: jax.Array
    best_u: jax.Array
    best_fitness: jax.Array
    done: jax.Array
    generations: jax.Array
    evaluations: jax.Array
    invalid: jax.Array
    judged_u: jax.Array | None = None
    judged_violation: jax.Array | None = None
