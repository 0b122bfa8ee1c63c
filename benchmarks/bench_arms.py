"""Robot-configuration independence: success rates on a family of random arms.

For each arm of `cgda_jax.datasets.arms` (2-7 hinge joints, random segment lengths
and axes; MJCF written here) a reachable 6-point goal curve (marker positions along a
joint-space path between two random postures) is executed by IE, IET and FTE, 30
seeds each as ONE batched `run_trials` call per strategy and arm, kinematic mode,
tolerance 20 mm. Prints the success table and the cost of restarts (tries used) and
of the polish (IE with ``refine="adam"``: run time with and without).

Target (issue 11): each strategy succeeds on at least 29 of 30 seeds per arm.

    python benchmarks/bench_arms.py [--joints 2 3 4 5 6 7] [--seeds 30]
        [--strategies ie iet fte] [--feasibility] [--no-polish] [--ie-backtracks N]

``--feasibility`` judges every move (`Simulator`'s ``feasibility=True``: the model's
joint limits, no move over 90 degrees, the approach; the random arms' geoms do not
collide and have no speed limits), as every experiment does by default since issue 21;
IE then evolves each point from where the points before it leave the arm, and a point
whose tries all miss backtracks (`IESettings.backtracks`). With it every success is
also checked independently, as `bench_seeds_check.py` checks the experiments: the
reported joints' moves by `motion_report` (4 x the postures, the step cap, limits) and
a replay at 16 x the sub-steps (`replay_check`); ``checked`` counts the successes
that pass both, ``backtracks`` sums the backtracks used (IE, IET).
``--no-polish`` skips the ``ie+adam`` row; ``--ie-backtracks 0`` runs IE without
backtracks (as before they existed; default: `IESettings`').

Issue 39's IE rows: ``nice -n 10 python benchmarks/bench_arms.py --feasibility
--no-polish --seeds 10 --joints 4 5 6 7 --strategies ie``.
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
from _common import print_table, report_target, write_json

from cgda_jax import MarkerScene, Robot, Simulator, run_trials
from cgda_jax.datasets.arms import arm_joints, random_arm_mjcf, reachable_goal
from cgda_jax.experiment.compute import replay_check
from cgda_jax.sim.motion_check import motion_report

SETTINGS = {
    "ie": dict(population_size=16, max_generations=100),
    "iet": dict(population_size=16, max_generations=100),
    "fte": dict(population_size=32, max_generations=400, distance="dtw_multi",
                stagnation=50),
}


def arm(n_joints: int, seed: int, feasibility: bool = False
        ) -> tuple[Simulator, np.ndarray]:
    """The random arm's simulator (``feasibility``: every move judged, the model's
    limits, `Simulator`'s ``feasibility=True``) and its reachable goal."""
    model = mujoco.MjModel.from_xml_string(random_arm_mjcf(n_joints, seed))
    robot = Robot(model, arm_joints(n_joints), "marker")
    sim = Simulator(robot, MarkerScene(), substeps=4, feasibility=feasibility or None)
    return sim, reachable_goal(robot, 6, seed)


def checked(sim: Simulator, results: list) -> int:
    """How many successes of ``results`` pass the independent check: their
    joints' moves feasible by `motion_report` and their replay at 16 x the
    sub-steps within the tolerance (`replay_check`)."""
    return sum(bool(motion_report(sim, np.asarray(r.joints))["feasible"]
                    and replay_check(sim, r)["success"])
               for r in results if r.success)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--joints", type=int, nargs="*", default=[2, 3, 4, 5, 6, 7])
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--strategies", nargs="*", default=["ie", "iet", "fte"])
    parser.add_argument("--tolerance", type=float, default=0.02)
    parser.add_argument("--feasibility", action="store_true")
    parser.add_argument("--no-polish", action="store_true")
    parser.add_argument("--ie-backtracks", type=int, default=None)
    args = parser.parse_args()
    settings = {**SETTINGS, "ie": {**SETTINGS["ie"], **(
        {} if args.ie_backtracks is None else {"backtracks": args.ie_backtracks})}}
    rows = []
    for n in args.joints:
        sim, goal = arm(n, seed=n, feasibility=args.feasibility)
        for name in args.strategies:
            t0 = time.perf_counter()
            res = run_trials(name, sim, goal, args.seeds, tolerance=args.tolerance,
                             **settings[name])
            total = time.perf_counter() - t0
            ok = sum(r.success for r in res)
            tries = [t for r in res  # IE/IET per point, FTE per run
                     for t in r.info.get("point_tries", [r.info.get("tries", 1)])]
            rows.append({
                "joints": n, "strategy": name, "successes": ok, "seeds": args.seeds,
                "worst_error_mm": 1e3 * max(r.max_point_error for r in res),
                "failed": [(s, round(1e3 * r.max_point_error, 1))
                           for s, r in enumerate(res) if not r.success],
                "mean_tries": float(np.mean(tries)) if tries else "",
                "backtracks": sum(r.info.get("backtracks_used", 0) for r in res),
                "batch_run_s": res[0].wall_time_s, "compile_s": res[0].compile_time_s,
                "total_s": total,
            })
            if args.feasibility:
                rows[-1]["checked"] = checked(sim, res)
            print(rows[-1], flush=True)
        # the polish: its cost and what it gives
        if "ie" in args.strategies and not args.no_polish:
            res = run_trials("ie", sim, goal, args.seeds, tolerance=args.tolerance,
                             refine="adam", **settings["ie"])
            rows.append({
                "joints": n, "strategy": "ie+adam", "successes":
                sum(r.success for r in res), "seeds": args.seeds,
                "worst_error_mm": 1e3 * max(r.max_point_error for r in res),
                "batch_run_s": res[0].wall_time_s, "compile_s": res[0].compile_time_s,
            })
            print(rows[-1], flush=True)
    print_table(rows, ["joints", "strategy", "successes", "seeds", "worst_error_mm",
                       "mean_tries", "backtracks", "batch_run_s", "compile_s",
                       *(["checked"] if args.feasibility else []), "failed"])
    for r in rows:
        if r["strategy"] in ("ie", "iet", "fte"):
            need = int(np.ceil(29 / 30 * r["seeds"]))
            report_target(f"{r['strategy']} on the {r['joints']}-joint arm succeeds on "
                          f">= {need} of {r['seeds']}", float(r["successes"]),
                          r["successes"] >= need)
    write_json("bench_arms", {"rows": rows, "tolerance": args.tolerance,
                              "feasibility": args.feasibility,
                              "ie_backtracks": args.ie_backtracks})


if __name__ == "__main__":
    main()
