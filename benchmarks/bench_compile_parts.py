"""Where the compile time of a clean-IE cold start goes (issue 14, target < 2 s).

Traces, lowers and compiles the programs `cgda_jax.strategies.runner.compile_plan`
builds for an IE experiment (default experiments/clean_ie.toml; one trial), each
timed apart, with JAX's persistent compilation cache off and its in-memory caches
cleared before every repeat; then, to split the generation chunk into its parts, the same chunk with
``restarts=0`` (no restart branch traced) and evosax's CMA-ES evolution step alone
(`cgda_jax.strategies.evolution.evolution_step` vmapped over the 9 points with a
trivial fitness, no kinematics). Reports the median of ``--repeats`` for each, and
the number of XLA fusions (roughly, kernels LLVM compiles) in each program.

    python benchmarks/bench_compile_parts.py [--repeats 3] [--experiment clean_ie]
        [--set strategy.feasibility=false]

``--runs NAME ...`` (issue 39): each built-in experiment run once in this process
(`run_experiment`, plots and renders off) with ``strategy.feasibility`` off then
on, every program it compiles taken one at a time (`compile_ahead` off), each
program's trace-and-lower and XLA compile seconds, StableHLO lines and XLA fusions:
where a feasible run's extra compile goes.  ``--culling NAME ...``: the pair
culling's start distances (`relevant_pairs`) compiled optimized and with
`cgda_jax.programs.RUN_ONCE_OPTIONS`, alternately ``--repeats`` times, with
whether their signs (the overlapping pairs) agree.
"""

from __future__ import annotations

import argparse
import re
import statistics
import time

import jax
import jax.numpy as jnp
from _common import print_table, write_json

from cgda_jax.builtin import resolve_config
from cgda_jax.experiment import load_config
from cgda_jax.experiment.build import build_goal, build_simulator, default_waypoint_s
from cgda_jax.strategies.base import check_config, make_algorithm
from cgda_jax.strategies.evolution import evolution_init, evolution_step
from cgda_jax.strategies.ie import RESTARTS, STAGNATION, IEPlan
from cgda_jax.strategies.runner import over_trials_fn, seed_keys


def timed_compile(fn, *args) -> dict:
    """Lower then compile ``jax.jit(fn)`` for ``args`` (caches cleared first)."""
    jax.clear_caches()
    t0 = time.perf_counter()
    lowered = jax.jit(fn).lower(*args)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    t2 = time.perf_counter()
    fusions = len(re.findall(r"= \S+ fusion\(", compiled.as_text()))
    return {"lower_s": t1 - t0, "compile_s": t2 - t1, "fusions": fusions}


def programs(sim, goal, s) -> dict:
    """name -> (function, argument) of every program timed."""
    kw = dict(algorithm=s.algorithm, population_size=s.population_size,
              tolerance=s.tolerance, max_generations=s.max_generations,
              restarts=RESTARTS, stagnation=STAGNATION)  # run_ie's defaults
    kw.update(s.options)
    keys = seed_keys([s.seed])
    one = over_trials_fn(1, None)  # a single trial, as compile_plan applies the plan
    out = {}
    for label, extra in (("", {}), (", restarts=0", {"restarts": 0})):
        plan = IEPlan(sim, goal, **{**kw, **extra})
        carry = jax.eval_shape(one(plan.init), keys)

        def chunk(c, plan=plan):
            return jax.lax.scan(lambda c, _: one(plan.step)(c), c, None,
                                length=s.chunk_size)

        if not extra:
            out["IE init (4,096 sampled restart postures)"] = (one(plan.init), keys)
        out[f"IE generation chunk{label}"] = (chunk, carry)
        if not extra:
            out["IE finish (execution of the result)"] = (one(plan.finish), carry)

    algo, params = make_algorithm(s.algorithm, s.population_size, int(sim.n_dof))
    n = goal.shape[0]

    def fitness(pop):
        return jnp.sum(pop**2, axis=-1)

    def stop(evo):
        return evo.best_fitness < s.tolerance

    evo = jax.eval_shape(jax.vmap(lambda k: evolution_init(
        algo, params, k, fitness, int(sim.n_dof))), jax.random.split(jax.random.key(0), n))

    def cma_chunk(e):
        return jax.lax.scan(lambda c, _: jax.vmap(
            lambda x: evolution_step(algo, params, x, fitness, stop))(c), e, None,
            length=s.chunk_size)

    out[f"{s.algorithm} step alone ({n} points, trivial fitness)"] = (cma_chunk, evo)
    return out


def run_programs(names: list[str]) -> list[dict]:
    """``--runs``: every program of a run, compiled one at a time (module doc)."""
    import os
    import pathlib
    import tempfile

    import cgda_jax.experiment.run as run_mod
    import cgda_jax.programs as programs_mod
    import cgda_jax.strategies.runner as runner_mod

    def one_at_a_time(*_, **__):  # compile_ahead off: each program timed alone
        return None

    programs_mod.compile_ahead = runner_mod.compile_ahead = one_at_a_time
    found, now = programs_mod._find_or_compile, {}
    xla = programs_mod._xla_compile
    rows: list[dict] = []

    def timed_find(key, fn, args, jit_kw, *rest):
        t0 = time.perf_counter()
        now.clear()
        out = found(key, fn, args, jit_kw, *rest)
        total = time.perf_counter() - t0
        rows.append({**now["row"], "program": getattr(fn, "__qualname__", "?")[-44:],
                     "trace_s": total - now.get("xla_s", 0.0)}
                    if "row" in now else {**ROW, "program": getattr(
                        fn, "__qualname__", "?")[-44:], "trace_s": total})
        return out

    def timed_xla(lowered):
        t0 = time.perf_counter()
        out = xla(lowered)
        now["xla_s"] = time.perf_counter() - t0
        now["row"] = {**ROW, "xla_s": now["xla_s"],
                      "lines": lowered.as_text().count("\n"),
                      "fusions": len(re.findall(r"= \S+ fusion\(", out[0].as_text()))}
        return out

    programs_mod._find_or_compile, programs_mod._xla_compile = timed_find, timed_xla
    out = []
    for name in names:
        for feasible in ("false", "true"):
            rows.clear()
            cfg = load_config(resolve_config(name), [
                "output.plots=false", "output.render=false",
                f"strategy.feasibility={feasible}"])
            with tempfile.TemporaryDirectory() as tmp:
                load = os.getloadavg()[0]
                res = run_mod.run_experiment(cfg, pathlib.Path(tmp) / "r")
            for r in rows:
                r.update(experiment=name, feasibility=feasible == "true",
                         load=round(load, 1))
            print(f"{name}, feasibility {feasible}: compile_time_s "
                  f"{res['compile_time_s']:.2f}, search {res['wall_time_s']:.3f} s")
            print_table(rows, ["program", "trace_s", "xla_s", "lines", "fusions"])
            out += rows
    return out


#: A `run_programs` row's defaults (a program found compiled: nothing compiled).
ROW = {"xla_s": 0.0, "lines": 0, "fusions": 0}


def culling(names: list[str], repeats: int) -> list[dict]:
    """``--culling``: the start distances' compile, optimized or not (module doc)."""
    import numpy as np

    import cgda_jax.sim.feasibility as feas
    from cgda_jax.programs import RUN_ONCE_OPTIONS

    seen, cull = [], feas.relevant_pairs

    def capture(collider, robot, obstacles=()):
        seen.append((collider, robot))
        return cull(collider, robot, obstacles)

    feas.relevant_pairs = capture
    rows = []
    for name in names:
        seen.clear()
        cfg = load_config(resolve_config(name), [])
        goal, demos, _ = build_goal(cfg)
        build_simulator(cfg, default_waypoint_s(demos, len(goal)), goal)
        collider, robot = seen[0]
        x = jnp.asarray(robot.start_genes)
        times: dict[str, list[float]] = {"optimized": [], "RUN_ONCE_OPTIONS": []}
        signs = {}
        for _ in range(repeats):
            for label, opts in (("optimized", {}),
                                ("RUN_ONCE_OPTIONS", {"compiler_options": RUN_ONCE_OPTIONS})):
                jax.clear_caches()
                t0 = time.perf_counter()
                compiled = jax.jit(collider.distances, **opts).lower(x).compile()
                times[label].append(time.perf_counter() - t0)
                signs[label] = np.asarray(compiled(x)) < 0
        same = bool(np.array_equal(signs["optimized"], signs["RUN_ONCE_OPTIONS"]))
        for label, ts in times.items():
            rows.append({"experiment": name, "pairs": collider.n_pairs,
                         "program": label, "compile_s": statistics.median(ts),
                         "same signs": same})
    print_table(rows, ["experiment", "pairs", "program", "compile_s", "same signs"])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a config value, as cgda run --set")
    parser.add_argument("--experiment", default="clean_ie",
                        help="a built-in IE experiment (default clean_ie)")
    parser.add_argument("--runs", nargs="+", metavar="NAME",
                        help="programs of whole runs, feasibility off and on")
    parser.add_argument("--culling", nargs="+", metavar="NAME",
                        help="the culling's start distances, optimized or not")
    args = parser.parse_args()
    jax.config.update("jax_enable_compilation_cache", False)
    if args.runs or args.culling:
        rows = (run_programs(args.runs) if args.runs
                else culling(args.culling, args.repeats))
        write_json("bench_compile_parts", {"runs": args.runs, "culling": args.culling,
                                           "rows": rows})
        return
    cfg = load_config(resolve_config(args.experiment), args.set)
    if cfg.strategy.name != "ie":
        parser.error(f"{args.experiment} runs {cfg.strategy.name}, not IE")
    goal, demos, _ = build_goal(cfg)
    sim = build_simulator(cfg, default_waypoint_s(demos, len(goal)), goal)
    s = cfg.strategy
    goal = check_config(sim, goal, tolerance=s.tolerance,
                        max_generations=s.max_generations)
    rows = []
    for name, (fn, arg) in programs(sim, goal, s).items():
        runs = [timed_compile(fn, arg) for _ in range(args.repeats)]
        rows.append({
            "program": name,
            "lower_s": statistics.median(r["lower_s"] for r in runs),
            "compile_s": statistics.median(r["compile_s"] for r in runs),
            "fusions": runs[-1]["fusions"],
        })
    print_table(rows, ["program", "lower_s", "compile_s", "fusions"])
    write_json("bench_compile_parts", {"experiment": args.experiment,
                                       "overrides": args.set,
                                       "repeats": args.repeats, "rows": rows})


if __name__ == "__main__":
    main()
