"""Dynamic physics: the model that is stepped, and the backends that step it.

Dynamic mode simulates the robot with gravity, its actuators and joint limits.
What is simulated (`reduced_model`) is the robot's MJCF rebuilt with ``mujoco.MjSpec``:

- the joints it holds driven as `cgda_jax.sim.control.plan_control` says: position
  actuators as the model has them; motors and other actuators (or, opted in, every
  joint) through a joint-space PD with gravity compensation, built into the model so
  that both backends step the same law;
- joints that are neither evolved nor needed are **welded**: a hinge or slide joint
  that is not evolved, is held by an actuator and starts at its reference
  value (``qpos0``) is deleted together with its actuator, so the body it moved is
  rigidly attached where the joint would hold it (TEO has 14 joints; the paper
  moves 3 and holds one).  Fixed joints at another value, passive joints (an
  object's free joint, a valve's hinge) and anything a backend cannot weld stay;
- a ``framepos`` sensor reads the marker site (what the scenes see at every step),
  and per evolved joint a ``jointpos`` and a ``jointactfrc`` sensor (its simulated
  position and actuator force at every step: what the feasibility check judges as
  executed, `Physics.executed`);
- automatic resetting of diverged simulations (``mjDSBL_AUTORESET``) is off, so a
  divergence shows up as non-finite values instead of a silent jump back to qpos0;
- ``timestep`` (optional) replaces the model's own.

A *backend* steps that model for one example, `segment(state, ctrl) -> (state, sens)`,
written for ONE candidate and batched with ``vmap`` at the call site:

- ``"mjx"``: ``mujoco.mjx`` (JAX implementation) under ``lax.scan``; runs unchanged
  on a GPU, the path for accelerators.
- ``"mujoco"``: MuJoCo's C code through ``mujoco.rollout`` (its own thread pool),
  called from the jitted program with ``jax.pure_callback``; under ``vmap`` the whole
  batch is one call.  Fastest on CPU-only machines; not differentiable.
- ``"auto"``: ``"mujoco"`` when JAX's default backend is the CPU, else ``"mjx"``.

Both give the same features on the same inputs (float32 MJX vs float64 C: within
1e-4 m on the tests' rollouts of 0.5-1 s).

The physics state carried between segments is ``concat(qpos, qvel)`` of the simulated
model, float32 (the constraint solver's warm start is not carried).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax import Array

from cgda_jax.sim._mujoco_env import mjx_module
from cgda_jax.sim.mjx_step import step_fn

__all__ = ["PHYSICS", "MjxBackend", "MujocoBackend", "Physics", "resolve_physics",
           "saturated"]

#: Names accepted by ``physics=``.
PHYSICS = ("auto", "mjx", "mujoco")

_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
_MARKER_SENSOR = "cgda_marker"
_JOINT_SENSORS = ("cgda_q_", "cgda_f_")  # + joint name: jointpos, jointactfrc

#: A C rollout whose |qpos| or |qvel| passes this (rad, m, rad/s, m/s) diverged:
#: ``mujoco.rollout`` stops a rollout at MuJoCo's "unstable simulation" warning and
#: repeats its last (huge but finite) state, from which sensors read plausible-looking
#: positions; such rollouts are turned into NaN (as MJX gives), which the strategies
#: count as invalid.
DIVERGED = 1e4


def resolve_physics(name: str) -> str:
    """``"auto"`` -> ``"mujoco"`` on a CPU-only JAX, else ``"mjx"``; others unchanged."""
    if name not in PHYSICS:
        raise ValueError(f"physics={name!r}; expected one of {PHYSICS}")
    if name == "auto":
        return "mujoco" if jax.default_backend() == "cpu" else "mjx"
    return name


def saturated(force, force_range, xp=np):
    """Where a joint's actuator force (..., DoF) is at its limit ``force_range``
    (DoF, 2; +-inf: none), within 0.1 % of it: a clamped force equals the limit.
    ``xp``: ``numpy`` or ``jax.numpy``."""
    lo, hi = (np.asarray(force_range, np.float64)[:, i] for i in (0, 1))
    hi = np.where(np.isfinite(hi), hi - 1e-3 * np.abs(hi), np.inf)
    lo = np.where(np.isfinite(lo), lo + 1e-3 * np.abs(lo), -np.inf)
    return (force >= xp.asarray(hi, force.dtype)) | (force <= xp.asarray(lo, force.dtype))


def _position_actuated(m: mujoco.MjModel) -> dict[int, int]:
    """joint id -> actuator id, for actuators that drive one joint."""
    out = {}
    for a in range(m.nu):
        if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT):
            out[int(m.actuator_trnid[a, 0])] = a
    return out


def weldable_joints(
    m: mujoco.MjModel, start_qpos: np.ndarray, keep: Sequence[str],
    held: Sequence[str] = (),
) -> list[str]:
    """Joints that `reduced_model` deletes: hinge/slide, not in `keep`, driven by an
    actuator (or named in `held`: joints the control would hold without one), and at
    their reference value (``m.qpos0``) in `start_qpos` (nq,)."""
    actuated = _position_actuated(m)
    out = []
    for j in range(m.njnt):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
        if not name or name in keep or int(m.jnt_type[j]) not in (_HINGE, _SLIDE):
            continue
        adr = int(m.jnt_qposadr[j])
        if (j in actuated or name in held) and abs(start_qpos[adr]
                                                   - m.qpos0[adr]) < 1e-9:
            out.append(name)
    return out


def reduced_model(
    spec: mujoco.MjSpec,
    marker_site: str,
    *,
    weld: Sequence[str] = (),
    timestep: float | None = None,
    features: Sequence = (),
    control=None,
    model: mujoco.MjModel | None = None,
    joints: Sequence[str] = (),
) -> mujoco.MjModel:
    """Compile `spec` with the drives of `control` (a
    `cgda_jax.sim.drives.ControlPlan` for `model`, the spec's compiled model), the
    joints `weld` deleted (and their actuators), a ``framepos`` sensor on
    `marker_site`, a ``jointpos`` and a ``jointactfrc`` sensor on each of
    `joints` (the evolved ones), the sensors of object `features`
    (`cgda_jax.sim.features.add_sensors`), autoreset off and an optional timestep.

    `spec` is modified (pass a copy you own).
    """
    if control is not None:
        control.apply(spec, model)
    weld = set(weld)
    for act in list(spec.actuators):
        if act.target in weld:
            spec.delete(act)
    for joint in list(spec.joints):
        if joint.name in weld:
            spec.delete(joint)
    sensor = spec.add_sensor()
    sensor.name = _MARKER_SENSOR
    sensor.type = mujoco.mjtSensor.mjSENS_FRAMEPOS
    sensor.objtype = mujoco.mjtObj.mjOBJ_SITE
    sensor.objname = marker_site
    for kind, prefix in zip((mujoco.mjtSensor.mjSENS_JOINTPOS,
                             mujoco.mjtSensor.mjSENS_JOINTACTFRC), _JOINT_SENSORS):
        for name in joints:
            sensor = spec.add_sensor()
            sensor.name, sensor.type = prefix + name, kind
            sensor.objtype, sensor.objname = mujoco.mjtObj.mjOBJ_JOINT, name
    if features:
        from cgda_jax.sim.features import add_sensors

        add_sensors(spec, features)
    model = spec.compile()
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    if timestep is not None:
        if not (np.isfinite(timestep) and timestep > 0):
            raise ValueError(
                f"timestep must be a positive number of seconds, got {timestep}")
        model.opt.timestep = float(timestep)
    return model


class Physics:
    """The simulated model of a robot in dynamic mode and its start state.

    Args:
        robot: the `Robot` (its MJCF source is rebuilt with ``MjSpec``).
        timestep: physics step in seconds (None: the model's own).
        reduce: weld the joints `weldable_joints` finds (default); False simulates
            every joint of the model (each unevolved actuated joint held by its
            actuator at its start value).
        features: object features (`FeatureSpec` or dicts) the scene reads; their
            sensors are added and `features` is their `FeatureSet` on `model`.
        control: how the held joints are driven, a `cgda_jax.sim.control.Control`
            or a ``[robot.control]`` table (None: the defaults).

    Attributes:
        model: the simulated ``MjModel``.
        control: the `cgda_jax.sim.drives.ControlPlan` (one `Drive` per held
            joint: the evolved ones, the fixed ones not welded, any other simulated
            joint with an actuator).
        welded: names of the welded (deleted) joints.
        nq, nv, nu, state_size (nq + nv).
        gene_qadr: (DoF,) qpos addresses of the evolved joints in `model`.
        act_qadr: (nu,) qpos address each actuator of `model` drives; act_gear:
            (nu,) its gear (a position servo's control is ``gear x q``).
        qpos0: (nq,) start posture of `model` (the robot's start values mapped by
            joint name).
        marker_adr: sensordata address of the marker's ``framepos`` sensor.
        gene_sensor_adr, force_sensor_adr: (DoF,) sensordata addresses of the
            evolved joints' positions and actuator forces (``qfrc_actuator``).
        force_range: (DoF, 2) the evolved joints' force limits [N m or N] (their
            drives', +-inf: none): a force there is saturated.
    """

    def __init__(self, robot, *, timestep: float | None = None, reduce: bool = True,
                 features: Sequence = (), control=None):
        from cgda_jax.sim.control import (
            Control,
            actuator_kind,
            check_transmissions,
            plan_control,
        )

        full = robot.mj_model
        start = np.asarray(robot.qpos0, np.float64)
        keep = list(robot.joint_names)
        if not isinstance(control, Control):
            control = Control.from_dict(control)
        pd_holds = list(robot.fixed) if control.mode == "pd" else []
        self.welded = weldable_joints(full, start, keep, pd_holds) if reduce else []
        jt = mujoco.mjtObj.mjOBJ_JOINT
        actuated = _position_actuated(full)
        held = keep + [n for n in robot.fixed if n not in self.welded]
        held += [mujoco.mj_id2name(full, jt, j) for j in sorted(actuated)
                 if int(full.jnt_type[j]) in (_HINGE, _SLIDE)
                 and mujoco.mj_id2name(full, jt, j) not in {*held, *self.welded}]
        if None in held or "" in held:  # an unnamed joint: only a servo holds it
            if any(actuator_kind(full, a) != "position" for j, a in actuated.items()
                   if not mujoco.mj_id2name(full, jt, j)):
                raise ValueError(f"control: {robot.source} has an unnamed joint "
                                 "driven by a motor; name it so that dynamic mode "
                                 "can drive it with a PD")
            held = [n for n in held if n]
        self.control = plan_control(full, start, held, control, robot.source,
                                    timestep)
        spec = robot.spec()
        self.model = reduced_model(spec, robot.marker_site, weld=self.welded,
                                   timestep=timestep, features=features,
                                   control=self.control, model=full,
                                   joints=keep)
        check_transmissions(self.model, robot.source)
        self._spec, self._source = spec, robot.source
        self.object_bodies = tuple(getattr(robot, "object_bodies", ()))
        self.features = None
        if features:
            from cgda_jax.sim.features import FeatureSet

            self.features = FeatureSet(self.model, features)
        m = self.model
        self.nq, self.nv, self.nu = m.nq, m.nv, m.nu
        self.state_size = m.nq + m.nv
        self.timestep = float(m.opt.timestep)
        # deleting joints keeps the others' order: carry the robot's start values over
        kept = [j for j in range(full.njnt)
                if mujoco.mj_id2name(full, jt, j) not in self.welded]
        assert len(kept) == m.njnt
        width = {int(mujoco.mjtJoint.mjJNT_FREE): 7, int(mujoco.mjtJoint.mjJNT_BALL): 4}
        qpos0 = np.array(m.qpos0, np.float64)
        for j, fj in enumerate(kept):
            n = width.get(int(m.jnt_type[j]), 1)
            a, b = int(m.jnt_qposadr[j]), int(full.jnt_qposadr[fj])
            qpos0[a:a + n] = start[b:b + n]
        self.qpos0 = qpos0
        self.gene_qadr = np.array(
            [m.jnt_qposadr[mujoco.mj_name2id(m, jt, n)] for n in robot.joint_names],
            np.int32,
        )
        self.act_qadr = np.asarray(m.jnt_qposadr[m.actuator_trnid[:, 0]], np.int32)
        self.act_gear = np.asarray(m.actuator_gear[:, 0], np.float32)
        sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, _MARKER_SENSOR)
        self.marker_adr = int(m.sensor_adr[sid])
        st = mujoco.mjtObj.mjOBJ_SENSOR
        self.gene_sensor_adr, self.force_sensor_adr = (np.array(
            [m.sensor_adr[mujoco.mj_name2id(m, st, prefix + n)] for n in keep],
            np.int32) for prefix in _JOINT_SENSORS)
        self.force_range = np.array(
            [self.control.drive(n).force for n in keep], np.float64).reshape(-1, 2)
        self.nsensordata = int(m.nsensordata)
        self.site_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, robot.marker_site)

    def __repr__(self) -> str:
        return (f"Physics(nq={self.nq}, nu={self.nu}, timestep={self.timestep}, "
                f"welded={len(self.welded)} joints)")

    def mjx_model(self) -> mujoco.MjModel:
        """`model` ready for MJX: unsupported geom pairs the task does not need
        turned off (`cgda_jax.sim.mjx_prep.mjx_ready`; an error naming a needed one).
        """
        from cgda_jax.sim.mjx_prep import mjx_ready

        return mjx_ready(self.model, self._spec, self.object_bodies, self._source)

    def start_state(self, genes: Array) -> Array:
        """(nq + nv,) state at rest with the evolved joints at ``genes`` (DoF,)."""
        qpos = jnp.asarray(self.qpos0, jnp.float32).at[self.gene_qadr].set(genes)
        return jnp.concatenate([qpos, jnp.zeros(self.nv, jnp.float32)])

    def executed(self, sens: Array, commanded: Array) -> tuple[Array, Array, Array]:
        """What a segment executed, from its sensordata (T, nsensordata) and the
        commanded postures of the evolved joints at its steps (T, DoF): (the
        simulated postures (T, DoF), the tracking error ``max |simulated -
        commanded|`` per joint (DoF,), the share of the steps at which any evolved
        joint's actuator force is at its limit (`saturated`), scalar)."""
        q = sens[:, self.gene_sensor_adr]
        force = sens[:, self.force_sensor_adr]
        track = jnp.max(jnp.abs(q - commanded), axis=0)
        sat = jnp.mean(jnp.any(saturated(force, self.force_range, jnp), axis=-1))
        return q, track, sat

    def ctrl_of(self, qpos: Array) -> Array:
        """(nu,) actuator targets that hold the posture ``qpos`` (..., nq)."""
        return qpos[..., self.act_qadr] * self.act_gear


class MjxBackend:
    """Steps `Physics.model` with ``mujoco.mjx`` (JAX implementation)."""

    name = "mjx"

    def __init__(self, physics: Physics):
        self.physics = physics
        mjx = mjx_module()
        m = physics.mjx_model()
        # mjx.step, or MuJoCo C's rule for saturated forces under implicitfast
        self._step = step_fn(m)
        with jax.ensure_compile_time_eval():
            self.model = mjx.put_model(m, impl="jax")
            self._data0 = mjx.make_data(self.model, impl="jax")

    def _data(self, state):
        p = self.physics
        return self._data0.replace(qpos=state[: p.nq], qvel=state[p.nq:])

    def segment(self, state: Array, ctrl: Array) -> tuple[Array, Array]:
        """Step once per row of ``ctrl`` (T, nu) from ``state`` (nq + nv,).

        Returns:
            (state after T steps, sensordata (T, nsensordata) after each step; the
            marker's position is at ``physics.marker_adr``).
        """
        mjx = mjx_module()

        def body(d, c):
            d = self._step(self.model, d.replace(ctrl=c))
            return d, d.sensordata  # of the state before this step

        d, xs = jax.lax.scan(body, self._data(state), ctrl)
        last = mjx.forward(self.model, d).sensordata
        sens = jnp.concatenate([xs[1:], last[None]], axis=0)
        return jnp.concatenate([d.qpos, d.qvel]).astype(jnp.float32), sens


class MujocoBackend:
    """Steps `Physics.model` with MuJoCo C (``mujoco.rollout``) from inside JAX.

    Args:
        physics: the `Physics`.
        nthread: threads of the rollout pool (default: the CPU count).
    """

    name = "mujoco"

    def __init__(self, physics: Physics, nthread: int | None = None):
        from mujoco import rollout

        self.physics = physics
        m = physics.model
        self.nthread = max(1, int(nthread or os.cpu_count() or 1))
        self._datas = [mujoco.MjData(m) for _ in range(self.nthread)]
        self._pool = rollout.Rollout(nthread=self.nthread)
        self._lock = threading.Lock()  # one pool, several devices may call at once
        spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
        d = mujoco.MjData(m)
        self._template = np.zeros(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, self._template, spec)
        # full-physics state layout: time (1), qpos (nq), qvel (nv), ...
        assert mujoco.mj_stateSize(m, int(mujoco.mjtState.mjSTATE_TIME)) == 1

    def _host_segment(self, state: np.ndarray, ctrl: np.ndarray):
        p = self.physics
        batch = state.shape[:-1]
        state = np.asarray(state, np.float64).reshape(-1, p.state_size)
        ctrl = np.asarray(ctrl, np.float64).reshape(-1, *ctrl.shape[-2:])
        n, t = ctrl.shape[:2]
        init = np.tile(self._template, (n, 1))
        init[:, 1:1 + p.state_size] = state
        # one extra step: the sensors of step k+1 read the state after step k
        ctrl = np.concatenate([ctrl, ctrl[:, -1:]], axis=1)
        with self._lock:
            states, sens = self._pool.rollout(
                p.model, self._datas, init, ctrl, nstep=t + 1
            )
        qv = states[:, :, 1:1 + p.state_size]
        bad = ~np.all(np.isfinite(qv), axis=(1, 2)) | np.any(np.abs(qv) > DIVERGED,
                                                            axis=(1, 2))
        final = states[:, t - 1, 1:1 + p.state_size]
        sens = sens.copy() if bad.any() else sens
        final[bad] = np.nan
        sens[bad] = np.nan
        return (final.reshape(*batch, p.state_size).astype(np.float32),
                sens[:, 1:].reshape(*batch, t, p.nsensordata).astype(np.float32))

    def segment(self, state: Array, ctrl: Array) -> tuple[Array, Array]:
        """As `MjxBackend.segment`, computed by MuJoCo C (float64 inside)."""
        p = self.physics
        t = ctrl.shape[0]
        shapes = (jax.ShapeDtypeStruct((p.state_size,), jnp.float32),
                  jax.ShapeDtypeStruct((t, p.nsensordata), jnp.float32))
        return jax.pure_callback(
            self._host_segment, shapes, state, jnp.asarray(ctrl, jnp.float32),
            vmap_method="broadcast_all",
        )


def make_backend(physics: Physics, name: str = "auto"):
    """The backend called ``name`` (see `PHYSICS`) for `physics`."""
    name = resolve_physics(name)
    return MjxBackend(physics) if name == "mjx" else MujocoBackend(physics)
