"""``cgda run CONFIG --trials N [--processes P]``: the success rate of N seeds.

The N seeds (``strategy.seed``, +1, ...) run in one batched call
(`cgda_jax.experiment.success_rate`). With ``--processes P`` (P > 1) this process checks
the config and takes the results folder (lock, temporary folder: a folder that is
not empty, in use or not writable is refused before any worker starts), then starts
P local copies of itself as one `jax.distributed` job (`cgda_jax.launch`); each
runs its share of the seeds (`cgda_jax.distributed.share`), the per-seed records
are gathered to every process, process 0 writes them into the temporary folder, and
this process moves it into place once every worker ended well, then prints the
summary line. Whatever ends the job first (a worker's failure, its death, Ctrl-C or
SIGTERM to this process) ends every process within seconds, with one line and the
documented status, and nothing is moved into place.

On a cluster the same job comes from the environment instead (``CGDA_COORDINATOR``,
``CGDA_NUM_PROCESSES``, ``CGDA_PROCESS_ID``, or ``CGDA_CLUSTER=auto`` under SLURM):
run ``cgda run CONFIG --trials N`` once per process; process 0 takes the folder and
the others learn at once when it was refused. In every process of a job a failure
is shared at the gather (the process where it happened says it; all end with its
status), and SIGINT / SIGTERM end the process at once (`SignalWatcher`, JAX's
preemption notifier off). Argument handling and messages only.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import signal
import sys
import time

from cgda_jax.cli.output import (
    EXIT_FAILURE,
    EXIT_MET,
    EXIT_SIGNAL,
    EXIT_USAGE,
    Interrupted,
    JobFailed,
    Session,
    SignalWatcher,
    failure,
    launched_worker,
    say,
)
from cgda_jax.job import (
    ENV_JOB_FOLDER,
    ENV_JOB_WORK,
    job_from_env,
    join_timeout,
)

#: How long the launching process holds a worker's line before showing it: what a
#: worker prints in the moments before the job ends (a JAX runtime's C++ complaint
#: that process 0 vanished) is dropped, not shown.
LINE_HOLD_S = 0.5


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


def check_processes(args) -> None:
    """``--processes P``: P >= 1, and only with ``--trials``.

    Raises:
        ValueError: naming the option.
    """
    p = getattr(args, "processes", 1)
    if p < 1:
        raise ValueError(f"--processes must be >= 1; got {p}")
    if p > 1 and args.trials is None:
        raise ValueError("--processes needs --trials N (the seeds are what is split "
                         "over the processes)")


def _launching(args) -> bool:
    """This process starts the ``--processes P`` job (it is no worker of one)."""
    return (getattr(args, "processes", 1) > 1 and not args.dry_run
            and job_from_env() is None)


def job_member(args) -> bool:
    """This command runs as one process of a multi-process job (it will join it)."""
    if args.command != "run" or getattr(args, "trials", None) is None:
        return False
    try:
        return job_from_env() is not None
    except ValueError:  # said by join_job
        return False


def join_job(args, session: Session) -> bool:
    """Joins the multi-process job the environment describes (before any JAX
    computation); False when there is none. A job's process ends at once on SIGINT
    or SIGTERM (`SignalWatcher`); workers other than 0 go quiet.

    Raises:
        ValueError: a partial or malformed job environment (names the variables).
    """
    if args.command != "run" or getattr(args, "trials", None) is None:
        return False
    from cgda_jax import distributed

    job_from_env()  # a half-described job is an error here, not a silent single run
    join_timeout()
    joined = distributed.initialize(
        waiting=None if launched_worker() else (
            lambda text: say(session, f"[job] {text}")),
        on_timeout=lambda line: print(f"cgda: error: {line}", file=sys.stderr))
    if joined:
        # until the processes' last gather, one that fails alone leaves at once
        # (`leave_job`): JAX's exit would wait for the others, who wait for it
        session.job_open = True
        SignalWatcher(session, quiet=launched_worker()).start()
        if not distributed.is_writer():
            session.quiet = True
    return joined


class FolderElsewhere:
    """`Session.run_folder` of a process whose job's results folder another process
    holds (the launcher, or process 0): the run has started (a failure is no longer
    bad input, as in `~cgda_jax.cli.output.user_error`), nothing is committed here
    and there is nothing to abandon."""

    committed = False

    def __init__(self, path: pathlib.Path | None = None,
                 work: pathlib.Path | None = None):
        self.path, self.work = path, work

    def abandon(self) -> bool:
        return False


def summary_line(cfg, s: dict, report: pathlib.Path) -> str:
    lo, hi = s["wilson95"]
    return (f"[{cfg.name}] {s['successes']}/{s['trials']} seeds met the goal: success "
            f"rate {s['success_rate']:.0%} (Wilson 95% {lo:.0%} to {hi:.0%}), median "
            f"max point error {s['median_max_point_error']:.4g} "
            f"({s['total_time_s']:.1f} s) -> {report}")


def run_trials_command(cfg, args, session: Session, open_folder, chosen,
                       built=None) -> int:
    """``--trials N`` after the config was checked: the folder is taken first (by
    the launching process, or process 0), so a taken folder fails before any work;
    every process runs its seeds, the records are gathered and process 0 writes
    them.

    Args:
        session: this process's state (`Session`): its folder, job, quiet.
        open_folder: ``open_folder()`` gives the `RunFolder` context manager.
        chosen: ``chosen(run_folder)`` says where the results go.
        built: what the checks built (`~cgda_jax.experiment.check_and_build`;
            None: each process builds its own).
    """
    from cgda_jax import distributed
    from cgda_jax.experiment.success_rate import check_trials

    n = check_trials(cfg, args.trials)
    if _launching(args):
        return _launch(cfg, args, session, open_folder, chosen)
    given = os.environ.get(ENV_JOB_WORK) or None  # launched: the launcher's folder
    writer = distributed.is_writer()
    with contextlib.ExitStack() as stack:
        if given:
            session.run_folder = FolderElsewhere(
                pathlib.Path(os.environ.get(ENV_JOB_FOLDER, given)), pathlib.Path(given))
            work = session.run_folder.work
        else:
            work = _take_folder(stack, session, open_folder, chosen, writer)
        t0 = time.perf_counter()
        records, procs = _run_share(cfg, session, n, built)
        if not writer:
            return EXIT_MET
        s = write_trials_folder(cfg, records, work, t0, procs)
    if given is None:  # the folder is in place: say so (launched: the launcher does)
        # the summary line goes to stdout even with --quiet: it is the result
        print(summary_line(cfg, s, session.run_folder.path / "report.md"))
    return EXIT_MET


def _take_folder(stack, session: Session, open_folder, chosen, writer: bool):
    """Process 0 takes the results folder; in a job, every process learns at once
    whether it could (one small gather), so a refusal ends them all. Returns the
    folder to write into (None on the others)."""
    import jax

    from cgda_jax import distributed

    err, work = None, None
    if writer:
        try:
            rf = stack.enter_context(open_folder())
            session.run_folder = rf
            chosen(rf)
            work = rf.work
        except Exception as e:  # noqa: BLE001 - shared with the others, raised below
            err = e
    if jax.process_count() > 1:
        payload = None if err is None else failure(session, err)[0]
        refused = [s for s in distributed.allgather_objects(payload) if s is not None]
        if refused:
            session.job_open = False  # every process knows: all may end
        if refused and err is None:
            raise JobFailed(refused[0])  # process 0 says why
    if err is not None:
        raise err
    if not writer:
        session.run_folder = FolderElsewhere()  # process 0 holds it
    return work


def _run_share(cfg, session: Session, n: int, built=None) -> tuple[list[dict], int]:
    """This process's seeds in one batch, then every process's records. In a job a
    failure on any process is shared at the gather: it is raised where it happened
    and ends the others with its status (`JobFailed`), so no process waits for
    one that gave up."""
    import jax

    from cgda_jax import distributed
    from cgda_jax.experiment.success_rate import trial_records
    from cgda_jax.progress import ProgressLine

    seeds = [cfg.strategy.seed + i for i in range(n)]
    procs = jax.process_count()
    mine = [seeds[i] for i in distributed.share(n)] if procs > 1 else seeds
    where = f" over {procs} processes ({len(mine)} here)" if procs > 1 else ""
    say(session, f"[{cfg.name}] {cfg.strategy.name.upper()} execution, {n} seeds in one "
        f"batch{where} ...")
    bar = ProgressLine(cfg.name, quiet=session.quiet)
    err = None
    try:
        records = trial_records(cfg, mine, bar, built) if mine else []
    except Exception as e:
        if procs == 1:
            raise
        err, records = e, []
    finally:
        bar.close()
    if procs == 1:
        return records, procs
    if err is not None:
        status, line = failure(session, err)
        distributed.allgather_objects(("error", status))
        session.job_open = False
        raise JobFailed(status, line)
    gathered = distributed.allgather_objects(("ok", records))
    session.job_open = False  # the last step all processes take together
    for kind, value in gathered:
        if kind == "error":
            raise JobFailed(value)  # the failing process says why
    return [r for _, part in gathered for r in part], procs


def write_trials_folder(cfg, records, folder, t0: float, procs: int) -> dict:
    from cgda_jax.experiment.success_rate import write_trials

    return write_trials(cfg, records, folder,
                        {"total_time_s": time.perf_counter() - t0, "processes": procs})


# ---------------------------------------------------------------------------
# The launching process of ``--processes P``
# ---------------------------------------------------------------------------


def _launch(cfg, args, session: Session, open_folder, chosen) -> int:
    """Take the folder, start the P workers, move their folder into place once all
    ended well; a failure, a worker's death or an interrupt discards it."""
    from cgda_jax.results_folder.reading import read_json
    from cgda_jax.results_folder.rules import MARKER
    from cgda_jax.launch import start_job, without_option

    p = args.processes
    cmd = [sys.executable, "-m", "cgda_jax.cli", *without_option(session.argv,
                                                                 "--processes")]
    with open_folder() as rf:
        session.run_folder = rf
        chosen(rf)
        env = {ENV_JOB_WORK: str(rf.work), ENV_JOB_FOLDER: str(rf.path),
               "CGDA_LAUNCHED_PROCESSES": str(p)}
        # status 1 is not a failure of a worker; every process exits like process 0
        end = start_job(p, cmd, ok_codes=(0, 1), env=env, mute_on_end=True,
                        hold_s=LINE_HOLD_S, drop=_chatter, keep=_own_line)
        if end.reason == "interrupted":
            raise Interrupted(end.signum)
        if end.reason != "ok":
            raise JobFailed(*_worker_ended(end, rf))
        if not (rf.work / MARKER).is_file():
            raise JobFailed(EXIT_FAILURE, (
                f"cgda: error: every process ended well but process 0 wrote no "
                f"results; nothing written ({rf.path} left as it was)"))
        s = read_json(rf.work / MARKER)
    print(summary_line(cfg, s, rf.path / "report.md"))
    return EXIT_MET


def _chatter(line: str) -> bool:
    """gloo's own line on stdout as it connects the processes."""
    return line.startswith("[Gloo] ")


def _own_line(line: str) -> bool:
    """A worker's own ``cgda: ...`` line (its error): shown whoever ends first."""
    return line.startswith("cgda: ")


def _worker_ended(end, rf) -> tuple[int, str | None]:
    """The job's status and line when a worker ended it: a status of ``cgda``'s own
    (2, 3) was said by that worker; a signal is named here."""
    i, code = end.process, end.code
    kept = f"nothing written ({rf.path} left as it was)"
    if code in (EXIT_USAGE, EXIT_FAILURE):
        return code, None
    signum = -code if code < 0 else next(
        (s for s, c in EXIT_SIGNAL.items() if c == code), None)
    if signum in EXIT_SIGNAL:  # stopped from outside (a worker's SIGTERM, ...)
        name = signal.Signals(signum).name
        return EXIT_SIGNAL[signum], (f"cgda: interrupted ({name} to process {i}); "
                                     f"stopped the others; {kept}")
    how = (f"was killed by {signal.Signals(signum).name}" if code < 0 and signum
           else f"exited with status {end.status}")
    return EXIT_FAILURE, f"cgda: error: process {i} {how}; stopped the others; {kept}"
