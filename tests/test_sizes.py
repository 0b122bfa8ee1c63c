"""Sizes before memory (issue 25): every size a run or a call allocates is estimated in
one place (`cgda_jax.sizes`) and refused by name, with the estimate, before anything
is allocated or compiled: in the API, in ``--dry-run`` and in the run."""

import os
import pathlib
import re
import subprocess
import sys
import time

import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path, sizes
from cgda_jax.sizes import SizeError

REPO = pathlib.Path(__file__).resolve().parents[1]
EXP = REPO / "experiments"  # this checkout's configs, not an installed copy
JOINTS = ["yaw", "shoulder", "elbow"]


@pytest.fixture(scope="module")
def sim():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")
    return Simulator(robot, MarkerScene(), substeps=2)


@pytest.fixture(scope="module")
def goal(sim):
    qs = [[0.2, 0.5, 0.6], [0.4, 0.6, 0.8], [0.6, 0.7, 0.6]]
    return np.stack([np.asarray(sim.robot.marker_position(jnp.asarray(q))) for q in qs])


# --------------------------------------------------------------------------- estimates
def clean_ie(trials):
    """clean_ie's run (TEO: 9 points, 3 features, 3 joints, 8 bodies, 4096 samples)."""
    return sizes.run_estimate(trials=trials, population=32, points=9, features=3,
                              dof=3, bodies=8, strategy="ie", samples=4096)


def test_the_estimate_matches_what_xla_measured_and_finds_the_32_bit_limit():
    # XLA's memory_analysis() of clean_ie's init at 4 trials: 4.06 MB temporaries
    assert 3.5e6 < clean_ie(4).nbytes < 4.5e6
    # the array that aborted XLA at 100000 trials (f32[3, 3.3e9]) is refused
    est = clean_ie(100_000)
    assert est.largest > sizes.INT32_ELEMENTS and est.scale == "trials"
    with pytest.raises(SizeError, match=r"--trials: 100,000 trials of IE needs one "
                       r"array of 1.23e\+10 elements .* beyond XLA's 32-bit limit.*at "
                       r"most 17,476 trials fit"):
        sizes.check_estimate(est, "--trials", memory=None)
    sizes.check_estimate(clean_ie(1000), "--trials", memory=None)  # 1e8: fits


def test_memory_is_checked_against_what_is_available():
    est = clean_ie(1000)  # about 0.9 GiB
    with pytest.raises(SizeError, match=r"n_trials: .* needs about 924 MiB of memory, "
                       r"more than 80% of the 512 MiB available; at most 443 trials"):
        sizes.check_estimate(est, "n_trials", memory=512 * 2**20)
    sizes.check_estimate(est, "n_trials", memory=64 * 2**30)
    assert sizes.available_memory() > 0 and sizes.cores() >= 1


def test_processes_against_cores_and_memory():
    with pytest.raises(SizeError, match=rf"--processes {sizes.cores() + 1}: this "
                       rf"machine gives this process {sizes.cores()} core"):
        sizes.check_processes(sizes.cores() + 1)
    sizes.check_processes(sizes.cores() + 1, local=False)  # spread over a cluster
    with pytest.raises(SizeError, match="--processes 1: 1 process needs about"):
        sizes.check_processes(1, run_bytes=10**15)


# --------------------------------------------------------------------------- the API
def test_run_trials_refuses_before_compiling(sim, goal):
    from cgda_jax import run_ie, run_trials

    t0 = time.perf_counter()
    with pytest.raises(SizeError, match=r"n_trials: 1,000,000 trials of IE needs one "
                       r"array .* 32-bit limit"):
        run_trials("ie", sim, goal, 10**6, population_size=8, max_generations=2)
    with pytest.raises(SizeError, match=r"restart_samples: 1 trial of IE needs one "
                       r"array .* at most \d[\d,]* samples fit"):
        run_ie(sim, goal, population_size=8, max_generations=2,
               restart_samples=10**9)
    assert time.perf_counter() - t0 < 20  # nothing compiled, nothing allocated


def test_one_sampled_postures_rule_for_the_plan_its_size_and_the_config(sim, goal):
    """The postures a trial samples are decided once (`PlanBase.sampled_postures`):
    the plan uses it, its size estimate counts it and the config's checks ask it
    (no copy of the rule in `cgda_jax.experiment.validate`). Nothing compiles."""
    from cgda_jax.experiment import ConfigError, check_experiment, load_config
    from cgda_jax.strategies import (
        FTEPlan,
        FTESettings,
        IEPlan,
        IESettings,
        IETPlan,
        IETSettings,
        OETPlan,
        OETSettings,
    )

    kin = jnp.asarray(goal, jnp.float32)
    cases = [(FTEPlan, FTESettings(init="auto", init_samples=70), (70, "init_samples")),
             (FTEPlan, FTESettings(init="start", init_samples=70), (0, "init_samples")),
             (IEPlan, IESettings(restarts=2, restart_samples=50),
              (50, "restart_samples")),
             (IEPlan, IESettings(restarts=0, restart_samples=50),
              (0, "restart_samples")),
             (IETPlan, IETSettings(restarts=1, restart_samples=30),
              (30, "restart_samples")),
             (OETPlan, OETSettings(), (0, ""))]
    for plan_cls, st, want in cases:
        assert plan_cls.sampled_postures(st, sim) == want, (plan_cls, st)
        plan = plan_cls(sim, kin, st)
        assert plan.estimate(3) == sizes.sim_estimate(
            sim, trials=3, population=st.population_size, points=kin.shape[0],
            strategy=plan.name, samples=want[0])
    # the config's checks name the option the rule names (FTE's init "auto" on a
    # kinematic marker run samples init_samples postures)
    cfg = load_config(EXP / "clean_fte.toml",
                      ["strategy.options.init_samples=1000000000"])
    with pytest.raises(ConfigError, match=r"strategy\.options\.init_samples"):
        check_experiment(cfg)


def test_seeds_outside_32_bits_are_refused_by_name(sim, goal):
    from cgda_jax import run_trials

    with pytest.raises(ValueError, match=r"seed 4294967296 \(trial 1\) is not an "
                       r"integer in 0 .. 4294967295"):
        run_trials("ie", sim, goal, 2, seed=2**32 - 1, population_size=4,
                   max_generations=1)


def test_recognition_samples_are_refused_before_allocating():
    import cgda_jax as cg
    from cgda_jax.datasets import synthetic_actions

    demos = synthetic_actions(3, 0)
    lib = cg.ActionLibrary.from_demonstrations({k: v[:2] for k, v in demos.items()})
    queries = [v[2] for v in demos.values()]
    t0 = time.perf_counter()
    with pytest.raises(SizeError, match=r"n_samples: recognition of 4 queries x 4 "
                       r"actions at 1,000,000,000 samples"):
        cg.recognize(queries, lib, n_samples=10**9)
    with pytest.raises(SizeError, match=r"n_samples: .* DTW cells .* at most 88,388"):
        cg.recognize(queries, lib, n_samples=10**6)
    assert time.perf_counter() - t0 < 5  # refused, not computed
    with pytest.raises(ValueError, match="n_samples must be a whole number >= 2"):
        cg.recognize(queries, lib, n_samples=2.5)
    # euclidean is linear in the samples: no DTW-cell limit, the memory one stays
    cg.cost_matrix(queries[:1], lib, metric="euclidean", n_samples=200_000)


def test_object_demonstrations_check_their_duration_first():
    from cgda_jax.datasets import move_box_demos, rotate_valve_demos

    with pytest.raises(SizeError, match=r"duration_s: 1e\+09 s at 30 Hz is 3.45e\+10 "
                       r"samples per demonstration"):
        move_box_demos(duration_s=1e9)
    with pytest.raises(ValueError, match="duration_s must be a finite number > 0"):
        rotate_valve_demos(duration_s=float("inf"))
    assert len(move_box_demos(n=1, duration_s=20.0)[0].times) > 500


# --------------------------------------------------------------------------- the CLI
@pytest.fixture(scope="module")
def env(tmp_path_factory):
    path = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path, "JAX_PLATFORMS": "cpu",
            "CGDA_JAX_CACHE": str(tmp_path_factory.getbasetemp() / "jaxcache")}


#: Address space of a process whose memory a test bounds (3 GB: a refused size
#: allocates nothing; JAX and XLA reserve about 1 GB of address space).
BOUND = 3_000_000_000


def cgda(env, *args, bound: int | None = None, timeout: float = 120):
    """``cgda ARGS`` in a process, its address space within ``bound`` bytes."""
    cmd = [sys.executable, "-m", "cgda_jax.cli"] if bound is None else [
        sys.executable, "-c", "import resource, sys; resource.setrlimit(resource."
        f"RLIMIT_AS, ({bound}, {bound})); from cgda_jax.cli import main; "
        "sys.exit(main(sys.argv[1:]))"]
    return subprocess.run([*cmd, *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=timeout, check=False)


def one_error(proc) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("cgda: error:"), \
        proc.stderr
    assert "Traceback" not in proc.stderr
    return proc.stderr


def test_cli_refuses_100000_trials_before_the_folder_or_xla(env, tmp_path):
    """It aborted inside XLA (SIGABRT, 32 lines of C++), leaving a lock and a
    temporary folder; the dry-run called it valid."""
    out = tmp_path / "out"
    err = one_error(cgda(env, "run", EXP / "clean_ie.toml", "--trials", 100000,
                         "--out", out, "--quiet"))
    assert "--trials: 100,000 trials" in err and "32-bit" in err and "fit" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no folder, lock, .tmp
    err = one_error(cgda(env, "run", EXP / "clean_ie.toml", "--dry-run", "--trials",
                         10**9))
    assert "--trials: 1,000,000,000 trials" in err


@pytest.mark.parametrize("args, words", [
    ([str(EXP / "clean_ie.toml"), "--trials", "2", "--set",
      "strategy.seed=4294967295"],
     ["strategy.seed", "4294967296", "32-bit"]),
    ([str(EXP / "move_push_box.toml"), "--set", "data.duration_s=1e9"],
     ["data.duration_s", "3.45e+10 samples per demonstration"]),
    ([str(EXP / "clean_ie.toml"), "--trials", "4", "--processes",
      str(sizes.cores() + 1)],
     [f"--processes {sizes.cores() + 1}", "core"]),
])
def test_cli_dry_run_refuses_sizes_by_name(env, args, words):
    err = one_error(cgda(env, "run", *args, "--dry-run"))
    for w in words:
        assert w in err


def test_generalization_and_resampling_sizes_are_refused_by_name():
    from cgda_jax import generalize, resample
    from cgda_jax.datasets import clean_circle_demos

    demos = clean_circle_demos(n=2, seed=0)
    with pytest.raises(SizeError, match=r"interval_s: 1e-06 s cuts the .* into "
                       r"[\d,]+ intervals, more than 10,000"):
        generalize(demos, interval_s=1e-6)
    action = generalize(demos, interval_s=1.0)
    with pytest.raises(SizeError, match=r"n: 3,000,000,000 samples x \d+ knots is one "
                       r"array .* 32-bit"):
        action.sample(3 * 10**9)
    with pytest.raises(SizeError, match=r"n: 1,000,000,000 samples x 3 features"):
        resample(np.zeros((5, 3), np.float32), 10**9)


# ------------------------------------------ what the checks let through (issue 43)
@pytest.mark.parametrize("setting, words", [
    ("strategy.population_size=1000000",
     ["keys 'strategy.population_size' and 'feasibility.samples'",
      "9,000,000 waypoints' moves x", "values of the motion check", "32-bit",
      "candidates fit"]),
    ("feasibility.samples=100000000",
     ["keys 'strategy.population_size' and 'feasibility.samples'",
      "not even 1 candidate fits"]),
])
def test_the_motion_check_s_samples_are_in_the_estimate(env, setting, words):
    """Both passed --dry-run and died after 60 s: "Out of memory allocating
    463,056,467,600 bytes" (status 3, 16 lines of XLA warnings)."""
    err = one_error(cgda(env, "run", EXP / "clean_ie.toml", "--dry-run", "--set",
                         setting, bound=BOUND))
    for w in words:
        assert w in err


def test_trials_the_refusal_says_fit_are_those_the_estimate_allows(env):
    """The --trials 100000 refusal said 17,476 fit (the 32-bit limit of the sampled
    postures alone), and 17,476 trials grew past 8 GB; the motion check's samples
    now count."""
    err = one_error(cgda(env, "run", EXP / "clean_ie.toml", "--dry-run", "--trials",
                         100000, bound=BOUND))
    fit = int(re.search(r"at most ([\d,]+) trials fit", err)[1].replace(",", ""))
    assert fit < 17_476
    assert "values of the motion check" in err


def test_the_pair_culling_s_grid_is_bounded_for_many_joints(tmp_path):
    """30 evolved joints: `cgda run` was killed at 23.6 GB, --dry-run passed 5 GB
    (a grid of 2**30 postures). 24 joints within 3 GB and a minute now; every pair
    that does not overlap at start is kept (checking more pairs is safe)."""
    code = f"""
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, ({BOUND}, {BOUND}))
import mujoco
from cgda_jax import Robot
from cgda_jax.sim.collision import Collider
from cgda_jax.sim.feasibility import relevant_pairs
n = 24
links = "".join(f'<body pos="0 0 0.05"><joint name="j{{i}}" axis="0 {{i % 2}} '
                f'{{1 - i % 2}}" range="-60 60"/><geom name="g{{i}}" type="capsule" '
                f'fromto="0 0 0 0 0 0.05" size="0.01"/>' for i in range(n))
xml = (f'<mujoco><compiler angle="degree"/><worldbody><geom name="floor" '
       f'type="plane" size="1 1 .1"/>{{links}}<site name="marker"/>'
       f'{{"</body>" * n}}</worldbody></mujoco>')
robot = Robot(mujoco.MjModel.from_xml_string(xml), [f"j{{i}}" for i in range(n)],
              "marker")
pairs = [("g20", "floor")]
keep, overlapping = relevant_pairs(Collider(robot, only=pairs), robot)
print(sorted(keep), sorted(overlapping))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True,
                          text=True, timeout=120, check=False,
                          env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "[('g20', 'floor')] []"


def test_the_estimate_holds_what_xla_allocates_with_the_motion_check(goal):
    """`cgda run clean_ie --trials 200` passed the check and died allocating 3.05 GB:
    the motion check's pairs held about 146 floats a pair and posture, the estimate
    counted 1. The estimate (`sim_estimate`, the one rule of the API and of
    --dry-run) must cover XLA's own count of the compiled programs (temporaries and
    outputs of init, chunk and finish) with feasibility on, and not by more than 3x.

    The ranked moves are judged in one flat batch up to `PACKED_MIN` postures and in a
    coarse-to-fine loop above it, which holds fewer (here 1-2 trials are flat, 8-16
    looped): the estimate must cover each regime's growth per trial, and be within 3x
    of the larger (a difference across the two regimes is meaningless: 4 trials hold
    less than 2)."""
    from cgda_jax.strategies import IEPlan, IESettings
    from cgda_jax.strategies.runner import compile_plan, seed_keys

    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")
    sim = Simulator(robot, MarkerScene(), substeps=2, feasibility=True)
    assert sim.feasibility.collider.n_pairs > 0
    plan = IEPlan(sim, jnp.asarray(goal, jnp.float32),
                  IESettings(population_size=8, max_generations=20, restarts=0))
    held = {}
    for trials in (1, 2, 8, 16):
        progs = compile_plan(plan, seed_keys(list(range(trials))))
        held[trials] = sum(p.memory_analysis().temp_size_in_bytes
                           + p.memory_analysis().output_size_in_bytes for p in progs)
    flat = held[2] - held[1]
    looped = (held[16] - held[8]) / 8
    assert 0 < looped < flat, held  # the loop holds less a trial than the flat batch
    est = plan.estimate(1).nbytes
    assert max(flat, looped) <= est <= 3 * max(flat, looped), (flat, looped, est)
