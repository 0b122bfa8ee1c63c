"""Whole-process time of ``cgda run experiments/clean_ie.toml``, cold and cached.

Runs the CLI in fresh processes with an empty persistent compilation cache
(``$CGDA_JAX_CACHE`` pointed at a new temporary folder):

1. ``--no-cache`` (every program compiled, nothing stored);
2. first run with the cache (compiles and fills it);
3. second run with the cache (loads the compiled programs).

Also times ``python -c "import cgda_jax"`` for the import share.
Targets (2-core CPU): the second run with the cache < 5 s, whole process
(clean_ie.toml); experiments/clean_ie_dynamic.toml with an empty cache < 60 s
(``--target-empty 60``).

    python benchmarks/bench_coldstart.py [--config experiments/clean_ie.toml]
        [--repeats 1] [--no-plots] [--target-empty SECONDS]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

from _common import print_table, report_target, write_json

REPO = pathlib.Path(__file__).resolve().parents[1]
TARGET_CACHED_S = 5.0


def timed(cmd: list[str], env: dict) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=REPO, capture_output=True, text=True)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stdout}\n{proc.stderr}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--config", default="experiments/clean_ie.toml")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--no-plots", action="store_true")
    parser.add_argument("--target-empty", type=float, default=None,
                        help="also report 'empty cache < SECONDS' (whole process)")
    args = parser.parse_args()

    cgda = [sys.executable, "-c", "from cgda_jax.cli import main; main()"]
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="cgda_coldstart_"))
    extra = ["--set", "output.plots=false"] if args.no_plots else []
    env = {**os.environ, "JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "cpu")}

    def run_cmd(tag: str) -> list[str]:
        out = tmp / f"out_{tag}"
        return [*cgda, "run", args.config, "--out", str(out), "--quiet", *extra]

    rows = []
    t = statistics.median(
        timed([sys.executable, "-c", "import cgda_jax"], env)
        for _ in range(max(args.repeats, 3))
    )
    rows.append({"run": "import cgda_jax", "seconds": t})
    times = []
    for r in range(args.repeats):
        times.append(timed(run_cmd(f"nocache{r}") + ["--no-cache"], env))
    rows.append({"run": "cgda run --no-cache", "seconds": statistics.median(times)})
    first, second = [], []
    for r in range(args.repeats):
        cache_env = {**env, "CGDA_JAX_CACHE": str(tmp / f"cache{r}")}
        first.append(timed(run_cmd(f"first{r}"), cache_env))
        second.append(timed(run_cmd(f"second{r}"), cache_env))
    rows.append({"run": "cgda run, empty cache", "seconds": statistics.median(first)})
    rows.append({"run": "cgda run, cache filled", "seconds": statistics.median(second)})
    print(f"config: {args.config}{' (no plots)' if args.no_plots else ''}")
    print_table(rows, ["run", "seconds"])
    cached = rows[-1]["seconds"]
    if args.config == "experiments/clean_ie.toml":
        report_target(
            f"second run with cache < {TARGET_CACHED_S:g} s (s)",
            cached,
            cached < TARGET_CACHED_S,
        )
    if args.target_empty is not None:
        empty = rows[-2]["seconds"]
        report_target(f"run with an empty cache < {args.target_empty:g} s (s)", empty,
                      empty < args.target_empty)
    write_json(
        "bench_coldstart" + ("_" + pathlib.Path(args.config).stem
                             if args.config != "experiments/clean_ie.toml" else ""),
        {
            "config": args.config,
            "plots": not args.no_plots,
            "rows": rows,
            "cached_s": cached,
            "target_s": TARGET_CACHED_S,
        },
    )


if __name__ == "__main__":
    main()
