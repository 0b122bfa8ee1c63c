"""A joint-space PD and the simulation's time step: the joint inertia the default
damping and the bounds use, the stiffest default gain a step keeps stable
(`stable_kp`), and the warning for gains too stiff for it (`check_stability`).

With MuJoCo's Euler (and RK4) integrators a PD's damping is explicit; a joint of
inertia ``I`` with gains ``kp``, ``kd`` stepped at ``dt`` stays stable while
``(kp dt + kd) dt / I`` stays below about 1 (`plan_control` warns above 1).  The
implicit integrators (``implicit``, ``implicitfast``) integrate the damping
implicitly, and only ``kp dt^2 / I`` counts.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from cgda_jax.logs import warn_once

__all__ = ["STABLE_SHARE", "check_stability", "implicit_damping", "joint_inertia",
           "stable_kp", "stiffness"]

#: A default PD gain is at most the one whose ``(kp dt + kd) dt / I`` (explicit
#: damping) or ``kp dt^2 / I`` (implicit) is this share of 1, the bound
#: `check_stability` warns at: the joint's inertia changes with the posture.
STABLE_SHARE = 0.5


def joint_inertia(m: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """(nv,) the mass matrix's diagonal at ``qpos`` (armature included)."""
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_forward(m, d)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    return np.diag(full).copy()


def implicit_damping(m: mujoco.MjModel) -> bool:
    """The model's integrator treats damping implicitly (implicit, implicitfast)."""
    return int(m.opt.integrator) in (int(mujoco.mjtIntegrator.mjINT_IMPLICIT),
                                     int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST))


def stiffness(kp: float, kd: float, inertia: float, dt: float,
              implicit: bool) -> float:
    """``(kp dt + kd) dt / I`` (explicit damping) or ``kp dt^2 / I`` (implicit
    integrators): about 1 or more, and the step is too coarse for the PD."""
    return kp * dt * dt / inertia + (0.0 if implicit else kd * dt / inertia)


def stable_kp(inertia: float, dt: float, damping_ratio: float,
              implicit: bool, share: float = STABLE_SHARE) -> float:
    """The largest ``kp`` whose PD, with ``kd = 2 damping_ratio sqrt(kp I)``, has
    `stiffness` ``share``: with ``x = dt sqrt(kp / I)``, ``x^2 + 2 zeta x = share``
    (``zeta`` 0 under the implicit integrators)."""
    zeta = 0.0 if implicit else float(damping_ratio)
    x = math.sqrt(zeta * zeta + share) - zeta
    return x * x * float(inertia) / (dt * dt)


def check_stability(m, inertia, dt, drives, source) -> None:
    """Warn when a PD's gains are too stiff for the time step ``dt`` (explicit
    damping under Euler / RK4); ``inertia`` (nv,) at the start posture."""
    pds = [d for d in drives if d.kind == "pd"]
    implicit = implicit_damping(m)
    for d in pds:
        i = float(inertia[m.jnt_dofadr[mujoco.mj_name2id(
            m, mujoco.mjtObj.mjOBJ_JOINT, d.joint)]])
        stiff = stiffness(d.kp, d.kd, i, dt, implicit)
        if stiff > 1.0:
            warn_once(f"control: the PD of joint {d.joint!r} of {source} (kp "
                      f"{d.kp:g}, kd {d.kd:g}, inertia {i:.3g}) is stiff for the "
                      f"{dt:g} s time step ((kp dt + kd) dt / I = {stiff:.2g} > 1): "
                      "the simulation may diverge; lower kp / kd or robot.timestep")
