"""Closed-loop OET: each step planned in the internal model from the state MEASURED
on a `cgda_jax.reality.protocol.Reality`, executed there, measured, re-localized.

One step:

1. plan: OET's own step (`OETPlan.step`, compiled once, run until one posture is
   executed in the model; its restarts and stagnation as OET's) from the current
   internal state;
2. execute: that posture as a short exported trajectory segment
   (`cgda_jax.reality.control_trajectory.trajectory_of` from where the robot was
   last sent, the run's move and hold times; the first segment is the approach from the start
   posture) sent through `cgda_jax.reality.protocol.measure` (a reality that raises
   or measures NaN stops the run with `RealityError`);
3. re-localize (`OETPlan.relocalize`): the goal step nearest the MEASURED features
   in OET's window, and the next step's evolution started from an internal state
   rebuilt on the measurement (`measured_state`: the evolved joints at the
   MEASURED joints, the marker there), its target moved against the measured
   features' offset from the model's prediction (``correct``: a model error the
   encoders cannot see, a calibration offset, a heavier object, is corrected at the
   next step), and (``relocate_objects``, dynamic mode) the model's objects put
   where the measured features say (`cgda_jax.sim.relocate.ObjectLocator`: a box's
   free joint from its measured position and yaw, a valve's hinge from its
   measured angle, at rest), so that the next step is planned against the object
   where the world has it (also before the first step, from the reality's start
   measurement).  What the features do not determine stays the model's
   prediction: the other velocities, an object feature the locator cannot invert
   (``info["not_relocalized"]`` says which and why) and a scene's carried state
   (painted cells).

It stops when the localized step is the goal's last point, after ``max_steps``
executed steps, or when a step's evolution found no valid posture.  With a reality
that measures exactly what the model predicts it is OET (`run_oet`).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.reality.calibrate import OffsetEstimate
from cgda_jax.reality.control_trajectory import trajectory_of
from cgda_jax.reality.protocol import Reality, RealityError, measure
from cgda_jax.sim.relocate import ObjectLocator
from cgda_jax.strategies.base import check_config
from cgda_jax.strategies.oet import OETPlan, OETSettings, ordered_point_errors
from cgda_jax.strategies.result import ExecutionResult
from cgda_jax.strategies.runner import seed_keys

__all__ = ["compiled_loop", "measured_state", "run_oet_closed_loop", "start_features"]


def measured_state(sim, predicted: Any, joints: jax.Array, locator: Any = None,
                   predicted_features: Any = None, features: Any = None) -> Any:
    """The internal `SimState` rebuilt on measured ``joints`` (DoF,), the rest the
    model's ``predicted`` state after the step. Kinematic mode: the posture
    (``genes``, clipped) and the marker at the measured joints. Dynamic mode: the
    physics posture's evolved joints at the measured ones (velocities and the other
    joints as predicted: the protocol measures none of them), the marker there;
    ``genes``, the commanded target the next move's ramp starts from, stays what
    was commanded (the exported segment starts there too).  With an
    `cgda_jax.sim.relocate.ObjectLocator` ``locator`` (dynamic mode), the objects
    are put where the measured ``features`` (F,) say, ``predicted_features`` (F,)
    the model's for ``predicted``."""
    q = sim.robot.clip(jnp.asarray(joints, jnp.float32))
    new = predicted.replace(marker=sim.robot.marker_position(q))
    if sim.mode == "dynamic":
        qadr = jnp.asarray(sim.physics.gene_qadr)
        data = predicted.data
        if locator is not None:
            data = locator.locate(data, predicted_features, features)
        return new.replace(data=data.at[qadr].set(q))
    return new.replace(genes=q)


def start_features(sim, state: Any) -> np.ndarray:
    """(F,) the world features of a dynamic-mode ``state`` (MuJoCo C's forward
    kinematics of its physics state): what the model has at the loop's start."""
    import mujoco

    phys = sim.physics
    data = np.asarray(state.data, np.float64)
    d = mujoco.MjData(phys.model)
    d.qpos[:], d.qvel[:] = data[:phys.nq], data[phys.nq:]
    mujoco.mj_forward(phys.model, d)
    return np.asarray(phys.features.from_data(d), np.float64)


_COMPILED: dict = {}  # (sim, goal, settings) -> the compiled loop; a few kept
_KEEP = 4


def compiled_loop(sim, goal: jax.Array, settings: OETSettings, locator: Any = None):
    """The loop's compiled functions ``(plan, init, advance, relocate, start)``: OET's plan
    of ``settings`` on ``sim`` and ``goal``, its
    ``init(key)``, ``advance(state)`` (OET's steps until one posture is executed
    in the model, with that step's best fitness) and ``relocate(state, prev_k,
    joints, features, correct)`` (`OETPlan.relocalize` on `measured_state`, the
    objects re-localized by ``locator`` when given; ``correct`` a traced bool),
    and ``start(state, joints, features, predicted)`` (`OETPlan.start_at` on
    `measured_state` of the reality's start measurement).
    Compiled once
    per simulator, goal and settings (the seed is an argument): the last few are
    kept, so a loop over seeds or realities compiles once."""
    goal_np = np.asarray(goal)
    cache_key = (id(sim), goal_np.shape, goal_np.tobytes(),
                 repr(settings), locator is not None)
    hit = _COMPILED.get(cache_key)
    if hit is not None and hit[0] is sim:
        return hit[1]
    plan = OETPlan(sim, goal, settings)

    def advance(s):
        n0 = s.steps

        def cond(c):
            return (c[0].steps == n0) & ~plan.done(c[0])

        def body(c):
            new, m = plan.step(c[0])
            return new, jnp.where(m["step"] == n0, m["best_fitness"], c[1])

        return jax.lax.while_loop(cond, body, (s, jnp.asarray(jnp.inf, jnp.float32)))

    def relocate(s, prev_k, joints, feats, correct):
        state = measured_state(sim, s.sim_state, joints, locator,
                               s.features[s.steps - 1], feats)
        return plan.relocalize(s, prev_k, state, feats, correct)

    def start(s, joints, feats, predicted):
        state = measured_state(sim, s.sim_state, joints, locator, predicted, feats)
        return plan.start_at(s, state)

    key = seed_keys([0])[0]
    init_c = jax.jit(plan.init).lower(key).compile()
    s = jax.eval_shape(plan.init, key)
    advance_c = jax.jit(advance).lower(s).compile()
    spec = jax.ShapeDtypeStruct
    relocate_c = jax.jit(relocate).lower(
        s, s.k, spec((plan.n_dof,), jnp.float32),
        spec((goal_np.shape[1],), jnp.float32), spec((), jnp.bool_)).compile()
    feat = spec((goal_np.shape[1],), jnp.float32)
    start_c = jax.jit(start).lower(s, spec((plan.n_dof,), jnp.float32), feat,
                                   feat).compile()
    while len(_COMPILED) >= _KEEP:
        _COMPILED.pop(next(iter(_COMPILED)))
    out = (plan, init_c, advance_c, relocate_c, start_c)
    _COMPILED[cache_key] = (sim, out)
    return out


def _check_names(sim, reality: Reality) -> None:
    for what, ours in (("feature_names", tuple(sim.feature_names)),
                       ("joint_names", tuple(sim.robot.joint_names))):
        theirs = tuple(getattr(reality, what, ()))
        if theirs != ours:
            raise RealityError(f"{type(reality).__name__}.{what} {list(theirs)} are "
                               f"not the simulator's {list(ours)}")


def _why_not_calibrated(est: OffsetEstimate | None, calibrate: bool) -> str | None:
    """Why the loop ran without joint offsets (None: it estimated them)."""
    if est is not None:
        return None
    if not calibrate:
        return "off (calibrate=False)"
    return "the reality does not measure the tool (Measurement.marker is None)"


def run_oet_closed_loop(
    sim: Any,
    goal: Any,
    reality: Reality,
    settings: OETSettings | None = None,
    *,
    seed: int = 0,
    rate: float = 100.0,
    correct: bool = True,
    relocate_objects: bool = True,
    step_tolerance: float | None = None,
    calibrate: bool = True,
    min_offset_deg: float = 0.1,
    progress_fn: Any = None,
    **changes: Any,
) -> ExecutionResult:
    """OET closed on ``reality`` (see the module doc).

    Args:
        sim: the internal model (a `cgda_jax.sim.simulator.Simulator`).
        goal: goal feature trajectory (N, F).
        reality: the `Reality` executed on; its feature and joint names must be
            the simulator's. It is `reset` first.
        rate: the exported segments' control rate [Hz].
        correct: the next step's target moved against the last step's measured
            offset from the model's prediction (`OETPlan.relocalize`); False:
            re-localized and re-planned from the measured joints only.
        relocate_objects: dynamic mode: after each step the model's objects are
            put where the measured features say
            (`cgda_jax.sim.relocate.ObjectLocator`; ``info["relocalized"]`` and
            ``info["not_relocalized"]`` name the feature columns); False: they
            stay where the model predicts them.
        step_tolerance: a step's evolution stops below this error in the model
            (None: ``tolerance``); the measured result is still judged at
            ``tolerance``.  A tighter one keeps the model from accepting a push
            that lands anywhere within the tolerance, which a world that
            slides further (a heavier box on less friction) overshoots.
        calibrate: when the reality measures the tool (``Measurement.marker``),
            the joints' calibration offsets are estimated from every measured
            (joints, tool) pair so far (`cgda_jax.reality.calibrate`): the model
            plans in the corrected frame (encoders + offsets) and the robot is
            sent ``planned - offsets``.  False, or a reality without the tool:
            the encoders are taken as they read.
        min_offset_deg: an estimated offset below this [deg] is not applied
            (a slide's, in metres, against the same value in radians): below what
            the tool's measurement resolves, and a world without offsets stays
            OET's.
        settings, changes: OET's settings (`cgda_jax.strategies.oet.OETSettings`;
            ``changes`` replace its fields, e.g. ``population_size=32``), as
            `cgda_jax.strategies.run_oet` takes them (``warm_start``: the first
            step starts from the posture the reality measured at its start;
            ``chunk_size`` unused: the loop steps per executed posture;
            ``devices`` None or 1: the loop runs on one device).
        seed: the run's seed.
        progress_fn: called after each step with a dict (step, k, planning_s,
            execution_s, error).

    Returns:
        An `ExecutionResult` (strategy "oet") whose joints are the planned
        postures (S, DoF) in the model's frame (the commanded ones plus the
        estimated offsets; without calibration the commanded ones) and features
        the MEASURED ones (S, F), judged per goal point as OET
        (`ordered_point_errors`); ``fitness_history`` holds each step's final best
        fitness only. ``info["closed_loop"]`` per step: ``planning_s``,
        ``execution_s``, ``error`` (measured features to the step's target
        point), ``predicted_features`` (the model's, before re-localizing),
        ``measured_joints`` (as the encoders read), ``commanded_joints`` (what
        the robot was sent), ``offsets_deg`` (the estimate after the step);
        ``info["calibration"]``: the final ``offsets_deg``, the tool fit's
        ``residual_mm`` and ``pairs``, or None (not calibrated: ``why``); and
        ``compile_time_s``.

    Raises:
        RealityError: the reality raised, measured NaN / inf or wrong shapes, or
            its names are not the simulator's.
        ValueError: bad settings (as `run_oet`), or ``devices`` other than 1.
    """
    st = OETSettings.of(settings, **changes)
    tolerance = st.tolerance
    if st.devices not in (None, 1):
        raise ValueError(f"devices={st.devices!r}: the closed loop runs on one device "
                         "(None or 1)")
    goal = check_config(sim, goal)
    if step_tolerance is not None and not (np.isfinite(step_tolerance)
                                           and step_tolerance > 0):
        raise ValueError(f"step_tolerance must be > 0; got {step_tolerance}")
    _check_names(sim, reality)
    settings = (st if step_tolerance is None else
                dataclasses.replace(st, tolerance=float(step_tolerance)))
    first = measure(reality)  # (a failing reality stops the run before compiling)
    t0 = time.perf_counter()
    found = ObjectLocator.of(sim) if relocate_objects else None
    locator = found if found is not None and found.any else None
    plan, init_c, advance_c, relocate_c, start_c = compiled_loop(sim, goal, settings,
                                                                 locator)
    compile_time = time.perf_counter() - t0
    est = None
    if calibrate and first.marker is not None:
        est = OffsetEstimate(sim.robot)
        est.add(first.joints, first.marker)
    floor = np.deg2rad(min_offset_deg)

    def offsets() -> np.ndarray:
        if est is None:
            return np.zeros(plan.n_dof)
        return np.where(np.abs(est.offsets) >= floor, est.offsets, 0.0)

    key = seed_keys([seed])[0]
    s = init_c(key)
    off = offsets()
    if locator is not None or np.any(off):
        # the objects where the reality measured them at its start; the arm where
        # the calibrated encoders say it is
        predicted = (start_features(sim, s.sim_state) if locator is not None
                     else first.features[0])  # (only the locator reads it)
        s = start_c(s, jnp.asarray(first.joints[0] + off, jnp.float32),
                    jnp.asarray(first.features[0], jnp.float32),
                    jnp.asarray(predicted, jnp.float32))

    t1 = time.perf_counter()
    steps: dict[str, list] = {"planning_s": [], "execution_s": [], "error": [],
                              "predicted_features": [], "measured_joints": [],
                              "commanded_joints": [], "offsets_deg": []}
    best: list[float] = []
    commanded = None
    goal_np = np.asarray(goal, np.float64)
    while not bool(plan.done(s)):
        prev_k = s.k
        tp = time.perf_counter()
        new, fit = jax.block_until_ready(advance_c(s))
        planning = time.perf_counter() - tp
        n = int(new.steps)
        if n == int(s.steps):  # stuck: no valid posture, nothing executed
            s = new
            break
        q = np.asarray(new.joints[n - 1], np.float64) - off  # what the robot is sent
        traj = trajectory_of(sim, q[None], rate=rate, start=commanded)
        te = time.perf_counter()
        got = measure(reality, traj)
        execution = time.perf_counter() - te
        feats = got.features[-1]
        target = int(new.targets[n - 1])
        steps["planning_s"].append(planning)
        steps["execution_s"].append(execution)
        steps["error"].append(float(np.linalg.norm(feats - goal_np[target])))
        steps["predicted_features"].append(np.asarray(new.features[n - 1]).tolist())
        steps["measured_joints"].append(got.joints[-1].tolist())
        steps["commanded_joints"].append(traj.q[-1].tolist())
        best.append(float(fit))
        if est is not None and got.marker is not None:
            est.add(got.joints, got.marker)
        off = offsets()
        steps["offsets_deg"].append(np.rad2deg(off).tolist())
        s = relocate_c(new, prev_k, jnp.asarray(got.joints[-1] + off, jnp.float32),
                       jnp.asarray(feats, jnp.float32), jnp.asarray(bool(correct)))
        commanded = np.asarray(traj.q[-1], np.float64)
        if progress_fn is not None:
            progress_fn({"strategy": "oet", "loop": "closed", "step": n,
                         "k": int(s.k), "planning_s": planning,
                         "execution_s": execution, "error": steps["error"][-1]})
    final = jax.tree.map(np.asarray, jax.block_until_ready(plan.finish(s)))
    wall = time.perf_counter() - t1
    n = int(final["steps"])
    history = {"best_fitness": np.asarray(best, np.float32),
               "step": np.arange(n, dtype=np.int32)}
    timing = {"wall_time_s": wall, "compile_time_s": compile_time,
              "trials_in_batch": 1}
    res = plan.to_result(final, history, timing)
    if step_tolerance is not None:  # judged at the run's tolerance, not the step's
        dist = np.linalg.norm(goal_np[:, None] - res.features[None], axis=-1)
        errors = ordered_point_errors(dist, tolerance)
        res = dataclasses.replace(
            res, point_errors=errors, tolerance=float(tolerance),
            success=bool(np.all(errors < tolerance)) and res.info.get("feasible", True))
    res.info.update({"seed": int(seed), "devices": 1, "loop": "closed",
                     "closed_loop": steps, "corrected": bool(correct),
                     "relocalized": list(found.located) if found else [],
                     "not_relocalized": dict(found.not_located) if found else {},
                     "reality": type(reality).__name__,
                     "calibration": None if est is None else {
                         "offsets_deg": np.rad2deg(offsets()).tolist(),
                         "estimated_deg": np.rad2deg(est.offsets).tolist(),
                         "residual_mm": 1e3 * est.residual,
                         "pairs": est.pairs},
                     "calibration_why": _why_not_calibrated(est, calibrate),
                     "step_tolerance": step_tolerance})
    return res
