"""The planned drives built into a robot's model spec (`cgda_jax.sim.control`).

`build_drives` turns each PD drive into a ``<general>`` actuator (gain ``kp``, bias
``[0, -kp, -kd]``, its control the joint's target, the joint's range as its control
range) with the force limit as the joint's ``actuatorfrcrange``, and switches on
MuJoCo's gravity compensation (``gravcomp`` on the bodies `gravity_sets` finds,
``actuatorgravcomp`` on their joints), so that MuJoCo C and MJX step the same law:

    tau = clip(kp (q_ref - q) - kd qdot + g(q), lo, hi)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np

if TYPE_CHECKING:
    from cgda_jax.sim.control import ControlPlan

__all__ = ["build_drives", "gravity_sets"]

_TRUE = mujoco.mjtLimited.mjLIMITED_TRUE
_FALSE = mujoco.mjtLimited.mjLIMITED_FALSE


def _limit(force) -> list[float]:
    """A force range for MuJoCo (+-inf as +-1e10)."""
    return [max(force[0], -1e10), min(force[1], 1e10)]


def build_drives(plan: ControlPlan, spec: mujoco.MjSpec,
                 model: mujoco.MjModel) -> None:
    """Change ``spec`` (of the compiled ``model``, before any joint is welded) so
    that it steps the drives of ``plan``: its PD actuators, the actuators they
    replace deleted, gravity compensation where planned."""
    acts, joints = list(spec.actuators), list(spec.joints)
    bodies = list(spec.bodies)
    if (len(acts), len(joints), len(bodies)) != (model.nu, model.njnt,
                                                model.nbody):
        raise ValueError("control: the model's spec does not match its compiled "
                         "model (actuators, joints or bodies differ)")
    by_name = {j.name: j for j in joints}
    for d in plan.drives:
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
    for a in sorted(plan.delete, reverse=True):
        spec.delete(acts[a])
    for b in plan.gravity_bodies:
        bodies[b].gravcomp = 1.0
    for j in plan.gravity_joints:
        joints[j].actgravcomp = True
        d = plan.drive(joints[j].name)
        if d is not None and d.kind == "position" and np.isfinite(d.force).any():
            # the servo's own forcerange now bounds servo + compensation
            acts[d.actuator_id].forcelimited = _FALSE
            joints[j].actfrclimited = _TRUE
            joints[j].actfrcrange = _limit(d.force)
    for j in plan.unloaded:  # no actuator: its share of the compensation cut
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
