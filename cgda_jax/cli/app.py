"""The ``cgda`` command's parser and `main`: each sub-command is handled by its own
module of `cgda_jax.cli`; failures become exit statuses here."""

from __future__ import annotations

import argparse
import signal
import sys

from cgda_jax.cli.demo import DEMO_EXAMPLES
from cgda_jax.cli.export import add_export_parser, cmd_export
from cgda_jax.cli.list import cmd_list
from cgda_jax.cli.output import (
    JobFailed,
    Session,
    Signals,
    enable_compilation_cache,
    failure,
    interrupted,
    leave_job,
    log_warnings,
)
from cgda_jax.cli.plot import add_plot_parser, cmd_plot
from cgda_jax.cli.run import RUN_EXAMPLES, cmd_run
from cgda_jax.cli.segment import add_segment_parser, cmd_segment
from cgda_jax.cli.track import add_track_parser, cmd_track
from cgda_jax.cli.trials import add_trials_arguments, job_member, join_job


def _version() -> str:
    from cgda_jax import __version__

    return __version__


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cgda",
        description="Continuous Goal-Directed Actions: generalize, recognize and "
        "execute demonstrated actions (JAX + MuJoCo MJX).",
        epilog="Start with `cgda demo`, then `cgda list` and `cgda run clean_ie`. "
        "`cgda run --help` lists the options.",
    )
    p.add_argument("--version", action="version", version=f"cgda {_version()}")
    sub = p.add_subparsers(dest="command", required=True,
                           metavar="{run,demo,list,plot,export,track,segment}")
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
    run.add_argument("--reality", action="store_true", help="also execute the result "
                     "open loop on the config's mismatched world ([reality] table); strategy oet "
                     "also runs closed loop there, each step planned from what the "
                     "world measured")
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
    add_export_parser(sub, fmt)
    add_track_parser(sub, fmt)
    add_segment_parser(sub, fmt)
    for s in (run, demo):
        s.add_argument("--overwrite", action="store_true",
                       help="replace the results folder whole if it holds an earlier "
                       "run (only once the new run is complete)")
        s.add_argument("--quiet", action="store_true",
                       help="no progress on stderr (warnings and errors still shown)")
        s.add_argument("--no-cache", action="store_true",
                       help="do not use the persistent JAX compilation cache "
                       "($CGDA_JAX_CACHE, default ~/.cache/cgda_jax/jax) nor the "
                       "compiled programs kept in it ($CGDA_JAX_PROGRAM_STORE=0: "
                       "keep the cache, not the programs)")
    return p


def _dispatch(args, session: Session, signals: Signals) -> int:
    try:
        if args.command == "list":
            return cmd_list(args)
        if args.command == "track":  # no JAX: no job, no compilation cache
            return cmd_track(args, session)
        if args.command == "segment":  # one process, no job
            return cmd_segment(args, session)
        join_job(args, session)  # a multi-process --trials job: before any JAX work
        if not args.no_cache:
            enable_compilation_cache()
        else:  # nor the program store an earlier call in this process set
            from cgda_jax.programs import set_program_store

            set_program_store(None)
        if args.command == "run":
            return cmd_run(args, session)
        if args.command == "plot":
            return cmd_plot(args, session)
        if args.command == "export":
            return cmd_export(args, session)
        from cgda_jax.cli.demo import cmd_demo

        return cmd_demo(args, session)
    except KeyboardInterrupt as e:
        return leave_job(session,
                         interrupted(session, getattr(e, "signum", signal.SIGINT)))
    except JobFailed as e:  # a multi-process job: said here, or elsewhere
        if e.line:
            print(e.line, file=sys.stderr)
        return leave_job(session, e.status)
    except Exception as e:  # noqa: BLE001 - every failure: one line
        if signals.received is not None:  # an interrupt wrapped by a library
            return leave_job(session, interrupted(session, signals.received))
        status, line = failure(session, e)
        print(line, file=sys.stderr)
        return leave_job(session, status)
    finally:
        signals.active = False  # a signal from here on only ends the process


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``cgda`` console script; returns the exit status.

    0 goal met, 1 goal not met, 2 usage or config error, 3 any other failure,
    130 / 143 interrupted by SIGINT / SIGTERM; every error is one line on stderr.
    """
    with Signals() as signals:
        try:
            args = _parser().parse_args(argv)
        except KeyboardInterrupt as e:
            return interrupted(None, getattr(e, "signum", signal.SIGINT))
        log_warnings()
        session = Session(argv=sys.argv[1:] if argv is None else list(argv),
                          quiet=bool(getattr(args, "quiet", False)))  # not in list
        if job_member(args):
            signals.default()  # until the job's SignalWatcher (join_job)
        return _dispatch(args, session, signals)

