"""How dynamic mode drives each joint it holds: the model's position servos, or a
joint-space PD with gravity compensation where the model has motors.

Dynamic mode commands joint *positions* (the min-jerk reference of the waypoints).
A joint it holds (an evolved joint, a fixed joint that is not welded, any other
simulated joint with an actuator) is driven by `plan_control`:

- a **position actuator** (``<position>``, or a ``<general>`` with a fixed gain and
  an affine bias ``-kp q - kv qdot``) on the joint: as the model has it (``mode =
  "auto"``, default);
- a **motor** (``<motor>``) or another **general actuator** (velocity, damper,
  muscle...): replaced, in the simulated model only, by a joint-space PD

      tau = clip(kp (q_ref - q) - kd qdot + g(q), lo, hi)

  where ``g(q)`` is the gravity part of MuJoCo's ``qfrc_bias`` (``qfrc_bias`` at
  zero velocity; switched off with ``gravity = False``) and ``[lo, hi]`` the joint's
  force limit.  The PD is built from MuJoCo's own parts, so that both physics
  backends (MuJoCo C and MJX) step the same law: a ``<general>`` actuator with gain
  ``kp`` and bias ``[0, -kp, -kd]`` (its control is ``q_ref``), ``gravcomp = 1`` on
  the bodies whose weight the PD carries with ``actuatorgravcomp`` on their joints
  (the compensation is counted as actuator force) and ``actuatorfrcrange`` for the
  limit, which clips the sum;
- ``mode = "pd"``: every held joint through the PD, a position servo too (it keeps
  its own ``kp`` and ``kv``, and gains the gravity compensation), and a joint
  without an actuator gets one (an arm without actuators, such as a Kinova Jaco's
  model, can then run);
- a held joint without an actuator (``mode = "auto"``), with more than one, or
  driven through a tendon, site or body transmission is refused by name.

The PD's numbers, per joint, from the first source that has them:

- ``kp``: `Control.kp`; a converted position servo's own ``kp``; else the force
  limit over `KP_SATURATION` (the limit reached at 0.1 rad of error), lowered where
  that is too stiff for the time step (`stable_kp`: with critical damping,
  ``(kp dt + kd) dt / I`` at most `STABLE_SHARE`, ``kp dt^2 / I`` under the implicit
  integrators, ``I`` the joint's inertia at the start posture); else an error;
- ``kd``: `Control.kd`; a converted position servo's ``kv``; else
  ``2 damping_ratio sqrt(kp I)``, with ``I`` the joint's diagonal of the mass matrix
  at the start posture (armature included): critically damped at the default 1;
- force limit: `Control.force_limit` (symmetric); else the actuator's (``gear x
  forcerange``, and for a motor ``gear x gain x ctrlrange``), intersected with the
  joint's ``actuatorfrcrange``; else none.

Gravity compensation reaches every held joint that carries a compensated body's
weight through its actuator (a position servo there too, its ``forcerange`` then
applied to the sum as the joint's ``actuatorfrcrange``); a joint without an actuator
on the way gets none (its ``actuatorfrcrange`` is set to +-1e-12).

Under MuJoCo's implicit integrators (``implicitfast``, ``implicit``) the PD's
damping is integrated implicitly, like a position actuator's ``kv``: more stable
than a hand-written loop, and not step-for-step equal to one.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping, Sequence
from typing import Any

import mujoco
import numpy as np

from cgda_jax.sim.drives import ControlPlan, Drive, gravity_sets
from cgda_jax.sim.pd_gains import (
    check_stability,
    implicit_damping,
    joint_inertia,
    stable_kp,
)

__all__ = ["CONTROL_MODES", "KP_SATURATION", "Control", "actuator_kind",
           "check_transmissions", "plan_control"]

#: ``Control.mode`` values.
CONTROL_MODES = ("auto", "pd")

#: The default PD gain reaches the force limit at this error [rad or m].
KP_SATURATION = 0.1

_JOINT = int(mujoco.mjtTrn.mjTRN_JOINT)


def _per_joint(value, what: str) -> float | dict[str, float] | None:
    """A `Control` gain or limit: None, a number > 0 (every joint) or a table."""
    if value is None or (isinstance(value, Mapping) and not value):
        return None
    items = value.items() if isinstance(value, Mapping) else [("", value)]
    out = {}
    for joint, v in items:
        key = f"control {what}" + (f".{joint}" if joint else "")
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise ValueError(f"{key} = {v!r}: not a number")
        if not (math.isfinite(v) and v >= 0) or (what != "kd" and v == 0):
            raise ValueError(f"{key} = {v!r}: must be a finite number "
                             f"{'>= 0' if what == 'kd' else '> 0'}")
        out[str(joint)] = float(v)
    return out[""] if "" in out else out


@dataclasses.dataclass(frozen=True)
class Control:
    """What dynamic mode may use to drive the joints (see the module doc).

    Attributes:
        mode: "auto" (position servos as the model has them, other actuators through
            the PD) or "pd" (every held joint through the PD).
        kp: PD stiffness [N m/rad or N/m]: one number for every PD joint or a table
            by joint name; None: from the model.
        kd: PD damping [N m s/rad or N s/m], likewise; None: from the model or
            critical damping.
        force_limit: the PD's largest force [N m or N], likewise; None: the model's.
        damping_ratio: of the default ``kd``.
        gravity: compensate gravity in the PD (default True).
    """

    mode: str = "auto"
    kp: float | Mapping[str, float] | None = None
    kd: float | Mapping[str, float] | None = None
    force_limit: float | Mapping[str, float] | None = None
    damping_ratio: float = 1.0
    gravity: bool = True

    def __post_init__(self):
        if self.mode not in CONTROL_MODES:
            raise ValueError(f"control mode {self.mode!r}: expected one of "
                             f"{list(CONTROL_MODES)}")
        for what in ("kp", "kd", "force_limit"):
            object.__setattr__(self, what, _per_joint(getattr(self, what), what))
        if not (math.isfinite(self.damping_ratio) and self.damping_ratio > 0):
            raise ValueError(f"control damping_ratio = {self.damping_ratio}: must "
                             "be > 0")
        if not isinstance(self.gravity, bool):
            raise ValueError(f"control gravity = {self.gravity!r}: true or false")

    @classmethod
    def from_dict(cls, table: Mapping[str, Any] | None) -> Control:
        """From a config's ``[robot.control]`` table (unknown keys are errors)."""
        table = dict(table or {})
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ValueError(f"control: unknown key(s) {unknown}; known: "
                             f"{sorted(known)}")
        return cls(**table)

    def value(self, what: str, joint: str) -> float | None:
        v = getattr(self, what)
        return v.get(joint) if isinstance(v, dict) else v

    def check_names(self, names: Sequence[str]) -> None:
        """Every joint a table names is one of ``names`` (the PD's joints)."""
        for what in ("kp", "kd", "force_limit"):
            v = getattr(self, what)
            bad = sorted(set(v) - set(names)) if isinstance(v, dict) else []
            if bad:
                raise ValueError(f"control {what}: joints {bad} are not driven by "
                                 f"the PD (its joints: {list(names)})")


def actuator_kind(m: mujoco.MjModel, a: int) -> str:
    """"position" (fixed gain kp, bias [0, -kp, -kv], no integrator), "motor" (a
    plain torque/force) or "general" (anything else)."""
    gain, bias = m.actuator_gainprm[a], m.actuator_biasprm[a]
    gtype, btype = int(m.actuator_gaintype[a]), int(m.actuator_biastype[a])
    dyn = int(m.actuator_dyntype[a])
    fixed = gtype == int(mujoco.mjtGain.mjGAIN_FIXED)
    if fixed and btype == int(mujoco.mjtBias.mjBIAS_NONE) and dyn == int(
            mujoco.mjtDyn.mjDYN_NONE):
        return "motor"
    filters = (int(mujoco.mjtDyn.mjDYN_NONE), int(mujoco.mjtDyn.mjDYN_FILTER),
               int(mujoco.mjtDyn.mjDYN_FILTEREXACT))
    if (fixed and btype == int(mujoco.mjtBias.mjBIAS_AFFINE) and dyn in filters
            and gain[0] > 0 and bias[0] == 0 and abs(bias[1] + gain[0]) <= 1e-9
            * max(1.0, gain[0]) and bias[2] <= 0):
        return "position"
    return "general"


def _name(m, kind, i: int) -> str:
    return mujoco.mj_id2name(m, kind, i) or f"#{i}"


def _force_range(m: mujoco.MjModel, jid: int, a: int | None, kind: str):
    """The joint-space force range the model gives the joint (and its source)."""
    lo, hi, src = -math.inf, math.inf, []
    if a is not None:
        g = float(m.actuator_gear[a, 0])
        ranges = []
        if m.actuator_forcelimited[a]:
            ranges.append(("forcerange", m.actuator_forcerange[a]))
        if kind == "motor" and m.actuator_ctrllimited[a]:
            ranges.append(("ctrlrange", m.actuator_gainprm[a, 0]
                           * m.actuator_ctrlrange[a]))
        for what, r in ranges:
            a_lo, a_hi = sorted(float(v) * g for v in r)
            lo, hi = max(lo, a_lo), min(hi, a_hi)
            src.append(f"{what}:{_name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a)}")
    if m.jnt_actfrclimited[jid]:
        j_lo, j_hi = (float(v) for v in m.jnt_actfrcrange[jid])
        lo, hi = max(lo, j_lo), min(hi, j_hi)
        src.append("actuatorfrcrange")
    return (lo, hi), "mjcf " + "+".join(src) if src else "none"


def plan_control(m: mujoco.MjModel, qpos: np.ndarray, held: Sequence[str],
                 control: Control | Mapping | None = None,
                 source: str = "the model", timestep: float | None = None,
                 ) -> ControlPlan:
    """The drive of every ``held`` joint of ``m`` (see the module doc).

    Args:
        m: the robot's whole model (before welding).
        qpos: (nq,) the start posture (the default ``kd``'s inertia).
        held: names of the joints dynamic mode holds (evolved, fixed, and every
            other simulated joint with an actuator).
        control: a `Control`, a ``[robot.control]`` table, or None (the defaults).
        source: the model's name in messages.
        timestep: the simulation's step (None: the model's own), for the default
            gain's and the stability warning's bound.

    Raises:
        ValueError: a held joint that cannot be driven (no actuator in "auto" mode,
            several, a tendon/site transmission), a PD without a gain, a bad
            `Control` (each message starts with "control" and names the joint).
    """
    if not isinstance(control, Control):
        control = Control.from_dict(control)
    jt, at = mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_ACTUATOR
    on_joint: dict[int, list[int]] = {}
    for a in range(m.nu):
        if int(m.actuator_trntype[a]) == _JOINT:
            on_joint.setdefault(int(m.actuator_trnid[a, 0]), []).append(a)
    jids = {n: mujoco.mj_name2id(m, jt, n) for n in held}
    missing, several, drives, delete = [], [], [], []
    inertia = joint_inertia(m, qpos)
    dt = float(m.opt.timestep if timestep is None else timestep)
    for name in held:
        jid = jids[name]
        acts = on_joint.get(jid, [])
        kinds = [actuator_kind(m, a) for a in acts]
        if len(acts) > 1 and control.mode == "auto":
            several.append(f"{name!r} ({', '.join(_name(m, at, a) for a in acts)})")
            continue
        if not acts and control.mode == "auto":
            missing.append(name)
            continue
        a = acts[0] if acts else None
        kind = kinds[0] if acts else ""
        delete += acts[1:]
        force, fsrc = _force_range(m, jid, a, kind)
        if kind == "position" and control.mode == "auto":
            drives.append(Drive(name, "position", _name(m, at, a), kind,
                                float(m.actuator_gainprm[a, 0]),
                                -float(m.actuator_biasprm[a, 2]) + 0.0, force, False,
                                {"kp": "mjcf", "kd": "mjcf", "force": fsrc}, a))
            continue
        limit = control.value("force_limit", name)
        if limit is not None:
            force, fsrc = (-limit, limit), "config"
        kp, kd = control.value("kp", name), control.value("kd", name)
        src = {"kp": "config", "kd": "config", "force": fsrc}
        if kp is None and kind == "position":
            kp, src["kp"] = float(m.actuator_gainprm[a, 0]), "mjcf position kp"
        if kp is None:
            half = max(abs(force[0]), abs(force[1]))
            if not math.isfinite(half) or half <= 0:
                raise ValueError(
                    f"control: joint {name!r} of {source} has no gain for its PD "
                    f"({'no actuator' if a is None else f'{kind} actuator'} and no "
                    "force limit); set robot.control.kp (or force_limit)")
            kp, src["kp"] = half / KP_SATURATION, f"force limit / {KP_SATURATION}"
            cap = stable_kp(float(inertia[m.jnt_dofadr[jid]]), dt,
                            control.damping_ratio, implicit_damping(m))
            if kp > cap:
                kp = cap
                src["kp"] += f", lowered for the {dt:g} s step"
        if kd is None and kind == "position" and kp == float(m.actuator_gainprm[a, 0]):
            kd = -float(m.actuator_biasprm[a, 2]) + 0.0  # no -0.0
            src["kd"] = "mjcf position kv"
        if kd is None:
            i = float(inertia[m.jnt_dofadr[jid]])
            kd = 2.0 * control.damping_ratio * math.sqrt(kp * i)
            src["kd"] = f"{control.damping_ratio:g} x critical (inertia {i:.3g})"
        drives.append(Drive(name, "pd", "" if a is None else _name(m, at, a), kind,
                            float(kp), float(kd), force, control.gravity, src,
                            -1 if a is None else a))
    if missing:
        raise ValueError(
            f"control: joints {missing} of {source} have no actuator, so dynamic mode "
            "cannot drive them; set robot.control.mode = \"pd\" (with kp or "
            "force_limit) to drive them with a joint-space PD, or weld them (leave "
            "them out of joints and fixed)")
    if several:
        raise ValueError(
            f"control: joints {several} of {source} are driven by several actuators; "
            "dynamic mode drives one per joint; set robot.control.mode = \"pd\" to "
            "replace them by one joint-space PD")
    control.check_names([d.joint for d in drives if d.kind == "pd"])
    check_stability(m, inertia, dt, drives, source)
    bodies, joints, unloaded = gravity_sets(m, drives, jids)
    return ControlPlan(tuple(drives), control, bodies, joints, unloaded,
                       tuple(sorted(delete)))


def check_transmissions(m: mujoco.MjModel, source: str) -> None:
    """Every actuator of the simulated model drives a joint (dynamic mode commands
    joint positions); one through a tendon, site or body is refused by name."""
    other = [_name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(m.nu)
             if int(m.actuator_trntype[a]) != _JOINT]
    if other:
        raise ValueError(
            f"control: actuators {other} of {source} drive a tendon, site or body, "
            "not a joint; dynamic mode commands joint positions and cannot hold them "
            "(remove them from the model, or use kinematic mode)")
