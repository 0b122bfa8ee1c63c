"""``cgda run CONFIG``: check a config, then run it into its results folder (or,
with ``--trials N``, many seeds of it: `cgda_jax.cli.trials`)."""

from __future__ import annotations

import os
import pathlib
import time

from cgda_jax.cli.output import EXIT_MET, EXIT_NOT_MET, Session, say, say_chosen
from cgda_jax.cli.trials import check_processes, run_trials_command
from cgda_jax.job import ENV_JOB_WORK

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
Config keys: the [data], [recognition], [selection], [robot], [scene], [strategy]
and [output] tables printed by --dry-run. With --trials N the folder gets trials.json and a
report.md success-rate table instead, and the exit status is 0 once they are
written, whatever the rate. Exit status: 0 goal met, 1 goal not met, 2 bad input
(config, files, results folder not empty, in use or not writable), 3 any other
failure (a diverged simulation; otherwise the traceback is saved to a log file
whose path is printed), 130 / 143 interrupted (SIGINT / SIGTERM).
Rendering needs offscreen OpenGL: MUJOCO_GL=egl or osmesa (picked automatically on
a headless Linux machine when unset).
"""


def _run_one(cfg, shown: pathlib.Path, work: pathlib.Path, session: Session,
             built=None) -> dict:
    """Run ``cfg`` into ``work`` (the temporary folder that becomes ``shown``) on
    ``built``, what its checks built (`~cgda_jax.experiment.check_and_build`)."""
    return start_one(cfg, shown, work, session, built).finish()


def start_one(cfg, shown: pathlib.Path, work: pathlib.Path, session: Session,
              built=None):
    """`_run_one` up to its outputs (`~cgda_jax.experiment.run.Outputs`)."""
    from cgda_jax.experiment import start_run
    from cgda_jax.progress import ProgressLine

    bar = ProgressLine(cfg.name, quiet=session.quiet)
    t0 = time.perf_counter()
    what = (f"{cfg.strategy.name.upper()} execution" if cfg.kind == "execution"
            else "recognition")
    say(session, f"[{cfg.name}] {what} ...")
    work.mkdir(exist_ok=True)
    try:
        pending = start_run(cfg, work, progress_fn=bar, built=built)
    finally:
        bar.close()
    result = pending.result
    verdict = "ok" if result.get("success") else "NOT met"
    extra = (f"accuracy {result['accuracy']:.0%}" if cfg.kind == "recognition"
             else f"max point error {result['max_point_error']:.4g}"
             + (f" {result['error_unit']}" if result.get("error_unit") else ""))
    say(session, f"[{cfg.name}] {verdict}: {extra} ({time.perf_counter() - t0:.1f} s) "
               f"-> {shown}")
    if cfg.kind == "execution":
        from cgda_jax.experiment.report import not_met_hint

        hint = not_met_hint(cfg, result)
        if hint:
            say(session, f"[{cfg.name}] hint: {hint}")
    return pending


def _facts(facts: dict) -> str:
    if "goal_points" in facts:
        n = facts["features"]
        return (f"goal {facts['goal_points']} points x {n} feature{'s' * (n != 1)}, "
                f"{facts['genes']} genes per candidate")
    return f"{facts.get('actions', '?')} actions"


def _job_size(args) -> tuple[int, bool]:
    """Processes the seeds are split over and whether they all share this machine:
    ``--processes P`` (a dry run, or the launcher), a launched worker, or one
    process of a cluster job (``CGDA_NUM_PROCESSES``)."""
    import os

    from cgda_jax.job import ENV_NUM_PROCESSES

    if getattr(args, "processes", 1) > 1:
        return args.processes, True
    for var, local in (("CGDA_LAUNCHED_PROCESSES", True), (ENV_NUM_PROCESSES, False)):
        try:
            n = int(os.environ.get(var, ""))
        except ValueError:
            continue
        if n > 1:
            return n, local
    return 1, True


def cmd_run(args, session: Session) -> int:
    from cgda_jax.builtin import resolve_config
    from cgda_jax.results_folder.writing import check_free
    from cgda_jax.experiment import (
        RunFolder,
        check_and_build,
        default_folder,
        dump_config,
        load_config,
        plan_folder,
    )

    check_processes(args)
    extra = ["reality.enabled=true"] if getattr(args, "reality", False) else []
    cfg = load_config(resolve_config(args.config), [*args.overrides, *extra])
    if args.trials is not None:
        from cgda_jax.experiment.success_rate import check_trials

        check_trials(cfg, args.trials)
    processes, local = _job_size(args)
    # a worker of `--processes P`: its launcher made these checks, on the same files
    facts, built = (None, None) if os.environ.get(ENV_JOB_WORK) else check_and_build(
        cfg, trials=args.trials, processes=processes, local=local)
    target = pathlib.Path(args.out).expanduser() if args.out else default_folder(cfg)
    fresh = args.out is None
    if args.dry_run:
        folder = plan_folder(target, overwrite=args.overwrite, fresh=fresh)
        check_free(folder)  # a folder another run holds is refused by the run too
        print(f"# {args.config}: valid ({_facts(facts)}); results would go to "
              f"{folder}\n# the keys that apply to it (a run's config.toml holds them "
              f"all)\n" + dump_config(cfg, applicable_only=True), end="")
        return EXIT_MET
    if args.trials is not None:
        return run_trials_command(
            cfg, args, session,
            lambda: RunFolder(target, overwrite=args.overwrite, fresh=fresh),
            lambda rf: say_chosen(session, cfg.name, rf), built)
    with RunFolder(target, overwrite=args.overwrite, fresh=fresh) as rf:
        session.run_folder = rf
        say_chosen(session, cfg.name, rf)
        result = _run_one(cfg, rf.path, rf.work, session, built)
    if not session.quiet:
        print(rf.path / "report.md")
    return EXIT_MET if result.get("success") else EXIT_NOT_MET
