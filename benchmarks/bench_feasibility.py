"""Feasible execution (issue 21): success that a robot could perform, and its cost.

For each execution experiment, R seeds (default 10, in one ``run_trials`` call) run
twice: with ``strategy.feasibility`` on (the default) and off (the paper's
unconstrained execution).  Every reported trajectory is then checked independently
with `cgda_jax.sim.motion_check.motion_report` (collisions at 4 x the postures, the
commanded speeds and accelerations, in dynamic mode a MuJoCo C replay at timestep / 4:
measured speeds, actuator forces, contacts).  A trial counts as a **feasible success**
when the strategy reports success and the independent check finds no problem: no
penetration over 5 mm, peak joint speed <= the limit (3 rad/s on TEO), effort <= its
limit (30 N m), no joint change over 90 degrees between consecutive waypoints.

Targets (issue 21): paint IET kinematic and dynamic >= 9 / 10 feasible successes;
iron and clean 10 / 10; a feasible run's run time within 2 x the unconstrained one and
its compile time within 1.5 x.

``--export`` also replays each trial's joints on the 4 x finer simulator
(``replay_ok``, `cgda_jax.experiment.compute.replay_check`), exports them as a
controller's trajectory (100 Hz, the run's minimum-jerk ramp), writes and reads it
back as JSON and replays it on MuJoCo C 4 x finer, as ``cgda run`` does
(`cgda_jax.experiment.compute.export_check`): issue 22's target is the replay within
the run's tolerance on 10 of 10 seeds of every execution experiment. ``--on-only``
skips the unconstrained runs.

``--judge`` measures what judging only the candidates whose rank matters saves
(issue 39; ``strategy.judge``, `cgda_jax.strategies.fitness.judge_best`): for each
experiment (default clean_ie and paint_iet) the single runs of seeds 0-3 (``--seeds``)
with ``judge = "all"`` (every candidate's move judged) and ``"ranked"`` back to back
in one process, each compiled before it is timed (its first run not counted): run
time (the result's, compile apart), success, the independent motion check on every
success, the ratio all / ranked; then ``--trials`` seeds in one ``run_trials`` call
against one seed's single run (``judge = "ranked"``, the pooled-trials target: within
3x of one seed).

    python benchmarks/bench_feasibility.py [--trials 10] [--only paint_iet ...]
        [--export] [--on-only]
    python benchmarks/bench_feasibility.py --judge [--seeds 0 1 2 3] [--trials 10]
        [--only clean_ie paint_iet]

``--ratios`` measures issue 39's targets for a single run, both sides in one
process: for each experiment (default clean_ie, paint_iet, iron_ie_xgnitive,
clean_fte) the unconstrained run (``strategy.feasibility = false``) and the feasible
one (the defaults: round geometry, ``judge = "ranked"``) of seed 0, each compiled by
its first run (``compile_time_s``, the unconstrained side first), then
``--repeats`` runs of each alternately (median run time): the feasible run within
3x of the unconstrained, its compile within 1.5x.  With ``--trials R`` (> 1) it
adds the pooled row for clean_ie: R seeds in one ``run_trials`` call (its second
call timed) against one seed's single run (within 3x) and against the sum of the
R seeds' single runs.

    python benchmarks/bench_feasibility.py --ratios [--repeats 5] [--trials 10]
        [--only clean_ie ...]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from _common import print_table, write_json

from cgda_jax.builtin import resolve_config
from cgda_jax.experiment import load_config
from cgda_jax.experiment.build import build_goal, build_simulator, default_waypoint_s
from cgda_jax.sim.motion_check import motion_report
from cgda_jax.strategies import run_trials

EXPERIMENTS = ["clean_ie", "clean_fte", "paint_iet", "clean_ie_dynamic",
               "paint_iet_dynamic", "move_push_box", "rotate_valve", "iron_ie_xgnitive"]
TARGETS = {"paint_iet": 9, "paint_iet_dynamic": 9, "iron_ie_xgnitive": 10,
           "clean_ie": 10, "clean_ie_dynamic": 10, "clean_fte": 10}


def run(name: str, trials: int, feasible: bool, export: bool = False) -> dict:
    cfg = load_config(resolve_config(name),
                      [f"strategy.feasibility={'true' if feasible else 'false'}"])
    goal, demos, _ = build_goal(cfg)
    sim = build_simulator(cfg, default_waypoint_s(demos, len(goal)), goal)
    s = cfg.strategy
    t0 = time.perf_counter()
    results = run_trials(s.name, sim, goal, trials, seed=s.seed, algorithm=s.algorithm,
                         population_size=s.population_size, tolerance=s.tolerance,
                         max_generations=s.max_generations, chunk_size=s.chunk_size,
                         **s.options)
    whole = time.perf_counter() - t0
    checks = [motion_report(sim, np.asarray(r.joints))
              if np.all(np.isfinite(r.joints)) else None for r in results]
    ok = [bool(r.success) for r in results]
    clean = [c is not None and c["feasible"] for c in checks]
    pen = [c["collisions"]["penetration_m"] if c and c["collisions"] else 0.0
           for c in checks if c]
    speed = [max([*c["peak_speed"].values(), *c.get("measured_speed", {}).values()])
             for c in checks if c]
    effort = [max([v for v in c.get("peak_effort", {}).values() if v is not None]
                  or [0.0]) for c in checks if c]
    jumps = [c["moves_over_max_step"] for c in checks if c]
    exported = {}
    if export:
        from cgda_jax.experiment.compute import export_check, replay_check

        ex = [export_check(sim, r) for r in results]
        exported = {
            # the run's own joints on the 4x finer simulator (cgda run's replay row)
            "replay_ok": sum(bool(replay_check(sim, r)["success"]) for r in results
                             if np.all(np.isfinite(r.joints))),
            "export_ok": sum(bool(e["success"]) for e in ex),
            "export_ok_of_successes": sum(bool(e["success"]) for e, a in zip(ex, ok)
                                          if a),
            # a trial without postures to export has no error: NaN, not skipped
            "export_worst_error": float(np.max([e.get("max_point_error", np.nan)
                                                for e in ex])),
            "export_feature_diff": max(e.get("max_feature_difference", 0.0)
                                       for e in ex),
        }
    return {**exported,
        "experiment": name, "feasibility": feasible, "trials": trials,
        "success": sum(ok), "feasible_success": sum(a and b for a, b in zip(ok, clean)),
        "max_penetration_mm": 1e3 * max(pen or [0.0]),
        "max_speed": max(speed or [0.0]), "max_effort": max(effort or [0.0]),
        "moves_over_90": sum(jumps),
        "run_s": float(results[0].wall_time_s),
        "compile_s": float(results[0].compile_time_s), "whole_s": whole,
        "problems": sorted({p.split(":")[0] if "mm into" not in p else p
                            for c in checks if c for p in c["problems"]})[:6],
    }


def _feasible_setup(name: str, feasible: bool = True):
    """Experiment ``name`` with feasibility on (or off): its strategy config,
    simulator, goal and the strategy's keyword settings (as ``cgda run`` passes
    them)."""
    cfg = load_config(resolve_config(name),
                      [f"strategy.feasibility={str(feasible).lower()}"])
    goal, demos, _ = build_goal(cfg)
    sim = build_simulator(cfg, default_waypoint_s(demos, len(goal)), goal)
    s = cfg.strategy
    kw = dict(algorithm=s.algorithm, population_size=s.population_size,
              tolerance=s.tolerance, max_generations=s.max_generations,
              chunk_size=s.chunk_size, **s.options)
    return s, sim, goal, kw


def judge_costs(name: str, seeds: list[int], trials: int) -> list[dict]:
    """The ``--judge`` rows of experiment ``name`` (see the module docstring)."""
    from cgda_jax.strategies import run as run_strategy

    s, sim, goal, kw = _feasible_setup(name)

    def once(judge, seed):
        return run_strategy(s.name, sim, goal, seeds=(seed,), batching="single",
                            judge=judge, **kw)[0]

    rows = []
    for judge in ("all", "ranked"):  # compiled before anything is timed
        once(judge, seeds[0])
    for seed in seeds:
        for judge in ("all", "ranked"):
            r = once(judge, seed)
            check = motion_report(sim, np.asarray(r.joints)) if r.success else None
            rows.append({"experiment": name, "judge": judge, "seed": seed,
                         "success": bool(r.success),
                         "checked": None if check is None else bool(check["feasible"]),
                         "run_s": float(r.wall_time_s),
                         "generations": int(r.generations),
                         "max_point_error": float(np.max(r.point_errors))})
            print(rows[-1], flush=True)
    if trials > 1:  # pooled trials vs one seed, compiled first
        for n in (trials, trials):  # the second call is the timed one
            t0 = time.perf_counter()
            res = run_trials(s.name, sim, goal, n, seed=seeds[0], judge="ranked", **kw)
            whole = time.perf_counter() - t0
        # the same seeds' single runs, summed: the work the batch shares
        done = {r["seed"]: r["run_s"] for r in rows if r["judge"] == "ranked"}
        singles = sum(done[k] if k in done else float(once("ranked", k).wall_time_s)
                      for k in range(seeds[0], seeds[0] + trials))
        rows.append({"experiment": name, "judge": "ranked", "seed": f"{trials} trials",
                     "success": sum(bool(r.success) for r in res),
                     "run_s": float(res[0].wall_time_s), "whole_s": whole,
                     "sum_of_singles_s": singles,
                     "batching": res[0].info.get("batching"),
                     "batch_sizes": res[0].info.get("batch_sizes")})
        print(rows[-1], flush=True)
    return rows


def evaluation_cost(name: str, repeats: int = 15) -> dict:
    """One generation's evaluation, judging all vs ranked, timed alone: for each
    point of a feasible run's result (seed 0, ``judge = "all"``), from where the
    earlier points leave the arm, a population around its posture (CMA-ES's
    32, std 0.05 in normalized genes); both compiled first, then timed in turn
    (``repeats``, median). Independent of the search path."""
    import jax
    import jax.numpy as jnp

    from cgda_jax.strategies import STRATEGIES, run as run_strategy
    from cgda_jax.strategies.evolution import from_joints

    s, sim, goal, kw = _feasible_setup(name)
    res = run_strategy(s.name, sim, goal, seeds=(0,), batching="single", judge="all",
                       **kw)[0]
    plan_cls, settings_cls = STRATEGIES[s.name].plan, STRATEGIES[s.name].settings
    plans = {j: plan_cls(sim, jnp.asarray(goal), settings_cls(**{**kw, "judge": j}))
             for j in ("all", "ranked")}
    joints = jnp.asarray(np.nan_to_num(res.joints), jnp.float32)
    states = jax.lax.scan(lambda st, w: (sim.step(st, w)[0], st), sim.init_state(),
                          joints)[1]
    u = from_joints(joints, sim.lower, sim.upper)
    key = jax.random.key(1)
    pops = u[:, None] + 0.05 * jax.random.normal(key, (len(u), int(s.population_size),
                                                       u.shape[1]))
    goal = jnp.asarray(goal, jnp.float32)

    def fit(plan):
        def all_points(states, pops):
            return jax.vmap(lambda st, pop, g: plan.point_fitness(st, g)(pop))(
                states, pops, goal)
        return jax.jit(all_points)

    fns = {j: fit(p) for j, p in plans.items()}
    out = {j: jax.block_until_ready(f(states, pops)) for j, f in fns.items()}
    times = {j: [] for j in fns}
    for _ in range(repeats):
        for j, f in fns.items():
            t0 = time.perf_counter()
            jax.block_until_ready(f(states, pops))
            times[j].append(time.perf_counter() - t0)
    med = {j: float(np.median(v)) for j, v in times.items()}
    best = np.sort(np.asarray(out["all"]), axis=1)[:, :16]
    same = np.allclose(best, np.sort(np.asarray(out["ranked"]), axis=1)[:, :16],
                       rtol=1e-5)
    return {"experiment": name, "points": len(u), "population": int(s.population_size),
            "all_ms": 1e3 * med["all"], "ranked_ms": 1e3 * med["ranked"],
            "ratio": med["all"] / max(med["ranked"], 1e-12),
            "best_half_same": bool(same)}


RATIO_EXPERIMENTS = ["clean_ie", "paint_iet", "iron_ie_xgnitive", "clean_fte"]


def ratios(names: list[str], repeats: int, trials: int) -> list[dict]:
    """``--ratios``: feasible against unconstrained, seed 0 (module docstring)."""
    from cgda_jax.strategies import run as run_strategy

    rows = []
    for name in names:
        sides = {}
        for feasible in (False, True):
            sides[feasible] = _feasible_setup(name, feasible)

        def once(feasible, seed=0):
            s, sim, goal, kw = sides[feasible]
            return run_strategy(s.name, sim, goal, seeds=(seed,), batching="single",
                                **kw)[0]

        first = {f: once(f) for f in (False, True)}  # compiles
        runs = {False: [], True: []}
        for _ in range(repeats):
            for f in (False, True):
                runs[f].append(once(f))
        row = {"experiment": name}
        for f, label in ((False, "off"), (True, "on")):
            r = runs[f][-1]
            row[f"{label}_run_s"] = float(np.median([x.wall_time_s for x in runs[f]]))
            row[f"{label}_compile_s"] = float(first[f].compile_time_s)
            row[f"{label}_generations"] = int(r.generations)
            row[f"{label}_success"] = bool(r.success)
        s, sim, goal, kw = sides[True]
        r = runs[True][-1]
        row["on_checked"] = (bool(motion_report(sim, np.asarray(r.joints))["feasible"])
                             if r.success else None)
        row["run_ratio"] = row["on_run_s"] / max(row["off_run_s"], 1e-9)
        row["ms_per_generation_ratio"] = (
            (row["on_run_s"] / max(row["on_generations"], 1))
            / max(row["off_run_s"] / max(row["off_generations"], 1), 1e-12))
        row["compile_ratio"] = row["on_compile_s"] / max(row["off_compile_s"], 1e-9)
        if trials > 1 and name == "clean_ie":
            for _ in range(2):  # the second call is the timed one
                res = run_trials(s.name, sim, goal, trials, seed=0, **kw)
            row["trials"] = trials
            row["trials_run_s"] = float(res[0].wall_time_s)
            row["trials_success"] = sum(bool(x.success) for x in res)
            row["trials_over_one_seed"] = row["trials_run_s"] / max(row["on_run_s"],
                                                                    1e-9)
            # the same seeds run one by one: the work the batch shares
            row["sum_of_singles_s"] = float(sum(once(True, k).wall_time_s
                                                for k in range(trials)))
            row["trials_over_sum_of_singles"] = row["trials_run_s"] / max(
                row["sum_of_singles_s"], 1e-9)
        print(row, flush=True)
        rows.append(row)
    return rows


def judge_main(names: list[str], seeds: list[int], trials: int) -> None:
    """``--judge``: the rows of every experiment, then the ratios."""
    cost = [evaluation_cost(name) for name in names]
    print_table(cost, list(cost[0]))
    rows = [row for name in names for row in judge_costs(name, seeds, trials)]
    summary = []
    for name in names:
        per = {j: [r for r in rows if r["experiment"] == name and r["judge"] == j
                   and isinstance(r["seed"], int)] for j in ("all", "ranked")}
        t = {j: float(np.sum([r["run_s"] for r in per[j]])) for j in per}
        gens = {j: max(1, int(np.sum([r["generations"] for r in per[j]]))) for j in per}
        single = [r["run_s"] for r in per["ranked"] if r["seed"] == seeds[0]]
        pooled = [r for r in rows if r["experiment"] == name
                  and not isinstance(r["seed"], int)]
        summary.append({
            "experiment": name, "seeds": len(seeds),
            "all_run_s": t["all"], "ranked_run_s": t["ranked"],
            "ratio": t["all"] / max(t["ranked"], 1e-9),
            # the search paths differ (see judge_best): the cost of a generation
            "ms_per_generation_all": 1e3 * t["all"] / gens["all"],
            "ms_per_generation_ranked": 1e3 * t["ranked"] / gens["ranked"],
            "generation_ratio": (t["all"] / gens["all"]) / max(t["ranked"] / gens["ranked"],
                                                               1e-12),
            "success_all": sum(r["success"] for r in per["all"]),
            "success_ranked": sum(r["success"] for r in per["ranked"]),
            "checked_ranked": sum(bool(r["checked"]) for r in per["ranked"]),
            "trials_run_s": pooled[0]["run_s"] if pooled else None,
            "trials_over_one_seed": (pooled[0]["run_s"] / max(single[0], 1e-9)
                                     if pooled and single else None),
            "trials_over_sum_of_singles": (
                pooled[0]["run_s"] / max(pooled[0]["sum_of_singles_s"], 1e-9)
                if pooled else None)})
    print_table(summary, list(summary[0]))
    print_table(cost, list(cost[0]))
    write_json("feasibility_judge", {"evaluation": cost, "rows": rows,
                                     "summary": summary})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--export", action="store_true",
                    help="replay each trial's exported trajectory on MuJoCo C")
    ap.add_argument("--on-only", action="store_true",
                    help="only the feasible runs (no unconstrained baseline)")
    ap.add_argument("--judge", action="store_true",
                    help="judge='all' vs 'ranked' back to back (see the docstring)")
    ap.add_argument("--seeds", type=int, nargs="*", default=[0, 1, 2, 3])
    ap.add_argument("--cost-only", action="store_true",
                    help="with --judge: only the evaluation cost (no runs)")
    ap.add_argument("--ratios", action="store_true",
                    help="feasible vs unconstrained run and compile, seed 0, one "
                         "process (see the docstring)")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    if args.ratios:
        os.environ.setdefault("CGDA_XGNITIVE_DIR", "../shared/data/xgnitive")
        rows = ratios(args.only or RATIO_EXPERIMENTS, args.repeats, args.trials)
        print_table(rows, list(dict.fromkeys(k for r in rows for k in r)))
        write_json("feasibility_ratios", {"rows": rows})
        return
    if args.judge:
        names = args.only or ["clean_ie", "paint_iet"]
        if args.cost_only:
            cost = [evaluation_cost(name) for name in names]
            print_table(cost, list(cost[0]))
            return
        judge_main(names, args.seeds, args.trials)
        return
    names = args.only or EXPERIMENTS
    if "iron_ie_xgnitive" in names and not os.environ.get("CGDA_XGNITIVE_DIR"):
        print("iron_ie_xgnitive skipped: set CGDA_XGNITIVE_DIR to the xgnitive data")
        names = [n for n in names if n != "iron_ie_xgnitive"]
    rows = []
    for name in names:
        for feasible in (True,) if args.on_only else (False, True):
            row = run(name, args.trials, feasible, args.export)
            print({k: row[k] for k in ("experiment", "feasibility", "success",
                                       "feasible_success", "run_s", "compile_s",
                                       "replay_ok", "export_ok") if k in row},
                  flush=True)
            rows.append(row)
    for row in rows:
        base = next((r for r in rows if r["experiment"] == row["experiment"]
                     and not r["feasibility"]), None)
        if row["feasibility"] and base is not None:
            row["run_ratio"] = row["run_s"] / max(base["run_s"], 1e-9)
            row["compile_ratio"] = row["compile_s"] / max(base["compile_s"], 1e-9)
        if row["feasibility"]:
            target = TARGETS.get(row["experiment"])
            row["target"] = "-" if target is None else (
                f">= {target}: {'met' if row['feasible_success'] >= target else 'MISSED'}")
    print_table(rows, ["experiment", "feasibility", "success", "feasible_success",
                       "max_penetration_mm", "max_speed", "max_effort", "moves_over_90",
                       "run_s", "compile_s", "run_ratio", "compile_ratio", "target"]
                + (["replay_ok", "export_ok", "export_ok_of_successes",
                    "export_worst_error", "export_feature_diff"] if args.export else []))
    for row in rows:
        if row["problems"]:
            print(f"{row['experiment']} feasibility={row['feasibility']}: "
                  f"{row['problems']}")
    write_json("feasibility", {"rows": rows})


if __name__ == "__main__":
    main()
