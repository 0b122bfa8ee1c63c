"""``cgda run CONFIG --trials N [--processes P]``: the success rate of N seeds.

The N seeds (``strategy.seed``, +1, ...) run in one batched call
(`cgda_jax.experiment.trials`); with ``--processes P`` (P > 1) the command starts P
local copies of itself as one `jax.distributed` job (`cgda_jax.launch`), each runs
its share of the seeds (`cgda_jax.distributed.share`), the per-seed records are
gathered to every process, and process 0 alone writes the results folder. On a
cluster the same job comes from the environment instead (``CGDA_COORDINATOR``,
``CGDA_NUM_PROCESSES``, ``CGDA_PROCESS_ID``, or ``CGDA_CLUSTER=auto`` under SLURM):
run ``cgda run CONFIG --trials N`` once per process; see `cgda_jax.distributed`.
Argument handling and messages only.
"""

from __future__ import annotations

import sys
import time

from cgda_jax.cli.output import EXIT_MET, EXIT_USAGE
from cgda_jax.job import ENV_PROCESS_ID


def add_trials_arguments(run) -> None:
    """``--trials`` and ``--processes`` on the ``run`` sub-parser."""
    run.add_argument("--trials", type=int, metavar="N",
                     help="run N seeds (strategy.seed, +1, ...) in one batched call "
                     "and write their success rate (trials.json, report.md); exit "
                     "status 0 whatever the rate (execution configs only)")
    run.add_argument("--processes", type=int, default=1, metavar="P",
                     help="with --trials: split the seeds over P local processes "
                     "(one jax.distributed job; process 0 writes the folder); on a "
                     "cluster set CGDA_* variables instead (README)")


def launch_if_asked(args, argv: list[str]) -> int | None:
    """Starts the ``--processes P`` job and returns its status, or None to go on
    in this process (P == 1, a worker, or a ``--dry-run``)."""
    p = getattr(args, "processes", 1)
    if args.command != "run" or p == 1 or args.dry_run:
        return None
    if p < 1:
        print(f"cgda: error: --processes must be >= 1; got {p}", file=sys.stderr)
        return EXIT_USAGE
    if args.trials is None:
        print("cgda: error: --processes needs --trials N (the seeds are what is "
              "split over the processes)", file=sys.stderr)
        return EXIT_USAGE
    import os

    if os.environ.get(ENV_PROCESS_ID) is not None:
        return None  # already a worker of a job: run our share
    from cgda_jax.launch import launch, without_option

    cmd = [sys.executable, "-m", "cgda_jax.cli", *without_option(argv, "--processes")]
    # status 1 is not a failure of a worker; every process exits like process 0
    return launch(p, cmd, ok_codes=(0, 1), env={"CGDA_LAUNCHED_PROCESSES": str(p)})


def join_job(args) -> bool:
    """Joins the multi-process job the environment describes (before any JAX
    computation); False when there is none. Workers other than 0 go quiet."""
    if args.command != "run" or getattr(args, "trials", None) is None:
        return False
    from cgda_jax import distributed

    joined = distributed.initialize()
    if joined and not distributed.is_writer():
        args.quiet = True
    return joined


def run_trials_command(cfg, args, open_folder, say, chosen) -> int:
    """``--trials N`` after the config was checked: process 0 opens the results
    folder (so a taken folder fails before any work), every process runs its
    seeds, the records are gathered and process 0 writes them.

    Args:
        open_folder: ``open_folder()`` gives the `RunFolder` context manager.
        say: ``say(text)`` prints unless quiet.
        chosen: ``chosen(run_folder)`` says where the results go.
    """
    from cgda_jax import distributed
    from cgda_jax.experiment.trials import check_trials

    n = check_trials(cfg, args.trials)
    if not distributed.is_writer():
        _run_share(cfg, args, n, say)
        return EXIT_MET
    with open_folder() as rf:
        args.run_folder = rf
        chosen(rf)
        t0 = time.perf_counter()
        records, procs = _run_share(cfg, args, n, say)
        rf.work.mkdir(exist_ok=True)
        s = write_trials_folder(cfg, records, rf.work, t0, procs)
    lo, hi = s["wilson95"]
    # the summary line goes to stdout even with --quiet: it is the result
    print(f"[{cfg.name}] {s['successes']}/{s['trials']} seeds met the goal: success "
          f"rate {s['success_rate']:.0%} (Wilson 95% {lo:.0%} to {hi:.0%}), median "
          f"max point error {s['median_max_point_error']:.4g} "
          f"({s['total_time_s']:.1f} s) -> {rf.path / 'report.md'}")
    return EXIT_MET


def _run_share(cfg, args, n: int, say) -> tuple[list[dict], int]:
    """This process's seeds in one batch, then every process's records."""
    import jax

    from cgda_jax import distributed
    from cgda_jax.experiment.trials import trial_records
    from cgda_jax.progress import ProgressLine

    seeds = [cfg.strategy.seed + i for i in range(n)]
    procs = jax.process_count()
    mine = [seeds[i] for i in distributed.share(n)] if procs > 1 else seeds
    where = f" over {procs} processes ({len(mine)} here)" if procs > 1 else ""
    say(f"[{cfg.name}] {cfg.strategy.name.upper()} execution, {n} seeds in one "
        f"batch{where} ...")
    bar = ProgressLine(cfg.name, quiet=args.quiet)
    try:
        records = trial_records(cfg, mine, bar) if mine else []
    finally:
        bar.close()
    if procs > 1:
        records = [r for part in distributed.allgather_objects(records) for r in part]
    return records, procs


def write_trials_folder(cfg, records, folder, t0: float, procs: int) -> dict:
    from cgda_jax.experiment.trials import write_trials

    return write_trials(cfg, records, folder,
                        {"total_time_s": time.perf_counter() - t0, "processes": procs})
