"""One MJX physics step that integrates like MuJoCo C when actuator forces saturate.

Under the ``implicitfast`` integrator MuJoCo C (checked on 4.0) drops an actuator's
velocity derivative from the implicit update while its force is clamped, at its own
``forcerange`` or at its joint's ``actuatorfrcrange``: a clamped force does not
depend on the velocity, so an implicit ``-kv qdot`` there would be damping the
actuator cannot give (one step of a saturated servo under C's ``implicitfast``
equals its ``Euler`` step exactly).  ``mjx.step`` keeps the derivative, so a
force-limited arm (the Panda's PD, the iiwa's servos) moves slower under MJX than
under C: 5 mm apart at the tool after 0.2 s of a 0.01 s step on the Panda, 1.5 mm at
0.005 s, against 3e-7 m under ``Euler``.

`step_fn(model)` returns ``mjx.step`` where that cannot happen (another integrator,
no force limit on an actuator or an actuated joint), else `clamped_implicit_step`:
``mjx.forward``, then ``mjx.implicit`` on a copy of the model whose clamped
actuators have their velocity terms (``biasprm[2]``, ``gainprm[2]``) set to zero.
Only the implicit update reads those terms; the forces were computed by the
forward pass with the model's own values.
"""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp
import mujoco
import numpy as np

from cgda_jax.sim._mujoco_env import mjx_module

__all__ = ["clamped_implicit_step", "needs_clamped_step", "step_fn"]

_JOINT_TRN = (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))


def _clamp_bounds(m: mujoco.MjModel):
    """Per actuator: its own force bounds, the dof of the joint it drives and that
    joint's ``actuatorfrcrange`` (+-inf where there is none)."""
    own = np.asarray(m.actuator_forcelimited, bool)
    own_lo = np.where(own, m.actuator_forcerange[:, 0], -np.inf).astype(np.float32)
    own_hi = np.where(own, m.actuator_forcerange[:, 1], np.inf).astype(np.float32)
    dof = np.zeros(m.nu, np.int32)
    j_lo = np.full(m.nu, -np.inf, np.float32)
    j_hi = np.full(m.nu, np.inf, np.float32)
    for a in range(m.nu):
        if int(m.actuator_trntype[a]) in _JOINT_TRN:
            j = int(m.actuator_trnid[a, 0])
            dof[a] = int(m.jnt_dofadr[j])
            if m.jnt_actfrclimited[j]:
                j_lo[a], j_hi[a] = m.jnt_actfrcrange[j]
    return own_lo, own_hi, dof, j_lo, j_hi


def needs_clamped_step(m: mujoco.MjModel) -> bool:
    """Whether ``mjx.step`` integrates ``m`` differently from MuJoCo C when a force
    saturates: ``implicitfast`` and a force limit on an actuator or on a joint an
    actuator drives."""
    if int(m.opt.integrator) != int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST) or not m.nu:
        return False
    own_lo, own_hi, _, j_lo, j_hi = _clamp_bounds(m)
    return not np.all(np.isinf([own_lo, own_hi, j_lo, j_hi]))


def clamped_implicit_step(m: mujoco.MjModel) -> Callable:
    """``step(mx, d) -> d``: an ``implicitfast`` step of the MJX model ``mx`` (put from
    ``m``) without the velocity derivative of the actuators clamped in this step."""
    mjx = mjx_module()
    own_lo, own_hi, dof, j_lo, j_hi = _clamp_bounds(m)

    def step(mx, d):
        d = mjx.forward(mx, d)
        f = d.actuator_force
        q = d.qfrc_actuator[dof]
        clamped = ((f <= own_lo) | (f >= own_hi) | (q <= j_lo) | (q >= j_hi))
        keep = jnp.where(clamped, 0.0, 1.0).astype(mx.actuator_biasprm.dtype)
        mi = mx.replace(
            actuator_biasprm=mx.actuator_biasprm.at[:, 2].multiply(keep),
            actuator_gainprm=mx.actuator_gainprm.at[:, 2].multiply(keep))
        return mjx.implicit(mi, d)

    return step


def step_fn(m: mujoco.MjModel) -> Callable:
    """The MJX step for the model ``m``: `clamped_implicit_step` where
    `needs_clamped_step`, else ``mjx.step``."""
    return clamped_implicit_step(m) if needs_clamped_step(m) else mjx_module().step
