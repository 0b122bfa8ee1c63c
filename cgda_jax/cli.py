"""The ``cgda`` command: ``cgda run CONFIG`` and ``cgda demo``.

Argument parsing, the JAX compilation cache, progress and error reporting only; the
work is done by :mod:`cgda_jax.experiment`.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import pathlib
import sys
import time

USER_ERRORS = (ValueError, FileNotFoundError, KeyError, NotADirectoryError)

#: Exit status when a simulation diverged (`cgda_jax.SimulationDiverged`); the
#: others: 0 goal met, 1 goal not met, 2 bad input (config, files), 130 interrupted.
EXIT_DIVERGED = 3


def _cache_dir() -> pathlib.Path:
    env = os.environ.get("CGDA_JAX_CACHE")
    return pathlib.Path(env) if env else pathlib.Path.home() / ".cache" / "cgda_jax" / "jax"


def enable_compilation_cache(path: pathlib.Path | None = None) -> pathlib.Path:
    """Turn on JAX's persistent compilation cache, small programs included."""
    import jax

    path = path or _cache_dir()
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


RUN_EXAMPLES = """\
examples:
  cgda run experiments/clean_ie.toml                 # results in results/clean_ie/
  cgda run experiments/paint_iet.toml --out /tmp/paint
  cgda run experiments/clean_ie.toml --set strategy.population_size=64 \\
      --set strategy.seed=3 --set output.render=false
  cgda run experiments/clean_ie.toml --dry-run       # check + print the resolved config

The results folder gets report.md (start there), result.json, arrays.npz,
config.toml (the resolved config; re-run it with `cgda run <folder>/config.toml`)
and plots/ (PNGs; execution runs also plots/execution.gif of the robot).
Config keys: the [data], [recognition], [robot], [scene], [strategy] and [output]
tables printed by --dry-run. Exit status: 0 goal met, 1 goal not met, 2 bad input,
3 the simulation diverged (every candidate gave non-finite features).
Rendering needs offscreen OpenGL: MUJOCO_GL=egl or osmesa (picked automatically on
a headless Linux machine when unset).
"""

DEMO_EXAMPLES = """\
examples:
  cgda demo                      # everything, results in results/demo/
  cgda demo --small --out /tmp/d # a quicker check

Runs the paper's recognition tables (all features, spatial, arm points) and two
executions on the simulated TEO: clean (IE) and paint (IET). Open
<out>/report.md: a summary table, then one section per experiment. The first run
compiles (tens of seconds); later runs reuse the compilation cache.
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cgda",
        description="Continuous Goal-Directed Actions: generalize, recognize and "
        "execute demonstrated actions (JAX + MuJoCo MJX).",
        epilog="Start with `cgda demo`, then `cgda run experiments/clean_ie.toml`. "
        "`cgda run --help` lists the options.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="{run,demo}")
    fmt = argparse.RawDescriptionHelpFormatter
    run = sub.add_parser("run", help="run one experiment config (TOML)",
                         description="Run one experiment described by a TOML file.",
                         epilog=RUN_EXAMPLES, formatter_class=fmt)
    run.add_argument("config", help="experiment file, e.g. experiments/clean_ie.toml")
    run.add_argument("--set", dest="overrides", action="append", default=[],
                     metavar="KEY=VALUE",
                     help="override a config value (repeatable), e.g. "
                     "--set strategy.population_size=64")
    run.add_argument("--out", metavar="DIR",
                     help="results folder (default: <output.dir>/<name>, "
                     "i.e. results/<config file name>)")
    run.add_argument("--dry-run", action="store_true",
                     help="validate the config and print it resolved; run nothing")
    demo = sub.add_parser(
        "demo", help="the main job: recognition tables, clean (IE) and paint (IET) on TEO",
        description="The paper's main results in one go.",
        epilog=DEMO_EXAMPLES, formatter_class=fmt,
    )
    demo.add_argument("--out", default="results/demo", metavar="DIR",
                      help="results folder (default: results/demo)")
    demo.add_argument("--small", action="store_true",
                      help="fewer generations and samples (a quick check)")
    for s in (run, demo):
        s.add_argument("--quiet", action="store_true",
                       help="no progress on stderr (warnings and errors still shown)")
        s.add_argument("--no-cache", action="store_true",
                       help="do not use the persistent JAX compilation cache "
                       "($CGDA_JAX_CACHE, default ~/.cache/cgda_jax/jax)")
    return p


def _say(args, text: str) -> None:
    if not args.quiet:
        print(text, file=sys.stderr, flush=True)


def _run_one(cfg, out, args) -> dict:
    from cgda_jax.experiment import run_experiment
    from cgda_jax.progress import ProgressLine

    bar = ProgressLine(cfg.name, quiet=args.quiet)
    t0 = time.perf_counter()
    what = (f"{cfg.strategy.name.upper()} execution" if cfg.kind == "execution"
            else "recognition")
    _say(args, f"[{cfg.name}] {what} ...")
    try:
        result = run_experiment(cfg, out, progress_fn=bar)
    finally:
        bar.close()
    verdict = "ok" if result.get("success") else "NOT met"
    extra = (f"accuracy {result['accuracy']:.0%}" if cfg.kind == "recognition"
             else f"max point error {result['max_point_error']:.4g}")
    _say(args, f"[{cfg.name}] {verdict}: {extra} ({time.perf_counter() - t0:.1f} s) -> {out}")
    return result


def cmd_run(args) -> int:
    from cgda_jax.experiment import dump_config, load_config, validate_config

    cfg = load_config(args.config, args.overrides)
    validate_config(cfg)
    if args.dry_run:
        print(f"# {args.config}: valid\n" + dump_config(cfg), end="")
        return 0
    out = pathlib.Path(args.out) if args.out else pathlib.Path(cfg.output.dir) / cfg.name
    result = _run_one(cfg, out, args)
    if not args.quiet:
        print(out / "report.md")
    return 0 if result.get("success") else 1


def summary_table(results: dict[str, dict]) -> list[str]:
    """Markdown rows: experiment, result, key figure, time (demo report head)."""
    rows = ["| experiment | result | key figure | time |", "|---|---|---|---|"]
    for name, r in results.items():
        verdict = "ok" if r.get("success") else "**NOT met**"
        if r.get("kind") == "recognition":
            key = (f"accuracy {r['accuracy']:.0%} "
                   f"({len(r['features'])} features, {r['metric']})")
        else:
            key = (f"{r['strategy'].upper()}: max point error {r['max_point_error']:.3g} "
                   f"(tolerance {r['tolerance']:.3g}), {r['points']} points, "
                   f"{r['generations']} generations")
        rows.append(f"| [{name}](#{name}) | {verdict} | {key} | "
                    f"{r.get('total_time_s', r.get('wall_time_s', 0.0)):.1f} s |")
    return rows


def cmd_demo(args) -> int:
    from cgda_jax.experiment import demo_configs

    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results = {}
    for cfg in demo_configs(small=args.small):
        results[cfg.name] = _run_one(cfg, out / cfg.name, args)
    wall = time.perf_counter() - t0
    success = all(r.get("success") for r in results.values())
    keys = ("success", "accuracy", "strategy", "points", "max_point_error",
            "final_fitness", "evaluations", "generations", "wall_time_s",
            "compile_time_s", "total_time_s", "render", "plots")
    summary = {
        "success": success,
        "small": args.small,
        "wall_time_s": wall,
        "experiments": {n: {k: r[k] for k in keys if k in r} for n, r in results.items()},
    }
    (out / "result.json").write_text(json.dumps(summary, indent=2) + "\n")
    report = [f"# cgda demo{' (small)' if args.small else ''}", "",
              f"Overall: {'success' if success else 'NOT all goals met'}; "
              f"{wall:.1f} s in total.", "", *summary_table(results), ""]
    for name in results:
        text = (out / name / "report.md").read_text()
        text = text.replace("](plots/", f"]({name}/plots/")
        report.append(text.replace("# ", "## ", 1))
    (out / "report.md").write_text("\n".join(report))
    _say(args, f"demo {'succeeded' if success else 'finished, goals NOT all met'} "
               f"in {wall:.1f} s -> {out / 'report.md'}")
    return 0 if success else 1


def _diverged(err: BaseException) -> bool:
    """`err` is a `cgda_jax.SimulationDiverged` (its module is loaded if it is one)."""
    mod = sys.modules.get("cgda_jax.strategies.result")
    return mod is not None and isinstance(err, mod.SimulationDiverged)


def _log_warnings() -> None:
    """Library warnings (logger ``cgda_jax``) as ``cgda: warning: ...`` lines."""
    logger = logging.getLogger("cgda_jax")
    if not logger.handlers:
        handler = logging.StreamHandler()  # resolves sys.stderr at each write
        handler.setFormatter(logging.Formatter("cgda: warning: %(message)s"))
        logger.addHandler(handler)
        logger.propagate = False


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cgda`` console script; returns the exit status."""
    args = _parser().parse_args(argv)
    _log_warnings()
    try:
        if not args.no_cache:
            enable_compilation_cache()
        if args.command == "run":
            return cmd_run(args)
        return cmd_demo(args)
    except USER_ERRORS as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)
        print(f"cgda: error: {msg}", file=sys.stderr)
        return 2
    except RuntimeError as e:
        if not _diverged(e):
            raise
        print(f"cgda: error: {e}", file=sys.stderr)
        return EXIT_DIVERGED
    except KeyboardInterrupt:
        print("cgda: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
