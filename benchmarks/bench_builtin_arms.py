"""Dynamic clean IE on the built-in 7-joint arms against TEO (issue 24 targets).

For experiments/panda_clean_ie_dynamic.toml (Franka Panda, motors through the
joint-space PD with gravity compensation), experiments/iiwa14_clean_ie_dynamic.toml
(KUKA iiwa 14, force-limited position servos) and TEO's own
experiments/clean_ie_dynamic.toml, the goal and simulator are built exactly as
``cgda run`` builds them and seeds 0..S-1 run as ONE batched `run_trials` call.
Every result is then checked as every run's report checks it: the replay at
timestep / 4 with MuJoCo C (`replay_check`) and the motion (`motion_check`: no
penetration, speeds, accelerations and efforts within the limits, tracking).

Targets (issue 24): on each arm at least 9 of 10 seeds succeed, every point within
20 mm, each run within 3x the generations of the same seed on TEO.  The arms' configs
start IE warm (``warm_start = true``: each point's first try a local search around
the start posture); TEO's is run as shipped (from the middle of its ranges) and,
with ``--teo-warm``, also warm ("teo_warm"), and each arm's generations are divided
by both.

    python benchmarks/bench_builtin_arms.py [--seeds 10] [--only panda iiwa14] [--teo-warm]
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import experiment_trials, print_table, report_target, write_json

from cgda_jax.experiment.compute import motion_check, replay_check

ARMS = {"teo": "clean_ie_dynamic", "teo_warm": "clean_ie_dynamic",
        "panda": "panda_clean_ie_dynamic", "iiwa14": "iiwa14_clean_ie_dynamic"}
OVERRIDES = {"teo_warm": ["strategy.options.warm_start=true"]}


def run(arm: str, n_seeds: int) -> tuple[list[dict], dict]:
    name = ARMS[arm]
    _, sim, _, results, total = experiment_trials(name, n_seeds,
                                                  OVERRIDES.get(arm, ()))
    rows = []
    for res in results:
        replay = replay_check(sim, res)
        checked = motion_check(sim, res)
        motion = checked[0] if checked else {"feasible": False, "problems": ["none"]}
        rows.append({
            "arm": arm, "seed": res.info["seed"], "success": bool(res.success),
            "max_point_error_mm": 1e3 * float(res.max_point_error),
            "generations": int(res.generations),
            "replay_success": replay["success"],
            "replay_max_diff": replay["max_feature_difference"],
            "motion_feasible": motion["feasible"],
            "problems": "; ".join(motion["problems"]),
            "tracking_note": motion.get("tracking_note") or "",
        })
    summary = {"arm": arm, "experiment": name, "seeds": n_seeds,
               "successes": sum(r["success"] for r in rows),
               "batch_wall_s": results[0].wall_time_s,
               "compile_s": results[0].compile_time_s, "total_s": total,
               "physics": sim.backend.name, "timestep": sim.physics.timestep,
               "waypoint_s": sim.waypoint_s}
    return rows, summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--only", nargs="*", choices=["panda", "iiwa14"],
                        default=["panda", "iiwa14"])
    parser.add_argument("--teo-warm", action="store_true",
                        help="also run TEO's config with warm_start = true")
    args = parser.parse_args()
    all_rows, summaries = [], []
    teos = ["teo", "teo_warm"] if args.teo_warm else ["teo"]
    for arm in [*teos, *args.only]:  # TEO first: the reference generations
        print(f"{ARMS[arm]}: {args.seeds} seeds in one batched call ...", flush=True)
        rows, summary = run(arm, args.seeds)
        all_rows += rows
        summaries.append(summary)
        # each arm's rows as soon as it ends (a long run stopped early keeps them)
        print_table(rows, ["arm", "seed", "success", "max_point_error_mm",
                           "generations", "replay_success", "motion_feasible"])
        print(summary, flush=True)
        write_json("bench_builtin_arms", {"rows": all_rows, "summaries": summaries,
                                          "complete": False})
    teo = {r["seed"]: r["generations"] for r in all_rows if r["arm"] == "teo"}
    warm = {r["seed"]: r["generations"] for r in all_rows if r["arm"] == "teo_warm"}
    for r in all_rows:
        r["x_teo_generations"] = r["generations"] / max(teo[r["seed"]], 1)
        if warm:
            r["x_teo_warm_generations"] = r["generations"] / max(warm[r["seed"]], 1)
    print_table(all_rows, ["arm", "seed", "success", "max_point_error_mm",
                           "generations", "x_teo_generations",
                           *(["x_teo_warm_generations"] if warm else []),
                           "replay_success",
                           "replay_max_diff", "motion_feasible", "problems"])
    print()
    print_table(summaries, ["arm", "seeds", "successes", "batch_wall_s", "compile_s",
                            "total_s", "physics", "timestep", "waypoint_s"])
    need = int(np.ceil(0.9 * args.seeds))
    for s in summaries[len(teos):]:
        rows = [r for r in all_rows if r["arm"] == s["arm"]]
        good = [r for r in rows if r["success"] and r["max_point_error_mm"] <= 20.0
                and r["x_teo_generations"] <= 3.0 and r["replay_success"]
                and r["motion_feasible"]]
        report_target(f"{s['arm']}: >= {need} of {args.seeds} seeds succeed within "
                      "20 mm, 3x TEO's generations, replayed and feasible",
                      float(len(good)), len(good) >= need)
        if warm:
            good = [r for r in good if r["x_teo_warm_generations"] <= 3.0]
            report_target(f"{s['arm']}: the same, also within 3x warm TEO's",
                          float(len(good)), len(good) >= need)
    write_json("bench_builtin_arms", {"rows": all_rows, "summaries": summaries})


if __name__ == "__main__":
    main()
