"""IE's backtracks (`IESettings.backtracks`): with the sequential context (feasibility
on), a point whose tries all miss reopens the points before it."""

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, run_trials
from cgda_jax.datasets.arms import arm_joints, random_arm_mjcf, reachable_goal
from cgda_jax.strategies import run_ie
from cgda_jax.strategies.ie import BACKTRACKS, IEPlan, IESettings, IEState, backtrack_to
from cgda_jax.strategies.iet import IETSettings

#: small budgets: 4 tries of 60 generations a point (20 without improvement stop one)
SETTINGS = dict(tolerance=0.02, population_size=16, max_generations=60, restarts=3,
                stagnation=20)


@pytest.fixture(scope="module")
def arm():
    """bench_arms' random 4-joint arm with every move judged (no move over 90
    degrees, the joint limits) and the first 3 points of its goal curve.  Point 0
    has two inverse-kinematics branches: base yaw j0 near +1.35 rad, from where
    the curve goes on (j0 +1.15, +0.95), and the mirrored j0 near -1.8 rad, from
    where points 1 and 2 need j0 past its limit (-1.9) and the other branch is a
    base move of about 180 degrees, over the cap."""
    model = mujoco.MjModel.from_xml_string(random_arm_mjcf(4, 4))
    robot = Robot(model, arm_joints(4), "marker")
    sim = Simulator(robot, MarkerScene(), substeps=4, feasibility=True)
    return sim, reachable_goal(robot, 6, 4)[:3]


def test_the_backtrack_rule_goes_back_further_each_time_from_one_point():
    first, depth = backtrack_to(jnp.int32(3), jnp.int32(-1), jnp.int32(0))
    assert (int(first), int(depth)) == (2, 1)
    first, depth = backtrack_to(jnp.int32(3), jnp.int32(3), depth)  # again from 3
    assert (int(first), int(depth)) == (1, 2)
    first, depth = backtrack_to(jnp.int32(3), jnp.int32(3), jnp.int32(5))
    assert (int(first), int(depth)) == (0, 6)  # never before point 0
    first, depth = backtrack_to(jnp.int32(4), jnp.int32(3), jnp.int32(2))
    assert (int(first), int(depth)) == (3, 1)  # another point: one back
    # one default and one rule for IE and IET
    assert IESettings().backtracks == IETSettings().backtracks == BACKTRACKS
    with pytest.raises(ValueError, match="backtracks"):
        IESettings(backtracks=-1)


def test_which_points_a_backtrack_reopens_and_renews(arm):
    sim, goal = arm
    plan = IEPlan(sim, jnp.asarray(goal), backtracks=2, **SETTINGS)
    assert plan.sequential and plan.backtracks == 2
    assert IEPlan(sim, jnp.asarray(goal), backtracks=0, **SETTINGS).backtracks == 0
    s = IEState(evo=None, keys=None, samples=None, tries=jnp.array([1, 2, 4]),
                best_u=None, best_fitness=None, done=None, generations=None,
                evaluations=None, invalid=None, entered=jnp.zeros(3, jnp.int32),
                backtracks=jnp.int32(0), stuck=jnp.int32(-1), depth=jnp.int32(0))
    met, miss = 0.01, 0.1  # point errors (m) within and beyond the 20 mm tolerance

    def call(s, done, best_f):
        s, reopened, renewed = plan.backtrack(s, jnp.array(done), jnp.array(best_f))
        return s, np.asarray(reopened).tolist(), np.asarray(renewed).tolist()

    # point 2 spent its tries, 0 and 1 met theirs: point 1 reopened, 1 and 2 renewed
    s1, reopened, renewed = call(s, [True, True, True], [met, met, miss])
    assert reopened == [False, True, False] and renewed == [False, True, True]
    assert np.asarray(s1.entered).tolist() == [0, 2, 4]  # new budgets from here
    assert (int(s1.backtracks), int(s1.stuck), int(s1.depth)) == (1, 2, 1)
    # again from point 2: two points back
    s2, reopened, renewed = call(s1, [True, True, True], [met, met, miss])
    assert reopened == [True, True, False] and renewed == [True, True, True]
    # the budget is spent: no more
    s3, reopened, _ = call(s2, [True, True, True], [met, met, miss])
    assert not any(reopened) and int(s3.backtracks) == 2
    # nothing to do: a point before it still evolving, point 0 missing (no prefix),
    # every point met (within the tolerance, even when its tries ran out)
    for done, best_f in (([True, False, True], [met, miss, miss]),
                         ([True, True, True], [miss, met, met]),
                         ([True, True, True], [met, met, 0.019])):
        s4, reopened, renewed = call(s, done, best_f)
        assert not any(renewed) and int(s4.backtracks) == 0


def test_without_backtracks_ie_stays_in_the_mirrored_branch(arm):
    sim, goal = arm
    r = run_ie(sim, goal, seed=0, backtracks=0, **SETTINGS)
    assert not r.success
    # point 0 met its goal in the mirrored branch; the later points spent every try
    assert r.point_errors[0] < 0.02 and r.joints[0, 0] < -1.5
    assert r.info["point_tries"] == [1, 4, 4]
    assert np.all(r.point_errors[1:] > 0.03)  # 37.8 and 100.8 mm on this tree
    assert r.info["backtracks"] == 0 and "backtracks_used" not in r.info


def test_backtracks_reopen_the_first_point_in_batched_trials(arm):
    # seeds 0 and 1 fail as above without backtracks (a single run each); one
    # batched call (vmap over the trials) with them
    sim, goal = arm
    results = run_trials("ie", sim, goal, 2, **SETTINGS)
    for r in results:
        assert r.success, (r.info["seed"], r.point_errors)
        assert r.info["backtracks"] == BACKTRACKS
        if r.info["backtracks_used"]:  # point 0 evolved again, now in the branch
            assert r.info["point_tries"][0] >= 2  # from which the curve goes on
        assert np.all(r.joints[:, 0] > 0.5)
        np.testing.assert_allclose(np.asarray(sim.execute(r.joints)), r.features,
                                   atol=1e-5)
    assert sum(r.info["backtracks_used"] for r in results) >= 1
