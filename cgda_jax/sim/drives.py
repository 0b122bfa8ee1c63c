"""The drives of the joints dynamic mode holds (`Drive`), as planned by
`cgda_jax.sim.control.plan_control` (`ControlPlan`), and built into a robot's model
spec.

`ControlPlan.apply` turns each PD drive into a ``<general>`` actuator (gain ``kp``, bias
``[0, -kp, -kd]``, its control the joint's target, the joint's range as its control
range) with the force limit as the joint's ``actuatorfrcrange``, and switches on
MuJoCo's gravity compensation (``gravcomp`` on the bodies `gravity_sets` finds,
``actuatorgravcomp`` on their joints), so that MuJoCo C and MJX step the same law:

    tau = clip(kp (q_ref - q) - kd qdot + g(q), lo, hi)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import mujoco
import numpy as np

__all__ = ["ControlPlan", "Drive", "gravity_sets"]

_TRUE = mujoco.mjtLimited.mjLIMITED_TRUE
_FALSE = mujoco.mjtLimited.mjLIMITED_FALSE


def _limit(force) -> list[float]:
    """A force range for MuJoCo (+-inf as +-1e10)."""
    return [max(force[0], -1e10), min(force[1], 1e10)]


@dataclasses.dataclass(frozen=True)
class Drive:
    """How one held joint is driven.

    Attributes:
        joint: its name.
        kind: "position" (the model's servo) or "pd".
        actuator: the model's actuator on it ("" when the PD adds one).
        actuator_kind: "position", "motor", "general" or "" (none).
        kp, kd: the gains (a position servo: its own).
        force: (lo, hi) the joint-space force limit [N m or N] (+-inf: none).
        gravity: the drive compensates gravity.
        sources: "kp", "kd", "force" -> where each came from.
        actuator_id: the model's actuator's id (-1: none).
    """

    joint: str
    kind: str
    actuator: str
    actuator_kind: str
    kp: float
    kd: float
    force: tuple[float, float]
    gravity: bool
    sources: Mapping[str, str]
    actuator_id: int = -1

    def as_dict(self) -> dict[str, Any]:
        return {"joint": self.joint, "drive": self.kind, "actuator": self.actuator,
                "actuator_kind": self.actuator_kind, "kp": self.kp, "kd": self.kd,
                "force_lo": self.force[0], "force_hi": self.force[1],
                "gravity": self.gravity, "sources": dict(self.sources)}


@dataclasses.dataclass(frozen=True)
class ControlPlan:
    """The drives of the held joints and what they change in the simulated model.

    Attributes:
        drives: one `Drive` per held joint.
        control: the `cgda_jax.sim.control.Control` it was planned with.
        gravity_bodies: names (or ids) of the bodies given ``gravcomp = 1``.
        gravity_joints: joints whose share of that compensation goes through their
            actuator; ``unloaded``: those without one (their share is cut to 0).
    """

    drives: tuple[Drive, ...]
    control: Any
    gravity_bodies: tuple[int, ...] = ()
    gravity_joints: tuple[int, ...] = ()
    unloaded: tuple[int, ...] = ()
    delete: tuple[int, ...] = ()  # actuators the PD replaces beyond the first

    def drive(self, joint: str) -> Drive | None:
        return next((d for d in self.drives if d.joint == joint), None)

    def as_dict(self) -> dict[str, Any]:
        return {"mode": self.control.mode, "gravity": self.control.gravity,
                "joints": [d.as_dict() for d in self.drives]}

    def apply(self, spec: mujoco.MjSpec, model: mujoco.MjModel) -> None:
        """Change ``spec`` (of the compiled ``model``, before any joint is welded)
        so that it steps the planned drives: its PD actuators, the actuators they
        replace deleted, gravity compensation where planned."""
        acts, joints = list(spec.actuators), list(spec.joints)
        bodies = list(spec.bodies)
        if (len(acts), len(joints), len(bodies)) != (model.nu, model.njnt,
                                                    model.nbody):
            raise ValueError("control: the model's spec does not match its compiled "
                             "model (actuators, joints or bodies differ)")
        by_name = {j.name: j for j in joints}
        for d in self.drives:
            if d.kind != "pd":
                continue
            joint = by_name[d.joint]
            if d.actuator_id >= 0:
                act = acts[d.actuator_id]
            else:
                act = spec.add_actuator(name=f"cgda_pd_{d.joint}", target=d.joint)
            act.trntype = mujoco.mjtTrn.mjTRN_JOINT
            act.target = d.joint
            act.dyntype = mujoco.mjtDyn.mjDYN_NONE
            act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
            act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
            act.gainprm = [d.kp] + [0.0] * 9
            act.biasprm = [0.0, -d.kp, -d.kd] + [0.0] * 7
            act.gear = [1.0, 0, 0, 0, 0, 0]
            act.forcelimited = _FALSE  # the joint's limit clips PD + gravity
            act.actlimited = _FALSE
            jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, d.joint)
            if model.jnt_limited[jid]:
                act.ctrllimited, act.ctrlrange = _TRUE, list(model.jnt_range[jid])
            else:
                act.ctrllimited = _FALSE
            if np.isfinite(d.force).any():
                joint.actfrclimited = _TRUE
                joint.actfrcrange = _limit(d.force)
        for a in sorted(self.delete, reverse=True):
            spec.delete(acts[a])
        for b in self.gravity_bodies:
            bodies[b].gravcomp = 1.0
        for j in self.gravity_joints:
            joints[j].actgravcomp = True
            d = self.drive(joints[j].name)
            if d is not None and d.kind == "position" and np.isfinite(d.force).any():
                # the servo's own forcerange now bounds servo + compensation
                acts[d.actuator_id].forcelimited = _FALSE
                joints[j].actfrclimited = _TRUE
                joints[j].actfrcrange = _limit(d.force)
        for j in self.unloaded:  # no actuator: its share of the compensation cut
            joints[j].actgravcomp = True  # off (MuJoCo wants lo < hi: 1e-12 N m)
            joints[j].actfrclimited = _TRUE
            joints[j].actfrcrange = [-1e-12, 1e-12]


def gravity_sets(m: mujoco.MjModel, drives, jids) -> tuple[tuple[int, ...], ...]:
    """Bodies compensated (the subtrees of the PD joints with gravity), the joints
    whose share goes through their actuator, and those without one."""
    pd = [jids[d.joint] for d in drives if d.kind == "pd" and d.gravity]
    if not pd:
        return (), (), ()
    comp = np.zeros(m.nbody, bool)
    for j in pd:
        comp[m.jnt_bodyid[j]] = True
    for b in range(1, m.nbody):  # parents come first
        comp[b] |= comp[m.body_parentid[b]]
    loaded = np.zeros(m.nbody, bool)  # compensated bodies and their ancestors
    for b in np.flatnonzero(comp):
        while b > 0 and not loaded[b]:
            loaded[b] = True
            b = m.body_parentid[b]
    held = {jids[d.joint] for d in drives}
    joints = [j for j in range(m.njnt) if loaded[m.jnt_bodyid[j]]]
    return (tuple(int(b) for b in np.flatnonzero(comp)),
            tuple(j for j in joints if j in held),
            tuple(j for j in joints if j not in held))
