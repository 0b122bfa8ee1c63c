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
  ``samples + 1`` (11) postures a move;
- the same posture's check and a whole move's (`Feasibility.move`, over a batch
  of random moves) with both geometries of `Feasibility`: ``exact`` (the geoms,
  ``Collider.distances(exact=False)``: box pairs by separating axes and feature
  searches) and ``round`` (the default: capsules that hold the moving geoms,
  closed-form pairs), per posture and per pair, against the floor of a plain
  vectorized capsule-capsule (clamped segment-segment) distance over a batch of
  `FLOOR_PAIRS` random pairs in the same process (``floor_ns``).

With ``--search`` it times instead the feasible search itself (the experiment's
strategy as `cgda run` builds it, seed 0) with each geometry, built and compiled
apart and then run alternately in one process (median of ``--repeats``): the run
time before (``exact``) and after (``round``), and each result's error.

    python benchmarks/bench_check_budget.py [--only clean_ie ...] [--repeats 3]
    python benchmarks/bench_check_budget.py --search --only clean_ie paint_iet

With ``--generation`` it times one generation of the experiment's search,
unconstrained and feasible (seed 0's generations stepped again one at a time
from their kept states, compiled, median of ``--repeats``), and their ratio:

    python benchmarks/bench_check_budget.py --generation --only clean_ie
"""

from __future__ import annotations

import argparse
import copy
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
#: Moves of the whole-move timing (each ``samples + 1`` postures).
MOVES = 1024
#: Random capsule pairs of the capsule-capsule floor.
FLOOR_PAIRS = 65536


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


def capsule_floor_ns(repeats: int) -> float:
    """Nanoseconds a pair of a plain vmapped capsule-capsule distance (clamped
    segment-segment minus the radii) over `FLOOR_PAIRS` random pairs."""
    from cgda_jax.sim.primitive_distances import segment_segment

    x = jnp.asarray(np.random.default_rng(1).normal(size=(FLOOR_PAIRS, 4, 3)),
                    jnp.float32)
    r = jnp.full((FLOOR_PAIRS, 2), 0.05, jnp.float32)
    f = jax.jit(jax.vmap(lambda s, r: segment_segment(s[0], s[1], s[2], s[3])
                         - r[0] - r[1]))
    return 1e9 * median_time(lambda: f(x, r), repeats=max(5, repeats)) / FLOOR_PAIRS


def check_parts(name: str, repeats: int) -> dict:
    _, _, sim = _build(name, [])
    feas = sim.feasibility
    col = feas.check
    lo, hi = np.asarray(sim.lower), np.asarray(sim.upper)
    rng = np.random.default_rng(0)
    q = jnp.asarray(rng.uniform(lo, hi, (POSTURES, sim.n_dof)), jnp.float32)
    frames = jax.jit(jax.vmap(col.geom_frames))
    t_frames = median_time(lambda: frames(q), repeats=max(5, repeats))
    out = {"pairs": col.n_pairs, "samples": feas.samples + 1,
           "frames_us": 1e6 * t_frames / POSTURES}
    q0 = jnp.asarray(rng.uniform(lo, hi, (MOVES, sim.n_dof)), jnp.float32)
    dq = jnp.asarray(rng.uniform(lo, hi, (MOVES, sim.n_dof)), jnp.float32) - q0
    dur = jnp.full((MOVES,), float(sim.move_s), jnp.float32)
    exact = copy.copy(feas)  # the same check on the geoms themselves
    exact.check, exact.geometry = feas.collider, "exact"
    for label, f in (("exact", exact), ("round", feas)):
        dist = jax.jit(jax.vmap(lambda g, c=f.check: c.distances(g, exact=False)))
        move = jax.jit(jax.vmap(lambda a, b, t, f=f: f.move(a, b, t)))
        t_dist = median_time(lambda: dist(q), repeats=max(5, repeats))
        t_move = median_time(lambda: move(q0, dq, dur), repeats=max(5, repeats))
        out[f"{label}_posture_us"] = 1e6 * t_dist / POSTURES
        out[f"{label}_pair_ns"] = 1e9 * t_dist / POSTURES / col.n_pairs
        out[f"{label}_move_us"] = 1e6 * t_move / MOVES
    out["posture_us"] = out["round_posture_us"]
    out["floor_ns"] = capsule_floor_ns(repeats)
    out["speedup"] = out["exact_move_us"] / out["round_move_us"]
    return out


def search_times(name: str, repeats: int) -> dict:
    """Median search time (s) of the experiment with each check geometry, run
    alternately in one process, and each run's largest point error."""
    built = {g: _build(name, [f"feasibility.geometry={g}"]) for g in ("exact", "round")}
    runs: dict[str, list] = {g: [] for g in built}
    for g, (cfg, goal, sim) in built.items():
        _run(cfg, sim, goal)  # compile
    for _ in range(repeats):
        for g, (cfg, goal, sim) in built.items():
            runs[g].append(_run(cfg, sim, goal))
    out = {"experiment": name}
    for g, rs in runs.items():
        out[f"{g}_search_s"] = float(np.median([r.wall_time_s for r in rs]))
        out[f"{g}_error"] = float(rs[-1].max_point_error)
        out[f"{g}_success"] = bool(rs[-1].success)
    out["speedup"] = out["exact_search_s"] / out["round_search_s"]
    return out


def generation_times(name: str, repeats: int) -> dict:
    """Milliseconds a generation, unconstrained and feasible: seed 0's run
    stepped one generation at a time (the plan's ``step``, compiled), its
    states kept, then every step taken again from them (median of
    ``repeats``); the same generations each repeat, compile apart."""
    from cgda_jax.strategies import strategy_of
    from cgda_jax.strategies.runner import seed_keys

    out = {"experiment": name}
    for label, feasible in (("off", "false"), ("on", "true")):
        cfg, goal, sim = _build(name, [f"strategy.feasibility={feasible}"])
        s = cfg.strategy
        entry = strategy_of(s.name)
        plan = entry.plan(sim, goal, entry.settings.of(
            None, algorithm=s.algorithm, population_size=s.population_size,
            tolerance=s.tolerance, max_generations=s.max_generations,
            chunk_size=s.chunk_size, **s.options))
        step, done = jax.jit(lambda c, p=plan: p.step(c)[0]), jax.jit(plan.done)
        carries = [jax.jit(plan.init)(seed_keys([s.seed])[0])]
        while not bool(done(carries[-1])) and len(carries) <= s.max_generations:
            carries.append(step(carries[-1]))
        carries = carries[:-1]

        def replay(carries=carries, step=step):
            for c in carries:
                y = step(c)
            return y

        t = median_time(replay, repeats=max(5, repeats))
        out[f"{label}_generations"] = len(carries)
        out[f"{label}_ms_per_generation"] = 1e3 * t / len(carries)
    out["ratio"] = out["on_ms_per_generation"] / out["off_ms_per_generation"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--search", action="store_true",
                    help="time the feasible search with each geometry instead")
    ap.add_argument("--generation", action="store_true",
                    help="time one generation, unconstrained and feasible, instead")
    args = ap.parse_args()
    os.environ.setdefault("CGDA_XGNITIVE_DIR", "../shared/data/xgnitive")
    if args.generation:
        rows = [generation_times(n, args.repeats) for n in args.only or EXPERIMENTS]
        print_table(rows, list(rows[0]))
        write_json("bench_check_budget_generation", {"rows": rows})
        return
    if args.search:
        rows = [search_times(n, args.repeats) for n in args.only or EXPERIMENTS]
        print_table(rows, list(rows[0]))
        write_json("bench_check_budget_search", {"rows": rows})
        return
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
    print_table(rows, ["experiment", "pairs", "exact_posture_us", "round_posture_us",
                       "exact_pair_ns", "round_pair_ns", "floor_ns", "exact_move_us",
                       "round_move_us", "speedup"])
    write_json("bench_check_budget", {"rows": rows})


if __name__ == "__main__":
    main()
