"""Shrinking trial batches (cgda_jax.strategies.runner): each trial equals its single
run, and the batch really shrinks as trials (or IE points) finish."""

import functools

import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path
from cgda_jax.strategies import run_fte, run_ie, run_iet, run_trials, runner
from cgda_jax.strategies.runner import drive_ie_points, ladder
from cgda_jax.strategies.ie import IEPlan, IESettings

JOINTS = ["yaw", "shoulder", "elbow"]


@pytest.fixture(scope="module")
def robot():
    return Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")


@pytest.fixture(scope="module")
def sim(robot):
    return Simulator(robot, MarkerScene(), substeps=4)


@pytest.fixture(scope="module")
def goal(robot):
    postures = [[0.2, 0.5, 0.6], [0.4, 0.6, 0.8], [0.6, 0.7, 0.6], [0.8, 0.5, 0.4],
                [1.0, 0.3, 0.2]]
    return np.stack([np.asarray(robot.marker_position(jnp.asarray(q)))
                     for q in postures])


def same(batched, single):
    """Equal up to float32 rounding: the batch runs the same per-point programs on
    other array shapes, so XLA may fuse (round) differently; the integer outcomes
    (generations, evaluations, tries, success) must be identical."""
    assert batched.info["seed"] == single.info["seed"]
    np.testing.assert_allclose(batched.joints, single.joints, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(batched.point_errors, single.point_errors, atol=1e-4)
    assert batched.evaluations == single.evaluations
    assert batched.generations == single.generations
    assert batched.success == single.success
    assert batched.fitness_history.shape == single.fitness_history.shape
    np.testing.assert_allclose(batched.fitness_history, single.fitness_history,
                               rtol=1e-4, atol=1e-5)


def test_ladder_halves_down_to_the_minimum():
    assert ladder(30) == [1, 2, 4, 8, 15, 30]
    assert ladder(270, 8) == [9, 17, 34, 68, 135, 270]
    assert ladder(5, 8) == [5]
    assert ladder(1) == [1]


# A tight tolerance and a small budget with short stagnation: points stop at very
# different generations and several restart (from a neighbour's genes or a random
# mean), so the pool's neighbour bookkeeping is exercised.
IE_KW = {"population_size": 8, "tolerance": 0.004, "max_generations": 12, "chunk_size": 3,
             "restarts": 2, "stagnation": 4}


def test_ie_points_pooled_equal_single_runs_and_the_pool_shrinks(sim, goal):
    trials = run_trials("ie", sim, goal, 4, seed=3, **IE_KW)
    assert [t.info["seed"] for t in trials] == [3, 4, 5, 6]
    info = trials[0].info
    assert info["batching"] == "points"
    sizes = info["batch_sizes"]
    assert sizes[0] == 4 * len(goal)  # every point of every trial at the start
    assert sizes == sorted(sizes, reverse=True) and sizes[-1] < sizes[0]
    assert set(sizes) <= set(ladder(4 * len(goal), 8))
    tries = np.array([t.info["point_tries"] for t in trials])
    assert (tries > 1).any()  # restarts happened
    assert len({t.generations for t in trials}) > 1
    # every trial against the lock-step batch (per-trial programs, one compile) ...
    lock = run_trials("ie", sim, goal, 4, seed=3, batching="lockstep", **IE_KW)
    assert "batching" not in lock[0].info
    for t, q in zip(trials, lock, strict=True):
        same(t, q)
        assert t.info["point_generations"] == q.info["point_generations"]
        assert t.info["point_tries"] == q.info["point_tries"]
    # the pool evaluated in blocks of 3 evolutions (sizes rounded up to whole blocks)
    blocked = runner.run_plan(
        IEPlan, sim, goal, IESettings(algorithm="CMA_ES", **IE_KW), [3, 4, 5, 6],
        driver=functools.partial(drive_ie_points, block_evaluations=24))
    assert blocked[0].info["batch_sizes"][0] == 21  # 20 points -> 7 blocks of 3
    for t, q in zip(blocked, lock, strict=True):
        same(t, q)
    # ... and the trial with the most restarts against its single run
    t = trials[int(np.argmax(tries.sum(axis=1)))]
    single = run_ie(sim, goal, seed=t.info["seed"], **IE_KW)
    same(t, single)
    assert t.info["point_tries"] == single.info["point_tries"]


# the paper's FTE (middle start, no restarts): its trials stop at different generations
# (the default gradient start meets this goal at once, and nothing would be re-packed)
FTE_KW = {"population_size": 8, "tolerance": 0.05, "max_generations": 30, "chunk_size": 2,
          "stagnation": 3, "init": "middle", "restarts": 0}


@pytest.mark.slow  # 44 s in CI; the IE pooling test stays
def test_fte_trials_repacked_equal_single_runs(sim, goal):
    trials = run_trials("fte", sim, goal[:3], 3, seed=1, **FTE_KW)
    sizes = trials[0].info["batch_sizes"]
    assert trials[0].info["batching"] == "trials"
    assert sizes[0] == 3 and sizes[-1] < 3 and sizes == sorted(sizes, reverse=True)
    assert len({t.generations for t in trials}) > 1
    for t in trials[1:]:  # seeds other than the batch's first
        same(t, run_fte(sim, goal[:3], seed=t.info["seed"], **FTE_KW))
    # issue 25: a trial does not depend on its batch, bit for bit: seed 2 alone (a
    # batch of one runs with a copy of itself) is seed 2 of the shrinking batch of 3;
    # only the unbatched single run above rounds apart (README, Success rates)
    (alone,) = run_trials("fte", sim, goal[:3], 1, seed=2, **FTE_KW)
    assert alone.info["trials_in_batch"] == 1
    bitwise(alone, trials[1])


def bitwise(a, b):
    """The same trial, bit for bit: joints, errors, history and counts."""
    assert a.info["seed"] == b.info["seed"]
    np.testing.assert_array_equal(a.joints, b.joints)
    np.testing.assert_array_equal(a.point_errors, b.point_errors)
    np.testing.assert_array_equal(a.fitness_history, b.fitness_history)
    assert (a.generations, a.evaluations, a.success) == \
        (b.generations, b.evaluations, b.success)


@pytest.mark.slow  # a third strategy through the same driver as FTE's (compiles)
def test_iet_trials_repacked_equal_single_runs(robot):
    paint = Simulator(robot, PaintWall(jnp.array([[0.2, 0.0, 0.3], [0.0, 0.2, 0.3]])),
                      substeps=2)
    goal = np.array([[50.0], [100.0]])
    kw = {"population_size": 6, "tolerance": 1.0, "max_generations": 8, "chunk_size": 4,
              "restarts": 1, "backtracks": 1}
    trials = run_trials("iet", paint, goal, 2, seed=2, **kw)
    assert trials[0].info["batching"] == "trials"
    for t in trials[1:]:
        single = run_iet(paint, goal, seed=t.info["seed"], **kw)
        np.testing.assert_allclose(t.joints, single.joints, rtol=1e-4, atol=1e-4)
        assert t.evaluations == single.evaluations and t.success == single.success


def test_unknown_batching_is_rejected(sim, goal):
    with pytest.raises(ValueError, match="batching must be one of"):
        run_trials("ie", sim, goal, 2, batching="magic")

