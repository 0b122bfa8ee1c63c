"""Gradient descent through the differentiable simulator (optax): polish and reach.

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

__all__ = ["REFINE", "descend", "nearest_samples", "polish", "polish_trajectory",
           "reachability"]

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
    opt, step = _stepper(method, learning_rate, loss)

    def body(carry, _):
        u, state, best_u, best = carry
        value, u_next, state = step(u, state)
        better = jnp.isfinite(value) & (value < best)
        best_u = jnp.where(better, u, best_u)
        best = jnp.where(better, value, best)
        return (u_next, state, best_u, best), None

    start = loss(u0)
    start = jnp.where(jnp.isfinite(start), start, jnp.inf)
    (u, _, best_u, best), _ = jax.lax.scan(
        body, (u0, opt.init(u0), u0, start), None, length=int(steps))
    last = loss(u)
    keep = jnp.isfinite(last) & (last < best)
    return jnp.where(keep, u, best_u), jnp.where(keep, last, best)


def feasibility_penalty(sim: Any, violation: Any) -> jax.Array:
    """The fitness penalty of ``violation`` on ``sim`` (0 without feasibility):
    added to a polish's loss and score, so that a polished candidate that leaves
    the feasible region is never kept."""
    feas = getattr(sim, "feasibility", None)
    if feas is None or violation is None:
        return jnp.float32(0.0)
    from cgda_jax.sim.feasibility import penalized

    return penalized(jnp.float32(0.0), violation, feas.penalty)


def point_loss(sim: Any, state: Any, goal_point: jax.Array, lower, upper):
    """Squared feature error (scalar) of stepping from `state` to ``to_joints(u)``
    (plus the feasibility penalty of the move; no gradient flows through it)."""

    def loss(u):
        new, feats = sim.step(state, to_joints(u, lower, upper))
        violation = getattr(new, "move_violation", None)
        pen = jax.lax.stop_gradient(feasibility_penalty(sim, violation))
        return jnp.sum((feats - goal_point) ** 2) + pen

    return loss


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
        u, sq = descend(point_loss(sim, state, g, lower, upper), u, method=method,
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
) -> tuple[jax.Array, jax.Array]:
    """The `k` sampled postures nearest each goal point (traced; jittable, vmappable).

    Draws `n_samples` normalized genes uniformly in ``[-1, 1]^D`` (the joint limits),
    maps them to features in ONE batched call ``features_u(u (S, D)) -> (S, F)``
    (the features of each posture stepped to from the start state) and keeps, for
    each goal point (N, F), the `k` nearest.

    Returns:
        ``(genes (N, k, D), distances (N, k))``, nearest first; non-finite features
        (a diverged sample) are never nearest.
    """
    u = jax.random.uniform(key, (int(n_samples), int(n_genes)), minval=-1.0,
                           maxval=1.0)
    dist = jnp.linalg.norm(goal[:, None, :] - features_u(u)[None], axis=-1)  # (N, S)
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
            loss = point_loss(sim, state, g, lower, upper)
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
