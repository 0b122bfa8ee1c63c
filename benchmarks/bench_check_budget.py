"""How much collision checking issue 21's run-time target leaves room for.

Issue 21 asks a feasible run to take at most 2x the unconstrained run on the same
experiment.  This measures, per experiment (as `cgda run` builds it):

- the unconstrained run (``strategy.feasibility = false``, the experiment's own
  strategy settings, compiled first, median of ``--repeats``) and the candidates
  it evaluates, lock-step included (the compiled loop's whole chunks of
  generations x population, x points for IE: every point's population is
  evaluated each generation), so its cost per evaluated candidate;
- the feasibility check's parts on the same experiment's `Feasibility` (its kept
  collision pairs), over a batch of random postures within the joint limits:
  the collision geoms' forward kinematics per posture, and the pairs' signed
  distances per posture (``exact=False``, as the check uses them);
- from these, how many postures a move could be checked at if the whole extra
  time a 2x run allows went to the check (``budget`` = one unconstrained
  evaluation's cost / one posture's check): the check looks at
  ``samples + 1`` (11) postures a move.

    python benchmarks/bench_check_budget.py [--only clean_ie ...] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os

import jax
import jax.numpy as jnp
import numpy as np
from _common import median_time, print_table, write_json

from cgda_jax.builtin import resolve_config
from cgda_jax.experiment import load_config
from cgda_jax.experiment.build import build_goal, build_simulator, default_waypoint_s
from cgda_jax.experiment.compute import strategy_function

EXPERIMENTS = ["clean_ie", "iron_ie_xgnitive", "paint_iet"]
POSTURES = 4096


def _build(name: str, overrides: list[str]):
    cfg = load_config(resolve_config(name), overrides)
    goal, demos, _ = build_goal(cfg)
    return cfg, goal, build_simulator(cfg, default_waypoint_s(demos, len(goal)), goal)


def _run(cfg, sim, goal):
    s = cfg.strategy
    return strategy_function(s.name)(
        sim, goal, algorithm=s.algorithm, population_size=s.population_size,
        tolerance=s.tolerance, max_generations=s.max_generations, seed=s.seed,
        chunk_size=s.chunk_size, **s.options)


def unconstrained(name: str, repeats: int) -> dict:
    cfg, goal, sim = _build(name, ["strategy.feasibility=false"])
    runs = [_run(cfg, sim, goal) for _ in range(repeats + 1)][1:]
    res = runs[-1]
    run_s = float(np.median([r.wall_time_s for r in runs]))
    gens = int(res.generations)
    pop, chunk = int(cfg.strategy.population_size), int(cfg.strategy.chunk_size)
    # the compiled loop runs whole chunks; each generation IE evaluates every
    # point's population (done ones masked), IET one point's
    steps = -(-gens // chunk) * chunk
    evaluated = steps * pop * (len(goal) if cfg.strategy.name == "ie" else 1)
    return {"run_s": run_s, "generations": gens, "evaluated": evaluated,
            "per_eval_us": 1e6 * run_s / evaluated}


def check_parts(name: str, repeats: int) -> dict:
    _, _, sim = _build(name, [])
    feas = sim.feasibility
    col = feas.collider
    lo, hi = np.asarray(sim.lower), np.asarray(sim.upper)
    q = jnp.asarray(np.random.default_rng(0).uniform(lo, hi, (POSTURES, sim.n_dof)),
                    jnp.float32)
    frames = jax.jit(jax.vmap(col.geom_frames))
    dist = jax.jit(jax.vmap(lambda g: col.distances(g, exact=False)))
    t_frames = median_time(lambda: frames(q), repeats=max(5, repeats))
    t_dist = median_time(lambda: dist(q), repeats=max(5, repeats))
    return {"pairs": col.n_pairs, "samples": feas.samples + 1,
            "frames_us": 1e6 * t_frames / POSTURES,
            "posture_us": 1e6 * t_dist / POSTURES}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    os.environ.setdefault("CGDA_XGNITIVE_DIR", "../shared/data/xgnitive")
    rows = []
    for name in args.only or EXPERIMENTS:
        u, c = unconstrained(name, args.repeats), check_parts(name, args.repeats)
        rows.append({
            "experiment": name, **u, **c,
            "move_check_us": c["posture_us"] * c["samples"],
            "budget_postures": u["per_eval_us"] / c["posture_us"],
        })
        print_table(rows[-1:], list(rows[-1]))
    print_table(rows, ["experiment", "run_s", "evaluated", "per_eval_us", "pairs",
                       "frames_us", "posture_us", "move_check_us", "budget_postures"])
    write_json("bench_check_budget", {"rows": rows})


if __name__ == "__main__":
    main()
