"""The timing of a minimum-jerk move and its peaks against joint limits.

The dynamic mode (`cgda_jax.sim.simulator`) moves each joint from
``q0`` to ``q1 = q0 + dq`` along the minimum-jerk profile
``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5``, ``tau = t / T`` in [0, 1], over the move's
duration ``T`` (``move_fraction * waypoint_s`` there), then holds.  With
``q(t) = q0 + dq s(t / T)``:

- velocity ``dq s'(tau) / T``, ``s'(tau) = 30 tau^2 (1 - tau)^2``, largest at
  ``tau = 1/2``: ``s'(1/2) = 30/16``, so **peak speed = 1.875 |dq| / T**;
- acceleration ``dq s''(tau) / T^2``, ``s''(tau) = 60 tau (1 - tau) (1 - 2 tau)``,
  largest in magnitude where ``s'''(tau) = 60 - 360 tau + 360 tau^2 = 0``, i.e.
  ``tau = (1 -+ 1/sqrt(3)) / 2``, where ``tau (1 - tau) = 1/6`` and
  ``|1 - 2 tau| = 1/sqrt(3)``: ``|s''| = 10 / sqrt(3)``, so **peak acceleration =
  (10 / sqrt(3)) |dq| / T^2 = 5.7735 |dq| / T^2**.

Hence the shortest duration within a velocity limit ``v`` and an acceleration limit
``a`` is ``max(1.875 |dq| / v, sqrt(5.7735 |dq| / a))`` over the joints (`min_duration`).
These are the continuous-time peaks; the simulator samples the reference at its
physics steps, whose discrete peaks are at most these.

Example:
    >>> import jax.numpy as jnp
    >>> from cgda_jax.sim.timing import move_peaks
    >>> speed, acc = move_peaks(jnp.array([1.0]), 1.0)
    >>> round(float(speed[0]), 4), round(float(acc[0]), 4)
    (1.875, 5.7735)
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from cgda_jax.sim.limits import JointLimits

__all__ = [
    "PEAK_ACCELERATION",
    "PEAK_JERK",
    "PEAK_SPEED",
    "MoveSamples",
    "approach_duration",
    "min_duration",
    "min_jerk",
    "min_jerk_d1",
    "min_jerk_d2",
    "move_peaks",
    "move_samples",
    "shortest_duration",
    "violation",
]

#: max over tau of s'(tau) = 30 tau^2 (1 - tau)^2, at tau = 1/2: 30/16.
PEAK_SPEED = 1.875
#: max over tau of |s''(tau)| = |60 tau (1 - tau) (1 - 2 tau)|: 10 / sqrt(3).
PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)
#: max over tau of |s'''(tau)| = |60 - 360 tau + 360 tau^2|: 60, at tau = 0 and 1.
PEAK_JERK = 60.0


# -- the minimum-jerk move -------------------------------------------------------------
def reference_profile(steps: int, move_steps: int) -> np.ndarray:
    """The share of a minimum-jerk move done after each of ``steps`` physics steps
    when the move takes ``move_steps`` of them (then 1: the hold), (steps,) float32."""
    tau = np.minimum(np.arange(1, steps + 1) / max(1, move_steps), 1.0)
    return (10 * tau**3 - 15 * tau**4 + 6 * tau**5).astype(np.float32)


def approach_profile(approach_s: float, dt: float, steps: int, move_steps: int
                     ) -> tuple[float, np.ndarray]:
    """The first move's reference: a minimum-jerk move over ``approach_s`` (rounded
    up to whole ``dt`` steps), then the hold of the other moves (``steps`` physics
    steps of which ``move_steps`` move).

    Returns:
        (the approach's move time [s], its profile (steps,) float32).
    """
    k = max(1, int(np.ceil(approach_s / dt - 1e-9)))
    return k * dt, reference_profile(k + steps - move_steps, k)


def min_jerk(tau: Array) -> Array:
    """Minimum-jerk profile ``s = 10 tau^3 - 15 tau^4 + 6 tau^5``, 0 -> 1 (JAX,
    float32; host code without JAX: `cgda_jax.numerics.min_jerk_np`).

    Args:
        tau: (...) normalized time ``t / T``; clipped into [0, 1] (0 before the move,
            1 after it).

    Returns:
        (...) the share of the move done.
    """
    t = jnp.clip(jnp.asarray(tau, jnp.float32), 0.0, 1.0)
    return t**3 * (10.0 + t * (-15.0 + 6.0 * t))


def min_jerk_d1(tau: Array) -> Array:
    """``ds/dtau = 30 tau^2 (1 - tau)^2`` (0 outside [0, 1]); velocity = dq s' / T.

    Args:
        tau: (...) normalized time.

    Returns:
        (...) the profile's first derivative per unit tau.
    """
    tau = jnp.asarray(tau, jnp.float32)
    inside = (tau >= 0.0) & (tau <= 1.0)
    return jnp.where(inside, 30.0 * tau**2 * (1.0 - tau) ** 2, 0.0)


def min_jerk_d2(tau: Array) -> Array:
    """``d2s/dtau2 = 60 tau (1 - tau) (1 - 2 tau)`` (0 outside [0, 1]);
    acceleration = dq s'' / T^2.

    Args:
        tau: (...) normalized time.

    Returns:
        (...) the profile's second derivative per unit tau^2.
    """
    tau = jnp.asarray(tau, jnp.float32)
    inside = (tau >= 0.0) & (tau <= 1.0)
    return jnp.where(inside, 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau), 0.0)


def _safe_div(num: Array, den: Array) -> Array:
    """num / den, 0 where num == 0 (also for den == 0), with finite gradients there."""
    zero = num == 0
    return jnp.where(zero, 0.0, num / jnp.where(zero, 1.0, den))


def move_peaks(dq: Array, duration) -> tuple[Array, Array]:
    """Peak speed and peak acceleration of a minimum-jerk move (closed form).

    ``peak_speed = 1.875 |dq| / T`` (at t = T/2) and
    ``peak_acceleration = (10 / sqrt(3)) |dq| / T^2`` (at t = T (1 -+ 1/sqrt(3)) / 2);
    derived in the module doc.  Jittable and vmappable.

    Args:
        dq: (..., DoF) the move, ``q1 - q0`` (rad or m).
        duration: scalar (or broadcastable to ``dq``) move time T in seconds, > 0.

    Returns:
        (peak_speed, peak_acceleration), each (..., DoF), rad/s and rad/s^2 (m/s,
        m/s^2 for slides); 0 where ``dq`` is 0, ``inf`` for a move in zero time.
    """
    a = jnp.abs(jnp.asarray(dq, jnp.float32))
    t = jnp.asarray(duration, jnp.float32)
    return PEAK_SPEED * _safe_div(a, t), PEAK_ACCELERATION * _safe_div(a, t * t)


class MoveSamples(NamedTuple):
    """A minimum-jerk move sampled at equally spaced times (a pytree).

    Attributes:
        t: (n,) times from 0 to T, seconds.
        q: (n, DoF) positions (rad or m).
        qd: (n, DoF) velocities (rad/s or m/s).
        qdd: (n, DoF) accelerations (rad/s^2 or m/s^2).
    """

    t: Array
    q: Array
    qd: Array
    qdd: Array


def move_samples(q0: Array, q1: Array, duration, n: int) -> MoveSamples:
    """Positions, velocities and accelerations of the minimum-jerk move ``q0 -> q1``
    at ``n`` equally spaced times ``0, T/(n-1), ..., T`` (for reports and figures).

    Jittable with ``n`` static (``jax.jit(move_samples, static_argnames="n")``).

    Args:
        q0: (DoF,) start posture.
        q1: (DoF,) end posture.
        duration: the move time T in seconds, > 0.
        n: number of samples, >= 2 (a Python int).

    Returns:
        `MoveSamples` (t (n,), q, qd, qdd (n, DoF)).
    """
    n = int(n)
    if n < 2:
        raise ValueError(f"move_samples needs n >= 2 samples, got {n}")
    q0 = jnp.asarray(q0, jnp.float32)
    dq = jnp.asarray(q1, jnp.float32) - q0
    t_end = jnp.asarray(duration, jnp.float32)
    tau = jnp.linspace(0.0, 1.0, n, dtype=jnp.float32)
    q = q0 + min_jerk(tau)[:, None] * dq
    qd = min_jerk_d1(tau)[:, None] * dq / t_end
    qdd = min_jerk_d2(tau)[:, None] * dq / t_end**2
    return MoveSamples(t=tau * t_end, q=q, qd=qd, qdd=qdd)


def shortest_duration(abs_dq, velocity, acceleration, jerk=None, xp=np):
    """Shortest minimum-jerk duration of ``|dq|`` (..., DoF) within the velocity,
    acceleration and (optional) jerk limits (DoF,): ``max_j max(1.875 |dq_j| / v_j,
    sqrt(5.7735 |dq_j| / a_j), cbrt(60 |dq_j| / j_j))``, max over the last axis; inf
    limits and zero moves contribute 0.  ``xp``: numpy (float64 in, float64 out) or
    jax.numpy (jittable)."""
    def term(peak, limit, root):
        off = (abs_dq == 0) | xp.isinf(limit)
        ratio = xp.where(off, 1.0, peak * abs_dq / xp.where(off, 1.0, limit))
        return xp.where(off, 0.0, root(ratio))

    t = xp.maximum(term(PEAK_SPEED, velocity, lambda x: x),
                   term(PEAK_ACCELERATION, acceleration, xp.sqrt))
    if jerk is not None:
        t = xp.maximum(t, term(PEAK_JERK, jerk, xp.cbrt))
    return xp.max(t, axis=-1)


def min_duration(dq: Array, limits: JointLimits) -> Array:
    """The shortest duration of a minimum-jerk move of ``dq`` within the velocity and
    acceleration limits: ``max_j max(1.875 |dq_j| / v_j, sqrt(5.7735 |dq_j| / a_j))``.
    A move that long reaches the binding limit exactly (`move_peaks`).  Jittable and
    vmappable (``limits`` is a pytree).

    In the simulator's dynamic mode the move lasts ``move_fraction * waypoint_s``, so
    a waypoint needs ``waypoint_s >= min_duration / move_fraction``.

    Args:
        dq: (..., DoF) the move (rad or m).
        limits: `JointLimits` of the same joints (inf: unlimited, ignored).

    Returns:
        (...) seconds, float32; 0 when ``dq`` is 0 (or every joint that moves is
        unlimited).
    """
    a = jnp.abs(jnp.asarray(dq, jnp.float32))
    return shortest_duration(a, jnp.asarray(limits.velocity, jnp.float32),
                             jnp.asarray(limits.acceleration, jnp.float32), xp=jnp)


def approach_duration(lower, upper, start, limits: JointLimits, floor: float = 0.0
                      ) -> float:
    """A move duration (a static Python float) long enough for a minimum-jerk move from
    ``start`` to ANY posture in the box ``[lower, upper]`` to respect the limits.

    The worst case over the box: `min_duration` grows with each ``|dq_j|`` on its
    own, so it is the move to the corner farthest from ``start`` in every joint,
    ``max(|upper - start|, |lower - start|)``.

    Args:
        lower: (DoF,) the box's lower corner (e.g. ``robot.lower``).
        upper: (DoF,) its upper corner.
        start: (DoF,) the start posture (e.g. ``robot.start_genes``).
        limits: `JointLimits` of the same joints.
        floor: the least duration returned, seconds (>= 0).

    Returns:
        ``max(floor, min_duration(worst dq, limits))`` in seconds.

    Raises:
        ValueError: shapes differ, ``floor`` is negative or not finite, or an
            unbounded box side meets a finite limit (no duration is enough).
    """
    lower, upper, start = (np.asarray(x, dtype=np.float64).reshape(-1)
                           for x in (lower, upper, start))
    n = limits.n_dof
    if not lower.shape == upper.shape == start.shape == (n,):
        raise ValueError(f"approach_duration: lower {lower.shape}, upper {upper.shape} "
                         f"and start {start.shape} must all be ({n},)")
    floor = float(floor)
    if not (math.isfinite(floor) and floor >= 0):
        raise ValueError(f"approach_duration: floor must be >= 0 seconds, got {floor}")
    worst = np.maximum(np.abs(upper - start), np.abs(lower - start))
    v = np.asarray(limits.velocity, dtype=np.float64)
    a = np.asarray(limits.acceleration, dtype=np.float64)
    bad = np.isinf(worst) & (np.isfinite(v) | np.isfinite(a))
    if np.any(bad):
        joints = [j for j, b in zip(limits.joint_names, bad) if b]
        raise ValueError(f"approach_duration: joints {joints} have an unbounded box "
                         "and a finite limit; no duration is long enough")
    worst = np.where(np.isinf(worst), 0.0, worst)
    return max(floor, float(shortest_duration(worst, v, a, xp=np)))


def violation(peak_speed: Array, peak_acc: Array, limits: JointLimits,
              peak_effort: Array | None = None) -> Array:
    """How far the peaks exceed the limits: ``max over joints and kinds of
    relu(peak / limit - 1)``; 0 within every limit, e.g. 0.5 for 1.5 x a limit.

    Infinite limits are ignored.  Piecewise linear in the peaks (a penalty term);
    finite for finite peaks.  Jittable and vmappable (``limits`` is a pytree).

    Args:
        peak_speed: (..., DoF) peak |velocity| (rad/s or m/s), e.g. from `move_peaks`.
        peak_acc: (..., DoF) peak |acceleration| (rad/s^2 or m/s^2).
        limits: `JointLimits` of the same joints.
        peak_effort: optional (..., DoF) peak |effort| (N m or N), checked against
            ``limits.effort``; None: effort is not checked.

    Returns:
        (...) the relative excess over the worst limit, float32 (a scalar for
        (DoF,) peaks).
    """
    pairs = [(peak_speed, limits.velocity), (peak_acc, limits.acceleration)]
    if peak_effort is not None:
        pairs.append((peak_effort, limits.effort))
    worst = None
    for peak, limit in pairs:
        peak = jnp.abs(jnp.asarray(peak, jnp.float32))
        limit = jnp.asarray(limit, jnp.float32)
        finite = jnp.isfinite(limit)
        excess = jnp.where(finite, peak / jnp.where(finite, limit, 1.0) - 1.0, 0.0)
        excess = jnp.max(jax.nn.relu(excess), axis=-1)
        worst = excess if worst is None else jnp.maximum(worst, excess)
    return worst
