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

``--demo`` times ``cgda demo`` instead (the main job: 3 recognition tables, clean IE,
paint IET, with figures and videos), each repeat with a new empty cache and then
again with it filled. Targets (issue 14, 2-core CPU): empty cache < 20 s, filled
cache < 8 s, whole process.

    python benchmarks/bench_coldstart.py [--config experiments/clean_ie.toml]
        [--repeats 1] [--no-plots] [--target-empty SECONDS]
    python benchmarks/bench_coldstart.py --demo [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import sys
import tempfile

from _common import print_table, report_target, timed_process, write_json

TARGET_CACHED_S = 5.0
#: ``cgda demo``, whole process: (empty cache, filled cache), issue 14.
DEMO_TARGETS_S = (20.0, 8.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--config", default="experiments/clean_ie.toml")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--no-plots", action="store_true")
    parser.add_argument("--target-empty", type=float, default=None,
                        help="also report 'empty cache < SECONDS' (whole process)")
    parser.add_argument("--demo", action="store_true",
                        help="time `cgda demo` (empty and filled cache) instead")
    args = parser.parse_args()

    cgda = [sys.executable, "-c", "from cgda_jax.cli import main; main()"]
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="cgda_coldstart_"))
    if args.demo:
        return demo(cgda, tmp, args.repeats)
    extra = ["--set", "output.plots=false"] if args.no_plots else []
    env = {**os.environ, "JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "cpu")}

    def run_cmd(tag: str) -> list[str]:
        out = tmp / f"out_{tag}"
        return [*cgda, "run", args.config, "--out", str(out), "--quiet", *extra]

    rows = []
    t = statistics.median(
        timed_process([sys.executable, "-c", "import cgda_jax"], env)
        for _ in range(max(args.repeats, 3))
    )
    rows.append({"run": "import cgda_jax", "seconds": t})
    times = []
    for r in range(args.repeats):
        times.append(timed_process(run_cmd(f"nocache{r}") + ["--no-cache"], env))
    rows.append({"run": "cgda run --no-cache", "seconds": statistics.median(times)})
    first, second = [], []
    for r in range(args.repeats):
        cache_env = {**env, "CGDA_JAX_CACHE": str(tmp / f"cache{r}")}
        first.append(timed_process(run_cmd(f"first{r}"), cache_env))
        second.append(timed_process(run_cmd(f"second{r}"), cache_env))
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


def demo(cgda: list[str], tmp: pathlib.Path, repeats: int) -> None:
    """``cgda demo`` in fresh processes: a new empty cache, then the same filled."""
    env = {**os.environ, "JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "cpu")}
    empty, filled, loads = [], [], []
    for r in range(repeats):
        cache_env = {**env, "CGDA_JAX_CACHE": str(tmp / f"demo_cache{r}")}
        for times in (empty, filled):
            loads.append(os.getloadavg()[0])
            times.append(timed_process([*cgda, "demo", "--quiet", "--overwrite", "--out",
                                str(tmp / "demo")], cache_env))
        print(f"repeat {r + 1}/{repeats}: empty {empty[-1]:.1f} s, filled "
              f"{filled[-1]:.1f} s", flush=True)
    rows = [{"run": "cgda demo, empty cache", "seconds": statistics.median(empty),
             "runs": [round(t, 2) for t in empty]},
            {"run": "cgda demo, cache filled", "seconds": statistics.median(filled),
             "runs": [round(t, 2) for t in filled]}]
    print(f"load avg (1 min) at the starts: {[round(x, 1) for x in loads]}")
    print_table(rows, ["run", "seconds", "runs"])
    for row, target in zip(rows, DEMO_TARGETS_S):
        report_target(f"{row['run']} < {target:g} s (s)", row["seconds"],
                      row["seconds"] < target)
    write_json("bench_coldstart_demo", {"rows": rows, "targets_s": DEMO_TARGETS_S,
                                        "load_avg_1min": loads})


if __name__ == "__main__":
    main()
