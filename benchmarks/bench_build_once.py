"""A run builds its goal, simulator and pair culling once, and what the second run of
the same experiment in one process costs.

    python benchmarks/bench_build_once.py [NAME] [--repeats R]

Runs the built-in experiment NAME (default clean_ie; plots and renders off) R + 1
times in this process with `run_experiment`, and prints per run: the wall time,
the strategy's own compile and search time (the rest is the fixed cost: checks,
builds, replays, the motion check, writing), and how many times
`cgda_jax.sim.feasibility.relevant_pairs` (the pair culling, ~1.5-3 s) ran.
Works on any checkout (PYTHONPATH=/path/to/checkout to measure another one).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import _common  # noqa: E402,F401  (the benchmarks' JAX settings)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("name", nargs="?", default="clean_ie")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()

    import cgda_jax
    from cgda_jax.builtin import resolve_config
    from cgda_jax.experiment import load_config, run_experiment
    from cgda_jax.sim import feasibility

    calls = {"n": 0, "s": 0.0}
    culling = feasibility.relevant_pairs

    def counted(*a, **k):
        t0 = time.perf_counter()
        try:
            return culling(*a, **k)
        finally:
            calls["n"] += 1
            calls["s"] += time.perf_counter() - t0

    feasibility.relevant_pairs = counted
    print(f"# {cgda_jax.__file__}")
    print("| run | wall (s) | compile (s) | search (s) | fixed cost (s) | "
          "pair cullings | culling (s) |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeats + 1):
            cfg = load_config(resolve_config(args.name),
                              ["output.plots=false", "output.render=false"])
            calls.update(n=0, s=0.0)
            t0 = time.perf_counter()
            res = run_experiment(cfg, pathlib.Path(tmp) / f"r{k}")
            wall = time.perf_counter() - t0
            comp, search = res["compile_time_s"], res["wall_time_s"]
            print(f"| {k + 1} | {wall:.2f} | {comp:.2f} | {search:.2f} | "
                  f"{wall - comp - search:.2f} | {calls['n']} | {calls['s']:.2f} |",
                  flush=True)


if __name__ == "__main__":
    main()
