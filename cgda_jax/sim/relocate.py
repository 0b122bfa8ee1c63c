"""Object re-localization: the simulated world's objects put where the features
were MEASURED (a closed loop's tracker; `cgda_jax.strategies.closed_loop`).

A robot's encoders give its joints; what it knows of the objects is the features
(a tracker's box position, a valve's angle).  `ObjectLocator` maps measured
features onto the physics state ``concat(qpos, qvel)`` of a dynamic-mode model,
where the features determine it:

- a joint feature (``angle`` of a hinge, ``position`` of a slide) that is not an
  evolved joint of the robot (a valve's hinge): that joint's qpos is set to the
  measured value, its velocity to 0;
- a body or site feature whose body hangs rigidly (no joints on the way) from a
  top-level body with a free joint (a box, or a site / child body on it): the free
  joint is moved by the measured features' offset from the model's prediction
  along the measured axes (``xy``: x and y, the height as predicted); ``yaw``
  rotates it about the world z axis through its own origin by the measured yaw's
  offset (wrapped to [-pi, pi)); its 6 velocities are set to 0 (at rest: what a
  tracker that sees positions only can assume).  Exact for the free body's own
  frame; for a point rigidly attached to it, the position is exact as long as no
  yaw is re-localized too (the rotation moves the point, the shift does not see
  that).

Everything else stays the model's prediction and is listed in `not_located` with
the reason: a body or site on the robot or on a hinge (a valve's rim: its angle
would need inverse kinematics; give the hinge's ``angle`` feature instead), an
evolved joint (the encoders measure it), a mocap or welded body, and the velocities
of everything but the re-localized joints.
"""

from __future__ import annotations

import jax.numpy as jnp
import mujoco
import numpy as np
from jax import Array

from cgda_jax.sim.features import FRAME_COLUMNS

__all__ = ["ObjectLocator"]

_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_OBJ = {"body": mujoco.mjtObj.mjOBJ_BODY, "site": mujoco.mjtObj.mjOBJ_SITE,
        "joint": mujoco.mjtObj.mjOBJ_JOINT}


_MOVED = ("moved by joints other than one free joint (the robot's links, a hinge): "
          "the features do not give its joints (no inverse kinematics here)")


def _free_root(m: mujoco.MjModel, body: int) -> tuple[int | None, str]:
    """The free joint ``body`` hangs rigidly from, or None and why not."""
    b = body
    while True:
        parent = int(m.body_parentid[b])
        if parent == 0:
            break
        if int(m.body_jntnum[b]) > 0:
            return None, _MOVED
        b = parent
    if b == 0:
        return None, "the world body"
    if int(m.body_jntnum[b]) == 1 and int(m.jnt_type[m.body_jntadr[b]]) == _FREE:
        return int(m.body_jntadr[b]), ""
    if int(m.body_jntnum[b]) == 0:
        return None, "fixed to the world (no free joint)"
    return None, _MOVED


class ObjectLocator:
    """Where a dynamic-mode model's objects are set from measured features.

    Args:
        model: the simulated ``MjModel`` (`cgda_jax.sim.physics.Physics.model`).
        specs: its features' `cgda_jax.sim.features.FeatureSpec` entries, in the
            order of the feature columns.
        robot_qadr: (DoF,) the evolved joints' qpos addresses (never re-localized
            here: the encoders measure them).

    Attributes:
        located: the feature columns (``"box.x"``) that set the model's state.
        not_located: ``{column: why not}`` for the others.
    """

    def __init__(self, model: mujoco.MjModel, specs, robot_qadr=()):
        self.nq, self.nv = int(model.nq), int(model.nv)
        robot = {int(a) for a in np.asarray(robot_qadr).ravel()}
        pos_cols, pos_q = [], []        # shifted qpos entries of free joints
        yaw_cols, yaw_q = [], []        # rotated free-joint quaternions (qpos adr)
        set_cols, set_q = [], []        # joints set to the measured value
        rest_v: set[int] = set()        # velocities set to 0
        self.located: list[str] = []
        self.not_located: dict[str, str] = {}
        col = 0
        for spec in specs:
            names = spec.columns()
            i = mujoco.mj_name2id(model, _OBJ[spec.kind], spec.name)
            if spec.kind == "joint":
                adr, dof = int(model.jnt_qposadr[i]), int(model.jnt_dofadr[i])
                if adr in robot:
                    self.not_located[names[0]] = "an evolved joint (measured)"
                else:
                    set_cols.append(col)
                    set_q.append(adr)
                    rest_v.add(dof)
                    self.located.append(names[0])
                col += 1
                continue
            body = i if spec.kind == "body" else int(model.site_bodyid[i])
            jnt, why = _free_root(model, body)
            for c, name in zip(FRAME_COLUMNS[spec.quantity], names):
                if jnt is None:
                    self.not_located[name] = why
                else:
                    adr = int(model.jnt_qposadr[jnt])
                    if c == "yaw":
                        yaw_cols.append(col)
                        yaw_q.append(adr + 3)
                    else:
                        pos_cols.append(col)
                        pos_q.append(adr + int(c))
                    dof = int(model.jnt_dofadr[jnt])
                    rest_v.update(range(dof, dof + 6))
                    self.located.append(name)
                col += 1
        as_i = lambda v: np.asarray(v, np.int32)
        self._pos = (as_i(pos_cols), as_i(pos_q))
        self._yaw = (as_i(yaw_cols), as_i(yaw_q))
        self._set = (as_i(set_cols), as_i(set_q))
        self._rest = as_i(sorted(rest_v))

    @classmethod
    def of(cls, sim) -> ObjectLocator | None:
        """The locator of a `cgda_jax.sim.simulator.Simulator`'s physics; None for a
        kinematic simulator or one whose scene reads no world features (a marker
        scene: nothing in the model is an object the features place)."""
        phys = getattr(sim, "physics", None)
        if phys is None or phys.features is None:
            return None
        return cls(phys.model, phys.features.specs, phys.gene_qadr)

    def __repr__(self) -> str:
        return f"ObjectLocator(located={self.located}, not_located={self.not_located})"

    @property
    def any(self) -> bool:
        """Whether any feature moves the model's state."""
        return bool(self.located)

    def locate(self, data: Array, predicted: Array, measured: Array) -> Array:
        """``data`` (nq + nv,), the model's state whose features are
        ``predicted`` (F,), with the objects put where ``measured`` (F,) says
        (see the module doc). Pure ``jnp``: jit it at the call site."""
        data = jnp.asarray(data)
        qpos, qvel = data[:self.nq], data[self.nq:]
        measured = jnp.asarray(measured, data.dtype)
        delta = measured - jnp.asarray(predicted, data.dtype)
        cols, adr = self._yaw
        if len(cols):
            a = jnp.mod(delta[cols] + jnp.pi, 2 * jnp.pi) - jnp.pi
            w, z = jnp.cos(a / 2), jnp.sin(a / 2)  # rotation about world z
            q = qpos[adr[:, None] + np.arange(4)]  # (K, 4): w, x, y, z
            rot = jnp.stack([w * q[:, 0] - z * q[:, 3], w * q[:, 1] - z * q[:, 2],
                             w * q[:, 2] + z * q[:, 1], w * q[:, 3] + z * q[:, 0]],
                            axis=-1)
            qpos = qpos.at[adr[:, None] + np.arange(4)].set(rot)
        cols, adr = self._pos
        if len(cols):
            qpos = qpos.at[adr].set(qpos[adr] + delta[cols])
        cols, adr = self._set
        if len(cols):
            qpos = qpos.at[adr].set(measured[cols])
        if len(self._rest):
            qvel = qvel.at[self._rest].set(0.0)
        return jnp.concatenate([qpos, qvel])
