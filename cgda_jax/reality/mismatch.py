"""The shipped `Reality`: a mismatched world, the run's scene in MuJoCo C with
perturbed parameters, so that a result can be tried on a world that is not the
model it was found in.

`Mismatch` holds the perturbations, each a number or a ``[low, high]`` range drawn
uniformly with its ``seed`` (`Mismatch.draw`):

- ``mass_scale``: every object body's mass (the whole model's bodies when the world
  has no objects) times this;
- ``friction_scale``: every geom's sliding friction times this;
- ``joint_offset_deg``: per evolved joint, the physical joint sits this far from
  what it is commanded (a calibration offset; its encoder still reads the
  commanded frame, so only the features show it); a range is drawn per joint; a
  table ``{joint = degrees}`` gives named joints their own (the others 0);
- ``damping_scale``: the evolved joints' damping times this;
- ``gain_scale``: the actuators' position gain (kp) times this;
- ``noise``: the features measured with Gaussian noise of this standard deviation
  (feature units), drawn from the same seed, new at every measurement;
- ``delay_s``: the features are those of this long before the measurement (a
  sensor's latency; within one `execute` call, at least its start);
- ``marker_noise``: the tool's position (``Measurement.marker``, the simulator's
  marker point, measured at the features' time) with Gaussian noise of this
  standard deviation [m].

`MismatchedWorld` needs a dynamic-mode simulator (its physics model).  With the
default `Mismatch` (nothing perturbed) it measures what the simulator computes.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Any

import numpy as np

from cgda_jax.reality.control_trajectory import ExportedTrajectory
from cgda_jax.reality.protocol import Measurement
from cgda_jax.reality.replay import SceneTracker

__all__ = ["FIELDS", "Mismatch", "MismatchedWorld"]

#: The perturbations, their neutral values and what each may be.
FIELDS = {"mass_scale": 1.0, "friction_scale": 1.0, "joint_offset_deg": 0.0,
          "damping_scale": 1.0, "gain_scale": 1.0, "noise": 0.0, "delay_s": 0.0,
          "marker_noise": 0.0}
_POSITIVE = ("mass_scale", "friction_scale", "gain_scale")
_NONNEGATIVE = ("damping_scale", "noise", "delay_s", "marker_noise")


def _value(name: str, v) -> float | tuple[float, float] | dict[str, float]:
    if name == "joint_offset_deg" and isinstance(v, dict):
        out = {str(k): _value(f"{name}.{k}", x) for k, x in v.items()}
        ranged = sorted(k for k, x in out.items() if isinstance(x, tuple))
        if ranged:
            raise ValueError(f"reality.{name}: joint(s) {ranged} given a range; a "
                             "table gives each named joint a number of degrees")
        return out
    if isinstance(v, (list, tuple)):
        if len(v) != 2:
            raise ValueError(f"reality.{name} = {list(v)}: a range is [low, high]")
        lo, hi = (_value(name, x) for x in v)
        if lo > hi:
            raise ValueError(f"reality.{name} = [{lo}, {hi}]: low > high")
        return (lo, hi)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(  # noqa: TRY004 - a config value: a config error
            f"reality.{name} = {v!r}: expected a number or [low, high]")
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"reality.{name} = {v}: not finite")
    if name in _POSITIVE and v <= 0:
        raise ValueError(f"reality.{name} = {v}: must be > 0")
    if name in _NONNEGATIVE and v < 0:
        raise ValueError(f"reality.{name} = {v}: must be >= 0")
    return v


@dataclasses.dataclass(frozen=True)
class Mismatch:
    """How the world differs from the model (see the module doc); numbers or
    ``(low, high)`` ranges, drawn with ``seed``."""

    mass_scale: Any = 1.0
    friction_scale: Any = 1.0
    joint_offset_deg: Any = 0.0
    damping_scale: Any = 1.0
    gain_scale: Any = 1.0
    noise: Any = 0.0
    delay_s: Any = 0.0
    marker_noise: Any = 0.0
    seed: int = 0

    def __post_init__(self):
        for name in FIELDS:
            object.__setattr__(self, name, _value(name, getattr(self, name)))
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise ValueError(  # noqa: TRY004 - a config value: a config error
                f"reality.seed = {self.seed!r}: expected an integer")

    @classmethod
    def from_dict(cls, table: dict) -> Mismatch:
        """From a ``[reality]`` table; an unknown key is an error naming it."""
        unknown = sorted(set(table) - set(FIELDS) - {"seed"})
        if unknown:
            raise ValueError(f"reality: unknown key(s) {unknown}; expected "
                             f"{sorted([*FIELDS, 'seed'])}")
        return cls(**table)

    def draw(self, n_dof: int, joint_names=None) -> dict[str, Any]:
        """The concrete values: ranges drawn uniformly (``joint_offset_deg`` per
        joint, (n_dof,) radians as ``joint_offset``; a table by ``joint_names``),
        with ``seed``.

        Raises:
            ValueError: a ``joint_offset_deg`` table names a joint not in
                ``joint_names``.
        """
        rng = np.random.default_rng(self.seed)
        out: dict[str, Any] = {}
        for name in FIELDS:
            v = getattr(self, name)
            if name == "joint_offset_deg" and isinstance(v, dict):
                names = list(joint_names or [])
                unknown = sorted(set(v) - set(names))
                if unknown or len(names) != n_dof:
                    raise ValueError(f"reality.joint_offset_deg: joint(s) {unknown} "
                                     f"are not the evolved joints {names}")
                out["joint_offset"] = np.deg2rad(
                    np.array([v.get(j, 0.0) for j in names], np.float64))
            elif name == "joint_offset_deg":
                off = (rng.uniform(v[0], v[1], n_dof) if isinstance(v, tuple)
                       else np.full(n_dof, v))
                out["joint_offset"] = np.deg2rad(off)
            else:
                out[name] = float(rng.uniform(*v)) if isinstance(v, tuple) else v
        return out


class MismatchedWorld:
    """The run's scene in MuJoCo C with `Mismatch`'s perturbations: a `Reality`.

    Args:
        sim: a dynamic-mode `cgda_jax.sim.simulator.Simulator` (its physics model,
            scene, robot and start posture).
        mismatch: the perturbations (default: none).

    Attributes:
        feature_names, joint_names: the simulator's.
        drawn: the concrete perturbation values (`Mismatch.draw`).
        model: the perturbed ``MjModel``.
    """

    def __init__(self, sim, mismatch: Mismatch | None = None):
        import mujoco

        if sim.mode != "dynamic":
            raise ValueError("a mismatched world is physics: it needs a dynamic-mode "
                             "simulator (robot.mode = \"dynamic\")")
        self.sim, self.mismatch = sim, mismatch or Mismatch()
        self.feature_names = tuple(sim.feature_names)
        self.joint_names = tuple(sim.robot.joint_names)
        self.phys = phys = sim.physics
        self.drawn = self.mismatch.draw(len(self.joint_names), self.joint_names)
        m = self.model = copy.deepcopy(phys.model)
        objects = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b)
                   for b in phys.object_bodies]
        bodies = [b for b in objects if b >= 0] or list(range(1, m.nbody))
        m.body_mass[bodies] *= self.drawn["mass_scale"]
        m.body_inertia[bodies] *= self.drawn["mass_scale"]
        m.geom_friction[:, 0] *= self.drawn["friction_scale"]
        jt = mujoco.mjtObj.mjOBJ_JOINT
        dofs = [m.jnt_dofadr[mujoco.mj_name2id(m, jt, n)] for n in self.joint_names]
        m.dof_damping[dofs] *= self.drawn["damping_scale"]
        m.actuator_gainprm[:, 0] *= self.drawn["gain_scale"]
        m.actuator_biasprm[:, 1] *= self.drawn["gain_scale"]
        self._rng = np.random.default_rng([self.mismatch.seed, 1])
        self._marker_rng = np.random.default_rng([self.mismatch.seed, 2])
        self._data = None

    def __repr__(self) -> str:
        return f"MismatchedWorld({self.mismatch})"

    def _features(self, sens: np.ndarray, markers: np.ndarray) -> np.ndarray:
        if self.phys.features is not None:
            f = np.asarray(self.phys.features.from_sensordata(sens), np.float64)
        else:
            f = self._tracker.advance(markers)
        return f + self._rng.normal(0.0, 1.0, f.shape) * self.drawn["noise"]

    def _tool(self, marker: np.ndarray) -> np.ndarray:
        """The tool's measured position (3,): the marker, with ``marker_noise``."""
        return (np.asarray(marker, np.float64)
                + self._marker_rng.normal(0.0, 1.0, 3) * self.drawn["marker_noise"])

    def reset(self) -> Measurement:
        """The start posture (offset as the world's joints are), at rest."""
        import mujoco

        d = self._data = mujoco.MjData(self.model)
        start = np.asarray(self.sim.robot.start_genes, np.float64)
        d.qpos[:] = self.phys.qpos0
        d.qpos[self.phys.gene_qadr] = start + self.drawn["joint_offset"]
        mujoco.mj_forward(self.model, d)
        marker = d.sensordata[self.phys.marker_adr:self.phys.marker_adr + 3].copy()
        self._tracker = SceneTracker(self.sim.scene, marker)
        self._commanded = start
        f = self._features(d.sensordata.copy(), marker[None])
        return Measurement(f[None], start[None], self._tool(marker)[None])

    def execute(self, trajectory: ExportedTrajectory) -> Measurement:
        """Follow the position targets of ``trajectory`` (linear between its
        samples, offset) from the current state; measure at its feature times.

        Raises:
            ValueError: before `reset`, or the trajectory does not start where the
                last one ended (the commanded posture), or other joints.
        """
        import mujoco
        from mujoco import rollout

        if self._data is None:
            raise ValueError("MismatchedWorld.execute before reset()")
        if tuple(trajectory.joint_names) != self.joint_names:
            raise ValueError(f"the trajectory's joints {list(trajectory.joint_names)} "
                             f"are not the world's {list(self.joint_names)}")
        if not np.allclose(trajectory.start, self._commanded, atol=1e-6):
            raise ValueError(f"the trajectory starts at {trajectory.start.tolist()}, "
                             f"not where the robot was sent: "
                             f"{self._commanded.tolist()}")
        m, d, phys = self.model, self._data, self.phys
        dt = float(m.opt.timestep)
        n_steps = max(1, math.ceil(trajectory.duration / dt - 1e-6))
        times = (np.arange(n_steps) + 1) * dt
        qpos = np.tile(np.asarray(phys.qpos0, np.float64), (n_steps, 1))
        qpos[:, phys.gene_qadr] = (trajectory.position_at(times)
                                   + self.drawn["joint_offset"])
        ctrl = np.asarray(phys.ctrl_of(qpos), np.float64)
        ctrl = np.concatenate([ctrl, ctrl[-1:]])
        spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
        init = np.zeros(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, init, spec)
        states, sens = rollout.rollout(m, d, init[None], ctrl[None],
                                       nstep=n_steps + 1)
        states, sens = states[0], sens[0]  # row k: after k steps
        ends = np.minimum(np.round(trajectory.feature_t / dt).astype(np.int64),
                          n_steps)
        delay = round(self.drawn["delay_s"] / dt)
        markers = sens[:, phys.marker_adr:phys.marker_adr + 3]
        feats, joints, tools, prev = [], [], [], 0
        for e in ends:
            seen = max(0, e - delay)
            feats.append(self._features(sens[seen], markers[prev + 1:seen + 1]
                                        if seen > prev else markers[seen:seen + 1]))
            tools.append(self._tool(markers[seen]))
            prev = max(prev, seen)
            q = states[e - 1, 1:1 + phys.nq] if e > 0 else d.qpos
            joints.append(np.asarray(q)[phys.gene_qadr] - self.drawn["joint_offset"])
        if prev < n_steps and phys.features is None:  # the rest of the path
            self._tracker.advance(markers[prev + 1:])
        mujoco.mj_setState(m, d, states[n_steps - 1], spec)
        mujoco.mj_forward(m, d)
        self._commanded = np.asarray(trajectory.q[-1], np.float64)
        return Measurement(np.asarray(feats), np.asarray(joints), np.asarray(tools))
