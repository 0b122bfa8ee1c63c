"""Every feasible success passes the independent check, on 10 seeds (issue 39).

For each built-in kinematic experiment (clean_ie, paint_iet, clean_fte,
iron_ie_xgnitive; the last needs the xgnitive data, found as
`benchmarks/same_results.py` finds it) seeds 0-9 run in one batched call as ``cgda run
CONFIG --trials 10`` makes it (`same_results.batched`; ``--single``: one run per seed
as ``cgda run`` calls the strategy, `same_results.single`), feasibility on (the
configs' default).  Every success is then checked independently, as ``cgda run``'s
report does:

- `cgda_jax.sim.motion_check.motion_report`: the reported joints' moves at 4 x the
  postures on the full model (collisions, the commanded speeds and accelerations,
  moves over the step cap): ``motion_ok`` when it finds no problem;
- `cgda_jax.experiment.compute.replay_check`: the joints re-executed on the finer
  simulator (16 x the sub-steps): ``replay_ok`` when every point stays within the
  tolerance, and the largest difference of its features from the run's.

A success counts as **checked** when both pass.  Target: checked = successes on every
experiment.  Run it below normal priority on a shared machine:

    nice -n 10 python benchmarks/bench_seeds_check.py [--seeds 0 1 ... 9]
        [--only clean_ie paint_iet clean_fte iron_ie_xgnitive] [--single]

``--only`` takes any kinematic experiment of ``experiments/`` by name (e.g.
``paint_iet_xgnitive iiwa14_clean_ie panda_clean_ie``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import print_table, report_target, write_json
from same_results import EXPERIMENTS, batched, build, single

from cgda_jax.experiment.compute import replay_check
from cgda_jax.sim.motion_check import motion_report


def check(name: str, seeds: list[int], one_by_one: bool) -> dict:
    """The experiment's runs over ``seeds`` and the independent check of each
    success (see the module doc)."""
    cfg, goal, sim = build(name, [])
    t0 = time.perf_counter()
    if one_by_one:
        results = [single(cfg, goal, sim, s) for s in seeds]
    else:
        results = batched(cfg, goal, sim, seeds)
    run_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    motion, replay, failed = [], [], []
    for seed, r in zip(seeds, results):
        if not r.success:
            failed.append((seed, round(float(r.max_point_error), 4)))
            continue
        m = motion_report(sim, np.asarray(r.joints))
        p = replay_check(sim, r)
        motion.append((seed, m))
        replay.append((seed, p))
    check_s = time.perf_counter() - t0
    ok = [bool(m["feasible"] and p["success"])
          for (_, m), (_, p) in zip(motion, replay)]
    pen = [m["collisions"]["penetration_m"] for _, m in motion if m.get("collisions")]
    return {
        "experiment": name, "seeds": len(seeds),
        "successes": sum(bool(r.success) for r in results),
        "motion_ok": sum(bool(m["feasible"]) for _, m in motion),
        "replay_ok": sum(bool(p["success"]) for _, p in replay),
        "checked": sum(ok),
        "worst_replay_difference": max((p["max_feature_difference"]
                                        for _, p in replay), default=float("nan")),
        "worst_replay_error": max((p["max_point_error"] for _, p in replay),
                                  default=float("nan")),
        "tolerance": float(cfg.strategy.tolerance),
        "deepest_mm": 1e3 * max(pen, default=0.0),
        "not_checked": [s for (s, _), o in zip(motion, ok) if not o],
        "problems": sorted({q for _, m in motion for q in m["problems"]})[:4],
        "failed_runs": failed,
        "run_s": run_s, "check_s": check_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, nargs="*", default=list(range(10)))
    parser.add_argument("--only", nargs="*", default=list(EXPERIMENTS))
    parser.add_argument("--single", action="store_true",
                        help="one run per seed instead of one batched call")
    args = parser.parse_args()
    rows = []
    for name in args.only:
        print(f"{name} ...", flush=True)
        rows.append(check(name, args.seeds, args.single))
        print(rows[-1], flush=True)
    print_table(rows, ["experiment", "seeds", "successes", "motion_ok", "replay_ok",
                       "checked", "worst_replay_difference", "worst_replay_error",
                       "tolerance", "deepest_mm", "run_s", "check_s"])
    for r in rows:
        report_target(f"{r['experiment']}: every success passes the independent check",
                      float(r["checked"]), r["checked"] == r["successes"])
    write_json("bench_seeds_check", {"rows": rows, "seeds": args.seeds,
                                     "single": args.single})


if __name__ == "__main__":
    main()
