"""The two object experiments (issue 10) over 10 seeds: success, errors, replay, time.

For each of experiments/move_push_box.toml and experiments/rotate_valve.toml the goal
and simulator are built exactly as ``cgda run`` builds them (`experiment.build`), then
seeds 0..9 run one after another (default; each run is what ``cgda run --set
strategy.seed=S`` computes, without plots and render) or as ONE batched `run_trials`
call (``--batched``: every trial runs until the slowest one stops).  Every result is
replayed with MuJoCo C at timestep / 4 (`experiment.compute.replay_check`, the check each
``cgda run`` of a dynamic experiment reports).  Target (issue 10): each experiment
succeeds on at least 8 of 10 seeds.  ``--only iiwa14_move_push_box`` runs the push on
the built-in KUKA iiwa 14 (issue 24) instead.

    python benchmarks/bench_objects.py [--seeds 10] [--only rotate_valve] [--batched]
"""

from __future__ import annotations

import argparse
import pathlib
import time

import numpy as np
from _common import print_table, report_target, write_json

from cgda_jax import experiment as ex, run_trials
from cgda_jax.experiment.build import default_waypoint_s
from cgda_jax.experiment.compute import replay_check
from cgda_jax.experiment.rules import strategy_function

REPO = pathlib.Path(__file__).resolve().parents[1]
EXPERIMENTS = ("move_push_box", "rotate_valve")
#: Run with ``--only`` (not by default).
OTHERS = ("iiwa14_move_push_box",)
#: Units of the reported errors: metres -> mm, radians -> degrees.
SCALE = {"move_push_box": (1000.0, "mm"), "rotate_valve": (np.degrees(1.0), "deg"),
         "iiwa14_move_push_box": (1000.0, "mm")}


def _row(name: str, res, replay: dict, seconds: float) -> dict:
    k, unit = SCALE[name]
    return {
        "experiment": name, "seed": res.info["seed"], "success": res.success,
        f"max_err_{unit}": k * res.max_point_error, "generations": res.generations,
        "evaluations": res.evaluations, "run_s": seconds,
        "replay_success": replay["success"],
        f"replay_max_err_{unit}": k * replay["max_point_error"],
        f"replay_diff_{unit}": k * replay["max_feature_difference"],
    }


def run(name: str, n_seeds: int, batched: bool) -> tuple[list[dict], dict]:
    cfg = ex.load_config(REPO / "experiments" / f"{name}.toml")
    ex.validate_config(cfg)
    goal, demos, _ = ex.build_goal(cfg)
    sim = ex.build_simulator(cfg, default_waypoint_s(demos, len(goal)), goal)
    s = cfg.strategy
    common = {"algorithm": s.algorithm, "population_size": s.population_size,
              "tolerance": s.tolerance, "max_generations": s.max_generations,
              "chunk_size": s.chunk_size, **s.options}
    t0 = time.perf_counter()
    rows = []
    if batched:
        results = run_trials(s.name, sim, goal, n_seeds, seed=0, **common)
        for res in results:
            rows.append(_row(name, res, replay_check(sim, res), res.wall_time_s))
        compile_s = results[0].compile_time_s
    else:
        compile_s = 0.0
        for seed in range(n_seeds):
            t1 = time.perf_counter()
            res = strategy_function(s.name)(sim, goal, seed=seed, **common)
            seconds = time.perf_counter() - t1
            compile_s += res.compile_time_s
            rows.append(_row(name, res, replay_check(sim, res), seconds))
            r = rows[-1]
            print(f"  seed {seed}: success {r['success']}, replay "
                  f"{r['replay_success']}, {seconds:.1f} s", flush=True)
    summary = {
        "experiment": name, "seeds": n_seeds, "points": len(goal),
        "successes": sum(r["success"] for r in rows),
        "replay_successes": sum(r["replay_success"] for r in rows),
        "total_s": time.perf_counter() - t0, "compile_s": compile_s,
        "mode": "batched" if batched else "sequential",
        "physics": sim.backend.name, "timestep": sim.physics.timestep,
        "waypoint_s": sim.waypoint_s,
    }
    return rows, summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--only", choices=EXPERIMENTS + OTHERS, default=None)
    parser.add_argument("--batched", action="store_true",
                        help="all seeds in one run_trials call")
    args = parser.parse_args()
    names = [args.only] if args.only else list(EXPERIMENTS)
    all_rows, summaries = [], []
    for name in names:
        print(f"{name}: {args.seeds} seeds ...", flush=True)
        rows, summary = run(name, args.seeds, args.batched)
        all_rows.append(rows)
        summaries.append(summary)
    for rows in all_rows:
        print()
        print_table(rows, list(rows[0]))
    print()
    print_table(summaries, ["experiment", "seeds", "points", "successes",
                            "replay_successes", "total_s", "compile_s", "mode",
                            "physics", "timestep", "waypoint_s"])
    for s in summaries:
        need = int(np.ceil(0.8 * s["seeds"]))
        report_target(f"{s['experiment']} succeeds on >= {need} of {s['seeds']} seeds",
                      float(s["successes"]), s["successes"] >= need)
    write_json("bench_objects", {"rows": [r for rows in all_rows for r in rows],
                                 "summaries": summaries})


if __name__ == "__main__":
    main()
