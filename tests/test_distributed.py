"""Multi-process runs (cgda_jax.distributed): 2 real processes on this machine joined
through jax.distributed (localhost coordinator, gloo CPU collectives) give the same
per-seed results as one process; a failing worker stops the job fast."""

import io
import os
import pathlib
import pickle
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import distributed as dist
from cgda_jax.sim import MarkerScene, Robot, Simulator, model_path
from cgda_jax.strategies import run_trials

TIMEOUT_S = 240  # the whole 2-process job (~50 s on a loaded 2-core machine); stopped
# and failed after it
KW = {"population_size": 6, "tolerance": 0.02, "max_generations": 12, "chunk_size": 4}
N_TRIALS, SEED = 5, 3  # 3 trials on process 0, 2 on process 1

# The same problem in the workers and here (single-process reference).
SETUP = """
import jax.numpy as jnp
from cgda_jax.sim import MarkerScene, Robot, Simulator, model_path
robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                        "marker")
sim = Simulator(robot, MarkerScene(), substeps=2)
goal = sim.execute(jnp.array([[0.3, 0.4, -0.5], [-0.2, 0.6, 0.3]]))
"""

WORKER = """
import os, pickle, sys
from cgda_jax import distributed as dist
assert dist.initialize(timeout_s=60, heartbeat_timeout_s=90)
import jax
assert jax.process_count() == 2 and len(jax.devices()) == 2, jax.devices()
assert dist.is_writer() == (jax.process_index() == 0)
""" + SETUP + f"""
if os.environ.get("FAIL_ON") == str(jax.process_index()):
    import cgda_jax.strategies as t
    def boom(*a, **k):
        raise ValueError("planned failure")
    t.run_trials = boom
res = dist.distributed_trials("ie", sim, goal, {N_TRIALS}, seed={SEED}, **{KW!r})
print("WORKER-OK", jax.process_index(), [r.info["process"] for r in res], flush=True)
if dist.is_writer():
    with open(sys.argv[1], "wb") as f:
        pickle.dump(res, f)
"""

needs_gloo = pytest.mark.skipif(
    "jax_cpu_collectives_implementation" not in jax.config.values,
    reason=f"jax {jax.__version__} has no gloo CPU collectives "
    "(jax_cpu_collectives_implementation): processes cannot gather results",
)


def _launch(tmp_path, extra_env=None):
    script = tmp_path / "worker.py"
    script.write_text(WORKER)
    out, err = io.StringIO(), io.StringIO()
    env = {"JAX_PLATFORMS": "cpu", **(extra_env or {})}
    t0 = time.monotonic()
    code = dist.launch(2, [sys.executable, str(script), str(tmp_path / "res.pkl")],
                       timeout_s=TIMEOUT_S, env=env, stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue(), time.monotonic() - t0


@needs_gloo
def test_two_processes_give_the_single_process_results(tmp_path):
    code, out, err, _ = _launch(tmp_path)
    assert code == 0, out + err[-4000:]
    # both processes hold all 5 results: 3 ran on process 0, 2 on process 1
    assert "[p0] WORKER-OK 0 [0, 0, 0, 1, 1]" in out, out
    assert "[p1] WORKER-OK 1 [0, 0, 0, 1, 1]" in out, out
    got = pickle.loads((tmp_path / "res.pkl").read_bytes())
    ns: dict = {}
    exec(SETUP, ns)  # noqa: S102 - the workers' own set-up
    ref = run_trials("ie", ns["sim"], ns["goal"], N_TRIALS, seed=SEED, **KW)
    assert [r.info["seed"] for r in got] == list(range(SEED, SEED + N_TRIALS))
    for g, r in zip(got, ref, strict=True):
        assert g.info["seed"] == r.info["seed"]
        # same per-trial program; only the batch size (3 or 2 vs 5) differs
        np.testing.assert_allclose(g.joints, r.joints, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(g.features, r.features, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(g.point_errors, r.point_errors, atol=1e-5)
        np.testing.assert_allclose(g.fitness_history, r.fitness_history,
                                   rtol=1e-5, atol=1e-6)
        assert (g.success, g.generations, g.evaluations) == (
            r.success, r.generations, r.evaluations)
    # Bit for bit the results of the batches each process ran (seeds 3-5 and 6-7):
    # the gather moves results exactly and each seed went to its process.
    # (Against the 5-trial batch above they agree only to float32 rounding: XLA's
    # code for a batch of 5 rounds differently from one of 3, as within a single
    # process.)
    parts = [run_trials("ie", ns["sim"], ns["goal"], 3, seed=SEED, **KW),
             run_trials("ie", ns["sim"], ns["goal"], 2, seed=SEED + 3, **KW)]
    for g, r in zip(got, parts[0] + parts[1], strict=True):
        for name in ("joints", "features", "point_errors", "fitness_history"):
            np.testing.assert_array_equal(getattr(g, name), getattr(r, name))
        assert g.summary() | {"wall_time_s": 0, "compile_time_s": 0, "info": 0} == (
            r.summary() | {"wall_time_s": 0, "compile_time_s": 0, "info": 0})
    # the trials differ from each other (a gather that copied one would fail)
    assert len({tuple(np.round(r.joints.ravel(), 4)) for r in got}) == N_TRIALS


@needs_gloo
def test_a_failing_process_fails_the_job_on_every_process(tmp_path):
    code, out, err, wall = _launch(tmp_path, {"FAIL_ON": "1"})
    assert code == 1, out + err[-4000:]
    assert "WORKER-OK" not in out
    # process 0 got process 1's error through the gather, not a hang
    assert "ValueError: planned failure" in err and "raised on process 1 of 2" in err
    assert wall < TIMEOUT_S


SLEEPER = "import os, sys, time; i = os.environ['CGDA_PROCESS_ID']; " \
    "print('hello from', i, os.environ['CGDA_NUM_PROCESSES'], flush=True); " \
    "time.sleep(0.2 if i == '0' else 60); sys.exit(int(sys.argv[1]) if i == '0' else 0)"


def test_launch_prefixes_output_and_returns_process_0_status():
    out, err = io.StringIO(), io.StringIO()
    code = dist.launch(1, [sys.executable, "-c", SLEEPER, "1"], timeout_s=30,
                       ok_codes=(0, 1), stdout=out, stderr=err)
    assert code == 1 and "[p0] hello from 0 1" in out.getvalue()


def test_launch_stops_the_others_when_one_fails():
    out, err = io.StringIO(), io.StringIO()
    t0 = time.monotonic()
    # process 0 fails with 3 after 0.2 s; process 1 would sleep 60 s
    code = dist.launch(2, [sys.executable, "-c", SLEEPER, "3"], timeout_s=50,
                       stdout=out, stderr=err)
    assert code == 3 and time.monotonic() - t0 < 20
    assert "[p1] hello from 1 2" in out.getvalue()
    assert "process 0 exited with status 3; stopped the others" in err.getvalue()


def test_launch_timeout_stops_everything():
    err = io.StringIO()
    t0 = time.monotonic()
    code = dist.launch(2, [sys.executable, "-c", "import time; time.sleep(60)"],
                       timeout_s=1, stdout=io.StringIO(), stderr=err)
    assert code == 124 and time.monotonic() - t0 < 15
    assert "timed out after 1 s" in err.getvalue()


def test_share_deals_trials_over_all_devices_in_process_order():
    # 2 processes with 1 device each
    assert [share for share in (dist.share(5, [1, 1], i) for i in (0, 1))] == [
        range(3), range(3, 5)]
    # unequal device counts: 10 trials over 1 + 3 devices -> 3 | 3+2+2
    assert dist.share(10, [1, 3], 0) == range(3)
    assert dist.share(10, [1, 3], 1) == range(3, 10)
    # fewer trials than devices: the last processes get none
    assert [len(dist.share(2, [1, 1, 1], i)) for i in range(3)] == [1, 1, 0]
    # one process: everything
    assert dist.share(7) == range(7)


def test_job_from_env_forms_and_errors():
    assert dist.job_from_env({}) is None
    job = dist.job_from_env({"CGDA_COORDINATOR": "node0:1234",
                             "CGDA_NUM_PROCESSES": "4", "CGDA_PROCESS_ID": "2",
                             "CGDA_LOCAL_DEVICE_IDS": "0,1"})
    assert job == {"coordinator_address": "node0:1234", "num_processes": 4,
                   "process_id": 2, "local_device_ids": [0, 1]}
    assert dist.job_from_env({"CGDA_CLUSTER": "auto"}) == {
        "cluster_detection_method": None, "local_device_ids": None}
    assert dist.job_from_env({"CGDA_CLUSTER": "slurm"})[
        "cluster_detection_method"] == "slurm"
    with pytest.raises(ValueError, match="CGDA_PROCESS_ID is not"):
        dist.job_from_env({"CGDA_COORDINATOR": "h:1", "CGDA_NUM_PROCESSES": "2"})
    with pytest.raises(ValueError, match="use host:port"):
        dist.job_from_env({"CGDA_COORDINATOR": "h", "CGDA_NUM_PROCESSES": "2",
                           "CGDA_PROCESS_ID": "0"})
    with pytest.raises(ValueError, match="0 <= CGDA_PROCESS_ID"):
        dist.job_from_env({"CGDA_COORDINATOR": "h:1", "CGDA_NUM_PROCESSES": "2",
                           "CGDA_PROCESS_ID": "2"})
    with pytest.raises(ValueError, match="CGDA_LOCAL_DEVICE_IDS"):
        dist.job_from_env({"CGDA_LOCAL_DEVICE_IDS": "gpu0"})


def test_single_process_without_a_job(monkeypatch):
    for name in ("CGDA_COORDINATOR", "CGDA_CLUSTER", "CGDA_PROCESS_ID"):
        monkeypatch.delenv(name, raising=False)
    assert dist.initialize() is False and dist.is_writer()
    monkeypatch.setenv("CGDA_PROCESS_ID", "1")  # a worker before it joined
    assert not dist.is_writer()
    assert dist.allgather_objects({"a": 1}) == [{"a": 1}]
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    sim = Simulator(robot, MarkerScene(), substeps=2)
    goal = sim.execute(jnp.array([[0.3, 0.4, -0.5]]))
    with pytest.raises(ValueError, match="decides `devices`"):
        dist.distributed_trials("ie", sim, goal, 2, devices=2, **KW)


def test_launch_module_command_line(capsys):
    from cgda_jax.launch import main

    code = main(["-n", "2", "--", sys.executable, "-c", SLEEPER.replace(
        "60", "0.1"), "0"])
    out = capsys.readouterr().out
    assert code == 0 and "[p0] hello from 0 2" in out and "[p1] hello from 1 2" in out
    with pytest.raises(SystemExit):
        main(["-n", "2"])  # no command


def test_without_option():
    from cgda_jax.launch import without_option

    argv = ["run", "c.toml", "--processes", "4", "--trials", "8", "--processes=2"]
    assert without_option(argv, "--processes") == ["run", "c.toml", "--trials", "8"]
    assert without_option(["--processesx", "1"], "--processes") == ["--processesx", "1"]


def test_sigterm_to_the_launcher_leaves_no_worker():
    import signal
    import subprocess

    child = "import os, time; print('pid', os.getpid(), flush=True); time.sleep(60)"
    proc = subprocess.Popen(
        [sys.executable, "-m", "cgda_jax.launch", "-n", "2", "--", sys.executable,
         "-c", child], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    pids = []
    while len(pids) < 2:
        line = proc.stdout.readline()
        assert line, proc.stderr.read()
        pids.append(int(line.split()[-1]))
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 143
    assert "interrupted (SIGTERM)" in proc.stderr.read()
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


GATHER_LATE = """
import time
from cgda_jax import distributed as dist
assert dist.initialize(timeout_s=60)
import jax
if jax.process_index() == 1:
    time.sleep(40)  # longer than gloo's 30 s limit for setting up its first collective
got = dist.allgather_objects({"p": jax.process_index(), "x": "ab" * jax.process_index()})
assert got == [{"p": 0, "x": ""}, {"p": 1, "x": "ab"}], got
print("GATHER-OK", flush=True)
"""


@pytest.mark.slow
@needs_gloo
def test_gather_waits_for_a_process_40_s_late():
    out = io.StringIO()
    code = dist.launch(2, [sys.executable, "-c", GATHER_LATE], timeout_s=TIMEOUT_S,
                       env={"JAX_PLATFORMS": "cpu"}, stdout=out, stderr=io.StringIO())
    assert code == 0 and out.getvalue().count("GATHER-OK") == 2, out.getvalue()


# process 0 starts a helper that shares its stderr and reads from it, then is
# killed: the helper notices its parent gone, complains and would stay 60 s
ORPHANING = """
import os, signal, subprocess, sys, time
if os.environ['CGDA_PROCESS_ID'] == '0':
    helper = subprocess.Popen([sys.executable, '-c', '''
import os, sys, time
print('helper', os.getpid(), flush=True)
try:
    input()
except EOFError:
    sys.stderr.write('Traceback (most recent call last):\\\\nEOFError: parent gone\\\\n')
    sys.stderr.flush()
time.sleep(60)
'''], stdin=subprocess.PIPE, stdout=sys.stdout)
    time.sleep(1.0)
    os.kill(os.getpid(), signal.SIGKILL)
time.sleep(60)
"""


def test_a_worker_killed_by_a_signal_leaves_no_helper_and_no_noise():
    """What a killed worker started is stopped with the job, and what it prints
    as it notices (on the worker's pipes) does not reach the user."""
    from cgda_jax.launch import start_job

    out, err = io.StringIO(), io.StringIO()
    t0 = time.monotonic()
    end = start_job(2, [sys.executable, "-c", ORPHANING], timeout_s=50, stdout=out,
                    stderr=err, mute_on_end=True, hold_s=0.5)
    assert end.reason == "failed" and end.process == 0 and end.code == -9
    assert time.monotonic() - t0 < 20
    assert "Traceback" not in err.getvalue() and "parent gone" not in err.getvalue()
    helper = int(next(line for line in out.getvalue().splitlines()
                      if "helper" in line).split()[-1])
    # SIGKILL is delivered asynchronously: the process may take a moment to die
    deadline = time.monotonic() + 5.0
    while _running(helper) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _running(helper)


def _running(pid: int) -> bool:
    """`pid` exists and is not a zombie (an orphan killed waits for init to reap it)."""
    try:
        stat = pathlib.Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"
