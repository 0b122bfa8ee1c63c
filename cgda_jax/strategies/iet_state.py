"""What an IET run carries from generation to generation (`IETState`), and the
stacked-pytree access it uses for the simulator states before each point."""

from __future__ import annotations

from typing import Any

import jax
from flax import struct

from cgda_jax.strategies.base import Evolution

__all__ = ["IETState", "tree_at", "tree_set"]


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
