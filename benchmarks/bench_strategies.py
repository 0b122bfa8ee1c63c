"""Execution strategies: cgda_jax vs pycma + MuJoCo C, on the paper's experiments.

For experiments/clean_ie.toml, clean_fte.toml and paint_iet.toml (TEO's right arm):

- ours: the strategy as ``cgda run`` calls it; cold = the first call in this process
  (trace + compile + run), steady = ``wall_time_s`` (run only, compile apart) as the
  median of ``--repeats`` calls;
- same search: ours again with the settings of the peer's search (`SAME_SEARCH`: the
  paper's strategies, without the restarts, stagnation stops, backtracks and sampled
  FTE start the defaults add); the speed ratio is the peer's time over this one's;
- peer: that search written with pycma's ask/tell and MuJoCo's C
  ``mj_kinematics``, one candidate at a time (benchmarks/peer_strategies.py: same
  gene space, start, step size, population size, fitness, stopping rule and success
  test; pycma's own termination criteria off); with the experiment's feasibility on
  (the default) the peer judges every move as ours does, with MuJoCo C
  (``mj_geomDistance`` on the same pairs and samples, the same limits, penalty,
  least-motion rule and, for IE, the same sequential evolution;
  benchmarks/peer_feasibility.py); the table's ``feasibility`` column says which;
- IET time per point: ours measured with one generation per chunk (a host sync per
  generation, so a little slower than the real run), the peer's per point;
  "flat" = mean of the last 3 points within 1.5x of the first 3;
- trials: ``run_trials("ie", ..., 30)`` in one batched call vs 30 sequential
  ``run_ie`` calls (seeds 0..29), with JAX's persistent compilation cache on (as the
  CLI does), so sequential calls after the first reuse the compiled program.

    python benchmarks/bench_strategies.py [--repeats 3] [--trials 30] [--quick]

``--quick`` lowers the generation budgets and trial count (a smoke test only).

``--to-success`` (paint IET, issue 39) compares time to success: ours as ``cgda run``
runs it (the experiment's restarts, backtracks and stagnation stop; steady =
``wall_time_s``, median of ``--repeats``) and the peer given the same restarts and
backtracks (`peer_strategies.pycma_iet` with `iet_search`), median of
``--peer-repeats`` runs, for each of ``--seeds``, both in this process; the ratio
counts only when both succeed (target >= 30x).

    python benchmarks/bench_strategies.py --to-success [--seeds 0] [--repeats 3]
        [--peer-repeats 3]
Targets (2-core CPU): clean IE >= 30x faster than the peer (steady state); cold
start incl. compile < 2 s (issue 14; it was 3 s); paint IET >= 10x faster than the
peer; 30 batched trials >= 3x the run-time throughput of 30 sequential runs (>= 10x on
a GPU).
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import tempfile
import time

import jax
import numpy as np
import peer_strategies
import peers
from _common import print_table, report_target, write_json

from cgda_jax import experiment as ex

REPO = pathlib.Path(__file__).resolve().parents[1]
TARGETS = {"ie": 30.0, "iet": 10.0, "fte": None}
#: Paint IET's time to success over the peer's with its restarts and backtracks
#: (issue 39).
TO_SUCCESS_TARGET = 30.0


def setup(name: str, overrides: list[str]):
    cfg = ex.load_config(REPO / "experiments" / f"{name}.toml", overrides)
    goal, _, _ = ex.build_goal(cfg)
    sim = ex.build_simulator(cfg)
    return cfg, np.asarray(goal, np.float32), sim


def strategy_kwargs(cfg) -> dict:
    s = cfg.strategy
    return dict(
        algorithm=s.algorithm,
        population_size=s.population_size,
        tolerance=s.tolerance,
        max_generations=s.max_generations,
        seed=s.seed,
        chunk_size=s.chunk_size,
        **s.options,
    )


#: Clean IE cold start in this process (trace + compile + run), issue 14.
COLD_TARGET_S = 2.0
#: Batched trials' run-time throughput over sequential runs (issue 14): on a CPU, on
#: a GPU.
TRIALS_TARGET_X = (3.0, 10.0)


#: Our strategies' settings for the comparison with the peer: the search the peer runs
#: (the paper's), without what the defaults add (restarts, stagnation stops of IE,
#: backtracks, FTE's sampled start).
SAME_SEARCH = {
    "ie": {"restarts": 0, "stagnation": None},
    "iet": {"restarts": 0, "backtracks": 0},
    "fte": {"restarts": 0, "min_improvement": 0.0, "init": "middle"},
}


#: The "as `cgda run`" columns when they are not run (``--ratio-only``).
EMPTY = dict.fromkeys(("cold_s", "compile_s", "steady_s", "evaluations", "success",
                       "max_point_error"), float("nan"))


def run_ours(cfg, goal, sim, repeats: int, **settings) -> dict:
    fn = ex.strategy_function(cfg.strategy.name)
    kw = {**strategy_kwargs(cfg), **settings}
    t0 = time.perf_counter()
    res = fn(sim, goal, **kw)
    cold = time.perf_counter() - t0
    walls = [res.wall_time_s]
    compiles = [res.compile_time_s]
    for _ in range(repeats - 1):
        r = fn(sim, goal, **kw)
        walls.append(r.wall_time_s)
        compiles.append(r.compile_time_s)
    return {
        "cold_s": cold,
        "compile_s": statistics.median(compiles),
        "steady_s": statistics.median(walls),
        "evaluations": res.evaluations,
        "success": res.success,
        "max_point_error": float(np.max(res.point_errors)),
    }


def run_peer(cfg, goal, sim, to_success: bool = False) -> dict:
    """The peer's search (`peer_strategies`), with the same feasibility checks as
    ours (`peer_feasibility`, MuJoCo C) when the simulator has them.

    ``to_success`` (IET): the peer also restarts and backtracks as ours does as
    ``cgda run`` runs it (`iet_search`), instead of the paper's plain search."""
    from peer_feasibility import FeasibleMarker

    from cgda_jax.strategies.ie import STAGNATION

    if sim.feasibility is not None:
        c_sim = FeasibleMarker.from_simulator(sim)
    else:
        c_sim = peers.MujocoMarker.from_simulator(sim)
    s = cfg.strategy
    args = (c_sim, goal, s.population_size, s.tolerance, s.max_generations)
    t0 = time.perf_counter()
    if s.name == "ie":  # SAME_SEARCH: no stagnation stop
        out = peer_strategies.pycma_ie(*args, seed=s.seed)
    elif s.name == "iet" and to_success:
        out = peer_strategies.pycma_iet(*args, seed=s.seed, **iet_search(cfg))
    elif s.name == "iet":  # ours keeps its stagnation stop under SAME_SEARCH
        stagnation = {**s.options, **SAME_SEARCH["iet"]}.get("stagnation", STAGNATION)
        out = peer_strategies.pycma_iet(*args, seed=s.seed, stagnation=stagnation)
    else:
        out = peer_strategies.pycma_fte(
            *args, stagnation=s.options.get("stagnation", 10), seed=s.seed
        )
    out["time_s"] = time.perf_counter() - t0
    return out


def iet_search(cfg) -> dict:
    """The restarts, backtracks and stagnation stop of the experiment's IET as
    ``cgda run`` runs it (its options over the library's defaults), for the peer."""
    from cgda_jax.strategies.iet import IETSettings

    st = IETSettings.of(None, **{k: v for k, v in cfg.strategy.options.items()
                                 if k in ("restarts", "backtracks", "stagnation")})
    return {"restarts": st.restarts, "backtracks": st.backtracks,
            "stagnation": st.stagnation}


def iet_point_times(cfg, goal, sim) -> list[float]:
    """Our IET's wall time per point, from one-generation chunks (the peer's search)."""
    kw = {**strategy_kwargs(cfg), **SAME_SEARCH["iet"], "chunk_size": 1}
    stamps: list[tuple[float, int]] = []

    def progress(info):
        stamps.append((info["elapsed_s"], int(np.ravel(info["point"])[0])))

    ex.strategy_function("iet")(sim, goal, progress_fn=progress, **kw)
    times, last_t, last_p = [], 0.0, 0
    for t, p in stamps:
        if p != last_p:  # point last_p was committed during this chunk
            times.append(t - last_t)
            last_t, last_p = t, p
    return times


def flatness(times) -> dict:
    first, last = float(np.mean(times[:3])), float(np.mean(times[-3:]))
    return {"first3_s": first, "last3_s": last, "flat": last <= 1.5 * first}


def trials_benchmark(cfg, goal, sim, n_trials: int) -> dict:
    from cgda_jax.cli import enable_compilation_cache
    from cgda_jax.strategies import run_ie
    from cgda_jax.strategies import run_trials

    enable_compilation_cache(pathlib.Path(tempfile.mkdtemp(prefix="cgda_bench_")))
    kw = strategy_kwargs(cfg)
    kw.pop("seed")
    t0 = time.perf_counter()
    batch = run_trials("ie", sim, goal, n_trials, seed=0, **kw)
    batch_total = time.perf_counter() - t0
    seq_walls, seq_compiles, seq_ok, seq_gens = [], [], 0, []
    t0 = time.perf_counter()
    for seed in range(n_trials):
        r = run_ie(sim, goal, seed=seed, **kw)
        seq_walls.append(r.wall_time_s)
        seq_compiles.append(r.compile_time_s)
        seq_ok += r.success
        seq_gens.append(r.generations)
    seq_total = time.perf_counter() - t0
    return {
        "n_trials": n_trials,
        "batched_run_s": batch[0].wall_time_s,
        "batched_compile_s": batch[0].compile_time_s,
        "batched_total_s": batch_total,
        "batched_successes": sum(r.success for r in batch),
        # The batch runs in lock-step until its slowest trial stops.
        "batched_generations": max(r.generations for r in batch),
        "sequential_generations_sum": int(np.sum(seq_gens)),
        "sequential_run_s": float(np.sum(seq_walls)),
        "sequential_compile_s": float(np.sum(seq_compiles)),
        "sequential_total_s": seq_total,
        "sequential_successes": seq_ok,
        "throughput_ratio_run": float(np.sum(seq_walls)) / batch[0].wall_time_s,
        "throughput_ratio_total": seq_total / batch_total,
    }


def to_success(name: str, seeds: list[int], repeats: int, peer_repeats: int
               ) -> list[dict]:
    """Time to success of ours (as ``cgda run``) and of the peer with the same
    restarts and backtracks, per seed (see the module doc)."""
    rows = []
    for seed in seeds:
        cfg, goal, sim = setup(name, [f"strategy.seed={seed}"])
        ours = run_ours(cfg, goal, sim, repeats)
        peers_ = [run_peer(cfg, goal, sim, to_success=True)
                  for _ in range(peer_repeats)]
        peer = peers_[0]
        peer_s = statistics.median(p["time_s"] for p in peers_)
        both = bool(ours["success"] and peer["success"])
        rows.append({
            "experiment": name, "seed": seed, **iet_search(cfg),
            "ours_steady_s": ours["steady_s"], "ours_compile_s": ours["compile_s"],
            "ours_evals": ours["evaluations"], "ours_ok": ours["success"],
            "peer_s": peer_s, "peer_runs": len(peers_),
            "peer_evals": peer["evaluations"], "peer_ok": peer["success"],
            "peer_backtracks": peer["backtracks_used"],
            "peer_restarts": int(np.sum(peer["tries"])) - len(peer["tries"]),
            "peer_worst": float(np.max(peer["point_errors"])),
            "peer_violation": peer.get("violation", ""),
            "ratio": peer_s / ours["steady_s"] if both else float("nan"),
            "met": both and peer_s / ours["steady_s"] >= TO_SUCCESS_TARGET,
        })
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--ratio-only", action="store_true",
                        help="only the same-search runs and the peer (no 'as cgda "
                        "run' runs, no IET per-point timing)")
    parser.add_argument(
        "--only", nargs="*", default=["clean_ie", "clean_fte", "paint_iet", "trials"]
    )
    parser.add_argument("--to-success", action="store_true",
                        help="paint IET: time to success, the peer with our "
                        "restarts and backtracks (see the module doc)")
    parser.add_argument("--seeds", type=int, nargs="*", default=[0])
    parser.add_argument("--peer-repeats", type=int, default=3)
    args = parser.parse_args()
    if args.to_success:
        names = [n for n in args.only if n not in ("clean_ie", "clean_fte", "trials")]
        rows = [r for n in names or ["paint_iet"]
                for r in to_success(n, args.seeds, args.repeats, args.peer_repeats)]
        print_table(rows, list(rows[0]))
        for r in rows:
            report_target(f"{r['experiment']} seed {r['seed']} time to success >= "
                          f"{TO_SUCCESS_TARGET:g}x pycma + MuJoCo C with restarts and "
                          "backtracks", r["ratio"], r["met"])
        write_json("bench_strategies_to_success", {"rows": rows})
        return
    overrides = ["strategy.max_generations=20"] if args.quick else []
    n_trials = 4 if args.quick else args.trials

    rows, payload = [], {"quick": args.quick}
    for name in [n for n in args.only if n != "trials"]:
        print(f"{name} ...", flush=True)
        cfg, goal, sim = setup(name, overrides)
        ours = (EMPTY if args.ratio_only  # as `cgda run` runs it
                else run_ours(cfg, goal, sim, args.repeats))
        same = run_ours(cfg, goal, sim, args.repeats,
                        **SAME_SEARCH[cfg.strategy.name])
        peer = run_peer(cfg, goal, sim)
        ratio = peer["time_s"] / same["steady_s"]
        target = TARGETS[cfg.strategy.name]
        rows.append(
            {
                "experiment": name,
                "points": goal.shape[0],
                # the peer judges the same moves with MuJoCo C when ours does
                "feasibility": "on (both)" if sim.feasibility is not None else "off",
                "ours_cold_s": ours["cold_s"],
                "ours_compile_s": ours["compile_s"],
                "ours_steady_s": ours["steady_s"],
                "ours_evals": ours["evaluations"],
                "ours_ok": ours["success"],
                "same_steady_s": same["steady_s"],
                "same_compile_s": same["compile_s"],
                "same_evals": same["evaluations"],
                "same_ok": same["success"],
                "peer_s": peer["time_s"],
                "peer_evals": peer["evaluations"],
                "peer_ok": peer["success"],
                "peer_violation": peer.get("violation", ""),
                "ratio": ratio,
                "target": "" if target is None else f">= {target:g}x",
                "met": "" if target is None else ratio >= target,
            }
        )
        payload[name] = {"ours": ours, "same_search": same, "peer": _plain(peer)}
        if cfg.strategy.name == "iet" and not args.ratio_only:
            ours_pt = iet_point_times(cfg, goal, sim)
            payload[name]["ours_point_times_s"] = ours_pt
            payload[name]["ours_flatness"] = flatness(ours_pt)
            payload[name]["peer_flatness"] = flatness(peer["point_times_s"])
        if cfg.strategy.name == "ie" and not args.ratio_only:
            payload["cold_start_s"] = ours["cold_s"]
    cols = list(rows[0]) if rows else []
    if rows:
        print_table(rows, cols)
    for name in ("paint_iet",):
        if name in payload and "ours_flatness" in payload[name]:
            print(
                f"{name} time per point: ours {payload[name]['ours_flatness']}, "
                f"peer {payload[name]['peer_flatness']}"
            )
    for r in rows:
        if r["target"]:
            report_target(
                f"{r['experiment']} {r['target']} faster than pycma + MuJoCo C",
                r["ratio"],
                r["met"],
            )
    c = payload.get("cold_start_s")
    report_target(
        f"clean IE cold start incl. compile < {COLD_TARGET_S:g} s (s)", c,
        c is not None and c < COLD_TARGET_S,
    )
    if "trials" in args.only:
        print(f"trials ({n_trials}) ...", flush=True)
        cfg, goal, sim = setup("clean_ie", overrides)
        tr = trials_benchmark(cfg, goal, sim, n_trials)
        payload["trials"] = tr
        print_table([tr], list(tr))
        ratio = tr["throughput_ratio_run"]
        need = TRIALS_TARGET_X[jax.default_backend() == "gpu"]
        report_target(
            f"{n_trials} trials batched >= {need:g}x sequential throughput (run only, "
            f"{jax.default_backend()})",
            ratio,
            ratio >= need,
        )
    payload["rows"] = rows
    write_json("bench_strategies", payload)


def _plain(d: dict) -> dict:
    return {
        k: (np.asarray(v).tolist() if isinstance(v, np.ndarray) else v)
        for k, v in d.items()
    }


if __name__ == "__main__":
    main()
