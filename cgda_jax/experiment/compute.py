"""Running an experiment: the numbers of a recognition or an execution run (the
strategy's result, replayed on a finer simulator) and the arrays saved with them.
What is drawn and written from them (figures, video, ``result.json``,
``report.md``) is `cgda_jax.experiment.run`'s.
"""

from __future__ import annotations

import functools
import json
import pathlib
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from cgda_jax.experiment.build import (
    BuiltExecution,
    error_unit,
    feature_labels,
    goal_scale,
    recognition_demos,
    selected_demos,
)
from cgda_jax.experiment.config import ExperimentConfig
from cgda_jax.experiment.rules import strategy_function
from cgda_jax.experiment.validate import check_and_build

#: What a run computes: the result dict (final but for its outputs' keys), the
#: arrays (as in ``arrays.npz``) and, for an execution, the simulator.
Computed = tuple[dict, dict[str, np.ndarray], Any]


def compute_recognition(cfg: ExperimentConfig, out: pathlib.Path) -> Computed:
    """Generalize, then recognize the held-out repetitions (paper Tables 2-4);
    ``arrays.npz`` is written into ``out``."""
    from cgda_jax.generalization import generalize, sample_actions
    from cgda_jax.recognition import ActionLibrary, cost_matrix

    d, r = cfg.data, cfg.recognition
    t0 = time.perf_counter()
    demos = recognition_demos(cfg)

    def library_of(train: dict) -> tuple[Any, dict, Any]:
        """The library generalized from ``train`` (after ``[selection]``), the
        demonstrations it kept and what was selected."""
        train, selection = selected_demos(cfg, train)
        return (ActionLibrary.from_demonstrations(train, d.interval_s, d.method),
                train, selection)

    def costs_of(library, tests: list) -> np.ndarray:
        """The (action, demonstration) ``tests``' costs against ``library``."""
        if r.query == "reduced":
            reduced = [generalize([t], d.interval_s, d.method) for _, t in tests]
            queries = list(np.asarray(sample_actions(reduced, r.n_samples)))
        else:
            queries = [t for _, t in tests]
        return np.asarray(cost_matrix(queries, library, r.metric, r.n_samples), float)

    if r.split == "leave_one_out":  # each repetition the query of its own library
        library, train, selection = library_of(demos)
        tests, rows = [], []
        for a, reps in demos.items():
            for k, t in enumerate(reps):
                rest = {b: [u for j, u in enumerate(v) if (b, j) != (a, k)]
                        for b, v in demos.items()}
                lib_k = library_of(rest)[0]
                tests.append((a, t.select(lib_k.feature_names)))
                order = [list(lib_k.names).index(n) for n in library.names]
                rows.append(costs_of(lib_k, tests[-1:])[0, order])
        costs = np.stack(rows)
    else:
        library, train, selection = library_of(
            {a: v[: d.n_train] for a, v in demos.items()})
        tests = [(a, t.select(library.feature_names)) for a, v in demos.items()
                 for t in v[d.n_train:]]
        costs = costs_of(library, tests)
    names = list(library.names)
    recognized = [names[i] for i in costs.argmin(axis=1)]
    truth = [a for a, _ in tests]
    accuracy = float(np.mean([p == t for p, t in zip(recognized, truth)]))
    result = {
        "kind": "recognition",
        "name": cfg.name,
        "features": list(library.feature_names),
        "feature_labels": feature_labels(cfg, library.feature_names),
        "metric": r.metric,
        "split": r.split,
        "actions": names,
        "queries": [t.name for _, t in tests],
        "truth": truth,
        "cost_matrix": costs,
        "recognized": recognized,
        "accuracy": accuracy,
        "success": accuracy == 1.0,
        "wall_time_s": time.perf_counter() - t0,
    }
    if selection is not None:
        result["selection"] = selection
    arrays = {"cost_matrix": costs}
    for a in names:
        arrays[f"knot_times_{a}"] = np.asarray(library[a].knot_times)
        arrays[f"knots_{a}"] = np.asarray(library[a].knots)
        arrays.update(_demo_arrays(train[a], f"demo_{a}_"))
    np.savez(out / "arrays.npz", **arrays)
    return result, arrays, None


def _demo_arrays(demos, prefix: str, scale: float = 1.0) -> dict[str, np.ndarray]:
    """``{prefix}{k}_times`` and ``{prefix}{k}_features`` (times scale) per demo."""
    out = {}
    for k, d in enumerate(demos):
        out[f"{prefix}{k}_times"] = np.asarray(d.times, np.float64)
        out[f"{prefix}{k}_features"] = np.asarray(d.features, np.float64) * scale
    return out


#: How much finer a result is replayed: dynamic runs at timestep / 4 (MuJoCo C),
#: kinematic runs at 16 x the sub-steps.
REPLAY_FACTOR = {"dynamic": 4, "kinematic": 16}


def replay_check(sim, res, factor: int | None = None) -> dict:
    """Re-execute the reported joints on a `factor` x finer simulator
    (`Simulator.finer`: dynamic mode timestep / factor on MuJoCo C, kinematic mode
    factor x the sub-steps; default `REPLAY_FACTOR`): the features must agree, or
    the optimiser exploited the resolution it was evaluated at."""
    fine = sim.finer(factor or REPLAY_FACTOR[sim.mode])
    feats = np.asarray(replayed_features(fine, res.joints), np.float64)
    from cgda_jax.strategies.fitness import point_errors  # JAX, evosax: lazily

    errors = point_errors(res.strategy, feats, res.goal, res.tolerance)
    out = ({"timestep": fine.physics.timestep} if fine.mode == "dynamic"
           else {"substeps": fine.substeps})
    return out | {
        "max_feature_difference": float(np.abs(feats - res.features).max()),
        "max_point_error": float(errors.max()),
        "success": bool(np.all(errors < res.tolerance)),
    }


def replayed_features(sim, joints) -> np.ndarray:
    """Features (N, F) of executing ``joints`` (N, DoF) on ``sim`` from its start,
    its moves not judged (``Simulator.step(judge=False)``: the features are the
    same, the collision check is not compiled): one program, compiled once a
    process for the same simulator and shape (`cgda_jax.programs.jit_call`)."""
    import jax
    import jax.numpy as jnp

    from cgda_jax.programs import jit_call
    from cgda_jax.sim.sim_state import check_waypoints

    joints = jnp.asarray(np.asarray(joints, np.float32))
    check_waypoints(joints, sim.robot)

    def features(waypoints):
        step = functools.partial(sim.step, judge=False)
        return jax.lax.scan(step, sim.init_state(), waypoints)[1]

    return np.asarray(jit_call(features, joints))


#: The control rate of the exported trajectory a run checks [Hz].
EXPORT_RATE = 100.0


def export_check(sim, res, rate: float = EXPORT_RATE, factor: int = 4,
                 profile: str = "min_jerk") -> dict:
    """The reported joints exported as a controller's trajectory
    (`cgda_jax.reality.control_trajectory.trajectory_of`, ``rate`` Hz), written as
    its JSON file and read back (`cgda_jax.reality.files`), then replayed on MuJoCo C
    (`cgda_jax.reality.replay.replay_trajectory`, ``factor`` x finer): its features
    against the goal and the run's features, and its samples against the limits.
    ``profile``: each move's (`cgda_jax.reality.profiles.PROFILES`).  A result
    without postures to export (NaN joints) says why instead."""
    from cgda_jax.reality.control_trajectory import trajectory_of
    from cgda_jax.reality.files import from_json_dict, to_json_dict
    from cgda_jax.reality.replay import replay_trajectory

    try:
        traj = trajectory_of(sim, res.joints, rate=rate, profile=profile)
    except ValueError as e:
        return {"exported": False, "reason": str(e), "success": False}
    traj = from_json_dict(json.loads(json.dumps(to_json_dict(traj))))  # the file
    feats = replay_trajectory(sim, traj, factor)
    from cgda_jax.strategies.fitness import point_errors  # JAX, evosax: lazily

    errors = point_errors(res.strategy, feats, res.goal, res.tolerance)
    over = {}
    for kind, values in (("velocity", traj.qd), ("acceleration", traj.qdd)):
        lim = traj.limits[kind]
        peak = np.abs(values).max(axis=0)
        finite = np.isfinite(lim)
        over[kind] = float((peak[finite] / lim[finite]).max()) if finite.any() else None
    return {
        "exported": True, "rate_hz": traj.rate, "samples": traj.n_samples,
        "duration_s": traj.duration, "profile": traj.info["profile"],
        **({"ruckig": traj.info["ruckig"]} if "ruckig" in traj.info else {}),
        "stretched_moves": len(traj.info["stretched"]),
        "limit_ratio": over,  # largest |sample| / limit per kind (None: no limit)
        "replay": ({"timestep": sim.physics.timestep / factor}
                   if sim.mode == "dynamic" else {"substeps": sim.substeps * factor}),
        "max_feature_difference": float(np.abs(feats - res.features).max()),
        "max_point_error": float(errors.max()),
        "success": bool(np.all(errors < res.tolerance)),
    }


def reality_check(sim, res, table: dict, rate: float = EXPORT_RATE) -> dict:
    """The reported joints executed OPEN LOOP on a mismatched world
    (`cgda_jax.reality.mismatch.MismatchedWorld` with the ``[reality]`` values
    ``table``): the exported trajectory sent as it is, the world's features
    measured at each waypoint and judged against the goal per point."""
    from cgda_jax.reality.control_trajectory import trajectory_of
    from cgda_jax.reality.mismatch import Mismatch, MismatchedWorld
    from cgda_jax.reality.protocol import measure

    world = MismatchedWorld(sim, Mismatch.from_dict(table))
    drawn = dict(world.drawn)  # the offsets in degrees, as the config gives them
    drawn["joint_offset_deg"] = np.rad2deg(drawn.pop("joint_offset")).tolist()
    out = {"mismatch": drawn, "seed": world.mismatch.seed}
    try:
        traj = trajectory_of(sim, res.joints, rate=rate)
    except ValueError as e:
        return out | {"executed": False, "reason": str(e), "success": False}
    measure(world)
    got = measure(world, traj)
    from cgda_jax.strategies.fitness import point_errors  # JAX, evosax: lazily

    errors = point_errors(res.strategy, got.features, res.goal, res.tolerance)
    return out | {
        "executed": True, "loop": "open",
        "point_errors": errors.tolist(),
        "max_point_error": float(errors.max()),
        "max_feature_difference": float(np.abs(got.features - res.features).max()),
        "success": bool(np.all(errors < res.tolerance)),
    }


def closed_loop_check(sim, goal, strategy, reality) -> dict:
    """OET closed on the mismatched world (`cgda_jax.strategies.closed_loop`, a
    fresh `MismatchedWorld` of the ``[reality]`` section ``reality``, with its
    loop options, and the run's strategy settings ``strategy``): each step
    planned from what the world measured; its measured features judged per goal
    point, and its planning and execution times per step."""
    from cgda_jax.reality.mismatch import Mismatch, MismatchedWorld
    from cgda_jax.strategies.closed_loop import run_oet_closed_loop

    s, loop = strategy, reality.loop_options()
    res = run_oet_closed_loop(
        sim, goal, MismatchedWorld(sim, Mismatch.from_dict(reality.mismatch_table())),
        algorithm=s.algorithm, population_size=s.population_size,
        tolerance=s.tolerance, max_generations=s.max_generations, seed=s.seed,
        **loop, **s.options)
    steps = res.info["closed_loop"]
    errors = np.asarray(res.point_errors, np.float64)
    return {
        "loop": "closed", "steps": len(res.joints),
        "point_errors": errors.tolist(), "max_point_error": float(errors.max()),
        "success": bool(res.success), "step_errors": steps["error"],
        "planning_s": steps["planning_s"], "execution_s": steps["execution_s"],
        "compile_time_s": res.compile_time_s,
        "relocalized": res.info["relocalized"],
        "not_relocalized": res.info["not_relocalized"],
        "calibration": res.info["calibration"],
        "options": loop,
    }


def compute_execution(
    cfg: ExperimentConfig, out: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
    built: BuiltExecution | None = None,
) -> Computed:
    """Run the strategy on the goal and simulator of ``built`` (those its checks
    built, `check_and_build`; default: checked and built here) and replay its
    result; ``arrays.npz`` is written into ``out`` (``result.json`` by the caller,
    from the returned summary)."""
    if built is None:
        built = check_and_build(cfg)[1]
    goal, demos, gen, sim = built.goal, built.demos, built.generalization, built.sim
    waypoint_s = built.waypoint_s
    s = cfg.strategy
    from cgda_jax.strategies import strategy_of

    if strategy_of(s.name).plan.per_point:  # a waypoint per goal point: the check's
        from cgda_jax.sim.motion_check import compile_collisions_ahead

        compile_collisions_ahead(sim, len(goal))  # program compiles meanwhile
    res = strategy_function(s.name)(
        sim, goal, algorithm=s.algorithm, population_size=s.population_size,
        tolerance=s.tolerance, max_generations=s.max_generations, seed=s.seed,
        chunk_size=s.chunk_size, progress_fn=progress_fn, **s.options,
    )
    # the strategy's summary as result.json holds it (through JSON) and its arrays
    summary = json.loads(json.dumps(res.summary()))
    labels = feature_labels(cfg, sim.feature_names)
    summary.update({"kind": "execution", "name": cfg.name,
                    "feature_names": list(sim.feature_names),
                    "feature_labels": labels, "error_unit": error_unit(labels),
                    "build": {"waypoint_s": waypoint_s},
                    "waypoint_s": float(sim.waypoint_s)})
    if cfg.selection.demonstrations:  # which ones the [selection] kept
        summary["selected_demonstrations"] = [d.name for d in demos]
    arrays = {k: np.asarray(v) for k, v in res.arrays().items()}
    if gen is not None:  # the generalization and demonstrations, in the goal's units
        arrays["knot_times"] = np.asarray(gen.knot_times, np.float64)
        arrays["knots"] = np.asarray(gen.knots, np.float64) * goal_scale(cfg)
        arrays.update(_demo_arrays(demos, "demo", goal_scale(cfg)))
    if sim.mode == "dynamic":
        summary["physics"] = {
            "backend": sim.backend.name, "waypoint_s": sim.waypoint_s,
            "timestep": sim.physics.timestep, "physics_steps": sim.physics_steps,
            "welded_joints": list(sim.physics.welded),
            "control": sim.physics.control.as_dict(),
        }
    else:
        summary["substeps"] = sim.substeps
    summary["replay"] = replay_check(sim, res)
    summary["export"] = export_check(sim, res)
    if cfg.reality.enabled:
        summary["reality"] = reality_check(sim, res, cfg.reality.mismatch_table())
        if s.name == "oet":  # online: also closed on the world, step by step
            summary["reality"]["closed_loop"] = closed_loop_check(
                sim, goal, s, cfg.reality)
    motion = motion_check(sim, res)
    if motion is not None:
        summary["motion"], profile = motion
        arrays.update(profile)
    np.savez(out / "arrays.npz", **arrays)
    return summary, arrays, sim


def motion_check(sim, res) -> tuple[dict, dict] | None:
    """The reported joints checked as a motion (`cgda_jax.sim.motion_check.motion_report`:
    collisions 4 x finer, speeds, accelerations, efforts and tracking in a dynamic
    replay, joint travel) and the commanded profile's arrays (``motion_t``,
    ``motion_q``, ``motion_qd``, ``motion_waypoint_t``) for the figure; None
    when no joints were found."""
    from cgda_jax.logs import warn_once
    from cgda_jax.sim.motion_check import motion_profile, motion_report

    joints = np.asarray(res.joints, np.float64)
    if joints.size == 0 or not np.all(np.isfinite(joints)):
        return None
    prof = motion_profile(sim, joints)
    report = motion_report(sim, joints)
    if report.get("tracking_note"):  # said once per run, also in report.md
        warn_once(f"{sim.robot.source}: {report['tracking_note']}")
    return report, {
        "motion_t": prof.t, "motion_q": prof.q, "motion_qd": prof.qd,
        "motion_waypoint_t": prof.waypoint_t,
        "joint_lower": np.asarray(sim.lower, np.float64),
        "joint_upper": np.asarray(sim.upper, np.float64)}
