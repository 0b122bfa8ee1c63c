"""The ``cgda`` command: ``cgda run CONFIG`` and ``cgda demo``.

Argument parsing, the JAX compilation cache, progress and error reporting only; the
work is done by :mod:`cgda_jax.experiment`.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import time

USER_ERRORS = (ValueError, FileNotFoundError, KeyError, NotADirectoryError)


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


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cgda",
        description="Continuous Goal-Directed Actions: generalize, recognize and "
        "execute demonstrated actions (JAX + MuJoCo MJX).",
    )
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run one experiment config (TOML)")
    run.add_argument("config", help="experiment file, e.g. experiments/clean_ie.toml")
    run.add_argument("--set", dest="overrides", action="append", default=[],
                     metavar="KEY=VALUE",
                     help="override a config value, e.g. --set strategy.population_size=64")
    run.add_argument("--out", help="results folder (default: <output.dir>/<name>)")
    run.add_argument("--dry-run", action="store_true",
                     help="validate the config and print it resolved; run nothing")
    demo = sub.add_parser(
        "demo", help="the main job: recognition tables, clean (IE) and paint (IET) on TEO"
    )
    demo.add_argument("--out", default="results/demo", help="results folder")
    demo.add_argument("--small", action="store_true",
                      help="smaller populations and fewer plots (a quick check)")
    for s in (run, demo):
        s.add_argument("--quiet", action="store_true", help="no progress on stderr")
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
    _say(args, f"[{cfg.name}] {cfg.kind} ...")
    result = run_experiment(cfg, out, progress_fn=bar)
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
            "compile_time_s", "plots")
    summary = {
        "success": success,
        "small": args.small,
        "wall_time_s": wall,
        "experiments": {n: {k: r[k] for k in keys if k in r} for n, r in results.items()},
    }
    (out / "result.json").write_text(json.dumps(summary, indent=2) + "\n")
    report = [f"# cgda demo{' (small)' if args.small else ''}", "",
              f"Overall: {'success' if success else 'NOT all goals met'}; "
              f"{wall:.1f} s in total.", ""]
    for name in results:
        text = (out / name / "report.md").read_text()
        text = text.replace("](plots/", f"]({name}/plots/")
        report.append(text.replace("# ", "## ", 1))
    (out / "report.md").write_text("\n".join(report))
    _say(args, f"demo {'succeeded' if success else 'finished, goals NOT all met'} "
               f"in {wall:.1f} s -> {out / 'report.md'}")
    return 0 if success else 1


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cgda`` console script; returns the exit status."""
    args = _parser().parse_args(argv)
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
    except KeyboardInterrupt:
        print("cgda: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
