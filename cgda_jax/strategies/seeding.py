"""Start means for evolutions: the nearest of many sampled postures to each goal point.

A distribution-based evolution (CMA-ES) started at the middle of the joint ranges
often settles in the wrong inverse-kinematics branch. Sampling postures uniformly in
the joint limits and executing them in batched simulator calls gives, for every goal
point, a posture already near it; its genes make a sound start mean (FTE: the whole
trajectory; restarts: the points that missed). The pool is sampled once per run
(`sample_pool`); restarts pick from it again (`nearest_in_pool`, no simulator call),
from a random half of it and away from where the point stuck. Everything here is
traced (jittable, vmappable over keys): no host work, no Python loop per restart.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

__all__ = ["nearest_in_pool", "sample_pool"]


def sample_pool(
    key: jax.Array,
    point_features: Callable[[jax.Array], jax.Array],
    n_genes: int,
    n_samples: int,
    batch: int | None = None,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Random postures and their features.

    Args:
        key: random key of the samples.
        point_features: normalized genes (B, D) -> features (B, F) (one batched
            simulator call, e.g. one step from the start state).
        n_genes: D.
        n_samples: S, drawn uniformly in ``[-1, 1]^D`` (the whole joint ranges).
        batch: evaluate the samples in batches of this size (the strategy's
            population size, so every simulator call has the shape of a
            generation's); S is rounded up to a multiple of it. None: one call.

    Returns:
        ``(genes (S', D), features (S', F), invalid)`` with S' the rounded S and
        `invalid` the count (int32) of samples whose features are not finite.
    """
    b = int(n_samples) if batch is None else int(batch)
    n_batches = -(-int(n_samples) // b)
    u = jax.random.uniform(key, (n_batches, b, int(n_genes)), minval=-1.0,
                           maxval=1.0)
    feats = jax.lax.map(point_features, u)
    u, feats = u.reshape(n_batches * b, -1), feats.reshape(n_batches * b, -1)
    invalid = jnp.sum(~jnp.all(jnp.isfinite(feats), axis=-1)).astype(jnp.int32)
    return u, feats, invalid


def nearest_in_pool(
    genes: jax.Array,
    features: jax.Array,
    goal: jax.Array,
    *,
    key: jax.Array | None = None,
    keep: float = 0.5,
    avoid: jax.Array | None = None,
    radius: float = 1.0,
) -> tuple[jax.Array, jax.Array]:
    """For each goal point, the genes of its nearest pool sample (feature distance).

    Args:
        genes, features: the pool (S, D), (S, F) (`sample_pool`).
        goal: (N, F) goal points.
        key: optional: draw from a random subset of the pool (each sample kept
            with probability `keep`), so repeated draws differ.
        keep: see `key`.
        avoid: optional (N, D) genes (NaN rows: nothing to avoid); point i then
            takes the nearest sample farther than `radius` (Euclidean, normalized
            genes) from ``avoid[i]``: a restart leaves the basin it was stuck in.
        radius: see `avoid`.

    Returns:
        ``(genes (N, D), distance (N,))``; where every candidate is excluded the
        plain nearest is taken.
    """
    dist = jnp.linalg.norm(goal[:, None, :] - features[None, :, :], axis=-1)  # (N, S)
    dist = jnp.where(jnp.isfinite(dist), dist, jnp.inf)
    out = jnp.zeros(dist.shape, bool)
    if key is not None:
        out = out | ~jax.random.bernoulli(key, keep, (1, genes.shape[0]))
    if avoid is not None:
        gap = jnp.linalg.norm(genes[None, :, :] - avoid[:, None, :], axis=-1)
        out = out | (gap <= radius)  # NaN rows: never near
    out = out & ~jnp.all(out | ~jnp.isfinite(dist), axis=1, keepdims=True)
    i = jnp.argmin(jnp.where(out, jnp.inf, dist), axis=1)
    return genes[i], jnp.take_along_axis(dist, i[:, None], axis=1)[:, 0]


def descended_candidates(
    genes: jax.Array,
    features: jax.Array,
    goal: jax.Array,
    loss_of: Callable[[jax.Array], Callable[[jax.Array], jax.Array]],
    *,
    n_starts: int = 4,
    steps: int = 60,
    learning_rate: float = 0.05,
) -> tuple[jax.Array, jax.Array]:
    """Per goal point, its `n_starts` nearest pool samples descended (adam) on the
    point's squared feature error (differentiable simulators only).

    Args:
        genes, features: the pool (S, D), (S, F) (`sample_pool`).
        goal: (N, F) goal points.
        loss_of: goal point (F,) -> loss of the genes (D,) -> squared error.
        n_starts, steps, learning_rate: of the descent
            (`cgda_jax.strategies.refine.descend`).

    Returns:
        ``(genes (N, K, D), errors (N, K))``: K = `n_starts` local minima (or
        near them) per point, their Euclidean errors (inf where not finite).
    """
    from cgda_jax.strategies.refine import descend

    dist = jnp.linalg.norm(goal[:, None, :] - features[None, :, :], axis=-1)
    dist = jnp.where(jnp.isfinite(dist), dist, jnp.inf)
    _, idx = jax.lax.top_k(-dist, min(int(n_starts), genes.shape[0]))  # (N, K)

    def point(g, starts):
        loss = loss_of(g)
        u, sq = jax.vmap(lambda s: descend(loss, s, steps=steps,
                                           learning_rate=learning_rate))(genes[starts])
        err = jnp.sqrt(sq)
        return u, jnp.where(jnp.isfinite(err), err, jnp.inf)

    return jax.vmap(point)(goal, idx)


def pick_candidate(
    key: jax.Array,
    genes: jax.Array,
    errors: jax.Array,
    tolerance: float,
    avoid: jax.Array | None = None,
    radius: float = 1.0,
) -> jax.Array:
    """Per point, one of its candidates (N, K, D) at random: among those within
    `tolerance` (errors (N, K)) and farther than `radius` from ``avoid`` (N, D) (NaN
    rows: nothing to avoid) when there are any, else among those within tolerance,
    else among those away from ``avoid``, else any. Returns genes (N, D)."""
    ok = errors < tolerance
    away = jnp.ones(errors.shape, bool)
    if avoid is not None:
        away = ~(jnp.linalg.norm(genes - avoid[:, None, :], axis=-1) <= radius)
    pref = ok & away
    for alt in (ok, away, jnp.isfinite(errors)):
        pref = jnp.where(jnp.any(pref, axis=1, keepdims=True), pref, alt)
    score = jax.random.uniform(key, errors.shape) + pref  # a random preferred one
    i = jnp.argmax(score, axis=1)
    return jnp.take_along_axis(genes, i[:, None, None], axis=1)[:, 0]
