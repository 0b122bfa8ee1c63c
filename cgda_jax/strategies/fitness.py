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
  move's penalty).

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

__all__ = ["distances", "feasibility_penalty", "least_motion", "ordered_point_errors",
           "penalized", "point_errors", "point_fitness", "polish_loss",
           "squared_error", "total_error"]


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


def polish_loss(sim: Any, state: Any, goal_point: Array, lower, upper):
    """Squared feature error (scalar) of stepping from `state` to ``to_joints(u)``
    (plus the feasibility penalty of the move; no gradient flows through it): the
    loss of normalized genes ``u`` (D,) a polish descends."""

    def loss(u):
        new, feats = sim.step(state, to_joints(u, lower, upper))
        violation = getattr(new, "move_violation", None)
        pen = jax.lax.stop_gradient(feasibility_penalty(sim, violation))
        return squared_error(feats, goal_point) + pen

    return loss
