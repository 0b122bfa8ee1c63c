"""The ``cgda`` command: ``cgda run CONFIG``, ``cgda demo``, ``cgda list`` and
``cgda plot FOLDER``.

Argument parsing, the JAX compilation cache, progress and error reporting only; the
work is done by :mod:`cgda_jax.experiment`.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import signal
import sys
import time

from cgda_jax.cli_errors import (  # noqa: F401  (the exit statuses are public here)
    EXIT_DIVERGED,
    EXIT_FAILURE,
    EXIT_MET,
    EXIT_NOT_MET,
    EXIT_SIGNAL,
    EXIT_USAGE,
    USER_ERRORS,
    Interrupted,
    _diverged,
    _first_line,
    _interrupted,
    _log_warnings,
    _save_traceback,
    _Signals,
    _user_error,
)
from cgda_jax.cli_plot import add_plot_parser, cmd_plot
from cgda_jax.cli_trials import (
    add_trials_arguments,
    join_job,
    launch_if_asked,
    run_trials_command,
)


def _version() -> str:
    from cgda_jax import __version__

    return __version__


def _cache_dir() -> pathlib.Path:
    env = os.environ.get("CGDA_JAX_CACHE")
    return pathlib.Path(env).expanduser() if env else (
        pathlib.Path.home() / ".cache" / "cgda_jax" / "jax")


def enable_compilation_cache(path: pathlib.Path | None = None) -> pathlib.Path:
    """Turn on JAX's persistent compilation cache, small programs included.

    Raises:
        FolderError: the folder cannot be created or written (names it and
            $CGDA_JAX_CACHE).
    """
    import jax

    from cgda_jax.experiment.results import FolderError, check_writable

    path = path or _cache_dir()
    what = f"compilation cache folder {path} ($CGDA_JAX_CACHE)"
    try:
        check_writable(path, what)
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise FolderError(f"{what} cannot be created: {err.strerror or err}") from None
    except FolderError as err:
        raise FolderError(f"{err}; point CGDA_JAX_CACHE at a writable folder or "
                          "pass --no-cache") from None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


RUN_EXAMPLES = """\
examples:
  cgda run clean_ie                  # built-in (`cgda list`) -> results/clean_ie/
  cgda run my_experiment.toml        # a config file of your own
  cgda run paint_iet --out /tmp/paint
  cgda run paint_iet --out /tmp/paint --overwrite   # replace it
  cgda run clean_ie --set strategy.population_size=64 \\
      --set strategy.seed=3 --set output.render=false
  cgda run clean_ie --dry-run        # check + print the resolved config
  cgda run clean_ie --trials 30     # success rate of seeds 0..29

The results folder gets report.md (start there), result.json, arrays.npz,
config.toml (the resolved config; re-run it with `cgda run <folder>/config.toml`)
and plots/ (PNGs; execution runs also plots/execution.gif of the robot). It is
written aside and moved into place when complete: a failed or interrupted run
leaves the folder as it was. A non-empty --out is refused unless --overwrite; a
lock refuses a second run into a folder in use.
Config keys: the [data], [recognition], [robot], [scene], [strategy] and [output]
tables printed by --dry-run. With --trials N the folder gets trials.json and a
report.md success-rate table instead, and the exit status is 0 once they are
written, whatever the rate. Exit status: 0 goal met, 1 goal not met, 2 bad input
(config, files, results folder not empty, in use or not writable), 3 any other
failure (a diverged simulation; otherwise the traceback is saved to a log file
whose path is printed), 130 / 143 interrupted (SIGINT / SIGTERM).
Rendering needs offscreen OpenGL: MUJOCO_GL=egl or osmesa (picked automatically on
a headless Linux machine when unset).
"""

DEMO_EXAMPLES = """\
examples:
  cgda demo                      # everything, results in results/demo/ (then -2, ...)
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
        epilog="Start with `cgda demo`, then `cgda list` and `cgda run clean_ie`. "
        "`cgda run --help` lists the options.",
    )
    p.add_argument("--version", action="version", version=f"cgda {_version()}")
    sub = p.add_subparsers(dest="command", required=True, metavar="{run,demo,list,plot}")
    fmt = argparse.RawDescriptionHelpFormatter
    run = sub.add_parser("run", help="run one experiment: a built-in one by name "
                         "(`cgda list`) or a config file (TOML)",
                         description="Run one experiment described by a TOML file "
                         "or a built-in one named by `cgda list`.",
                         epilog=RUN_EXAMPLES, formatter_class=fmt)
    run.add_argument("config", help="experiment file (TOML), or the name of a built-in "
                     "experiment (`cgda list`), e.g. clean_ie")
    run.add_argument("--set", dest="overrides", action="append", default=[],
                     metavar="KEY=VALUE",
                     help="override a config value (repeatable), e.g. "
                     "--set strategy.population_size=64")
    run.add_argument("--out", metavar="DIR",
                     help="results folder, missing or empty unless --overwrite "
                     "(default: the first free one of <output.dir>/<name>, "
                     "<output.dir>/<name>-2, ...; output.dir is results)")
    run.add_argument("--dry-run", action="store_true",
                     help="check everything the run would check (config, files, "
                     "robot, scene, algorithm, sizes, results folder) and print the "
                     "resolved config; compiles no simulation, runs nothing")
    add_trials_arguments(run)
    demo = sub.add_parser(
        "demo", help="the main job: recognition tables, clean (IE) and paint (IET) on TEO",
        description="The paper's main results in one go.",
        epilog=DEMO_EXAMPLES, formatter_class=fmt,
    )
    demo.add_argument("--out", metavar="DIR",
                      help="results folder, missing or empty unless --overwrite "
                      "(default: the first free one of results/demo, results/demo-2, "
                      "...)")
    demo.add_argument("--small", action="store_true",
                      help="fewer generations and samples (a quick check)")
    sub.add_parser("list", help="the built-in experiments, one line each",
                   description="The built-in experiments: `cgda run NAME` runs one; "
                   "`cgda run NAME --dry-run` prints its config.")
    add_plot_parser(sub, fmt)
    for s in (run, demo):
        s.add_argument("--overwrite", action="store_true",
                       help="replace the results folder whole if it holds an earlier "
                       "run (only once the new run is complete)")
        s.add_argument("--quiet", action="store_true",
                       help="no progress on stderr (warnings and errors still shown)")
        s.add_argument("--no-cache", action="store_true",
                       help="do not use the persistent JAX compilation cache "
                       "($CGDA_JAX_CACHE, default ~/.cache/cgda_jax/jax)")
    return p


def _say(args, text: str) -> None:
    if not args.quiet:
        print(text, file=sys.stderr, flush=True)


def _run_one(cfg, shown: pathlib.Path, work: pathlib.Path, args) -> dict:
    """Run ``cfg`` into ``work`` (the temporary folder that becomes ``shown``)."""
    return _start_one(cfg, shown, work, args).finish()


def _start_one(cfg, shown: pathlib.Path, work: pathlib.Path, args):
    """`_run_one` up to its outputs (`~cgda_jax.experiment.run.Outputs`)."""
    from cgda_jax.experiment import start_run
    from cgda_jax.progress import ProgressLine

    bar = ProgressLine(cfg.name, quiet=args.quiet)
    t0 = time.perf_counter()
    what = (f"{cfg.strategy.name.upper()} execution" if cfg.kind == "execution"
            else "recognition")
    _say(args, f"[{cfg.name}] {what} ...")
    work.mkdir(exist_ok=True)
    try:
        pending = start_run(cfg, work, progress_fn=bar)
    finally:
        bar.close()
    result = pending.result
    verdict = "ok" if result.get("success") else "NOT met"
    extra = (f"accuracy {result['accuracy']:.0%}" if cfg.kind == "recognition"
             else f"max point error {result['max_point_error']:.4g}"
             + (f" {result['error_unit']}" if result.get("error_unit") else ""))
    _say(args, f"[{cfg.name}] {verdict}: {extra} ({time.perf_counter() - t0:.1f} s) "
               f"-> {shown}")
    return pending


def _facts(facts: dict) -> str:
    if "goal_points" in facts:
        n = facts["features"]
        return (f"goal {facts['goal_points']} points x {n} feature{'s' * (n != 1)}, "
                f"{facts['genes']} genes per candidate")
    return f"{facts.get('actions', '?')} actions"


def _say_chosen(args, label: str, rf) -> None:
    if rf.path != rf.target:
        _say(args, f"[{label}] {rf.target} is taken: results go to {rf.path}")


def cmd_run(args) -> int:
    from cgda_jax.builtin import resolve_config
    from cgda_jax.experiment import (
        RunFolder,
        check_experiment,
        default_folder,
        dump_config,
        load_config,
        plan_folder,
    )

    cfg = load_config(resolve_config(args.config), args.overrides)
    if args.trials is not None:
        from cgda_jax.experiment.trials import check_trials

        check_trials(cfg, args.trials)
    facts = check_experiment(cfg)
    target = pathlib.Path(args.out).expanduser() if args.out else default_folder(cfg)
    fresh = args.out is None
    if args.dry_run:
        folder = plan_folder(target, overwrite=args.overwrite, fresh=fresh)
        print(f"# {args.config}: valid ({_facts(facts)}); results would go to "
              f"{folder}\n" + dump_config(cfg), end="")
        return EXIT_MET
    if args.trials is not None:
        return run_trials_command(
            cfg, args, lambda: RunFolder(target, overwrite=args.overwrite, fresh=fresh),
            lambda text: _say(args, text), lambda rf: _say_chosen(args, cfg.name, rf))
    with RunFolder(target, overwrite=args.overwrite, fresh=fresh) as rf:
        args.run_folder = rf
        _say_chosen(args, cfg.name, rf)
        result = _run_one(cfg, rf.path, rf.work, args)
    if not args.quiet:
        print(rf.path / "report.md")
    return EXIT_MET if result.get("success") else EXIT_NOT_MET


def cmd_list(args) -> int:
    from cgda_jax.builtin import experiment_lines

    print("\n".join(experiment_lines()))
    return EXIT_MET


def _dispatch(args, signals: _Signals) -> int:
    try:
        if args.command == "list":
            return cmd_list(args)
        join_job(args)  # a multi-process --trials job: before any JAX work
        if not args.no_cache:
            enable_compilation_cache()
        if args.command == "run":
            return cmd_run(args)
        if args.command == "plot":
            return cmd_plot(args)
        from cgda_jax.cli_demo import cmd_demo

        return cmd_demo(args)
    except KeyboardInterrupt as e:
        return _interrupted(args, getattr(e, "signum", signal.SIGINT))
    except Exception as e:  # noqa: BLE001 - every failure: one line
        if signals.received is not None:  # an interrupt wrapped by a library
            return _interrupted(args, signals.received)
        if _user_error(args, e):
            print(f"cgda: error: {_first_line(e)}", file=sys.stderr)
            return EXIT_USAGE
        if _diverged(e):
            print(f"cgda: error: {_first_line(e)}", file=sys.stderr)
            return EXIT_DIVERGED
        where = _save_traceback()
        print(f"cgda: error: {type(e).__name__}: {_first_line(e)} ({where})",
              file=sys.stderr)
        return EXIT_FAILURE
    finally:
        signals.active = False  # a signal from here on only ends the process


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cgda`` console script; returns the exit status.

    0 goal met, 1 goal not met, 2 usage or config error, 3 any other failure,
    130 / 143 interrupted by SIGINT / SIGTERM; every error is one line on stderr.
    """
    with _Signals() as signals:
        try:
            args = _parser().parse_args(argv)
        except KeyboardInterrupt as e:
            return _interrupted(None, getattr(e, "signum", signal.SIGINT))
        _log_warnings()
        launched = launch_if_asked(args, sys.argv[1:] if argv is None else list(argv))
        if launched is not None:
            return launched
        return _dispatch(args, signals)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
