"""Run the paper's execution experiments (and the real-data ones) once, print the figures.

Usage:
    python experiments/scripts/paper_execution.py [clean_ie clean_fte paint_iet
        clean_oet paint_oet paint_xgnitive iron_ie] [--out experiments/results] [--seed 0]

TEO model, right arm. Paper joints: shoulder flexion, shoulder abduction, elbow, forearm
rotation fixed at 45 deg. Each run saves result.json + arrays.npz under --out/<name>/ and
prints success, per-point errors, evaluations, wall time (compile time apart); the paper
reports 53 +/- 12 s (clean IE, 9 points) and 258 +/- 7 s (paint IET, 17 points).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib

import numpy as np

import cgda_jax as cg
from cgda_jax.datasets import clean_circle_demos, paint_ramp

PAPER_JOINTS = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
PAPER_FIXED = {"r_forearm_rotation": np.deg2rad(45.0)}
# Iron (real demos): the paper's 3 joints cannot bring the 0.267 m marker to the demo's
# tool points (they lie low and close to the body); adding upper-arm rotation and the
# wrist gives the arm the reach (chosen subset, reported in the output).
IRON_JOINTS = ["r_shoulder_flexion", "r_shoulder_abduction", "r_upper_arm_rotation",
               "r_elbow", "r_wrist"]
XGNITIVE = pathlib.Path(
    os.environ.get("CGDA_XGNITIVE_DIR",
                   pathlib.Path(__file__).resolve().parents[3] / "shared/data/xgnitive")
)


def teo_sim(scene, joints=PAPER_JOINTS, fixed=PAPER_FIXED, substeps=8):
    robot = cg.Robot.from_mjcf(cg.model_path("teo.xml"), joints, "marker", fixed=fixed)
    return cg.Simulator(robot, scene, substeps=substeps)


def clean_goal(seed=0):
    # default demos: ~9 s each (circling + pauses) -> the paper's 9-point goal
    demos = clean_circle_demos(seed=seed)
    return np.asarray(cg.generalize(demos, interval_s=1.0).knots)


def experiment(name, seed):
    if name == "clean_ie":
        goal = clean_goal()
        return cg.run_ie(teo_sim(cg.MarkerScene()), goal, population_size=32,
                         tolerance=0.02, max_generations=200, seed=seed), {}
    if name == "clean_fte":
        goal = clean_goal()
        # paper rule (stagnation 10) stops CMA-ES at generation ~15; see clean_fte.toml
        return cg.run_fte(teo_sim(cg.MarkerScene()), goal, population_size=64,
                          tolerance=0.02, stagnation=50, max_generations=1000,
                          distance="dtw_multi", algorithm_params={"std_init": 0.3},
                          seed=seed), {"distance": "dtw_multi", "stagnation": 50}
    if name == "paint_iet":
        return cg.run_iet(teo_sim(cg.PaintWall.grid()), paint_ramp(17),
                          population_size=32, tolerance=1.0, max_generations=100,
                          seed=seed), {}
    if name == "clean_oet":
        return cg.run_oet(teo_sim(cg.MarkerScene()), clean_goal(), population_size=32,
                          tolerance=0.02, max_generations=200, seed=seed), {}
    if name == "paint_oet":
        return cg.run_oet(teo_sim(cg.PaintWall.grid()), paint_ramp(17),
                          population_size=32, tolerance=1.0, max_generations=100,
                          seed=seed), {}
    if name == "paint_xgnitive":
        demos = cg.load_xgnitive(XGNITIVE, "paint", "paintSquaresOnScreen")
        gen = cg.generalize(demos, interval_s=10.0, method="xgnitive")
        goal = np.asarray(gen.knots)
        # goal values lie between multiples of 6.25 %: each executed point must be
        # within half a square (3.125 %) of its goal = its nearest paintable value
        res = cg.run_iet(teo_sim(cg.PaintWall.grid()), goal, population_size=32,
                         tolerance=3.125, max_generations=100, seed=seed)
        nearest = 6.25 * np.round(goal / 6.25)
        return res, {"goal": goal.ravel().round(2).tolist(),
                     "executed_is_nearest_step": bool(np.allclose(res.features, nearest))}
    if name == "iron_ie":
        demos = cg.load_xgnitive(XGNITIVE, "iron", "teo/rightArm", ["X", "Y", "Z"])
        gen = cg.generalize(demos, interval_s=3.0, method="xgnitive")
        goal = np.asarray(gen.knots)
        return cg.run_ie(teo_sim(cg.MarkerScene(), joints=IRON_JOINTS, fixed={}),
                         goal, population_size=32, tolerance=0.02,
                         max_generations=300, seed=seed), {"joints": IRON_JOINTS}
    raise ValueError(f"unknown experiment {name!r}")


def trials(name, n_trials, seed):
    """The paper's 30-trial timing runs, all trials in one batched call."""
    if name == "clean_ie":
        res = cg.run_trials("ie", teo_sim(cg.MarkerScene()), clean_goal(), n_trials,
                            seed=seed, population_size=32, tolerance=0.02,
                            max_generations=200)
    elif name == "paint_iet":
        res = cg.run_trials("iet", teo_sim(cg.PaintWall.grid()), paint_ramp(17),
                            n_trials, seed=seed, population_size=32, tolerance=1.0,
                            max_generations=100)
    else:
        raise ValueError(f"no trials set-up for {name!r}")
    evals = np.array([r.evaluations for r in res])
    return {
        "experiment": f"{name} x{n_trials} trials (one batched call)",
        "successes": int(sum(r.success for r in res)),
        "max_point_error_worst": float(max(r.max_point_error for r in res)),
        "evaluations_mean": float(evals.mean()), "evaluations_std": float(evals.std()),
        "batch_wall_time_s": round(res[0].wall_time_s, 3),
        "batch_compile_time_s": round(res[0].compile_time_s, 2),
    }


def main(argv=None):
    names = ["clean_ie", "clean_fte", "paint_iet", "clean_oet", "paint_oet",
             "paint_xgnitive", "iron_ie"]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=names)
    ap.add_argument("--out", default="experiments/results")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--trials", type=int, default=0,
                    help="also run clean_ie / paint_iet this many times, batched")
    args = ap.parse_args(argv)
    for name in args.names:
        if args.trials and name in ("clean_ie", "paint_iet"):
            print(json.dumps(trials(name, args.trials, args.seed)), flush=True)
        res, extra = experiment(name, args.seed)
        res.info.update(extra)
        res.save(pathlib.Path(args.out) / name)
        unit = 1000.0 if res.goal.shape[1] == 3 else 1.0
        print(json.dumps({
            "experiment": name, "success": res.success,
            "point_errors": np.round(res.point_errors * unit, 2).tolist(),
            "error_unit": "mm" if unit == 1000.0 else "feature",
            "final_fitness": round(res.final_fitness, 5),
            "evaluations": res.evaluations, "generations": res.generations,
            "wall_time_s": round(res.wall_time_s, 2),
            "compile_time_s": round(res.compile_time_s, 2), **extra,
        }), flush=True)


if __name__ == "__main__":
    main()
