"""Waypoints -> feature trajectories: the simulator the strategies evaluate.

`Simulator` moves a `Robot` through joint waypoints and lets a scene turn the marker
path into object features.  All methods are pure and jittable; the model is on the
device already and every shape (waypoints, sub-steps, physics steps) is static.

Modes:
    kinematic (default): from the current posture to the waypoint in ``substeps``
        equally spaced joint-space sub-steps (the last one is the waypoint); forward
        kinematics of the marker at each.  A scene with ``sweep`` (the paint wall)
        sees the straight segments between consecutive positions (from the last
        position of the previous move on), with enough sub-steps that they stay
        within the scene's ``path_tolerance`` of the curved path
        (`cgda_jax.sim.chain.path_substeps`); other scenes are updated at each
        position.  No dynamics.
    dynamic: a waypoint lasts ``waypoint_s`` seconds of physics (gravity, the
        actuators, joint limits).  The actuators track a smooth reference: a
        minimum-jerk move from the previous waypoint to this one over the first
        ``move_fraction`` of the time, then the waypoint is held while the arm
        settles; the features are read at the end.  The scene sees every physics
        step (a paint wall: the segments between consecutive steps).  The
        evolved and fixed joints are driven to their targets by position servos
        or a joint-space PD (``control``, `cgda_jax.sim.control`); joints neither
        evolved nor fixed are welded where they start (see `cgda_jax.sim.physics`,
        ``reduce``).  The physics backend is MJX or MuJoCo C (``physics``); both
        give the same features.

Waypoints outside the joint limits are clipped into them (the robot cannot go there).

Feasibility (``feasibility``, `cgda_jax.sim.feasibility`): each move is also judged
as a motion: its sub-step postures (kinematic mode) or its commanded reference at
``substeps`` points (dynamic mode) against collisions, in dynamic mode also what the
physics executed (`Feasibility.executed`: the simulated postures at ``2 * samples +
1`` physics steps of the move against collisions, the tracking error of the
evolved joints and the share of steps at their force limit), and its minimum-jerk timing
(``move_fraction * waypoint_s`` seconds in both modes; the first move from the
start posture, the approach, over its own duration `Feasibility.approach_s`, in
dynamic mode as a longer first segment of physics)
against the joint speed and acceleration limits.  The state carries the move's
violation and their sum over the execution (0 = feasible).

Example:
    >>> import jax.numpy as jnp
    >>> from cgda_jax import MarkerScene, Robot, Simulator, model_path
    >>> robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
    ...                         "marker")
    >>> sim = Simulator(robot, MarkerScene(), substeps=4)
    >>> sim.execute(jnp.zeros((5, 3))).shape
    (5, 3)
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from cgda_jax.sim.rollouts import Executions
from cgda_jax.sim.feasibility import scene_obstacles
from cgda_jax.sim.host_replay import reference_ctrl
from cgda_jax.sim.robot import Robot
from cgda_jax.sim.scenes import feature_labels
from cgda_jax.sim.sim_state import (
    MODES,
    SimState,
    check_settings,
    scene_along,
)

__all__ = ["MODES", "SimState", "Simulator", "scene_obstacles"]


class Simulator(Executions):
    """Execute joint waypoints on a robot and return the scene's features.

    Args:
        robot: the `Robot` (model, evolved joints, marker site).
        scene: a scene (`MarkerScene`, `PaintWall`, or anything with the same methods).
        mode: "kinematic" (default) or "dynamic".
        substeps: kinematic mode: forward-kinematics evaluations per waypoint, equally
            spaced in joint space from the previous posture, the last one at the
            waypoint (1 = jump straight to it).  A scene with a ``path_tolerance``
            (`PaintWall`) raises it to `cgda_jax.sim.chain.path_substeps`, so that
            the straight segments between sub-steps stay that close to the
            marker's curved path.
        waypoint_s: seconds per waypoint (the experiments default it to the
            demonstrations' timing: mean duration / knots): dynamic mode's physics
            time; kinematic mode's timing for the feasibility check (a move over
            ``move_fraction`` of it, then a hold, as in dynamic mode).
        physics_steps: dynamic mode: physics steps per waypoint; None (default):
            ``round(waypoint_s / timestep)``.
        timestep: dynamic mode: physics step (s); None: the model's own.
        move_fraction: share of a waypoint's time spent moving (the minimum-jerk
            reference); the rest holds the waypoint so the arm settles.
        physics: dynamic mode backend, "auto" (MuJoCo C on a CPU-only JAX, MJX on
            accelerators), "mjx" or "mujoco" (see `cgda_jax.sim.physics`).
        reduce: dynamic mode: weld joints that are neither evolved nor fixed
            (default True; False simulates every joint).
        control: dynamic mode: a `cgda_jax.sim.control.Control` (or its table).
        batch_size: dynamic mode, MJX: `execute_population` simulates the population in
            slices of at most this many candidates (``lax.map`` over ``vmap``ped
            slices; the result is the same).  On the CPU, XLA's LAPACK kernels
            (Cholesky / triangular solve of the mass matrix in ``mjx.step``) split
            large batches over the intra-op thread pool and can deadlock in it
            (P >= 512 on 2 cores hangs with every thread idle); slices of 256 run.
            None: the whole population in one ``vmap`` (fine on a GPU).
        feasibility: a `cgda_jax.sim.feasibility.Feasibility` that judges every
            move (collisions, joint limits; see the module doc); True: one with the
            model's limits and the scene's ``obstacles`` (the paint board); None
            (default): moves are not judged (the paper's unconstrained execution).

    Attributes:
        n_dof, n_features, feature_names, lower, upper: the robot's and the scene's
            (lower and upper: the (DoF,) joint limits).
        dynamic_args: ``move_fraction``, ``reduce`` and ``control`` as given.
    """

    def __init__(
        self,
        robot: Robot,
        scene,
        mode: str = "kinematic",
        substeps: int = 8,
        *,
        waypoint_s: float = 1.0,
        physics_steps: int | None = None,
        timestep: float | None = None,
        move_fraction: float = 0.6,
        physics: str = "auto",
        reduce: bool = True,
        batch_size: int | None = 256,
        feasibility: Any = None,
        control: Any = None,
    ):
        check_settings(mode=mode, substeps=substeps, waypoint_s=waypoint_s,
                       physics_steps=physics_steps, move_fraction=move_fraction,
                       batch_size=batch_size)
        if not isinstance(robot, Robot):
            raise TypeError(f"Simulator: robot must be a Robot, got "
                            f"{type(robot).__name__}")
        if scene is None:
            raise TypeError(f"Simulator: scene must be a scene (e.g. MarkerScene()), "
                            f"got {type(scene).__name__}")
        self.robot = robot
        self.scene = scene
        self.mode = mode
        self.substeps = int(substeps)
        tol = getattr(scene, "path_tolerance", None)
        if mode == "kinematic" and tol is not None:
            from cgda_jax.sim.chain import path_substeps

            self.substeps = max(self.substeps, path_substeps(robot, tol))
        self.batch_size = None if batch_size is None else int(batch_size)
        self.move_fraction = float(move_fraction)
        self.n_dof = robot.n_dof
        self.n_features = scene.n_features
        self.feature_names = tuple(scene.feature_names)
        #: the names with their units (``"X [m]"``), for figures
        self.feature_labels = feature_labels(scene)
        self.lower = robot.lower
        self.upper = robot.upper
        self._alphas = np.arange(1, self.substeps + 1, dtype=np.float32) / self.substeps
        self.dynamic_args = {"move_fraction": move_fraction, "reduce": reduce,
                              "control": control}
        # object scenes read the simulated world (`ObjectScene`), others the marker
        self._world_specs = tuple(getattr(scene, "world_features", ()))
        self._fset = None
        if self._world_specs:  # names checked against the whole model first
            from cgda_jax.sim.features import FeatureSet

            self._fset = FeatureSet(robot.mj_model, self._world_specs)
        if mode == "kinematic":  # constraints, tendons, features it cannot honour
            from cgda_jax.sim.model_checks import check_kinematic

            check_kinematic(robot.mj_model, robot.joint_ids, self._fset.specs
                            if self._fset is not None else (),
                            None if self._world_specs else robot.site_id)
        self.physics = self.backend = None
        self.physics_steps = 0
        if mode == "dynamic":
            from cgda_jax.sim.physics import Physics, make_backend
            from cgda_jax.sim.timing import approach_profile, reference_profile

            self.physics = Physics(robot, timestep=timestep, reduce=reduce,
                                   features=self._world_specs, control=control)
            self._fset = self.physics.features
            self.backend = make_backend(self.physics, physics)
            if physics_steps is None:
                physics_steps = max(1, round(waypoint_s / self.physics.timestep))
            self.physics_steps = int(physics_steps)
            if self.backend.name == "mujoco":
                self.batch_size = None  # C threads, no XLA LAPACK batches to slice
            self._move_steps = max(1, round(self.move_fraction * self.physics_steps))
            self._profile = reference_profile(self.physics_steps, self._move_steps)
        elif self._world_specs:
            robot.make_data()  # mujoco.mjx and the device model, outside any trace
        # kinematic mode: the timing its feasibility check (and report) assumes
        self.waypoint_s = (self.physics_steps * self.physics.timestep
                           if mode == "dynamic" else float(waypoint_s))
        self.move_s = float(move_fraction) * self.waypoint_s
        if feasibility is True:
            from cgda_jax.sim.feasibility import Feasibility

            feasibility = Feasibility(robot, obstacles=scene_obstacles(scene))
        self.feasibility = feasibility or None
        self.approach_s = self.move_s
        self.approach_steps = self.physics_steps
        if self.feasibility is not None:
            self.approach_s = self.feasibility.approach_s(robot, self.move_s)
        if mode == "dynamic" and self.approach_s > self.move_s:
            # the approach: a min-jerk move over approach_s, then the usual hold
            self.approach_s, self._approach_profile = approach_profile(
                self.approach_s, self.physics.timestep, self.physics_steps,
                self._move_steps)
            self.approach_steps = len(self._approach_profile)
        # eager set-up and replays: one program each, not one per operation
        self._init_state = jax.jit(self._start)
        super().__init__()  # the rollout and population programs (`Executions`)

    def finer(self, factor: int = 4, physics: str = "mujoco") -> Simulator:
        """The same simulator with ``factor`` times finer steps: kinematic mode
        ``substeps * factor``; dynamic mode ``timestep / factor`` (same waypoint time
        and reference), by default on MuJoCo C.  For replaying a result: an
        optimiser may exploit the resolution it was evaluated at."""
        if self.mode != "dynamic":
            return Simulator(self.robot, self.scene, substeps=self.substeps * factor,
                             waypoint_s=self.waypoint_s,
                             move_fraction=self.move_fraction,
                             feasibility=self.feasibility)
        return Simulator(
            self.robot, self.scene, mode="dynamic", physics=physics,
            timestep=self.physics.timestep / factor,
            physics_steps=self.physics_steps * factor, **self.dynamic_args,
            feasibility=self.feasibility,
        )

    def __repr__(self) -> str:
        if self.mode == "dynamic":
            extra = (f"physics={self.backend.name!r}, waypoint_s={self.waypoint_s:g}, "
                     f"physics_steps={self.physics_steps}, "
                     f"timestep={self.physics.timestep:g}")
        else:
            extra = f"substeps={self.substeps}"
        return (f"Simulator({self.robot!r}, {type(self.scene).__name__}, "
                f"mode={self.mode!r}, {extra})")

    # -- the one-example functions -----------------------------------------------
    def init_state(self, genes0: Array | None = None) -> SimState:
        """Start state: posture ``genes0`` (default the robot's `start_genes`: the
        evolved joints' values in its start posture, 0 unless a keyframe or start
        values say otherwise; clipped into the limits), the scene updated with the
        marker there.

        Args:
            genes0: (DoF,) start values of the evolved joints, or None.
        """
        if genes0 is None:
            genes0 = self.robot.start_genes
        self.robot.check_genes(genes0, "genes0")
        return self._init_state(genes0)

    def _start(self, genes0: Array) -> SimState:
        """`init_state` of checked ``genes0`` (jitted per simulator in ``__init__``:
        one program where it is called eagerly, inlined under a trace)."""
        genes0 = self.robot.clip(jnp.asarray(genes0, jnp.float32))
        data = None
        if self.mode == "dynamic":
            data = self.physics.start_state(genes0)  # at rest
        marker = self.robot.marker_position(genes0)  # welded joints sit at qpos0
        scene = self.scene.update(self.scene.init_state(), marker)
        state = SimState(genes=genes0, scene=scene, data=data, marker=marker)
        if self.feasibility is not None:
            zero = jnp.float32(0.0)
            state = state.replace(violation=zero, move_violation=zero,
                                  first=jnp.bool_(True))
        return state

    def _judge(self, state: SimState, new: SimState, judge: bool = True,
               executed: Array | None = None) -> SimState:
        """``new`` with the violation of the move from ``state`` to it (unchanged
        without feasibility; ``judge=False``: the violations carried unchanged, the
        move no longer the first); ``executed``: dynamic mode's violation of what
        the physics did in the move, maxed in."""
        if self.feasibility is None:
            return new
        if not judge:
            return new.replace(first=jnp.bool_(False))
        duration = jnp.where(state.first, self.approach_s, self.move_s)
        v = self.feasibility.move(state.genes, new.genes - state.genes, duration,
                                  state.first)
        if executed is not None:
            v = jnp.maximum(v, executed)
        return new.replace(violation=state.violation + v, move_violation=v,
                           first=jnp.bool_(False))

    def judge(self, state: SimState, new: SimState) -> SimState:
        """``new``, a `step` from ``state`` with ``judge=False``, with its move
        judged: the state that `step` with ``judge=True`` returns, without
        stepping again (a caller that judges only some of its moves, e.g.
        `cgda_jax.strategies.fitness.judge_best`).  Kinematic mode only: in
        dynamic mode the violation includes what the physics executed in the
        move, which only `step` sees.

        Raises:
            ValueError: in dynamic mode."""
        if self.mode == "dynamic":
            raise ValueError("Simulator.judge is for kinematic mode: a dynamic move's "
                             "violation includes what the physics executed; step "
                             "with judge=True instead")
        return self._judge(state, new)

    def judge_moves(self, state: SimState, news: SimState,
                    need: Array | None = None) -> Array:
        """The move violations (M,) of `judge` for M states ``news`` (stacked)
        stepped to from ``state`` with ``judge=False`` (or from M states
        ``state``, stacked: each move its own start, e.g. a trajectory's
        moves): the same values, judged
        together (`cgda_jax.sim.feasibility.Feasibility.moves`: the collisions
        coarse to fine, batched calls packed into one); ``need`` (M,) bool:
        only those moves' collisions checked, for a caller that discards the
        others.  Kinematic mode with feasibility only (`judge`).

        Raises:
            ValueError: in dynamic mode or without feasibility."""
        if self.mode == "dynamic" or self.feasibility is None:
            raise ValueError("Simulator.judge_moves is for kinematic mode with "
                             "feasibility")
        dq = news.genes - state.genes
        duration = jnp.where(state.first, self.approach_s, self.move_s)
        m = dq.shape[0]
        return self.feasibility.moves(
            jnp.broadcast_to(state.genes, dq.shape), dq,
            jnp.broadcast_to(duration, (m,)), jnp.broadcast_to(state.first, (m,)),
            need)

    def step(self, state: SimState, waypoint: Array, *,
             judge: bool = True) -> tuple[SimState, Array]:
        """Move to one waypoint.

        Args:
            state: the current `SimState`.
            waypoint: (DoF,) target joint values (clipped into the limits).
            judge: with feasibility, judge the move (``move_violation``, added to
                ``violation``); False skips the judgement (the violations are
                carried unchanged), for a caller that judges the same move
                elsewhere or does not use it: the collision check then is not
                part of this call's program.

        Returns:
            (new state, features (F,) at the waypoint).
        """
        self.robot.check_genes(waypoint, "waypoint")
        target = self.robot.clip(jnp.asarray(waypoint, jnp.float32))
        if self.mode == "dynamic":
            return self._step_dynamic(state, target, judge)
        return self._step_kinematic(state, target, judge)

    def _step_kinematic(self, state: SimState, target: Array,
                        judge: bool = True) -> tuple[SimState, Array]:
        alphas = jnp.asarray(self._alphas)[:, None]
        path = state.genes + alphas * (target - state.genes)  # (K, DoF)
        markers = jax.vmap(self.robot.marker_position)(path)  # (K, 3)
        scene_state = scene_along(self.scene, state.scene, self._from(state), markers)
        if self._fset is not None:  # objects: forward kinematics of the whole world
            data = self.robot.kinematics_data(self.robot.qpos(target))
            features = self._fset.from_data(data)
        else:
            features = self.scene.features(scene_state, markers[-1])
        new = state.replace(genes=target, scene=scene_state, marker=markers[-1])
        return self._judge(state, new, judge), features

    def _from(self, state: SimState) -> Array:
        """The marker where the next move starts (from ``genes`` when not carried)."""
        if state.marker is None:
            return self.robot.marker_position(state.genes)
        return state.marker

    def reference_profiles(self) -> tuple[np.ndarray, np.ndarray]:
        """Dynamic mode: the min-jerk share of the move at each physics step of the
        approach (the first move) and of every other move, (T_approach,), (T,)."""
        if self.mode != "dynamic":
            raise ValueError("reference_profiles: a kinematic simulator has none")
        first = getattr(self, "_approach_profile", None)
        return (self._profile if first is None else first), self._profile

    def _segment(self, state: SimState, target: Array, profile: np.ndarray,
                 judge: bool = False):
        """Physics from ``state`` along the min-jerk reference ``profile`` (T,) to
        ``target``: (physics state, scene state, marker (3,), features (F,), the
        violation of what was executed: `Feasibility.executed` of the simulated
        postures at ``2 * samples + 1`` steps, the tracking error and the time at the
        force limit; 0 unless ``judge`` with feasibility)."""
        phys = self.physics
        ctrl = reference_ctrl(phys, state.genes, target, profile, jnp)  # (T, nu)
        data, sens = self.backend.segment(state.data, ctrl)  # (T, nsensordata)
        path = sens[:, phys.marker_adr:phys.marker_adr + 3]
        scene_state = scene_along(self.scene, state.scene, self._from(state), path)
        if self._fset is not None:  # objects: the world's sensors at the end
            features = self._fset.from_sensordata(sens[-1])
        else:
            features = self.scene.features(scene_state, path[-1])
        executed = jnp.float32(0.0)
        if judge and self.feasibility is not None:
            commanded = state.genes + jnp.asarray(profile)[:, None] * (
                target - state.genes)
            q, track, sat = phys.executed(sens, commanded)
            k = np.unique(np.round(np.linspace(
                0, len(profile) - 1, 2 * self.feasibility.samples + 1)).astype(int))
            executed = self.feasibility.executed(q[k], track, sat)
        return data, scene_state, path[-1], features, executed

    def _step_dynamic(self, state: SimState, target: Array,
                      judge: bool = True) -> tuple[SimState, Array]:
        if self.approach_steps != self.physics_steps and state.first is not None:
            data, scene_state, marker, features, executed = jax.lax.cond(
                state.first,
                lambda: self._segment(state, target, self._approach_profile, judge),
                lambda: self._segment(state, target, self._profile, judge))
        else:
            data, scene_state, marker, features, executed = self._segment(
                state, target, self._profile, judge)
        new = state.replace(genes=target, scene=scene_state, data=data,
                            marker=marker)
        # judged on the commanded reference (limits, flailing, its path) and on
        # what the physics executed (its postures, tracking, force saturation)
        return self._judge(state, new, judge, executed), features
