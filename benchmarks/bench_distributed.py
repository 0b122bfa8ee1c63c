"""Trials over several processes: 1 vs 2 vs 4 processes on the same total trials.

The clean circle of experiments/clean_ie.toml (TEO's right arm, kinematic, IE, 32
candidates, 200 generations at most, 20 mm) run as ``--trials`` seeds 0..R-1 with
`cgda_jax.distributed.distributed_trials`, each process count started by
`cgda_jax.distributed.launch` (localhost coordinator, gloo collectives, one CPU
device per process). Per process count:

- end-to-end: launch to the last exit (process start, imports, set-up, compile,
  run, gather, shutdown);
- trials call: ``distributed_trials`` on process 0 (compile + run + gather);
- compile / run: the slowest process's ``compile_time_s`` / ``wall_time_s`` (its
  own batch, compile apart);
- throughput: trials per second of the trials call;
- same results: every seed's joints and point errors equal the 1-process run's
  (largest absolute difference printed).

Each process compiles its own program (no persistent cache), as a fresh job on a
cluster would; with ``--cache`` the processes share JAX's persistent compilation
cache (as ``cgda`` does) and an untimed job per process count fills it first, so
compile becomes loading. A process count is one job, so the figure is one run, not
a median (``--repeats`` runs each count again and reports the median).

    python benchmarks/bench_distributed.py [--trials 32] [--processes 1 2 4]
        [--repeats 1] [--cache] [--quick]

On a machine with fewer cores than processes the processes share them (say so when
reporting); the gain comes from cores (or devices) that one process leaves idle.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import pickle
import statistics
import sys
import tempfile
import time

REPO = pathlib.Path(__file__).resolve().parents[1]


def worker(trials: int, out: str, overrides: list[str]) -> None:
    from cgda_jax import distributed as dist

    dist.initialize(timeout_s=600)
    import numpy as np

    from cgda_jax import experiment as ex

    cfg = ex.load_config(REPO / "experiments" / "clean_ie.toml", overrides)
    goal, _, _ = ex.build_goal(cfg)
    sim = ex.build_simulator(cfg)
    s = cfg.strategy
    t0 = time.perf_counter()
    res = dist.distributed_trials(
        "ie", sim, np.asarray(goal, np.float32), trials, seed=0,
        algorithm=s.algorithm, population_size=s.population_size,
        tolerance=s.tolerance, max_generations=s.max_generations,
        chunk_size=s.chunk_size, **s.options)
    call = time.perf_counter() - t0
    if dist.is_writer():
        with open(out, "wb") as f:
            pickle.dump({"call_s": call, "results": res}, f)


def one_job(n: int, trials: int, overrides: list[str], tmp: pathlib.Path,
            cache: bool = False) -> dict:
    from cgda_jax.distributed import launch

    out = tmp / f"p{n}.pkl"
    argv = [sys.executable, __file__, "--worker", "--trials", str(trials),
            "--out", str(out)] + [a for o in overrides for a in ("--set", o)]
    t0 = time.perf_counter()
    env = {"JAX_PLATFORMS": "cpu"}
    if cache:  # JAX's persistent compilation cache, shared by the processes
        env |= {"JAX_COMPILATION_CACHE_DIR": str(tmp / "jax-cache"),
                "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
                "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0"}
    code = launch(n, argv, timeout_s=1800, env=env)
    end_to_end = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"{n} processes: the job failed with status {code}")
    data = pickle.loads(out.read_bytes())
    res = data["results"]
    by_proc: dict[int, dict] = {}
    for r in res:
        by_proc.setdefault(r.info["process"], r.info | {
            "compile": r.compile_time_s, "run": r.wall_time_s})
    return {
        "processes": n,
        "end_to_end_s": end_to_end,
        "trials_call_s": data["call_s"],
        "compile_s": max(p["compile"] for p in by_proc.values()),
        "compile_by_process": [round(by_proc[k]["compile"], 2) for k in sorted(by_proc)],
        "run_by_process": [round(by_proc[k]["run"], 2) for k in sorted(by_proc)],
        "run_s": max(p["run"] for p in by_proc.values()),
        "trials_per_s": trials / data["call_s"],
        "successes": sum(r.success for r in res),
        "results": res,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=32)
    parser.add_argument("--processes", type=int, nargs="*", default=[1, 2, 4])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--cache", action="store_true",
                        help="a persistent compilation cache: one untimed job per "
                        "process count fills it, the timed ones load their programs")
    parser.add_argument("--quick", action="store_true",
                        help="8 trials, 40 generations (a smoke test only)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.trials, args.out, args.overrides)
        return
    if args.quick:
        args.trials = 8
        args.overrides = ["strategy.max_generations=40"]

    import numpy as np
    from _common import machine, print_table, write_json

    rows, ref = [], None
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.processes:
            job = (n, args.trials, args.overrides, pathlib.Path(tmp), args.cache)
            if args.cache:
                one_job(*job)  # fills the cache for this process count
            runs = [one_job(*job) for _ in range(args.repeats)]
            row = {k: statistics.median(r[k] for r in runs) if isinstance(
                runs[0][k], float) else runs[0][k] for k in runs[0]}
            res = row.pop("results")
            if ref is None:
                ref = res
            row["max_abs_diff"] = max(
                float(np.max(np.abs(np.concatenate([a.joints.ravel() - b.joints.ravel(),
                                                    a.point_errors - b.point_errors]))))
                for a, b in zip(res, ref, strict=True))
            row["same_success"] = [a.success for a in res] == [b.success for b in ref]
            rows.append(row)
            print(f"{n} process(es): {row['trials_call_s']:.1f} s, "
                  f"{row['trials_per_s']:.2f} trials/s; compile by process "
                  f"{row['compile_by_process']} s, run {row['run_by_process']} s",
                  flush=True)
    load_after = os.getloadavg()
    m = machine()
    print(f"\n{args.trials} clean-IE trials (TEO kinematic), {m['cpu']}, "
          f"{m['cores']} cores, jax {m['jax']} ({m['jax_backend']}); load average "
          f"(1/5/15 min) before {load_before}, after {load_after}")
    if max(args.processes) > (m["cores"] or 1):
        print(f"note: {max(args.processes)} processes on {m['cores']} cores "
              "oversubscribe the CPU")
    print_table(rows, ["processes", "end_to_end_s", "trials_call_s", "compile_s",
                       "run_s", "trials_per_s", "successes", "max_abs_diff",
                       "same_success"])
    base = rows[0]["trials_call_s"]
    for r in rows[1:]:
        print(f"speed-up of the trials call, {r['processes']} vs "
              f"{rows[0]['processes']} process(es): {base / r['trials_call_s']:.2f}x")
    write_json("bench_distributed", {
        "trials": args.trials, "overrides": args.overrides, "cache": args.cache,
        "load_avg_before": load_before, "load_avg_after": load_after,
        "rows": rows,
    })


if __name__ == "__main__":
    main()
