"""A multi-process job ends as one job (issue 25, part 1): ``cgda run --trials N
--processes P`` under faults. Each case runs the real command in a subprocess and
checks its exit status, that stderr is one line, the folder afterwards (as it was,
no lock or temporary folder beside it) and, in the process table, that no process
of the job is left. Every case is time-boxed: a hang fails the test.

The jobs are stopped while their workers compile (signals) or before they compute
(refusals, a planned failure injected through ``sitecustomize``), so no case waits
for an evolution."""

import io
import os
import pathlib
import signal
import socket
import subprocess
import sys
import time
import uuid

import pytest

from cgda_jax.results_folder.writing import RunFolder

REPO = pathlib.Path(__file__).resolve().parents[1]
CLEAN = REPO / "experiments" / "clean_ie.toml"
# a run that would go on for minutes unless stopped; on the tiny arm without the
# feasibility check, so that every process is quick to build (and to check) it
LONG = ["strategy.population_size=4", "strategy.max_generations=1000000",
        "strategy.tolerance=1e-9", "strategy.options.stagnation=1000000",
        "strategy.feasibility=false", "robot.model=tiny_arm.xml",
        'robot.joints=["yaw", "shoulder", "elbow"]', "robot.fixed={}",
        "output.plots=false", "output.render=false"]
JOB_S = 90  # the longest any job below may take; it takes 2-10 s
GONE_S = 10  # every process of a job is gone this soon after it ended


def sets(settings):
    return [a for s in settings for a in ("--set", s)]


@pytest.fixture
def tag():
    return uuid.uuid4().hex


@pytest.fixture
def env(tmp_path, tag):
    """This checkout first on the path, CPU, a cache of its own, and a tag that
    finds the job's processes in the process table."""
    path = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)
    out = {**os.environ, "PYTHONPATH": path, "JAX_PLATFORMS": "cpu",
           "CGDA_JAX_CACHE": str(tmp_path / "cache"), "CGDA_TEST_TAG": tag}
    for name in ("CGDA_COORDINATOR", "CGDA_NUM_PROCESSES", "CGDA_PROCESS_ID",
                 "CGDA_CLUSTER", "CGDA_LAUNCHER_PID"):
        out.pop(name, None)
    return out


def tagged(tag: str) -> dict[int, dict[str, str]]:
    """Running processes (not zombies) whose environment holds the tag: pid ->
    their CGDA_* variables (the process table, from /proc)."""
    found = {}
    for entry in pathlib.Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            raw = (entry / "environ").read_bytes()
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state == "Z" or f"CGDA_TEST_TAG={tag}".encode() not in raw:
            continue
        env = dict(v.split("=", 1) for v in raw.decode(errors="replace").split("\0")
                   if v.startswith("CGDA_") and "=" in v)
        found[int(entry.name)] = env
    return found


def none_left(tag: str) -> None:
    deadline = time.monotonic() + GONE_S
    while tagged(tag) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not tagged(tag), f"processes left running: {tagged(tag)}"


def worker(tag: str, index: int, timeout: float = JOB_S) -> int:
    """The pid of the job's worker ``index`` (once it exists)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for pid, env in tagged(tag).items():
            if env.get("CGDA_PROCESS_ID") == str(index):
                return pid
        time.sleep(0.1)
    pytest.fail(f"no worker {index} appeared")


def no_leftovers(folder: pathlib.Path) -> None:
    hidden = sorted(p.name for p in folder.parent.iterdir() if p.name.startswith("."))
    assert hidden == [], hidden


def one_line(err: str, start: str) -> str:
    assert "Traceback" not in err and "stack trace" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(start), err
    return lines[0]


def cgda(env, *args, **kwargs):
    return subprocess.run([sys.executable, "-m", "cgda_jax.cli", *map(str, args)],
                          env=env, capture_output=True, text=True, timeout=JOB_S,
                          check=False, **kwargs)


def start(env, out, *extra):
    return subprocess.Popen(
        [sys.executable, "-m", "cgda_jax.cli", "run", str(CLEAN), "--trials", "2",
         "--processes", "2", "--out", str(out), *sets(LONG), *extra],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for_workers(proc) -> None:
    """Until process 0 says its share started: both workers joined the job, so
    they compile now (stderr read up to that line)."""
    deadline = time.monotonic() + JOB_S
    seen = []
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        seen.append(line)
        if line.startswith("[p0] ") and "seeds in one batch over 2 processes" in line:
            return
    proc.kill()
    pytest.fail(f"the job did not start: {''.join(seen)}")


def previous(folder: pathlib.Path) -> dict[str, str]:
    folder.mkdir()
    (folder / "result.json").write_text('{"run": "previous"}\n')
    (folder / "report.md").write_text("# previous\n")
    return {p.name: p.read_text() for p in folder.iterdir()}


def contents(folder: pathlib.Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in folder.iterdir()}


# ----------------------------------------------------------------- before a worker
@pytest.mark.parametrize("given, missing", [
    ({"CGDA_PROCESS_ID": "1", "CGDA_NUM_PROCESSES": "2"}, "CGDA_COORDINATOR"),
    ({"CGDA_COORDINATOR": "127.0.0.1:1234"}, "CGDA_NUM_PROCESSES and CGDA_PROCESS_ID"),
    ({"CGDA_CLUSTER": "auto", "CGDA_PROCESS_ID": "0"}, "not both"),
], ids=["id-without-coordinator", "coordinator-alone", "both-forms"])
def test_a_partial_job_environment_is_an_error_naming_the_variables(
        given, missing, env, tmp_path, tag):
    out = tmp_path / "out"
    proc = cgda({**env, **given}, "run", CLEAN, "--trials", "2", "--out", out,
                "--quiet")
    line = one_line(proc.stderr, "cgda: error:")
    assert proc.returncode == 2, proc.stderr
    assert missing in line and all(name in line for name in given), line
    assert not out.exists() and proc.stdout == ""
    none_left(tag)


def test_a_process_whose_job_never_joins_says_so_and_ends_with_status_3(
        env, tmp_path, tag):
    """Process 0 of 2 with nobody to join: silent for 300 s, then SIGABRT (134)
    with a 14-line C++ stack. Now it says it waits and, after CGDA_JOIN_TIMEOUT
    seconds, ends with status 3 and one line; nothing is left."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    job = {"CGDA_COORDINATOR": f"127.0.0.1:{port}", "CGDA_NUM_PROCESSES": "2",
           "CGDA_PROCESS_ID": "0", "CGDA_JOIN_TIMEOUT": "8"}
    out = tmp_path / "out"
    t0 = time.monotonic()
    proc = cgda({**env, **job}, "run", CLEAN, "--trials", "2", "--out", out,
                *sets(LONG))
    assert proc.returncode == 3, proc.stderr
    waiting, _, error = proc.stderr.strip().partition("\n")
    assert waiting == (f"[job] waiting for every process of the job to join at "
                       f"127.0.0.1:{port} (up to 8 s, CGDA_JOIN_TIMEOUT)")
    line = one_line(error, "cgda: error: the multi-process job at 127.0.0.1:")
    assert "did not join within 8 s" in line
    assert time.monotonic() - t0 < 8 + 60  # JAX's own wait ends 60 s later
    assert not out.exists()
    no_leftovers(out)
    none_left(tag)
    bad = cgda({**env, **job, "CGDA_JOIN_TIMEOUT": "soon"}, "run", CLEAN, "--trials",
               "2", "--out", out)
    assert bad.returncode == 2 and "CGDA_JOIN_TIMEOUT='soon'" in one_line(
        bad.stderr, "cgda: error:")


@pytest.mark.parametrize("case", ["not-empty", "in-use"])
def test_the_results_folder_is_checked_before_any_worker_starts(
        case, env, tmp_path, tag):
    out = tmp_path / "out"
    before = previous(out)
    holder = RunFolder(out, overwrite=True) if case == "in-use" else None
    if holder is not None:
        holder.__enter__()  # another run holds the folder's lock
    try:
        t0 = time.monotonic()
        proc = cgda(env, "run", CLEAN, "--trials", "2", "--processes", "2",
                    "--out", out, *sets(LONG), *(["--overwrite"] if holder else []))
        wall = time.monotonic() - t0
    finally:
        if holder is not None:
            holder.__exit__(KeyboardInterrupt, None, None)
    line = one_line(proc.stderr, "cgda: error: results folder")
    assert proc.returncode == 2
    assert ("not empty" if case == "not-empty" else "in use by another run") in line
    assert "[p" not in proc.stdout + proc.stderr  # no worker ever started
    assert contents(out) == before
    no_leftovers(out)
    none_left(tag)
    assert wall < 30, wall


# ------------------------------------------------------------------ while running
STOPS = {
    # who gets which signal, when -> (status, the one line)
    "SIGTERM-launcher": (143, "cgda: interrupted (SIGTERM); nothing written"),
    "SIGTERM-worker1": (143, ("cgda: interrupted (SIGTERM to process 1); stopped "
                              "the others; nothing written")),
    "SIGTERM-worker1-early": (143, ("cgda: interrupted (SIGTERM to process 1); "
                                    "stopped the others; nothing written")),
    "SIGKILL-worker0": (3, ("cgda: error: process 0 was killed by SIGKILL; stopped "
                            "the others; nothing written")),
}


@pytest.mark.parametrize("case", sorted(STOPS))
def test_a_signal_to_any_process_ends_the_whole_job_at_once(case, env, tmp_path, tag):
    """While the workers compile (or, early, while worker 1 is still starting).
    Process 0 hosts JAX's coordination service: when it dies first the others'
    runtime aborts with a C++ stack of its own, which must not reach the user."""
    out = tmp_path / "out"
    before = previous(out)
    proc = start(env, out, "--overwrite")
    try:
        name, who, *early = case.split("-")
        if not early:
            wait_for_workers(proc)
        sig = getattr(signal, name)
        if who == "launcher":
            proc.send_signal(sig)
        else:
            os.kill(worker(tag, int(who[-1])), sig)
        t0 = time.monotonic()
        _, err = proc.communicate(timeout=JOB_S)
        wall = time.monotonic() - t0
    finally:
        proc.kill()
    status, text = STOPS[case]
    assert proc.returncode == status, err
    workers = [line for line in err.splitlines() if line.startswith("[p")]
    lines = [line for line in err.splitlines() if not line.startswith("[p")]
    assert one_line("\n".join(lines), "cgda:") == f"{text} ({out} left as it was)"
    # nothing from the workers after the signal (no "SIGTERM caught" of JAX's
    # preemption notifier, no C++ stack); early, worker 0 may have said that its
    # share started
    assert all(early and "seeds in one batch" in line for line in workers), err
    assert wall < 10, wall  # seconds, not the 3 s + of a SIGKILL fallback each
    assert contents(out) == before
    no_leftovers(out)
    none_left(tag)


SITECUSTOMIZE = '''
import os
if os.environ.get("CGDA_PROCESS_ID") is not None:  # the job's workers only
    import cgda_jax.experiment.success_rate as trials

    def trial_records(cfg, seeds, progress_fn=None, built=None):
        if os.environ["CGDA_PROCESS_ID"] == os.environ["FAIL_ON"]:
            raise ValueError("planned failure of process " + os.environ["FAIL_ON"])
        return [{"seed": s, "success": True, "max_point_error": 0.0,
                 "final_fitness": 0.0, "generations": 1, "evaluations": 1,
                 "run_time_s": 0.0, "batch_run_time_s": 0.0, "compile_time_s": 0.0,
                 "trials_in_batch": len(seeds)} for s in seeds]

    trials.trial_records = trial_records
    if os.environ.get("FAIL_AT") == "alone":  # before the processes' first step
        check_trials = trials.check_trials

        def check_alone(cfg, n):
            if os.environ["CGDA_PROCESS_ID"] == os.environ["FAIL_ON"]:
                raise ValueError("planned failure of process " + os.environ["FAIL_ON"])
            return check_trials(cfg, n)

        trials.check_trials = check_alone
'''


@pytest.fixture
def planned(env, tmp_path):
    """The workers' seeds cost nothing; FAIL_ON names a process whose share fails."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    return {**env, "PYTHONPATH": os.pathsep.join([str(site), env["PYTHONPATH"]])}


@pytest.mark.parametrize("at", ["share", "alone"])
def test_a_worker_s_failure_ends_every_process_with_its_line(
        at, planned, tmp_path, tag):
    """In its share of the seeds (the others learn of it at the gather; a failure
    once the run started: status 3 and its traceback in a log), or alone before
    the processes' first common step (process 0 waits there for it: the failing
    one must leave at once rather than wait in JAX's exit for the others)."""
    out = tmp_path / "out"
    t0 = time.monotonic()
    proc = cgda({**planned, "FAIL_ON": "1", "FAIL_AT": at}, "run", CLEAN, "--trials",
                "3", "--processes", "2", "--out", out, "--quiet", *sets(LONG))
    wall = time.monotonic() - t0
    none_left(tag)
    if at == "share":
        line = one_line(proc.stderr, "[p1] cgda: error: ValueError: planned failure "
                        "of process 1 (traceback in ")
        assert proc.returncode == 3, line
    else:
        line = one_line(proc.stderr, "[p1] cgda: error: planned failure of process 1")
        assert proc.returncode == 2, line
    assert proc.stdout == ""
    assert not out.exists()
    no_leftovers(out)
    assert wall < 60, wall  # not a gather waiting for the process that gave up


def test_a_cluster_job_s_process_0_refusal_ends_them_all(env, tmp_path, tag):
    """Without the launcher (the CGDA_* variables set per process, as a scheduler
    does), process 0 takes the folder; its refusal reaches the others at once."""
    out = tmp_path / "out"
    before = previous(out)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    job = {"CGDA_COORDINATOR": f"127.0.0.1:{port}", "CGDA_NUM_PROCESSES": "2"}
    procs = [subprocess.Popen(
        [sys.executable, "-m", "cgda_jax.cli", "run", str(CLEAN), "--trials", "2",
         "--out", str(out), *sets(LONG)],
        env={**env, **job, "CGDA_PROCESS_ID": str(i)}, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True) for i in range(2)]
    try:
        done = [p.communicate(timeout=JOB_S) for p in procs]
    finally:
        for p in procs:
            p.kill()
    assert [p.returncode for p in procs] == [2, 2], done
    line = one_line(done[0][1], "cgda: error: results folder")
    assert "not empty" in line
    assert done[1][1] == ""  # process 1 ends with process 0's status, quietly
    assert contents(out) == before
    no_leftovers(out)
    none_left(tag)


# ------------------------------------------------------------------ the launcher
def test_sigint_to_start_job_stops_every_worker_and_says_how_it_ended(tag):
    import threading

    from cgda_jax.launch import start_job

    env = {"CGDA_TEST_TAG": tag}
    # Python's own SIGINT handling (KeyboardInterrupt), whatever an earlier test in
    # this process left installed (the full suite once swallowed the signal here)
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        end = start_job(2, [sys.executable, "-c", "import time; time.sleep(60)"],
                        env=env, stdout=io.StringIO(), stderr=io.StringIO(),
                        timeout_s=30)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, old)
    assert (end.status, end.reason, end.signum) == (130, "interrupted", signal.SIGINT)
    none_left(tag)


CHILD = """
import os, pathlib, sys, time
here = pathlib.Path(sys.argv[1])
if os.environ["CGDA_PROCESS_ID"] == "1":
    while not (here / "ending").exists():
        time.sleep(0.02)
    print("NOISE as process 0 ends", flush=True)
    print("cgda: error: process 1's own line", file=sys.stderr, flush=True)
    (here / "said").touch()
    time.sleep(60)
else:
    print("hello", flush=True)
    time.sleep(1.5)  # "hello" is shown meanwhile
    (here / "ending").touch()
    while not (here / "said").exists():
        time.sleep(0.02)
    print("my own error", file=sys.stderr, flush=True)
    sys.exit(3)
"""


@pytest.mark.parametrize("hold_s", [0.0, 5.0])
def test_lines_printed_as_a_job_ends_are_held_and_dropped(hold_s, tmp_path, tag):
    """Process 1 prints a line just before process 0 fails (as JAX's runtime does
    when its coordinator vanishes): held, it is dropped with the others' lines;
    the failing process's own line is kept, and so is a line ``keep`` names (a
    worker's own error, when it happened to end second). Without holding the noise
    gets through."""
    from cgda_jax.launch import start_job

    out, err = io.StringIO(), io.StringIO()
    end = start_job(2, [sys.executable, "-c", CHILD, str(tmp_path)],
                    env={"CGDA_TEST_TAG": tag}, stdout=out, stderr=err,
                    mute_on_end=True, hold_s=hold_s,
                    drop=lambda line: line.startswith("[Gloo] "),
                    keep=lambda line: line.startswith("cgda: "))
    assert (end.status, end.reason, end.process) == (3, "failed", 0)
    # two processes' pipes are relayed by their own threads: the order of lines from
    # different processes is not fixed (seen under load), their content is
    assert sorted(err.getvalue().splitlines(keepends=True)) == [
        "[p0] my own error\n", "[p1] cgda: error: process 1's own line\n"]
    noise = "[p1] NOISE as process 0 ends\n"
    assert out.getvalue() == "[p0] hello\n" + ("" if hold_s else noise)
    none_left(tag)


HELPER_PARENT = """
import os, signal, subprocess, sys, time
helper = '''
import os, signal, sys, time
signal.signal(signal.SIGTERM, signal.SIG_IGN)  # outlives the group's SIGTERM
parent = int(sys.argv[1])
while os.path.exists(f"/proc/{parent}"):
    time.sleep(0.02)
print("helper: my parent vanished", file=sys.stderr, flush=True)
'''
if os.environ["CGDA_PROCESS_ID"] == "1":
    signal.signal(signal.SIGTERM, lambda *a: sys.exit(143))  # caught, as cgda does
    subprocess.Popen([sys.executable, "-c", helper, str(os.getpid())])
    print("process 1 ready", file=sys.stderr, flush=True)
time.sleep(60)
"""


@pytest.mark.skipif(not pathlib.Path("/proc").is_dir(), reason="needs /proc")
def test_a_helper_complaining_after_a_caught_signal_is_dropped(tmp_path, tag):
    """Process 1 catches SIGTERM and exits 143; a helper it started then complains
    on the pipe it inherited (as in a flaky CI run: a BrokenPipeError traceback
    relayed as "[p1] ..."). That is noise like the others' lines, not process 1's
    own last words: dropped."""
    import threading

    from cgda_jax.launch import start_job

    out, err = io.StringIO(), io.StringIO()

    def stop_process_1():
        os.kill(worker(tag, 1), signal.SIGTERM)

    timer = threading.Timer(1.5, stop_process_1)
    timer.start()
    try:
        end = start_job(2, [sys.executable, "-c", HELPER_PARENT],
                        env={"CGDA_TEST_TAG": tag}, stdout=out, stderr=err,
                        mute_on_end=True, keep=lambda line: line.startswith("cgda: "))
    finally:
        timer.cancel()
    assert (end.status, end.reason, end.process) == (143, "failed", 1), end
    assert "helper" not in err.getvalue(), err.getvalue()
    none_left(tag)
