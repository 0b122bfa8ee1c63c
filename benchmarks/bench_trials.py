"""Batched trials vs sequential runs: 30 clean-IE trials (experiments/clean_ie.toml).

Three batched drivers of `run_trials` (`cgda_jax.strategies.runner`) against R
sequential `run_ie` calls (seeds 0..R-1), all in this process:

- lockstep: one batch of R trials until the slowest stops (one compiled chunk);
- trials: finished trials leave the batch between chunks (re-packed, <= log2 R sizes);
- points (the default): all trials' IE points pooled, finished points leave;
  points_c5: the same re-packed every 5 generations (``chunk_size=5``: the same
  results, IE's outcome does not depend on the chunk size).

Run time = ``wall_time_s`` (compile apart: JAX's persistent compilation cache is on, as
in the CLI, so sequential calls after the first reuse the compiled program; compile
time is reported apart). The figure is the median over ``--repeats`` of each
variant's run time; sequential = the sum of the R runs' run times. The machine's
1-minute load is recorded with the figures (the ratios are measured in one process).

    python benchmarks/bench_trials.py [--trials 30] [--repeats 3] [--quick]

Target (2-core CPU): the default batched run >= 3x the run-time throughput of R
sequential runs.
"""

from __future__ import annotations

import argparse
import gc
import os
import pathlib
import statistics
import tempfile
import time

import jax
import numpy as np
from _common import print_table, report_target, write_json

from cgda_jax import experiment as ex

REPO = pathlib.Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true",
                        help="4 trials, 40 generations (a smoke test only)")
    parser.add_argument("--only", nargs="*",
                        default=["points", "points_c5", "trials", "lockstep",
                                 "sequential"])
    args = parser.parse_args()
    from cgda_jax.cli import enable_compilation_cache
    from cgda_jax.strategies import run_ie
    from cgda_jax.strategies import run_trials

    enable_compilation_cache(pathlib.Path(tempfile.mkdtemp(prefix="cgda_bench_")))
    overrides = ["strategy.max_generations=40"] if args.quick else []
    n = 4 if args.quick else args.trials
    cfg = ex.load_config(REPO / "experiments" / "clean_ie.toml", overrides)
    goal, _, _ = ex.build_goal(cfg)
    sim = ex.build_simulator(cfg)
    s = cfg.strategy
    kw = dict(algorithm=s.algorithm, population_size=s.population_size,
              tolerance=s.tolerance, max_generations=s.max_generations,
              chunk_size=s.chunk_size, **s.options)

    rows, loads = [], []
    runs: dict[str, list[float]] = {}
    compiles: dict[str, float] = {}
    extra: dict[str, dict] = {}
    for rep in range(args.repeats):
        for name in args.only:
            # each variant starts from the same process state: JAX's in-memory caches
            # hold every earlier call's programs, and a process that has run many
            # calls runs the next one up to 1.5x slower (measured: 0.24-0.30 s
            # after clear_caches against 0.39-0.46 s without, same call)
            jax.clear_caches()
            gc.collect()
            loads.append(os.getloadavg()[0])
            if name == "sequential":
                walls, comp, ok, gens = [], [], 0, []
                for seed in range(n):
                    r = run_ie(sim, goal, seed=seed, **kw)
                    walls.append(r.wall_time_s)
                    comp.append(r.compile_time_s)
                    ok += r.success
                    gens.append(r.generations)
                runs.setdefault(name, []).append(float(np.sum(walls)))
                compiles.setdefault(name, float(np.sum(comp)))
                extra[name] = {"successes": ok, "generations_sum": int(np.sum(gens))}
                print(f"  {name}: run {runs[name][-1]:.3f} s, {ok}/{n} succeed",
                      flush=True)  # as it ends: a time-boxed run keeps its figures
                continue
            t0 = time.perf_counter()
            mode = "auto" if name.startswith("points") else name
            chunk = {"chunk_size": 5} if name == "points_c5" else {}
            res = run_trials("ie", sim, goal, n, seed=0, batching=mode,
                             **{**kw, **chunk})
            total = time.perf_counter() - t0
            runs.setdefault(name, []).append(res[0].wall_time_s)
            compiles.setdefault(name, res[0].compile_time_s)  # the first (cold) one
            extra[name] = {
                "successes": sum(r.success for r in res),
                "generations_max": max(r.generations for r in res),
                "batch_sizes": res[0].info.get("batch_sizes"),
                "total_s_last": total,
            }
            print(f"  {name}: run {res[0].wall_time_s:.3f} s (compile "
                  f"{res[0].compile_time_s:.1f} s), {extra[name]['successes']}/{n} "
                  f"succeed", flush=True)
        print(f"repeat {rep + 1}/{args.repeats} done (load {loads[-1]:.1f})",
              flush=True)

    seq = statistics.median(runs["sequential"]) if "sequential" in runs else None
    for name, walls in runs.items():
        run_s = statistics.median(walls)
        rows.append({
            "variant": name, "run_s": run_s, "runs": [round(w, 3) for w in walls],
            "compile_s": compiles[name],
            "throughput_x": (seq / run_s) if seq else None,
            **{k: v for k, v in extra[name].items() if k != "batch_sizes"},
        })
    print(f"{n} clean-IE trials, load avg (1 min) during the runs: "
          f"min {min(loads):.1f} median {statistics.median(loads):.1f} "
          f"max {max(loads):.1f}")
    print_table(rows, ["variant", "run_s", "runs", "compile_s", "throughput_x",
                       "successes"])
    for name in ("points", "points_c5", "trials"):
        if name in extra:
            print(f"{name} batch sizes per chunk: {extra[name]['batch_sizes']}")
    best = next((r for r in rows if r["variant"] == "points"), None)
    c5 = next((r for r in rows if r["variant"] == "points_c5"), None)
    if c5 and seq:
        report_target(f"{n} batched trials, re-packed every 5 generations, >= 3x",
                      c5["throughput_x"], c5["throughput_x"] >= 3.0)
    if best and seq:
        report_target(f"{n} batched trials >= 3x the run-time throughput of {n} "
                      "sequential runs", best["throughput_x"],
                      best["throughput_x"] >= 3.0)
    write_json("bench_trials", {"quick": args.quick, "n_trials": n, "rows": rows,
                                "extra": extra, "load_avg_1min": loads})


if __name__ == "__main__":
    main()
