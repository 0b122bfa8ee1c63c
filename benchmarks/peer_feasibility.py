"""The feasibility checks of cgda_jax written with MuJoCo's C bindings, for the peers.

`MujocoFeasibility` is what a pycma + MuJoCo user would write to judge one move the
way `cgda_jax.sim.feasibility.Feasibility.move` does:

- the scene's obstacles (the paint board) are added to a copy of the robot's MJCF as
  real geoms of the world body (``mujoco.MjSpec``);
- at ``samples + 1`` postures equally spaced along the straight joint-space move
  (both ends) ``mj_kinematics`` places the geoms and ``mj_geomDistance`` (MuJoCo's
  own signed distance) measures each pair that our `Feasibility` kept
  (``relevant_pairs``: the same pairs, so the same work);
- the depth is minus the most negative sampled distance, and must stay ``margin``
  inside the penetration limit (``allowed = penetration - margin``); with
  ``certify``, between samples ``k``, ``k + 1`` a pair's distance stays above
  ``(d_k + d_k+1 - L / samples) / 2`` with ``L = pair_reach @ |dq|`` (our Collider's
  per-pair reach: a constant of the model, taken from it), the depth is the most
  negative of these bounds and of the samples, and ``allowed = penetration``;
- the violation ``max(relu(peak / limit - 1), relu(depth - allowed) /
  penetration, relu(max |dq| / max_step - 1))`` with the min-jerk peaks ``1.875 |dq| /
  T`` and ``5.7735 |dq| / T^2`` (the approach, the first move, over ``approach_s``
  and not capped by ``max_step``), and the penalty ``fitness + penalty * (1 +
  violation)`` of an infeasible candidate.

`FeasibleMarker` wraps `peers.MujocoMarker` so that each step also returns that move's
violation and the state carries the summed violation (as ``SimState.violation``).
tests/test_bench_peers.py checks both against ours.
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence

import mujoco
import numpy as np

#: The min-jerk move's peak speed and acceleration per |dq| / T and |dq| / T^2.
PEAK_SPEED = 1.875
PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)
#: mj_geomDistance's ``distmax`` (m): farther pairs read as this (never binding: the
#: between-samples bound would need a move of over 2 m per sample to reach 0).
DISTMAX = 1.0

_GEOM_TYPES = {"box": mujoco.mjtGeom.mjGEOM_BOX, "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
               "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
               "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
               "plane": mujoco.mjtGeom.mjGEOM_PLANE}


def model_with_obstacles(mjcf: str | pathlib.Path, obstacles: Sequence[dict]):
    """The MJCF compiled with each obstacle dict (``name``, ``type``, ``pos``,
    ``size``, optional ``quat`` [w, x, y, z]) added as a geom of the world body."""
    path = pathlib.Path(mjcf)
    if not path.is_file():
        raise FileNotFoundError(f"MujocoFeasibility needs the robot's MJCF file; "
                                f"{mjcf!r} is not one")
    spec = mujoco.MjSpec.from_file(str(path))
    for o in obstacles:
        size = np.zeros(3)
        given = np.asarray(o.get("size", ()), float).ravel()[:3]
        size[: given.size] = given
        if o["type"] == "plane":
            size = np.array([10.0, 10.0, 0.1])
        quat = np.asarray(o.get("quat", (1.0, 0.0, 0.0, 0.0)), float)
        spec.worldbody.add_geom(name=o["name"], type=_GEOM_TYPES[o["type"]], size=size,
                                pos=np.asarray(o["pos"], float),
                                quat=quat / np.linalg.norm(quat))
    return spec.compile()


class MujocoFeasibility:
    """Judges one move with MuJoCo C (see the module doc).

    Args:
        model: the robot's model with the obstacles as world geoms.
        joints: evolved joint names (gene order).
        qpos0: (nq,) posture of the joints not evolved.
        pairs: (robot geom, other geom) names to measure.
        reach: (pairs, DoF) how far each pair's geoms move per unit of each joint.
        velocity, acceleration: (DoF,) limits (inf: none).
        penetration: metres tolerated; penalty: fitness added when infeasible, times
            (1 + violation); samples: collision samples a move (plus its start);
        max_step: the largest joint change between two waypoints (radians).
        margin: metres the sampled depth must stay below ``penetration``;
        certify: bound the distance between samples instead.
    """

    def __init__(self, model, joints: Sequence[str], qpos0, pairs, reach, velocity,
                 acceleration, *, penetration: float, penalty: float, samples: int,
                 max_step: float, margin: float = 0.002, certify: bool = False):
        self.model = model
        self.data = mujoco.MjData(model)
        jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints]
        self.qadr = np.asarray(model.jnt_qposadr[jids])
        self.qpos0 = np.array(qpos0, np.float64)

        def gid(name):
            g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
            if g < 0:
                raise KeyError(f"MujocoFeasibility: no geom {name!r} in the model")
            return g

        self.pairs = [(gid(a), gid(b)) for a, b in pairs]
        self.pair_names = [tuple(p) for p in pairs]
        self.reach = np.asarray(reach, np.float64).reshape(len(self.pairs), -1)
        self.velocity = np.asarray(velocity, np.float64)
        self.acceleration = np.asarray(acceleration, np.float64)
        self.penetration, self.penalty = float(penetration), float(penalty)
        self.samples, self.max_step = int(samples), float(max_step)
        self.alphas = np.arange(self.samples + 1) / self.samples
        self.certify = bool(certify)
        self.allowed = self.penetration - (0.0 if self.certify else float(margin))

    @classmethod
    def from_feasibility(cls, feas, robot, obstacles: Sequence[dict] = ()):
        """The twin of our `Feasibility` ``feas`` of ``robot`` (its pairs, reach,
        limits and settings; the model rebuilt from the robot's MJCF with the
        ``obstacles``, e.g. ``scene_obstacles(scene)``)."""
        model = model_with_obstacles(robot.source, obstacles)
        col = feas.collider
        return cls(model, robot.joint_names, np.asarray(robot.qpos0),
                   [] if col is None else col.pair_names,
                   np.zeros((0, robot.n_dof)) if col is None else col.pair_reach,
                   feas.limits.velocity, feas.limits.acceleration,
                   penetration=feas.penetration, penalty=feas.penalty,
                   samples=feas.samples, max_step=feas.max_step,
                   margin=feas.margin, certify=feas.certify)

    def distances(self, q) -> np.ndarray:
        """(pairs,) signed distances (m) at the posture ``q`` (DoF,)."""
        d = self.data
        d.qpos[:] = self.qpos0
        d.qpos[self.qadr] = q
        mujoco.mj_kinematics(self.model, d)
        return np.array([mujoco.mj_geomDistance(self.model, d, a, b, DISTMAX, None)
                         for a, b in self.pairs])

    def depth(self, q0, dq) -> float:
        """The deepest penetration (m, >= 0) of the move from ``q0`` by ``dq`` at
        its samples (``certify``: a bound on the whole move)."""
        return max(self.worst(q0, dq), 0.0)

    def worst(self, q0, dq) -> float:
        """Minus the smallest sampled distance (``certify``: minus its bound)."""
        if not self.pairs:
            return -math.inf
        d = np.stack([self.distances(q0 + a * dq) for a in self.alphas])
        if not self.certify:
            return -float(np.min(d))
        rate = self.reach @ np.abs(dq)
        low = 0.5 * (d[:-1] + d[1:] - rate / self.samples)
        return -float(np.min(np.minimum(low, d[1:])))

    def limit_violation(self, dq, duration: float) -> float:
        """Relative excess of the min-jerk move's peaks over the limits."""
        a = np.abs(dq)
        worst = 0.0
        for peak, limit in ((PEAK_SPEED * a / duration, self.velocity),
                            (PEAK_ACCELERATION * a / duration**2, self.acceleration)):
            ok = np.isfinite(limit)
            if np.any(ok):
                worst = max(worst, float(np.max(peak[ok] / limit[ok] - 1.0)))
        return max(worst, 0.0)

    def move(self, q0, dq, duration: float, approach: bool = False) -> float:
        """Violation (0 = feasible) of the move from ``q0`` by ``dq`` in ``duration``
        seconds (``approach``: not capped by ``max_step``)."""
        q0, dq = np.asarray(q0, np.float64), np.asarray(dq, np.float64)
        worst = self.limit_violation(dq, duration)
        if not approach:
            worst = max(worst, float(np.max(np.abs(dq))) / self.max_step - 1.0)
        over = (self.worst(q0, dq) - self.allowed) / self.penetration
        worst = max(worst, over)
        return max(worst, 0.0)

    def penalized(self, fitness: float, violation: float) -> float:
        """``fitness + penalty * (1 + violation)`` when infeasible."""
        return fitness + self.penalty * (1.0 + violation) if violation > 0 else fitness


class FeasibleMarker:
    """`peers.MujocoMarker` whose steps are judged by a `MujocoFeasibility`.

    State: (posture, painted, marker, first, summed violation); `step` returns
    (state, features, the move's violation), the first move (the approach) over
    ``approach_s``, the others over ``move_s``.
    """

    def __init__(self, marker, feas: MujocoFeasibility, move_s: float,
                 approach_s: float):
        self.marker, self.feas = marker, feas
        self.move_s, self.approach_s = float(move_s), float(approach_s)
        self.lower, self.upper = marker.lower, marker.upper

    @classmethod
    def from_simulator(cls, sim):
        """The C twin of a kinematic ``Simulator`` with feasibility."""
        from peers import MujocoMarker

        from cgda_jax.sim.feasibility import scene_obstacles

        feas = MujocoFeasibility.from_feasibility(sim.feasibility, sim.robot,
                                                  scene_obstacles(sim.scene))
        return cls(MujocoMarker.from_simulator(sim), feas, sim.move_s, sim.approach_s)

    def init_state(self, start=None) -> tuple:
        q, painted, pos = self.marker.init_state(start)
        return q, painted, pos, True, 0.0

    def step(self, state: tuple, waypoint) -> tuple[tuple, np.ndarray, float]:
        q, painted, last, first, total = state
        (w, painted, last), feats = self.marker.step((q, painted, last), waypoint)
        v = self.feas.move(q, w - q, self.approach_s if first else self.move_s, first)
        return (w, painted, last, False, total + v), feats, v

    def execute(self, waypoints, start=None) -> tuple[np.ndarray, float]:
        """(features (N, F), summed violation) of executing the waypoints."""
        state, feats = self.init_state(start), []
        for w in np.asarray(waypoints, np.float64):
            state, f, _ = self.step(state, w)
            feats.append(f)
        return np.asarray(feats), state[4]
