"""What a run costs besides its search (issue 39, "no fixed cost that the search does
not need"), in one command:

    python benchmarks/bench_fixed_costs.py [--name clean_ie] [--repeats 3]
        [--demo] [--small] [--skip-process]

1. In this process: `run_experiment` of the built-in ``--name`` (plots and renders
   off) ``repeats + 1`` times, each phase timed (the checks and builds with the
   pair culling, the strategy's compile and search, the replay, export and motion
   checks) with `cgda_jax.programs.cache_stats` (``traced``: programs traced and
   lowered; ``by key``: found by the run's key without tracing); the fixed cost of
   a run again is its wall time less its search (target: <= 1.5 s), median over
   runs 2.. .
2. Fresh processes (unless ``--skip-process``): ``cgda run NAME --quiet`` with a new
   empty persistent cache (``$CGDA_JAX_CACHE`` in a temporary folder), then again
   with it filled (the persistent cache and the program store in its
   ``programs/``); whether the second wrote no new entry (every program read from
   the cache); median of ``repeats`` (targets for clean_ie: <= 8 s empty, <= 4 s
   filled). ``python -c "import cgda_jax"`` apart.
3. ``--demo``: ``cgda demo`` the same way (``--small`` passes ``--small``; targets
   for the full demo: <= 20 s empty, <= 10 s filled).

Works on any checkout (``PYTHONPATH=/path/to/checkout`` measures another one, e.g.
``git archive main``).  Prints the load average at each start: the figures of a loaded machine are not
comparable with an idle one's; compare runs taken back to back.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

from _common import REPO, print_table, report_target, timed_process, write_json  # noqa: E402

#: Targets, whole process (s): (empty cache, filled cache).
RUN_TARGETS_S = {"clean_ie": (8.0, 4.0)}
DEMO_TARGETS_S = (20.0, 10.0)
#: A run again in one process: its wall time less its search (s).
AGAIN_TARGET_S = 1.5
#: What the in-process runs time (module, function): the phases of a run.
PHASES = (("cgda_jax.experiment.run", "check_and_build"),
          ("cgda_jax.sim.feasibility", "relevant_pairs"),
          ("cgda_jax.experiment.compute", "replay_check"),
          ("cgda_jax.experiment.compute", "export_check"),
          ("cgda_jax.experiment.compute", "motion_check"),
          ("cgda_jax.experiment.run", "write_run"))


def _timed_phases(spent: dict[str, float]) -> None:
    """Wrap the `PHASES` functions to add their seconds into ``spent``."""
    import importlib

    for mod_name, fn_name in PHASES:
        mod = importlib.import_module(mod_name)
        fn = getattr(mod, fn_name)

        def timed(*a, _fn=fn, _name=fn_name, **k):
            t0 = time.perf_counter()
            try:
                return _fn(*a, **k)
            finally:
                spent[_name] = spent.get(_name, 0.0) + time.perf_counter() - t0

        setattr(mod, fn_name, timed)


def in_process(name: str, repeats: int) -> list[dict]:
    from cgda_jax.builtin import resolve_config
    from cgda_jax.experiment import load_config

    try:  # a checkout before the program cache (PYTHONPATH=...) has none
        from cgda_jax.programs import cache_stats
    except ImportError:
        def cache_stats():
            return {"hits": 0, "misses": 0}

    spent: dict[str, float] = {}
    _timed_phases(spent)
    import cgda_jax.experiment.run as run_mod

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(repeats + 1):
            cfg = load_config(resolve_config(name),
                              ["output.plots=false", "output.render=false"])
            spent.clear()
            before = cache_stats()
            load = os.getloadavg()[0]
            t0 = time.perf_counter()
            res = run_mod.run_experiment(cfg, pathlib.Path(tmp) / f"r{k}")
            wall = time.perf_counter() - t0
            after = cache_stats()
            search = res["wall_time_s"]
            rows.append({
                "run": k + 1, "load": round(load, 1), "wall": wall,
                "compile": res["compile_time_s"], "search": search,
                "fixed": wall - search,
                "checks+build": spent.get("check_and_build", 0.0),
                "culling": spent.get("relevant_pairs", 0.0),
                "replay": spent.get("replay_check", 0.0),
                "export": spent.get("export_check", 0.0),
                "motion": spent.get("motion_check", 0.0),
                # by key, without tracing: "-" on a checkout before it
                **{col: after[k] - before[k] if k in after else "-" for col, k in (
                    ("hits", "hits"), ("misses", "misses"), ("traced", "traced"),
                    ("by key", "keyed_hits"))},
                "success": res["success"]})
            print(rows[-1], flush=True)
    return rows


def _entries(folder: pathlib.Path) -> int:
    return sum(1 for p in folder.rglob("*") if p.is_file()) if folder.exists() else 0


def processes(args_list: list[str], label: str, repeats: int,
              tmp: pathlib.Path) -> list[dict]:
    """``cgda ARGS`` in fresh processes: a new empty cache, then the same filled."""
    cgda = [sys.executable, "-c", "from cgda_jax.cli import main; main()"]
    env = {**os.environ, "JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "cpu")}
    empty, filled, loads, all_hit = [], [], [], []
    for r in range(repeats):
        cache = tmp / f"cache_{label}_{r}"
        cache_env = {**env, "CGDA_JAX_CACHE": str(cache)}
        for i, times in enumerate((empty, filled)):
            loads.append(round(os.getloadavg()[0], 1))
            n0 = _entries(cache)
            times.append(timed_process(
                [*cgda, *args_list, "--quiet", "--overwrite", "--out",
                 str(tmp / f"out_{label}")], cache_env))
            if i == 1:
                all_hit.append(_entries(cache) == n0)
        print(f"{label} {r + 1}/{repeats}: empty {empty[-1]:.1f} s, filled "
              f"{filled[-1]:.1f} s, no new cache entry: {all_hit[-1]}", flush=True)
    return [{"run": f"{label}, empty cache", "seconds": statistics.median(empty),
             "runs": [round(t, 2) for t in empty], "loads": loads[0::2]},
            {"run": f"{label}, cache filled", "seconds": statistics.median(filled),
             "runs": [round(t, 2) for t in filled], "loads": loads[1::2],
             "every program from the cache": all(all_hit)}]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--name", default="clean_ie")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--demo", action="store_true", help="also time `cgda demo`")
    ap.add_argument("--small", action="store_true", help="`cgda demo --small`")
    ap.add_argument("--skip-process", action="store_true",
                    help="only the in-process runs")
    args = ap.parse_args()

    out: dict = {"name": args.name}
    rows = in_process(args.name, args.repeats)
    print_table(rows, ["run", "load", "wall", "compile", "search", "fixed",
                       "checks+build", "culling", "replay", "export", "motion",
                       "hits", "misses", "traced", "by key"])
    again = statistics.median(r["fixed"] for r in rows[1:])
    report_target(f"run again in a process: wall less search <= {AGAIN_TARGET_S:g} s"
                  " (s)", again, again <= AGAIN_TARGET_S)
    out |= {"in_process": rows, "again_fixed_s": again}
    tmp = pathlib.Path(tempfile.mkdtemp(prefix="cgda_fixed_"))
    if not args.skip_process:
        env = {**os.environ, "JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "cpu")}
        imp = statistics.median(timed_process([sys.executable, "-c",
                                                "import cgda_jax"], env)
                                for _ in range(3))
        prows = processes(["run", args.name], f"cgda run {args.name}", args.repeats,
                          tmp)
        print(f"import cgda_jax: {imp:.2f} s")
        print_table(prows, ["run", "seconds", "runs", "loads"])
        for row, target in zip(prows, RUN_TARGETS_S.get(args.name, ())):
            report_target(f"{row['run']} <= {target:g} s (s)", row["seconds"],
                          row["seconds"] <= target)
        out |= {"import_s": imp, "process": prows}
    if args.demo:
        extra = ["--small"] if args.small else []
        drows = processes(["demo", *extra], "cgda demo" + " --small" * args.small,
                          args.repeats, tmp)
        print_table(drows, ["run", "seconds", "runs", "loads"])
        if not args.small:
            for row, target in zip(drows, DEMO_TARGETS_S):
                report_target(f"{row['run']} <= {target:g} s (s)", row["seconds"],
                              row["seconds"] <= target)
        out["demo"] = drows
    write_json("bench_fixed_costs", out)


if __name__ == "__main__":
    main()
