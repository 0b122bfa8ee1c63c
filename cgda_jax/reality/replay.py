"""The exported file is what is checked: its samples replayed on MuJoCo C give the
run's features.

`replay_trajectory` commands the exported positions as a controller would: at every
physics step the position target is the trajectory at the step's end time
(`ExportedTrajectory.position_at`): in dynamic runs the quintic through the
neighbouring samples' positions, velocities and accelerations (the file carries all
three), which is the run's own minimum-jerk reference exactly (linear between the
100 Hz samples it differs by up to 5e-5 rad a radian of move, and a pressing contact
can turn that into millimetres and newtons); in kinematic runs linear between the
samples.

- Dynamic runs: the run's physics model (`cgda_jax.sim.physics.Physics`: gravity,
  actuators, contacts, the objects), stepped by MuJoCo C (``mujoco.rollout``) at
  ``timestep / factor``; the targets become actuator controls as in the simulator
  (`Physics.ctrl_of`).  The scene sees the marker at every physics step (a paint
  wall sweeps the path between them) and the objects' sensors at each waypoint's
  feature time.
- Kinematic runs: MuJoCo C forward kinematics (``mj_kinematics`` on the robot's
  model) at every sample, each control period cut into enough pieces that a move
  is seen at ``factor`` x the simulator's sub-steps; the features at each
  waypoint's feature time.

Everything but the scene's own feature functions (painting a swept path, reading
the world's features) is host NumPy and MuJoCo C; nothing of the simulator's
jitted execution is used.
"""

from __future__ import annotations

import math

import numpy as np

from cgda_jax.reality.control_trajectory import ExportedTrajectory

__all__ = ["SceneTracker", "replay_trajectory", "scene_features"]


class SceneTracker:
    """A scene's state carried along a marker path given piece by piece (a paint
    wall remembers what was painted): `advance` takes the next positions and
    returns the features at the last one.

    Args:
        scene: the run's scene.
        start: (3,) the marker at the start posture.
    """

    def __init__(self, scene, start):
        import jax
        import jax.numpy as jnp

        self.scene = scene
        self.state = scene.update(scene.init_state(), jnp.asarray(start, jnp.float32))
        self.last = np.asarray(start, np.float64)
        self._sweep = getattr(scene, "sweep", None)
        if self._sweep is None:
            def go(st, path):
                return jax.lax.scan(lambda s, m: (scene.update(s, m), None), st,
                                    path)[0]
            self._go = go
        else:
            self._go = self._sweep
        self._programs: dict[tuple, object] = {}  # per path length

    def _advance(self, state, path):
        """``_go`` compiled once per path shape (a program compiled before in the
        process for the same scene is reused: `cgda_jax.programs`)."""
        from cgda_jax.programs import compile_jit

        if path.shape not in self._programs:
            self._programs[path.shape] = compile_jit("replay.advance", self._go,
                                                     state, path)
        return self._programs[path.shape](state, path)

    def advance(self, markers: np.ndarray) -> np.ndarray:
        """Move the marker through ``markers`` (K, 3), K >= 1 (a paint wall sweeps
        the segments from the last position on); the features (F,) at the end."""
        import jax.numpy as jnp

        markers = np.asarray(markers, np.float64).reshape(-1, 3)
        if self._sweep is not None:
            path = np.concatenate([self.last[None], markers])
            # padded to a power of two rows with its last position (segments of no
            # length at the end, where the last one already painted): a few
            # programs for paths of any length, not one for each length
            size = 1 << (len(path) - 1).bit_length()
            path = np.concatenate([path, np.repeat(path[-1:], size - len(path), 0)])
        else:
            path = markers
        self.state = self._advance(self.state, jnp.asarray(path, jnp.float32))
        self.last = markers[-1]
        return np.asarray(self.scene.features(self.state, jnp.asarray(
            self.last, jnp.float32)), np.float64)


def scene_features(scene, markers: np.ndarray, ends: np.ndarray, world=None):
    """The scene's features after the marker moved along ``markers`` (K, 3) (the
    first row: the start), read at the rows ``ends`` (N,): ``sweep`` along the
    path where the scene has it (a paint wall), else ``update`` at each position.

    Args:
        scene: the run's scene.
        markers: (K, 3) marker positions in order.
        ends: (N,) increasing row indices (>= 1) at which features are read.
        world: optional (N, F) world features already read there (object scenes):
            returned as they are.

    Returns:
        (N, F) float64.
    """
    if world is not None:
        return np.asarray(world, np.float64)
    tracker = SceneTracker(scene, markers[0])
    out, prev = [], 0
    for e in np.asarray(ends, np.int64):
        out.append(tracker.advance(markers[prev + 1:e + 1]) if e > prev
                   else np.asarray(scene.features(tracker.state, markers[e])))
        prev = e
    return np.asarray(out, np.float64)


def _check(sim, traj: ExportedTrajectory) -> None:
    if tuple(traj.joint_names) != tuple(sim.robot.joint_names):
        raise ValueError(f"the trajectory's joints {list(traj.joint_names)} are not "
                         f"the simulator's {list(sim.robot.joint_names)}")
    if not (np.all(np.isfinite(traj.q)) and traj.n_samples >= 2):
        raise ValueError("the trajectory has NaN or inf positions (or < 2 samples)")


def _dynamic(sim, traj: ExportedTrajectory, factor: int) -> np.ndarray:
    import mujoco
    from mujoco import rollout

    phys = sim.finer(factor).physics if factor > 1 else sim.physics
    m = phys.model
    dt = float(m.opt.timestep)
    n_steps = math.ceil(traj.duration / dt - 1e-6)
    times = (np.arange(n_steps) + 1) * dt  # the end of each physics step
    qpos = np.tile(np.asarray(phys.qpos0, np.float64), (n_steps, 1))
    qpos[:, phys.gene_qadr] = traj.position_at(times, quintic=True)
    ctrl = np.asarray(phys.ctrl_of(qpos), np.float64)
    d = mujoco.MjData(m)
    d.qpos[:] = phys.qpos0
    d.qpos[phys.gene_qadr] = traj.start
    mujoco.mj_forward(m, d)
    spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    init = np.zeros(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, init, spec)
    # one step more: rollout's sensors of step k read the state before step k
    ctrl = np.concatenate([ctrl, ctrl[-1:]])
    states, sens = rollout.rollout(m, d, init[None], ctrl[None], nstep=n_steps + 1)
    sens = sens[0]  # row k: the state after k steps
    if not np.all(np.isfinite(states)):
        raise ValueError("the replay of the exported trajectory diverged (NaN state)")
    ends = np.minimum(np.round(traj.feature_t / dt).astype(np.int64), n_steps)
    markers = sens[:, phys.marker_adr:phys.marker_adr + 3]
    world = None
    if phys.features is not None:
        world = np.stack([np.asarray(phys.features.from_sensordata(sens[e]))
                          for e in ends])
    return scene_features(sim.scene, markers, ends, world)


def _kinematic(sim, traj: ExportedTrajectory, factor: int) -> np.ndarray:
    import mujoco

    robot = sim.robot
    m = robot.mj_model
    moves = np.diff(np.concatenate([[0], traj.reached_index]))
    per_move = int(np.max(np.maximum(moves, 1)))  # control periods of a move
    pieces = max(1, math.ceil(sim.substeps * factor / per_move))
    times = np.arange((traj.n_samples - 1) * pieces + 1) / (traj.rate * pieces)
    q = traj.position_at(times)
    d = mujoco.MjData(m)
    qpos0 = np.asarray(robot.qpos0, np.float64)
    markers = np.empty((len(q), 3))
    for k, genes in enumerate(q):
        d.qpos[:] = qpos0
        d.qpos[robot.qpos_adr] = genes
        mujoco.mj_kinematics(m, d)
        markers[k] = d.site_xpos[robot.site_id]
    ends = traj.feature_index * pieces
    world = None
    specs = tuple(getattr(sim.scene, "world_features", ()))
    if specs:
        from cgda_jax.sim.features import FeatureSet

        fset = FeatureSet(m, specs)
        rows = []
        for e in ends:
            d.qpos[:] = qpos0
            d.qpos[robot.qpos_adr] = q[e]
            mujoco.mj_kinematics(m, d)
            rows.append(np.asarray(fset.from_data(d)))
        world = np.stack(rows)
    return scene_features(sim.scene, markers, ends, world)


def replay_trajectory(sim, traj: ExportedTrajectory, factor: int = 4) -> np.ndarray:
    """The features (N, F) of replaying ``traj``'s samples on MuJoCo C, read at each
    waypoint's feature time (see the module doc).

    Args:
        sim: the run's `cgda_jax.sim.simulator.Simulator` (its model, scene, mode).
        traj: the exported trajectory (e.g. read back from its file).
        factor: how much finer than the run the replay steps (dynamic: timestep /
            factor; kinematic: factor x the sub-steps per move).

    Raises:
        ValueError: the trajectory is not of this simulator's joints, holds NaN, or
            its replay diverged.
    """
    _check(sim, traj)
    factor = max(1, int(factor))
    if sim.mode == "dynamic":
        return _dynamic(sim, traj, factor)
    return _kinematic(sim, traj, factor)
