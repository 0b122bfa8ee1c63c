"""What IE's restarts and its gradient polish cost, on the clean TEO task.

experiments/clean_ie.toml (TEO's right arm, 3 DoF, kinematic, 20 mm, population 32)
run with IE's restarts off (``restarts=0``, no stagnation stop) and at their defaults
(`cgda_jax.strategies.ie.RESTARTS` restarts, stagnation `STAGNATION`, restart means
from `RESTART_SAMPLES` sampled postures), and with ``refine`` "none", "adam" and
"lbfgs". Each setting runs `--repeats` times (the first compiles); the table gives the
median run time (compile apart), the compile time, the evaluations and the worst
point error.

    python benchmarks/bench_restarts.py [--repeats 3] [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import pathlib
import statistics

import numpy as np
from _common import print_table, write_json

from cgda_jax import experiment as ex
from cgda_jax.strategies import run_ie

REPO = pathlib.Path(__file__).resolve().parents[1]
SETTINGS = {
    "restarts 0": {"restarts": 0, "stagnation": None},
    "restarts default": {},
    "default + adam": {"refine": "adam"},
    "default + lbfgs": {"refine": "lbfgs"},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2])
    args = parser.parse_args()
    cfg = ex.load_config(REPO / "experiments" / "clean_ie.toml", [])
    goal, _, _ = ex.build_goal(cfg)
    sim = ex.build_simulator(cfg)
    s = cfg.strategy
    base = {"algorithm": s.algorithm, "population_size": s.population_size,
            "tolerance": s.tolerance, "max_generations": s.max_generations}
    rows = []
    for label, extra in SETTINGS.items():
        for seed in args.seeds:
            runs = [run_ie(sim, np.asarray(goal, np.float32), seed=seed, **base,
                           **extra) for _ in range(args.repeats)]
            r = runs[-1]
            rows.append({
                "setting": label, "seed": seed, "success": bool(r.success),
                "worst_error_mm": 1e3 * float(r.max_point_error),
                "evaluations": int(r.evaluations),
                "max_tries": max(r.info["point_tries"]),
                "run_s": statistics.median(x.wall_time_s for x in runs),
                "compile_s": runs[0].compile_time_s,
            })
            print(rows[-1], flush=True)
    print_table(rows, ["setting", "seed", "success", "worst_error_mm", "evaluations",
                       "max_tries", "run_s", "compile_s"])
    write_json("bench_restarts", {"rows": rows})


if __name__ == "__main__":
    main()
