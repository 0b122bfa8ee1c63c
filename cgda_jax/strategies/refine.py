"""Postures found outside the evolution: gradient descent through the differentiable
simulator (optax: polish and reach) and sampled start means.

Where a step's features depend only on its posture and the simulator is differentiable
(kinematic mode with a stateless scene: the marker; see `points_independent`), the
squared error of one goal point is a smooth function of the normalized genes ``u``
(joint angles ``to_joints(u)``, inside the limits by construction). Two uses:

- `polish`: after evolution, descend each point's error from its best genes with an
  optax optimiser ("adam" or "lbfgs"), keeping the best iterate (never worse than the
  start);
- `reachability`: before evolving, sample thousands of postures through the batched
  forward kinematics, descend from the nearest few per goal point, and report the
  points that no posture brings within tolerance (with their nearest approach), so a
  run need not spend its budget on them.

Discrete features (a painted percentage) have no useful gradient: both need
`points_independent` (the caller checks).

Sampled start means (`sample_pool`, `nearest_in_pool`, `descended_candidates`,
`pick_candidate`): start means for evolutions: the nearest of many sampled postures to each goal point.

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

import time
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from cgda_jax.strategies.base import to_joints
from cgda_jax.strategies.fitness import distances, feasibility_penalty, polish_loss

__all__ = ["REFINE", "best_iterate", "descend", "descended_candidates",
           "descent_path", "nearest_in_pool", "nearest_samples", "pick_candidate",
           "polish", "polish_trajectory", "reachability", "sample_pool"]

#: Names accepted by ``refine=``.
REFINE = ("none", "adam", "lbfgs")


def _optimizer(method: str, learning_rate: float):
    if method == "adam":
        return optax.adam(learning_rate)
    if method == "lbfgs":
        return optax.lbfgs()
    raise ValueError(f"refine={method!r}; expected one of {REFINE}")


def _stepper(method: str, learning_rate: float, loss):
    """``(optimizer, step)``: ``step(u, state) -> (loss(u), next u, next state)``,
    one optax update of `method` (L-BFGS gets the value and its line search)."""
    opt = _optimizer(method, learning_rate)
    value_and_grad = (optax.value_and_grad_from_state(loss) if method == "lbfgs"
                      else jax.value_and_grad(loss))

    def step(u, state):
        if method == "lbfgs":
            value, grad = value_and_grad(u, state=state)
            updates, state = opt.update(grad, state, u, value=value, grad=grad,
                                        value_fn=loss)
        else:
            value, grad = value_and_grad(u)
            updates, state = opt.update(grad, state, u)
        return value, optax.apply_updates(u, updates), state

    return opt, step


def descend(
    loss: Callable[[jax.Array], jax.Array],
    u0: jax.Array,
    *,
    method: str = "adam",
    steps: int = 100,
    learning_rate: float = 0.02,
) -> tuple[jax.Array, jax.Array]:
    """Minimize ``loss(u)`` from ``u0`` (D,) for `steps` optax steps (one example).

    Returns:
        ``(best u, its loss)``: the best iterate seen, ``u0`` included, so the result
        is never worse than the start. Non-finite losses are never kept.
    """
    return best_iterate(*descent_path(loss, u0, method=method, steps=steps,
                                      learning_rate=learning_rate))


def descent_path(
    loss: Callable[[jax.Array], jax.Array],
    u0: jax.Array,
    *,
    method: str = "adam",
    steps: int = 100,
    learning_rate: float = 0.02,
) -> tuple[jax.Array, jax.Array]:
    """Every iterate of `descend` and its loss: ``u0``, each step's and the
    last, ``(iterates (steps + 2, D), losses (steps + 2,))``; `best_iterate` is
    `descend`'s choice among them (for losses given a term apart first, e.g.
    the moves' feasibility penalty judged together,
    `cgda_jax.strategies.fitness.polish_penalty`)."""
    opt, step = _stepper(method, learning_rate, loss)

    def body(carry, _):
        u, state = carry
        value, u_next, state = step(u, state)
        return (u_next, state), (value, u)

    start = loss(u0)
    (u, _), (values, us) = jax.lax.scan(body, (u0, opt.init(u0)), None,
                                        length=int(steps))
    return (jnp.concatenate([u0[None], us, u[None]]),
            jnp.concatenate([start[None], values, loss(u)[None]]))


def best_iterate(iterates: jax.Array, losses: jax.Array
                 ) -> tuple[jax.Array, jax.Array]:
    """`descend`'s choice among `descent_path`'s iterates (T, D) by their losses
    (T,): the first of the smallest finite losses (``u0`` when none is finite;
    its loss inf)."""
    i = jnp.argmin(jnp.where(jnp.isfinite(losses), losses, jnp.inf))
    return iterates[i], jnp.where(jnp.isfinite(losses[i]), losses[i], jnp.inf)


def polish(
    sim: Any,
    best_u: jax.Array,
    goal: jax.Array,
    *,
    method: str = "adam",
    steps: int = 100,
    learning_rate: float = 0.02,
) -> tuple[jax.Array, jax.Array]:
    """Refine each point's genes (N, D) towards its goal point (N, F) from the start
    state (points independent). Returns ``(genes (N, D), errors (N,))``."""
    lower = jnp.asarray(sim.lower, jnp.float32)
    upper = jnp.asarray(sim.upper, jnp.float32)
    state = sim.init_state()

    def one(u, g):
        u, sq = descend(polish_loss(sim, state, g, lower, upper), u, method=method,
                        steps=steps, learning_rate=learning_rate)
        return u, jnp.sqrt(sq)

    return jax.vmap(one)(best_u, goal)


def nearest_samples(
    features_u: Callable[[jax.Array], jax.Array],
    goal: jax.Array,
    key: jax.Array,
    n_genes: int,
    n_samples: int,
    k: int,
    around: jax.Array | None = None,
    width: float = 1.0,
) -> tuple[jax.Array, jax.Array]:
    """The `k` sampled postures nearest each goal point (traced; jittable, vmappable).

    Draws `n_samples` normalized genes uniformly in ``[-1, 1]^D`` (the joint limits;
    with ``around`` (D,): in ``around +- width``, clipped to the limits), maps them
    to features in ONE batched call ``features_u(u (S, D)) -> (S, F)`` (the
    features of each posture stepped to from the start state) and keeps, for
    each goal point (N, F), the `k` nearest.

    Returns:
        ``(genes (N, k, D), distances (N, k))``, nearest first; non-finite features
        (a diverged sample) are never nearest.
    """
    u = jax.random.uniform(key, (int(n_samples), int(n_genes)), minval=-1.0,
                           maxval=1.0)
    if around is not None:
        u = jnp.clip(around + width * u, -1.0, 1.0)
    dist = distances(goal[:, None, :], features_u(u)[None])  # (N, S)
    dist = jnp.where(jnp.isfinite(dist), dist, jnp.inf)
    neg, idx = jax.lax.top_k(-dist, int(k))  # (N, k)
    return u[idx], -neg


def reachability(
    sim: Any,
    goal: Any,
    tolerance: float,
    *,
    n_samples: int = 2048,
    n_starts: int = 4,
    steps: int = 60,
    seed: int = 0,
) -> dict[str, Any]:
    """Which goal points (N, F) no posture brings within `tolerance`.

    Samples `n_samples` postures uniformly in the joint limits (one batched forward
    kinematics call), then descends (adam) from the `n_starts` nearest samples of each
    goal point.

    Returns:
        dict with ``nearest`` (N,) nearest approach found, ``genes`` (N, D) the
        normalized genes reaching it, ``unreachable`` (indices with nearest >=
        tolerance) and ``seconds``.
    """
    t0 = time.perf_counter()
    goal = jnp.asarray(goal, jnp.float32)
    lower = jnp.asarray(sim.lower, jnp.float32)
    upper = jnp.asarray(sim.upper, jnp.float32)

    @jax.jit
    def run(key):
        state = sim.init_state()
        starts, _ = nearest_samples(
            lambda u: jax.vmap(lambda w: sim.step(state, w)[1])(
                to_joints(u, lower, upper)), goal, key, sim.n_dof, n_samples, n_starts)

        def refine(g, starts):
            loss = polish_loss(sim, state, g, lower, upper)
            us, sq = jax.vmap(lambda s: descend(loss, s, steps=steps,
                                                learning_rate=0.05))(starts)
            i = jnp.argmin(sq)
            return us[i], jnp.sqrt(sq[i])

        return jax.vmap(refine)(goal, starts)

    genes, nearest = run(jax.random.key(seed))
    nearest = np.asarray(nearest, np.float64)
    return {
        "nearest": nearest,
        "genes": np.asarray(genes),
        "unreachable": [int(i) for i in np.flatnonzero(~(nearest < tolerance))],
        "seconds": time.perf_counter() - t0,
    }


def polish_trajectory(
    sim: Any,
    u0: jax.Array,
    goal: jax.Array,
    distance: Callable[[jax.Array, jax.Array], jax.Array],
    *,
    method: str = "adam",
    steps: int = 100,
    gamma: float = 1e-3,
    multi: bool = False,
    learning_rate: float = 0.02,
) -> tuple[jax.Array, jax.Array]:
    """Refine a whole trajectory's genes (FTE) by descending the soft-DTW.

    The loss is ``soft_dtw(executed features, goal, gamma, multi=multi)`` of the
    trajectory ``to_joints(u.reshape(N, D))`` executed from the start state (the
    kinematic chain is differentiable); the iterate KEPT is the one with the lowest
    true `distance` (the FTE fitness), ``u0`` included, so the result is never worse
    than the start by that distance. Non-finite distances are never kept.

    Args:
        sim: a simulator whose execution is differentiable (kinematic mode,
            stateless scene; the caller checks).
        u0: (N * D,) the start genes (FTE's best).
        goal: (N, F) goal features.
        distance: the true fitness ``(executed (N, F), goal (N, F)) -> scalar``.
        method: "adam" or "lbfgs".
        steps: optimiser steps.
        gamma: soft-DTW smoothing.
        multi: soft-DTW with `dtw_multi`'s local cost (else `dtw`'s).
        learning_rate: adam's step size (lbfgs uses its line search).

    Returns:
        ``(genes (N * D,), their distance)``.
    """
    from cgda_jax.distance import soft_dtw

    goal = jnp.asarray(goal)
    lower = jnp.asarray(sim.lower, jnp.float32)
    upper = jnp.asarray(sim.upper, jnp.float32)
    n_points = goal.shape[0]
    state0 = sim.init_state()

    def rollout(u):
        q = to_joints(u.reshape(n_points, -1), lower, upper)
        return sim.rollout(q, state0)

    def loss(u):
        return soft_dtw(rollout(u)[0], goal, gamma, multi=multi)

    def score(u):
        feats, final = rollout(u)
        d = distance(feats, goal) + feasibility_penalty(
            sim, getattr(final, "violation", None))
        return jnp.where(jnp.isfinite(d), d, jnp.inf)

    opt, step = _stepper(method, learning_rate, loss)

    def body(carry, _):
        u, state, best_u, best = carry
        _, u, state = step(u, state)
        d = score(u)
        better = d < best
        return (u, state, jnp.where(better, u, best_u),
                jnp.where(better, d, best)), None

    (_, _, best_u, best), _ = jax.lax.scan(
        body, (u0, opt.init(u0), u0, score(u0)), None, length=int(steps))
    return best_u, best


# --------------------------------------------------------------------------- sampled start means
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
    dist = distances(goal[:, None, :], features[None, :, :])  # (N, S)
    dist = jnp.where(jnp.isfinite(dist), dist, jnp.inf)
    out = jnp.zeros(dist.shape, bool)
    if key is not None:
        out = out | ~jax.random.bernoulli(key, keep, (1, genes.shape[0]))
    if avoid is not None:
        gap = distances(genes[None, :, :], avoid[:, None, :])
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
    penalty: Callable[[jax.Array], jax.Array] | None = None,
) -> tuple[jax.Array, jax.Array]:
    """Per goal point, its `n_starts` nearest pool samples descended (adam) on the
    point's squared feature error (differentiable simulators only).

    Args:
        genes, features: the pool (S, D), (S, F) (`sample_pool`).
        goal: (N, F) goal points.
        loss_of: goal point (F,) -> loss of the genes (D,) -> squared error.
        n_starts, steps, learning_rate: of the descent
            (`cgda_jax.strategies.refine.descend`).
        penalty: None, or ``(losses (..., T), iterates (..., T, D)) ->
            losses`` with the feasibility penalty
            (`cgda_jax.strategies.fitness.polish_penalty`): every point's and
            start's iterates
            (`descent_path`, on ``loss_of``'s loss without it) penalized in one
            call, then each descent's best chosen (`best_iterate`).

    Returns:
        ``(genes (N, K, D), errors (N, K))``: K = `n_starts` local minima (or
        near them) per point, their Euclidean errors (inf where not finite).
    """
    dist = distances(goal[:, None, :], features[None, :, :])
    dist = jnp.where(jnp.isfinite(dist), dist, jnp.inf)
    _, idx = jax.lax.top_k(-dist, min(int(n_starts), genes.shape[0]))  # (N, K)

    if penalty is None:
        def point(g, starts):
            loss = loss_of(g)
            return jax.vmap(lambda s: descend(loss, s, steps=steps,
                                              learning_rate=learning_rate))(
                genes[starts])

        u, sq = jax.vmap(point)(goal, idx)
    else:  # every point's and start's iterates penalized together, then chosen
        def path(g, starts):
            loss = loss_of(g)
            return jax.vmap(lambda s: descent_path(loss, s, steps=steps,
                                                   learning_rate=learning_rate))(
                genes[starts])

        us, losses = jax.vmap(path)(goal, idx)  # (N, K, T, D), (N, K, T)
        u, sq = jax.vmap(jax.vmap(best_iterate))(us, penalty(losses, us))
    err = jnp.sqrt(sq)
    return u, jnp.where(jnp.isfinite(err), err, jnp.inf)


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
        away = ~(distances(genes, avoid[:, None, :]) <= radius)
    pref = ok & away
    for alt in (ok, away, jnp.isfinite(errors)):
        pref = jnp.where(jnp.any(pref, axis=1, keepdims=True), pref, alt)
    score = jax.random.uniform(key, errors.shape) + pref  # a random preferred one
    i = jnp.argmax(score, axis=1)
    return jnp.take_along_axis(genes, i[:, None, None], axis=1)[:, 0]
