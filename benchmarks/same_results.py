"""Same results, bit for bit: store every result array of a set of runs, or compare
this tree's runs with stored ones exactly (``np.array_equal``, NaNs equal).

A refactoring that must not change behaviour (issue 40) is checked by saving on the
untouched tree and comparing after:

    python benchmarks/same_results.py --save DIR      # before
    python benchmarks/same_results.py --compare DIR   # after: exit 1 on a difference
    python benchmarks/same_results.py --compare DIR --stored DIR2  # DIR2 saved after

Runs (CPU by default; set JAX_PLATFORMS to change): the built-in experiments
clean_ie, paint_iet, clean_fte and iron_ie_xgnitive (the last needs the xgnitive
data: $CGDA_XGNITIVE_DIR or ``shared/data/xgnitive`` beside the repository
or its parent), each with seeds 0-3

- single: one run per seed as ``cgda run`` calls the strategy
  (`cgda_jax.experiment.compute.compute_execution`: the goal and simulator built
  from the config, the strategy function of `cgda_jax.experiment.rules` with the
  config's settings), without the replays, figures and reports;
- batched: one `cgda_jax.strategies.run_seeds` call over seeds 0-3, as
  ``cgda run CONFIG --trials 4`` calls it (`cgda_jax.experiment.success_rate`).

Stored per run: every `ExecutionResult` array (joints, features, goal, point
errors, fitness history), its counts (generations, evaluations, invalid
evaluations), final fitness and success, and every numeric ``info`` entry (the
violation, per-point generations and tries, ...) but times.

``--only NAME ...`` restricts the experiments, ``--set KEY=VALUE`` overrides config
keys (as ``cgda run --set``; the same overrides must be given to save and compare).
JAX's persistent compilation cache is on, as in ``cgda run``, in ``DIR/jax_cache``:
a program compiled for the save is taken from there when the compare's is the same
(the cache is keyed by the program), so unchanged programs are not compiled twice.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
EXPERIMENTS = ("clean_ie", "paint_iet", "clean_fte", "iron_ie_xgnitive")
SEEDS = (0, 1, 2, 3)


def _flatten(prefix: str, value, out: dict[str, np.ndarray]) -> None:
    """Numeric leaves of ``value`` as arrays under ``prefix/...`` (times skipped)."""
    if isinstance(value, dict):
        for k, v in value.items():
            if "time" in str(k) or str(k).endswith("_s"):
                continue  # wall and compile times change run to run
            _flatten(f"{prefix}/{k}", v, out)
        return
    if isinstance(value, str) or value is None:
        out[prefix] = np.asarray(json.dumps(value))
        return
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        out[prefix] = np.asarray(repr(value))
        return
    if arr.dtype == object:
        if isinstance(value, list | tuple):
            for i, v in enumerate(value):
                _flatten(f"{prefix}/{i}", v, out)
        else:
            out[prefix] = np.asarray(repr(value))
        return
    out[prefix] = arr


def result_arrays(res) -> dict[str, np.ndarray]:
    """Every array and number of an `ExecutionResult` but its times."""
    out = {k: np.asarray(v) for k, v in res.arrays().items()}
    for k in ("generations", "evaluations", "invalid_evaluations", "final_fitness",
              "success", "tolerance", "strategy"):
        out[k] = np.asarray(getattr(res, k))
    _flatten("info", res.info, out)
    return out


def build(name: str, overrides: list[str]):
    """The config, goal and simulator of a built-in experiment, as ``cgda run``."""
    from cgda_jax import experiment as ex
    from cgda_jax.experiment.build import (
        build_goal,
        build_simulator,
        default_waypoint_s,
    )

    cfg = ex.load_config(REPO / "experiments" / f"{name}.toml", overrides)
    if cfg.data.source == "xgnitive" and not cfg.data.data_dir:
        found = [p for p in (os.environ.get("CGDA_XGNITIVE_DIR"),
                             *(r / "shared" / "data" / "xgnitive"
                               for r in REPO.parents))
                 if p and pathlib.Path(p).is_dir()]
        cfg.data.data_dir = str(found[0]) if found else ""
    goal, demos, _ = build_goal(cfg)
    sim = build_simulator(cfg, default_waypoint_s(demos, len(goal)), goal)
    return cfg, goal, sim


def single(cfg, goal, sim, seed: int):
    """One run as `compute_execution` calls the strategy."""
    from cgda_jax.experiment.rules import strategy_function

    s = cfg.strategy
    return strategy_function(s.name)(
        sim, goal, algorithm=s.algorithm, population_size=s.population_size,
        tolerance=s.tolerance, max_generations=s.max_generations, seed=seed,
        chunk_size=s.chunk_size, progress_fn=None, **s.options)


def batched(cfg, goal, sim, seeds):
    """One batched call as ``cgda run --trials`` makes it."""
    try:
        from cgda_jax.strategies import run_seeds
    except ImportError:  # a tree before issue 40
        from cgda_jax.strategies.trials import run_seeds

    s = cfg.strategy
    return run_seeds(
        s.name, sim, goal, list(seeds), algorithm=s.algorithm,
        population_size=s.population_size, tolerance=s.tolerance,
        max_generations=s.max_generations, chunk_size=s.chunk_size,
        progress_fn=None, **s.options)


def collect(names, overrides, folder: pathlib.Path | None = None
            ) -> dict[str, np.ndarray]:
    """``{run/key: array}`` of every run; with ``folder``, each experiment's arrays
    are also stored there (``results_NAME.npz``) as soon as its runs end."""
    out: dict[str, np.ndarray] = {}
    for name in names:
        t0 = time.perf_counter()
        mine = set(out)
        cfg, goal, sim = build(name, overrides)
        for seed in SEEDS:
            for k, v in result_arrays(single(cfg, goal, sim, seed)).items():
                out[f"{name}/single/seed{seed}/{k}"] = v
        for seed, res in zip(SEEDS, batched(cfg, goal, sim, SEEDS)):
            for k, v in result_arrays(res).items():
                out[f"{name}/batched/seed{seed}/{k}"] = v
        if folder is not None:
            np.savez(folder / f"results_{name}.npz",
                     **{k: v for k, v in out.items() if k not in mine})
        print(f"{name}: {time.perf_counter() - t0:.0f} s", flush=True)
    return out


def stored(folder: pathlib.Path, names) -> dict[str, np.ndarray]:
    """The arrays `collect` stored in ``folder`` for the experiments ``names``."""
    out = {}
    for name in names:
        with np.load(folder / f"results_{name}.npz") as f:
            out.update({k: f[k] for k in f.files})
    return out


def compare(got: dict, want: dict) -> list[str]:
    """Lines naming each key missing, extra or not exactly equal."""
    lines = []
    for k in sorted(set(want) | set(got)):
        if k not in got:
            lines.append(f"missing now: {k}")
        elif k not in want:
            lines.append(f"new now: {k}")
        else:
            a, b = np.asarray(got[k]), np.asarray(want[k])
            nan = a.dtype.kind in "fc" and b.dtype.kind in "fc"
            if a.shape != b.shape or a.dtype != b.dtype:
                lines.append(f"{k}: {a.dtype}{a.shape} != stored {b.dtype}{b.shape}")
            elif not np.array_equal(a, b, equal_nan=nan):
                diff = (float(np.nanmax(np.abs(a.astype(float) - b.astype(float))))
                        if a.dtype.kind in "fciub" else "-")
                lines.append(f"{k}: differs (max |difference| {diff})")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--save", type=pathlib.Path, help="run and store into DIR")
    group.add_argument("--compare", type=pathlib.Path,
                       help="run and compare with DIR exactly")
    parser.add_argument("--only", nargs="*", default=list(EXPERIMENTS))
    parser.add_argument("--set", action="append", default=[], dest="overrides")
    parser.add_argument("--cache", type=pathlib.Path,
                        help="JAX compilation cache folder (default DIR/jax_cache)")
    parser.add_argument("--stored", type=pathlib.Path,
                        help="with --compare: take this tree's results from a folder "
                        "--save wrote (e.g. saved from another checkout at the same "
                        "time) instead of running")
    args = parser.parse_args()
    folder = args.save or args.compare
    from cgda_jax.cli import enable_compilation_cache

    enable_compilation_cache((args.cache or folder / "jax_cache").resolve())
    names = [n for n in args.only if n in EXPERIMENTS] or list(EXPERIMENTS)
    if args.stored:  # this tree's results as --save stored them elsewhere
        got = stored(args.stored, names)
    else:
        if args.save:
            folder.mkdir(parents=True, exist_ok=True)
        got = collect(names, args.overrides, folder if args.save else None)
    if args.save:
        (folder / "runs.json").write_text(json.dumps(
            {"experiments": names, "seeds": SEEDS, "overrides": args.overrides}))
        print(f"stored {len(got)} arrays in {folder}")
        return 0
    want = stored(folder, names)
    lines = compare(got, want)
    for line in lines:
        print(line)
    print(f"{len(got)} arrays compared: "
          + ("identical" if not lines else f"{len(lines)} differ"))
    return 1 if lines else 0


if __name__ == "__main__":
    sys.exit(main())
