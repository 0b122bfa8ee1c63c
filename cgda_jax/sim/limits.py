"""Joint velocity, acceleration and effort limits, and the timing of a minimum-jerk move.

Limits (`read_limits` -> `JointLimits`), per evolved joint and kind (velocity in rad/s
or m/s, acceleration in rad/s^2 or m/s^2, effort in N m or N), come from the first of
these sources that gives a value (highest precedence first):

a. ``overrides`` (what a config's ``[robot.limits]`` table passes):
   ``{"velocity": 3.0, "effort": {"r_elbow": 20.0}, ...}``: a number applies to every
   evolved joint, a table to the joints it names.  ``inf`` means "no limit".
   Source ``"config"``.
b. an MJCF per-joint numeric, ``<custom><numeric name="velocity_limit:JOINT"
   data="3.0"/></custom>`` (likewise ``acceleration_limit:JOINT``,
   ``effort_limit:JOINT``).  Source ``"mjcf custom velocity_limit:JOINT"``.
c. effort only: the joint's ``actuatorfrcrange`` (``jnt_actfrclimited`` /
   ``jnt_actfrcrange``; the limit is ``max(|lo|, |hi|)``), source
   ``"mjcf actuatorfrcrange"``; else, when every actuator driving the joint (joint
   transmission) is force-limited, the sum of their ``max(|lo|, |hi|) * |gear|``,
   source ``"mjcf forcerange:ACTUATOR[+ACTUATOR...]"``.
d. an MJCF model-wide numeric ``velocity_limit`` (``acceleration_limit``,
   ``effort_limit``), one value for every joint of the model.  Source
   ``"mjcf custom velocity_limit"``.
e. none: ``inf``, source ``"none"``.

Every value must be a positive number (``inf`` allowed); a bad override or numeric
(wrong length, zero, negative, NaN, a per-joint numeric naming no joint of the model) is
a ValueError naming it.

Timing of one move.  The dynamic mode (`cgda_jax.sim.execute`) moves each joint from
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
    >>> from cgda_jax.sim.limits import move_peaks
    >>> speed, acc = move_peaks(jnp.array([1.0]), 1.0)
    >>> round(float(speed[0]), 4), round(float(acc[0]), 4)
    (1.875, 5.7735)
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax import Array

__all__ = [
    "KINDS",
    "PEAK_ACCELERATION",
    "PEAK_SPEED",
    "JointLimits",
    "MoveSamples",
    "approach_duration",
    "min_duration",
    "min_jerk",
    "min_jerk_d1",
    "min_jerk_d2",
    "move_peaks",
    "move_samples",
    "read_limits",
    "violation",
]

#: The limit kinds, in the order `JointLimits` holds them.
KINDS = ("velocity", "acceleration", "effort")

#: max over tau of s'(tau) = 30 tau^2 (1 - tau)^2, at tau = 1/2: 30/16.
PEAK_SPEED = 1.875
#: max over tau of |s''(tau)| = |60 tau (1 - tau) (1 - 2 tau)|: 10 / sqrt(3).
PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)


# -- the limits ----------------------------------------------------------------------
def _limit_array(values, n: int, what: str) -> np.ndarray:
    arr = np.array(values, dtype=np.float32).reshape(-1)
    if arr.shape != (n,):
        raise ValueError(f"JointLimits.{what} has shape {arr.shape}, expected ({n},)")
    if np.any(np.isnan(arr)) or np.any(arr <= 0):
        raise ValueError(f"JointLimits.{what} = {arr.tolist()}: every limit must be > 0 "
                         "(inf: no limit)")
    arr.setflags(write=False)
    return arr


@dataclasses.dataclass(frozen=True, eq=False)
class JointLimits:
    """Per-joint velocity, acceleration and effort limits of the evolved joints.

    Also a JAX pytree (the three arrays are its leaves), so it can be passed to
    jitted or vmapped functions such as `min_duration` and `violation`.

    Attributes:
        velocity: (DoF,) float32, rad/s (hinge) or m/s (slide); ``inf``: no limit.
        acceleration: (DoF,) float32, rad/s^2 or m/s^2; ``inf``: no limit.
        effort: (DoF,) float32, N m or N; ``inf``: no limit.
        joint_names: (DoF,) the joints, in gene order.
        source: kind -> (DoF,) where each value came from (``"config"``,
            ``"mjcf custom velocity_limit:r_elbow"``, ``"mjcf actuatorfrcrange"``,
            ``"mjcf forcerange:r_elbow"``, ``"mjcf custom velocity_limit"``,
            ``"none"``; see the module doc).
    """

    velocity: np.ndarray
    acceleration: np.ndarray
    effort: np.ndarray
    joint_names: tuple[str, ...]
    source: Mapping[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        names = tuple(str(j) for j in self.joint_names)
        n = len(names)
        object.__setattr__(self, "joint_names", names)
        for kind in KINDS:
            object.__setattr__(self, kind, _limit_array(getattr(self, kind), n, kind))
        source = {k: tuple(str(s) for s in self.source.get(k, ("none",) * n))
                  for k in KINDS}
        for kind, where in source.items():
            if len(where) != n:
                raise ValueError(f"JointLimits.source[{kind!r}] has {len(where)} "
                                 f"entries, expected {n}")
        object.__setattr__(self, "source", source)

    @property
    def n_dof(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    def as_dict(self) -> dict:
        """JSON-ready: ``{"joints": [...], "velocity": {joint: value or None}, ...,
        "source": {kind: {joint: str}}}`` (``None``: no limit)."""
        out: dict = {"joints": list(self.joint_names)}
        for kind in KINDS:
            values = getattr(self, kind)
            out[kind] = {j: (float(v) if np.isfinite(v) else None)
                         for j, v in zip(self.joint_names, values)}
        out["source"] = {k: dict(zip(self.joint_names, self.source[k])) for k in KINDS}
        return out

    def __repr__(self) -> str:
        def fmt(values) -> str:
            vals = {f"{v:g}" for v in np.asarray(values, dtype=np.float64)}
            if len(vals) == 1:
                return vals.pop()
            return "[" + ", ".join(f"{v:g}" for v in np.asarray(values)) + "]"

        if not isinstance(self.velocity, np.ndarray):  # traced leaves
            return f"JointLimits(joints={self.joint_names}, traced)"
        kinds = ", ".join(f"{k}={fmt(getattr(self, k))}" for k in KINDS)
        return f"JointLimits(joints={list(self.joint_names)}, {kinds})"


def _flatten(limits: JointLimits):
    source = tuple((k, limits.source[k]) for k in KINDS)
    return (limits.velocity, limits.acceleration, limits.effort), (
        limits.joint_names, source)


def _unflatten(aux, leaves) -> JointLimits:
    obj = object.__new__(JointLimits)  # leaves may be tracers: no checks
    names, source = aux
    for kind, leaf in zip(KINDS, leaves):
        object.__setattr__(obj, kind, leaf)
    object.__setattr__(obj, "joint_names", names)
    object.__setattr__(obj, "source", dict(source))
    return obj


jax.tree_util.register_pytree_node(JointLimits, _flatten, _unflatten)


def _check_value(value, where: str) -> float:
    """A limit value: a real number > 0 (``inf`` allowed)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{where} = {value!r}: not a number (give a limit > 0, or "
                         "inf for none)")
    v = float(value)
    if math.isnan(v) or v <= 0:
        raise ValueError(f"{where} = {value!r}: a limit must be > 0 (inf: no limit)")
    return v


def _numerics(mj_model: mujoco.MjModel) -> dict[str, np.ndarray]:
    out = {}
    for i in range(mj_model.nnumeric):
        name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_NUMERIC, i) or ""
        adr, size = int(mj_model.numeric_adr[i]), int(mj_model.numeric_size[i])
        out[name] = np.array(mj_model.numeric_data[adr:adr + size], dtype=np.float64)
    return out


def _numeric_value(name: str, data: np.ndarray) -> float:
    if data.shape != (1,):
        raise ValueError(f"MJCF custom numeric {name!r} has {data.size} values "
                         f"{data.tolist()}; give one (data=\"3.0\")")
    return _check_value(float(data[0]), f"MJCF custom numeric {name!r}")


def _actuator_effort(mj_model: mujoco.MjModel, jid: int) -> tuple[float, str] | None:
    """(summed max |force| * |gear|, source) of the actuators driving joint ``jid``,
    or None when none drives it or one of them is not force-limited."""
    total, names = 0.0, []
    for a in range(mj_model.nu):
        if (int(mj_model.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT)
                or int(mj_model.actuator_trnid[a, 0]) != jid):
            continue
        if not mj_model.actuator_forcelimited[a]:
            return None
        lo, hi = (float(v) for v in mj_model.actuator_forcerange[a])
        total += max(abs(lo), abs(hi)) * abs(float(mj_model.actuator_gear[a, 0]))
        names.append(mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
                     or f"#{a}")
    if not names:
        return None
    return total, "mjcf forcerange:" + "+".join(names)


def read_limits(
    mj_model: mujoco.MjModel,
    joint_names: Sequence[str],
    overrides: Mapping | None = None,
) -> JointLimits:
    """The velocity, acceleration and effort limits of the evolved joints.

    Args:
        mj_model: the compiled model.
        joint_names: (DoF,) the evolved joints, in gene order.
        overrides: ``{kind: number | {joint: number}}`` for kinds ``"velocity"``,
            ``"acceleration"``, ``"effort"`` (a config's ``[robot.limits]``); a number
            applies to every joint in ``joint_names``, a table to the joints it
            names; ``inf`` means no limit.  Wins over the model (see the module doc
            for the whole precedence).

    Returns:
        `JointLimits` with (DoF,) float32 arrays and the source of every value.

    Raises:
        KeyError: a joint in ``joint_names`` is not in the model.
        ValueError: an unknown kind or joint in ``overrides``, a value that is not a
            number > 0 (``inf`` allowed), or a bad custom numeric (not one value,
            not > 0, or ``KIND_limit:JOINT`` naming no joint of the model); the
            message names the key and value.
    """
    names = tuple(joint_names)
    jt = mujoco.mjtObj.mjOBJ_JOINT
    jids = []
    for name in names:
        jid = mujoco.mj_name2id(mj_model, jt, name)
        if jid < 0:
            raise KeyError(f"joint {name!r} not found in the model")
        jids.append(jid)
    n = len(names)

    # a. overrides, checked whole before use
    config: dict[str, dict[str, float]] = {k: {} for k in KINDS}
    for kind, spec in dict(overrides or {}).items():
        if kind not in KINDS:
            raise ValueError(f"limits: unknown kind {kind!r} (= {spec!r}); expected one "
                             f"of {list(KINDS)}")
        if isinstance(spec, Mapping):
            for joint, value in spec.items():
                if joint not in names:
                    raise ValueError(f"limits.{kind}: unknown joint {joint!r} "
                                     f"(= {value!r}); the evolved joints are "
                                     f"{list(names)}")
                config[kind][joint] = _check_value(value, f"limits.{kind}.{joint}")
        else:
            v = _check_value(spec, f"limits.{kind}")
            config[kind] = dict.fromkeys(names, v)

    # b./d. custom numerics, all checked (a typo in a joint name is an error)
    numerics = _numerics(mj_model)
    per_joint: dict[str, dict[str, float]] = {k: {} for k in KINDS}
    model_wide: dict[str, float] = {}
    for nname, data in numerics.items():
        for kind in KINDS:
            key = f"{kind}_limit"
            if nname == key:
                model_wide[kind] = _numeric_value(nname, data)
            elif nname.startswith(key + ":"):
                joint = nname[len(key) + 1:]
                if mujoco.mj_name2id(mj_model, jt, joint) < 0:
                    raise ValueError(f"MJCF custom numeric {nname!r}: no joint "
                                     f"{joint!r} in the model")
                per_joint[kind][joint] = _numeric_value(nname, data)

    values = {k: np.full(n, np.inf, dtype=np.float64) for k in KINDS}
    source = {k: ["none"] * n for k in KINDS}
    for i, (name, jid) in enumerate(zip(names, jids)):
        for kind in KINDS:
            if name in config[kind]:
                v, src = config[kind][name], "config"
            elif name in per_joint[kind]:
                v, src = per_joint[kind][name], f"mjcf custom {kind}_limit:{name}"
            elif kind == "effort" and mj_model.jnt_actfrclimited[jid]:
                lo, hi = (float(x) for x in mj_model.jnt_actfrcrange[jid])
                v = _check_value(max(abs(lo), abs(hi)),
                                 f"actuatorfrcrange of joint {name!r}")
                src = "mjcf actuatorfrcrange"
            elif kind == "effort" and _actuator_effort(mj_model, jid) is not None:
                v, src = _actuator_effort(mj_model, jid)
                v = _check_value(v, f"{src} x gear of joint {name!r}")
            elif kind in model_wide:
                v, src = model_wide[kind], f"mjcf custom {kind}_limit"
            else:
                continue
            values[kind][i], source[kind][i] = v, src
    return JointLimits(values["velocity"], values["acceleration"], values["effort"],
                       names, {k: tuple(s) for k, s in source.items()})


# -- the minimum-jerk move -------------------------------------------------------------
def min_jerk(tau: Array) -> Array:
    """Minimum-jerk profile ``s = 10 tau^3 - 15 tau^4 + 6 tau^5``, 0 -> 1.

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


def _duration(abs_dq, velocity, acceleration, xp):
    """Shortest min-jerk duration of |dq| (..., DoF) within the limits, max over the
    last axis; inf limits and zero moves contribute 0.  ``xp``: numpy or jax.numpy."""
    zero_v = (abs_dq == 0) | xp.isinf(velocity)
    zero_a = (abs_dq == 0) | xp.isinf(acceleration)
    t_v = xp.where(zero_v, 0.0, PEAK_SPEED * abs_dq / xp.where(zero_v, 1.0, velocity))
    ratio = xp.where(zero_a, 1.0, PEAK_ACCELERATION * abs_dq
                     / xp.where(zero_a, 1.0, acceleration))
    t_a = xp.where(zero_a, 0.0, xp.sqrt(ratio))
    return xp.max(xp.maximum(t_v, t_a), axis=-1)


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
    return _duration(a, jnp.asarray(limits.velocity, jnp.float32),
                     jnp.asarray(limits.acceleration, jnp.float32), jnp)


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
    return max(floor, float(_duration(worst, v, a, np)))


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
