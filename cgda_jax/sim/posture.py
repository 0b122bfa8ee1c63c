"""The start posture of a robot: the model's ``qpos0`` (or a keyframe) with the fixed
and start values applied, each checked against its joint.

`start_posture` is what `cgda_jax.sim.robot.Robot` starts every execution from:

- the model's ``qpos0`` (the joints' ``ref``) or a keyframe's ``qpos``; every ball or
  free joint's quaternion normalized (a zero or non-finite one is an error);
- ``fixed`` values (joints held during execution): a finite number within the
  joint's range (within `FIXED_RANGE_TOL` of it: clipped in, rounding), else an error;
- ``start`` values of evolved joints: within the range, else an error;
- an evolved joint whose start value from the model or keyframe is outside its range
  (public models have them: a Kinova Jaco's ``qpos0`` of 0 on joints whose range
  excludes 0) is **moved into the range**, with one warning naming the joint, the
  value and where it goes; an unlimited hinge's value is wrapped into [-pi, pi)
  (the same posture).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import mujoco
import numpy as np

from cgda_jax.logs import warn_once

__all__ = ["FIXED_RANGE_TOL", "fixed_value", "joint_label", "start_posture",
           "valid_quaternions"]

_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
_BALL = int(mujoco.mjtJoint.mjJNT_BALL)
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)

#: A fixed value this far (radians / metres) beyond a limited joint's range is clipped
#: into it (rounding, e.g. degrees converted to radians); farther is an error.
FIXED_RANGE_TOL = 1e-6


def joint_label(mj_model: mujoco.MjModel, jid: int) -> str:
    """``'name'`` of a joint, or ``#id (unnamed)``."""
    name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_JOINT, jid)
    return repr(name) if name else f"#{jid} (unnamed)"


def _span(mj_model: mujoco.MjModel, jid: int, v: float, lo: float, hi: float):
    """``value`` and ``[lo, hi]`` as text in the joint's units (degrees beside
    radians for hinges)."""
    if int(mj_model.jnt_type[jid]) == _HINGE:
        deg = f"[{math.degrees(lo):g}, {math.degrees(hi):g}] deg"
        return f"{v:g} rad ({math.degrees(v):g} deg)", f"[{lo:g}, {hi:g}] rad ({deg})"
    return f"{v:g} m", f"[{lo:g}, {hi:g}] m"


def fixed_value(
    mj_model: mujoco.MjModel, jid: int, name: str, value, source: str
) -> float:
    """A fixed joint's value, checked: a finite number within the joint's range
    (clipped into it when within `FIXED_RANGE_TOL`)."""
    where = f"fixed joint {name!r} in {source}"
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: value {value!r} is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{where}: value {v} is not finite")
    if not mj_model.jnt_limited[jid]:
        return v
    lo, hi = (float(x) for x in mj_model.jnt_range[jid])
    if lo - FIXED_RANGE_TOL <= v <= hi + FIXED_RANGE_TOL:
        return min(max(v, lo), hi)
    text, span = _span(mj_model, jid, v, lo, hi)
    raise ValueError(f"{where}: value {text} is outside the joint's range {span}")


def valid_quaternions(
    mj_model: mujoco.MjModel, qpos0: np.ndarray, origin: str, source: str
) -> np.ndarray:
    """``qpos0`` with every ball/free joint's quaternion normalized, as
    ``mj_kinematics`` uses it; a non-finite start value or a zero quaternion (which
    MuJoCo silently reads as the identity) is an error naming the joint."""
    qpos0 = np.array(qpos0, dtype=np.float64)
    for jid in range(mj_model.njnt):
        jtype, adr = int(mj_model.jnt_type[jid]), int(mj_model.jnt_qposadr[jid])
        size = {_FREE: 7, _BALL: 4}.get(jtype, 1)
        values = qpos0[adr : adr + size]
        kind = mujoco.mjtJoint(jtype).name.removeprefix("mjJNT_").lower()
        label = f"{kind} joint {joint_label(mj_model, jid)} in {source}"
        if not np.all(np.isfinite(values)):
            raise ValueError(
                f"{label}: its start value {values.tolist()} in {origin} is not finite"
            )
        if jtype in (_BALL, _FREE):
            q = values[-4:]
            norm = float(np.linalg.norm(q))
            if norm < 1e-9:
                raise ValueError(
                    f"{label}: its quaternion {q.tolist()} in {origin} is zero, not a "
                    "rotation; give a unit quaternion [w, x, y, z] such as [1, 0, 0, 0]"
                )
            qpos0[adr + size - 4 : adr + size] = q / norm
    return qpos0


def _moved_into_range(mj_model, jid: int, name: str, v: float, lo: float, hi: float,
                      origin: str, source: str) -> float:
    """An evolved joint's start value from the model, inside its range: wrapped (an
    unlimited hinge), clipped within `FIXED_RANGE_TOL`, else moved to the nearest
    end with a warning."""
    if not mj_model.jnt_limited[jid]:  # an unlimited hinge: the same posture
        return (v + math.pi) % (2 * math.pi) - math.pi if not lo <= v <= hi else v
    if lo - FIXED_RANGE_TOL <= v <= hi + FIXED_RANGE_TOL:
        return min(max(v, lo), hi)
    moved = min(max(v, lo), hi)
    text, span = _span(mj_model, jid, v, lo, hi)
    to = _span(mj_model, jid, moved, lo, hi)[0]
    warn_once(f"{source}: evolved joint {name!r} starts at {text} in {origin}, "
              f"outside its range {span}; every execution starts from {to} instead "
              "(the nearest end; set its start value, robot.start in a config, to "
              "choose another)")
    return moved


def start_posture(
    mj_model: mujoco.MjModel,
    joints: Sequence[str],
    joint_ids: Sequence[int],
    bounds: tuple[Sequence[float], Sequence[float]],
    fixed: Mapping[str, float],
    start: Mapping[str, float],
    keyframe: str | None,
    source: str,
) -> np.ndarray:
    """The start posture (nq,) float64 (see the module doc).

    Args:
        mj_model: the compiled model.
        joints, joint_ids: (DoF,) the evolved joints' names and ids.
        bounds: (lower, upper), each (DoF,): the evolved joints' ranges (an
            unlimited hinge: [-pi, pi]).
        fixed: joint name -> held value (radians / metres).
        start: evolved joint name -> start value (radians / metres).
        keyframe: a ``<key>`` name whose ``qpos`` replaces the model's ``qpos0``.
        source: the model's name in messages.

    Raises:
        KeyError: an unknown keyframe or fixed joint (the message lists the model's).
        ValueError: a fixed value that is not finite or outside its range, a start
            value outside its range or of a joint that is not evolved, a zero or
            non-finite quaternion (each message names the joint and value).
    """
    if keyframe is None:
        qpos0 = np.array(mj_model.qpos0, dtype=np.float64)
        origin = "the model's qpos0"
    else:
        kid = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_KEY, keyframe)
        if kid < 0:
            keys = [mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_KEY, i)
                    for i in range(mj_model.nkey)]
            raise KeyError(f"keyframe {keyframe!r} not found in {source}; it has "
                           f"{keys}")
        qpos0 = np.array(mj_model.key_qpos[kid], dtype=np.float64)
        origin = f"keyframe {keyframe!r}"
    qpos0 = valid_quaternions(mj_model, qpos0, origin, source)
    lower, upper = bounds
    joints = tuple(joints)
    for k, (name, jid) in enumerate(zip(joints, joint_ids)):
        if name in start:
            continue
        adr = int(mj_model.jnt_qposadr[jid])
        qpos0[adr] = _moved_into_range(mj_model, int(jid), name, float(qpos0[adr]),
                                       float(lower[k]), float(upper[k]), origin, source)
    jt = mujoco.mjtObj.mjOBJ_JOINT
    for name, value in fixed.items():
        jid = mujoco.mj_name2id(mj_model, jt, name)
        if jid < 0:
            names = [mujoco.mj_id2name(mj_model, jt, i) for i in range(mj_model.njnt)]
            raise KeyError(f"fixed joint {name!r} not found in {source}; it has "
                           f"{names}")
        if int(mj_model.jnt_type[jid]) not in (_HINGE, _SLIDE):
            raise ValueError(f"fixed joint {name!r} in {source} is not a hinge/slide")
        qpos0[mj_model.jnt_qposadr[jid]] = fixed_value(mj_model, jid, name, value,
                                                       source)
    for name, value in start.items():  # start values of evolved joints
        if name not in joints:
            raise ValueError(f"start value for {name!r}: not an evolved joint "
                             f"{list(joints)} (hold others with 'fixed')")
        k = joints.index(name)
        lo, hi = lower[k], upper[k]
        if not lo - 1e-9 <= float(value) <= hi + 1e-9:
            raise ValueError(f"start value {value} of joint {name!r} is outside "
                             f"its range [{lo}, {hi}]")
        qpos0[mj_model.jnt_qposadr[joint_ids[k]]] = float(value)
    return qpos0
