"""The fitness of the execution strategies, in one place: how far an execution is
from its goal, and what feasibility adds to it.

Every strategy, restart, polish and result computes its distance to the goal here,
so that the search, the polish and the reported point errors cannot quietly
disagree:

- `distances`: each point's Euclidean feature error to its goal point (the
  paper's IE / IET fitness, the result's point errors, OET's localization);
  `squared_error` its square, `total_error` the Euclidean norm over all points;
- `ordered_point_errors` and `point_errors`: the errors a result reports (OET:
  the goal followed in order by the executed steps);
- `least_motion`: with feasibility, the candidates that meet the aim ranked by
  their joint motion instead (no flailing);
- `penalized` and `feasibility_penalty`: the feasibility penalty, pushing an
  infeasible candidate behind every feasible one;
- `point_fitness`: a point's fitness from the three (the plans' `outcome_fitness`);
- `polish_loss`: the loss a gradient polish descends (squared error plus the
  move's penalty), `polish_penalty` the penalties of many iterates at once;
- `judge_best`: the penalty of only the candidates whose rank matters (the
  collision check is the costly part of a feasible candidate).

Functions of arrays only (NumPy in gives NumPy out where noted, else traced JAX):
the plans (`cgda_jax.strategies.base.PlanBase`) hold the settings they are
called with.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from cgda_jax.strategies.evolution import to_joints

__all__ = ["distances", "feasibility_penalty", "judge_best", "judged_round",
           "least_motion", "ordered_point_errors", "penalized", "point_errors",
           "point_fitness", "polish_loss", "polish_penalty", "squared_error",
           "total_error"]


def distances(features: Any, goal: Any) -> Any:
    """Each point's Euclidean error ``|features - goal|`` over the last axis
    (shapes broadcast: (N, F) and (N, F) -> (N,), (P, F) and (F,) -> (P,)).
    NumPy arrays in (both): NumPy out in their precision; else traced (jnp)."""
    if isinstance(features, np.ndarray) and isinstance(goal, np.ndarray):
        return np.linalg.norm(features - goal, axis=-1)
    return jnp.linalg.norm(features - goal, axis=-1)


def squared_error(features: Array, goal_point: Array) -> Array:
    """The summed squared feature error over the last axis (traced)."""
    return jnp.sum((features - goal_point) ** 2, axis=-1)


def total_error(features: np.ndarray, goal: np.ndarray) -> np.floating:
    """The Euclidean norm of every point's error together (N, F) -> scalar, NumPy
    (IET's fitness over the whole trajectory)."""
    return np.linalg.norm(features - goal)


def ordered_point_errors(dist: np.ndarray, tolerance: float) -> np.ndarray:
    """Each goal point's error when the goal must be followed IN ORDER.

    Goal point j counts as reached by the first executed step, no earlier than the
    step that reached point j-1, within `tolerance` of it (one step may reach
    several close points); its error is that step's. A point not reached that way
    gets its smallest error over the steps from there on (inf when none is left),
    which is >= tolerance, so success (every error < tolerance) means every point
    was reached in order, the last one included.

    Args:
        dist: (N, S) distances between goal point j and executed step i's features.
        tolerance: the reach threshold.

    Returns:
        (N,) errors.
    """
    n_points, n_steps = dist.shape
    out = np.full(n_points, np.inf)
    start = 0
    for j in range(n_points):
        d = dist[j, start:]
        hit = np.flatnonzero(d < tolerance)
        if hit.size:
            out[j] = d[hit[0]]
            start += int(hit[0])
        elif d.size:
            out[j] = d.min()
    return out


def point_errors(strategy: str, features: np.ndarray, goal: np.ndarray,
                 tolerance: float) -> np.ndarray:
    """Each goal point's error (float64) as ``strategy`` judges it: IE / IET / FTE
    the distance of point i's features to goal point i; OET the goal followed in
    order by its executed steps (`ordered_point_errors`)."""
    features, goal = np.asarray(features, np.float64), np.asarray(goal, np.float64)
    if strategy == "oet":
        return ordered_point_errors(distances(goal[:, None, :], features[None, :, :]),
                                    tolerance)
    return distances(features, goal)


def least_motion(error: Array, motion: Array, aim: float) -> Array:
    """``error`` where it misses the aim, else ``aim * motion / (motion + 1)``:
    every candidate that meets the aim still does, and the one that moves least
    (``motion``, radians, Euclidean) ranks first."""
    return jnp.where(error < aim, aim * motion / (motion + 1.0), error)


def penalized(fitness: Array, violation: Array, penalty: float) -> Array:
    """``fitness + penalty * (1 + violation)`` where ``violation > 0``, else
    ``fitness`` (shapes broadcast).  Finite for finite inputs."""
    v = jnp.asarray(violation, jnp.float32)
    return jnp.where(v > 0, fitness + penalty * (1.0 + v), fitness)


def point_fitness(error: Array, violation: Any = None, penalty: float | None = None,
                  *, motion: Array | None = None, aim: float | None = None,
                  prefix_sq: Array | None = None) -> Array:
    """A point's fitness from its ``error`` (P,): ranked by ``motion`` below the
    ``aim`` (`least_motion`, where given), with ``prefix_sq`` (the summed squared
    error of earlier points) ``sqrt(prefix_sq + error^2)``, and `penalized` by
    ``violation`` (where given with a ``penalty``)."""
    if motion is not None:
        error = least_motion(error, motion, aim)
    f = error if prefix_sq is None else jnp.sqrt(prefix_sq + error**2)
    if violation is None or penalty is None:
        return f
    return penalized(f, violation, penalty)


def feasibility_penalty(sim: Any, violation: Any) -> Array:
    """The fitness penalty of ``violation`` on ``sim`` (0 without feasibility):
    added to a polish's loss and score, so that a polished candidate that leaves
    the feasible region is never kept."""
    feas = getattr(sim, "feasibility", None)
    if feas is None or violation is None:
        return jnp.float32(0.0)
    return penalized(jnp.float32(0.0), violation, feas.penalty)


def polish_loss(sim: Any, state: Any, goal_point: Array, lower, upper, *,
                judge: bool = True):
    """Squared feature error (scalar) of stepping from `state` to ``to_joints(u)``
    (plus the feasibility penalty of the move; no gradient flows through it): the
    loss of normalized genes ``u`` (D,) a polish descends.  ``judge=False``:
    the squared error alone, the move not judged (its penalty taken apart,
    `polish_penalty`)."""

    def loss(u):
        q = to_joints(u, lower, upper)
        if not judge and getattr(sim, "feasibility", None) is not None:
            return squared_error(sim.step(state, q, judge=False)[1], goal_point)
        new, feats = sim.step(state, q)
        violation = getattr(new, "move_violation", None)
        pen = jax.lax.stop_gradient(feasibility_penalty(sim, violation))
        return squared_error(feats, goal_point) + pen

    return loss


def polish_penalty(sim: Any, state: Any, lower, upper):
    """``(losses (..., T), iterates (..., T, D)) -> losses (..., T)``: the
    squared errors of `polish_loss` (``judge=False``) of iterates ``u`` with
    the feasibility penalty of their moves from `state` to ``to_joints(u)``
    added where they are judged, the best of each row first, until its
    smallest loss is sure (`judge_best` with one rank, batched: the smallest
    loss of a row and the first iterate that has it are those of judging every
    move; the others at least as large), the judged moves of every row checked
    together (`cgda_jax.sim.simulator.Simulator.judge_moves`: one copy of the
    check, coarse to fine).  None where that does not apply (no feasibility,
    dynamic mode): `polish_loss` then judges each move itself."""
    feas = getattr(sim, "feasibility", None)
    if (feas is None or getattr(sim, "mode", "kinematic") != "kinematic"
            or not hasattr(sim, "judge_moves")):
        return None

    def penalty(losses, us):
        def judge(idx, need):  # idx, need (..., k): the rows' picked iterates
            u = jnp.take_along_axis(us, idx[..., None], axis=-2)
            q = to_joints(u.reshape(-1, u.shape[-1]), lower, upper)
            news = jax.vmap(lambda w: sim.step(state, w, judge=False)[0])(q)
            return sim.judge_moves(state, news, need.reshape(-1)).reshape(idx.shape)

        return judge_best(losses, judge, feas.penalty, 1, judged_round(1))[0]

    return penalty


def judged_round(ranks: int) -> int:
    """How many candidates `judge_best` judges in one round when the best
    ``ranks`` must be exact: ``ranks`` and a quarter more (rounded up), so that a
    few infeasible among the best rarely need a second round."""
    return int(ranks) + -(-int(ranks) // 4)


def judge_best(fitness: Array, judge: Any, penalty: float, ranks: int,
               size: int, lead: int = 0, frozen: Any = False) -> tuple[Array, Array]:
    """The `penalized` fitness of a population where only the candidates whose
    rank matters are judged (traced; fixed shapes).

    ``fitness`` (P,) is the candidates' fitness without the penalty (non-finite:
    invalid, whatever the move); ``judge(idx, need)`` gives the violations
    (size,) of the candidates ``idx`` (size,) (int32; may repeat one) where
    ``need`` (size,) bool holds; the others' values are not used (under a
    ``vmap`` a round runs for every batch entry while any needs it: ``need`` is
    False where this entry's rounds are over, so a judge that packs the batch's
    moves together, `cgda_jax.sim.simulator.Simulator.judge_moves`, skips them). Candidates are judged
    in rounds of ``size``, best ``fitness`` first, until ``ranks`` of the judged
    have a penalized fitness no worse than the best unjudged ``fitness``, or every
    finite candidate is judged (at most ``ceil(P / size)`` rounds, a
    `lax.while_loop`).  A candidate never judged is given ``fitness + penalty``.

    Why the best ``ranks`` are exact (the same set, the same order and values as
    judging every candidate; ``penalty`` > 0): the penalty only adds, so an
    unjudged candidate's true fitness is at least its ``fitness`` >= ``m``, the
    best unjudged ``fitness`` (candidates are judged in ``fitness`` order).  The
    loop stops with ``ranks`` judged candidates at or below ``m``, so the
    ``ranks`` best true values are all among the judged (told their true
    value), and every unjudged one is told ``fitness + penalty`` > ``m``: after
    them, as its true value is.  So is every judged feasible candidate: its
    value is its ``fitness`` <= ``m``.  The order among the candidates after
    the best ``ranks`` may differ from judging all (an unjudged candidate may be
    feasible, or infeasible by more): an algorithm that uses those ranks
    (evosax's CMA-ES gives them negative weights in its covariance update) then
    takes a slightly different step; the best, the mean update and the stop
    tests are exact.

    With ``lead``, the first ``lead`` candidates are other moves that must be
    judged whatever their fitness (IE's bests in their contexts,
    `cgda_jax.strategies.base.PlanBase.ranked_outcome`): they join the first
    round (``size + lead`` judged), count for no rank and leave every round's
    set of the other candidates as without them, so that one call of ``judge``
    judges both and the compiled program carries one copy of the check.

    With ``frozen`` (a scalar bool) True nothing is judged (a caller that
    discards the values: IE's frozen points, `cgda_jax.strategies.ie.IEPlan`).

    Batched: ``fitness`` (..., P) holds populations of their own, each judged
    as above (the rounds run while any needs one), ``judge`` given ``idx`` and
    ``need`` (..., size) at once: one traced call of it, where a ``vmap`` of
    this function would trace the loop's body (and the check in it) again for
    each of its batching passes.

    Returns:
        ``(fitness (..., P), violation (..., P))``: penalized fitness as above;
        the judged candidates' violations, NaN where not judged.
    """
    batch, n, lead = fitness.shape[:-1], fitness.shape[-1], int(lead)
    rows = fitness.reshape(-1, n)  # (B, n): one row unless batched
    frozen = jnp.asarray(frozen, bool)
    size = min(int(size), n - lead)
    rounds = -(-(n - lead) // size)
    first = jnp.arange(n) < lead  # judged in the first round, counted for no rank
    key = jnp.where(first, -jnp.inf, jnp.where(jnp.isfinite(rows), rows, jnp.inf))
    # the leads, then best first (stable: ties by index)
    order = jnp.argsort(key, axis=-1)
    order = jnp.concatenate([order, jnp.broadcast_to(
        order[:, -1:], (rows.shape[0], rounds * size + lead - n))], axis=-1)
    # each round's positions in ``order``: the first round the leads and ``size``
    # more, every later round its ``size`` (the last repeated ``lead`` times)
    at = np.stack([np.concatenate([lead + r * size + np.arange(size),
                                   np.full(lead, lead + r * size + size - 1)])
                   for r in range(rounds)])
    at[0] = np.arange(size + lead)
    at = jnp.asarray(at, jnp.int32)
    need = min(int(ranks), n - lead)
    row = jnp.arange(rows.shape[0])[:, None]

    def told(violation, judged):
        return jnp.where(judged, penalized(rows, violation, penalty), rows + penalty)

    def going(carry):  # (B,): the rows whose rounds go on
        r, violation, judged = carry
        left = judged | ~(jnp.isfinite(rows) | first)
        m = jnp.min(jnp.where(left, jnp.inf, key), axis=-1, keepdims=True)
        ok = judged & ~first & (told(violation, judged) <= m)
        enough = (jnp.sum(ok, axis=-1) >= need) | jnp.all(left, axis=-1)
        return (r < rounds) & ~enough & ~frozen

    def body(carry):
        r, violation, judged = carry
        idx = order[:, at[r]].astype(jnp.int32)  # (B, size + lead)
        need = jnp.broadcast_to(going(carry)[:, None], idx.shape)
        v = jnp.asarray(judge(idx.reshape(*batch, -1), need.reshape(*batch, -1)),
                        jnp.float32).reshape(idx.shape)
        v = jnp.where(need, v, violation[row, idx])  # rows done: as they were
        return (r + 1, violation.at[row, idx].set(v),
                judged.at[row, idx].set(judged[row, idx] | need))

    carry = (jnp.int32(0), jnp.full(rows.shape, jnp.nan, jnp.float32),
             jnp.zeros(rows.shape, bool))
    _, violation, judged = jax.lax.while_loop(lambda c: jnp.any(going(c)), body,
                                              carry)
    return (told(violation, judged).reshape(fitness.shape),
            violation.reshape(fitness.shape))
