"""Open-loop IET against closed-loop OET on a mismatched world, over seeds (issue 22).

experiments/move_push_box_mismatch.toml: the box twice as heavy, half the friction,
3 degree offsets on the shoulder flexion and the elbow, 2 mm feature noise.  The goal
and the (exact) internal model are built as ``cgda run`` builds them.  For each
strategy seed:

- open loop: IET (the config's settings) found on the model, its exported
  trajectory sent as it is to the mismatched world
  (`cgda_jax.experiment.compute.reality_check`);
- closed loop: OET on the same world (`cgda_jax.strategies.closed_loop`), each push
  planned from what the world measured; the same population, tolerance, generations
  per step and step size (``std_init``) as the IET run.

Both judged per goal point on the world's measured features (OET in order).

``--tiny``: the tiny arm instead (tests/test_closed_loop.py's goal and settings,
offsets drawn in [-3, 3] degrees, mismatch seeds 5 and 6, OET seeds 0 and 1): OET's
plan replayed open loop against OET closed loop.

``--config rotate_valve_mismatch``: the valve variant (the lever twice as heavy,
3 degree offsets on the abduction and the elbow, 0.01 rad of angle noise).
``--no-relocate`` / ``--no-correct`` / ``--no-calibrate``: the closed loop without
the objects' re-localization / the target's correction / the joint offsets estimated
from the measured tool; ``--step-tolerance``, ``--restarts``,
``--stagnation``: the closed loop's OET settings (`run_oet_closed_loop`).  OET's
first step starts from the measured start posture when the config's
``strategy.options.warm_start`` is true (as IET's points do); ``--cold-start``: from
the middle of the joint ranges.

``--levels 0 0.5 1 1.5``: a sweep of mismatch levels (`scaled_table`: each scale
factor raised to the level, each offset, noise and delay times it; the tool's
``marker_noise`` is the sensor's and stays), every seed at every level; ``--open-only``
the open loop alone (cheap: the IET batch once, one replay per seed and level).

    python benchmarks/bench_closed_loop.py [--seeds 5] [--tiny] [--config NAME]
        [--levels 0.5 1] [--open-only]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import experiment_trials, print_table, write_json

from cgda_jax.experiment.compute import reality_check
from cgda_jax.reality.mismatch import Mismatch, MismatchedWorld
from cgda_jax.strategies.closed_loop import run_oet_closed_loop

NAME = "move_push_box_mismatch"
_SCALES = ("mass_scale", "friction_scale", "damping_scale", "gain_scale")
_ADDED = ("joint_offset_deg", "noise", "delay_s")


def scaled_table(table: dict, level: float) -> dict:
    """The ``[reality]`` values at mismatch ``level`` (1: as given, 0: the model):
    scale factors to the power ``level``, offsets, noise and delay times it (a
    ``[low, high]`` range and a per-joint table element-wise)."""
    def one(name, v):
        if isinstance(v, dict):
            return {k: one(name, x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [one(name, x) for x in v]
        return float(v) ** level if name in _SCALES else float(v) * level

    return {k: one(k, v) if k in _SCALES + _ADDED else v for k, v in table.items()}


def tiny() -> None:
    from cgda_jax import MarkerScene, Robot, Simulator, model_path
    from cgda_jax.reality.control_trajectory import trajectory_of
    from cgda_jax.reality.protocol import measure
    from cgda_jax.strategies import run_oet
    from cgda_jax.strategies.oet import ordered_point_errors

    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    sim = Simulator(robot, MarkerScene(), mode="dynamic", waypoint_s=0.5,
                    physics="mujoco")
    wps = np.array([[0.1, 0.2, 0.1], [0.3, 0.4, 0.2], [0.5, 0.5, 0.3]], np.float32)
    goal = np.asarray(sim.execute(wps), np.float64)
    kw = {"population_size": 16, "tolerance": 0.01, "max_generations": 80}
    rows = []
    for world_seed in (5, 6):
        mm = Mismatch(joint_offset_deg=[-3.0, 3.0], seed=world_seed)
        for seed in (0, 1):
            plan = run_oet(sim, goal, seed=seed, **kw)
            world = MismatchedWorld(sim, mm)
            measure(world)
            got = measure(world, trajectory_of(sim, plan.joints)).features
            dist = np.linalg.norm(goal[:, None] - got[None], axis=-1)
            open_loop = ordered_point_errors(dist, kw["tolerance"])
            closed = run_oet_closed_loop(sim, goal, MismatchedWorld(sim, mm),
                                         seed=seed, **kw)
            steps = closed.info["closed_loop"]
            rows.append({"world_seed": world_seed, "seed": seed,
                         "open_mm": np.round(1e3 * open_loop, 1).tolist(),
                         "closed_mm": np.round(1e3 * closed.point_errors, 1).tolist(),
                         "planning_s": float(np.sum(steps["planning_s"])),
                         "execution_s": float(np.sum(steps["execution_s"]))})
            print(rows[-1], flush=True)
    write_json("bench_closed_loop_tiny", {"rows": rows})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--tiny", action="store_true")
    parser.add_argument("--config", default=NAME,
                        help=f"an experiment with a [reality] table (default {NAME})")
    parser.add_argument("--no-relocate", action="store_true",
                        help="closed loop without the objects' re-localization")
    parser.add_argument("--no-correct", action="store_true",
                        help="closed loop without the target's correction")
    parser.add_argument("--levels", type=float, nargs="+", default=[1.0],
                        help="mismatch levels (1: the config's; see scaled_table)")
    parser.add_argument("--open-only", action="store_true",
                        help="the open loop only (no closed-loop OET)")
    parser.add_argument("--cold-start", action="store_true",
                        help="OET's first step from the middle of the joint ranges "
                             "(default: from the measured start posture when the "
                             "config's strategy.options.warm_start is true)")
    parser.add_argument("--no-calibrate", action="store_true",
                        help="closed loop without the joint offsets estimated "
                             "from the measured tool")
    parser.add_argument("--step-tolerance", type=float, default=None,
                        help="closed loop: a step's evolution stops below this "
                             "(default: the config's tolerance; judged at that)")
    parser.add_argument("--restarts", type=int, default=0,
                        help="closed loop: restarts of a stalled step's evolution")
    parser.add_argument("--stagnation", type=int, default=None,
                        help="closed loop: a try stops after this many "
                             "generations without improvement")
    args = parser.parse_args()
    if args.tiny:
        tiny()
        return
    cfg, sim, goal, iet, iet_s = experiment_trials(args.config, args.seeds)
    s, given = cfg.strategy, cfg.reality.mismatch_table()
    rows, summaries = [], []
    for level in args.levels:
        table = scaled_table(given, level)
        level_rows = []
        for res in iet:
            row = {"level": level, **one_seed(args, sim, goal, s, res, table)}
            level_rows.append(row)
            print(row, flush=True)
        rows += level_rows
        summaries.append({
            "level": level, "seeds": args.seeds,
            "open_loop_successes": sum(r["open_loop_success"] for r in level_rows),
            "closed_loop_successes": None if args.open_only else sum(
                r["closed_loop_success"] for r in level_rows),
            "mismatch": level_rows[0]["mismatch"]})
        print(summaries[-1], flush=True)
    print_table(rows, [k for k in rows[0] if k not in ("closed_step_error_mm",
                                                       "mismatch")])
    print()
    print_table(summaries, ["level", "seeds", "open_loop_successes",
                            "closed_loop_successes"])
    summary = {"seeds": args.seeds, "iet_batch_s": iet_s, "levels": args.levels,
               "relocate_objects": not args.no_relocate,
               "correct": not args.no_correct, "calibrate": not args.no_calibrate,
               "step_tolerance": args.step_tolerance, "restarts": args.restarts,
               "stagnation": args.stagnation, "per_level": summaries}
    write_json("bench_closed_loop" + ("" if args.config == NAME else f"_{args.config}"),
               {"rows": rows, "summary": summary})


def one_seed(args, sim, goal, s, res, table: dict) -> dict:
    """Seed ``res``'s IET result open loop, and (unless ``--open-only``) closed-loop
    OET of the same seed, on the world of ``table``."""
    seed = res.info["seed"]
    open_loop = reality_check(sim, res, table)
    row = {"seed": seed, "iet_model_success": res.success,
           "open_loop_success": open_loop["success"],
           "open_loop_max_err_mm": 1e3 * open_loop["max_point_error"],
           "mismatch": open_loop["mismatch"]}
    if args.open_only:
        return row
    t1 = time.perf_counter()
    closed = run_oet_closed_loop(
        sim, goal, MismatchedWorld(sim, Mismatch.from_dict(table)),
        algorithm=s.algorithm, population_size=s.population_size,
        tolerance=s.tolerance, max_generations=s.max_generations, seed=seed,
        algorithm_params=s.options.get("algorithm_params"),
        relocate_objects=not args.no_relocate, correct=not args.no_correct,
        calibrate=not args.no_calibrate,
        step_tolerance=args.step_tolerance, restarts=args.restarts,
        stagnation=args.stagnation,
        warm_start=bool(s.options.get("warm_start")) and not args.cold_start)
    steps = closed.info["closed_loop"]
    cal = closed.info["calibration"]
    return row | {
        "closed_loop_success": closed.success,
        "closed_loop_max_err_mm": 1e3 * float(closed.max_point_error),
        "closed_steps": len(closed.joints),
        "planning_s": float(np.sum(steps["planning_s"])),
        "execution_s": float(np.sum(steps["execution_s"])),
        "closed_compile_s": closed.compile_time_s,
        "offsets_deg": cal and np.round(cal["offsets_deg"], 2).tolist(),
        "closed_step_error_mm": np.round(1e3 * np.asarray(steps["error"]),
                                         1).tolist(),
        "targets": closed.info["targets"],
        "end": np.round(closed.features[-1], 4).tolist(),
        "closed_total_s": time.perf_counter() - t1,
    }


if __name__ == "__main__":
    main()
