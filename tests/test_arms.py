"""Random arms (robot-configuration independence): a fast subset of bench_arms.py."""

import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, run_trials
from cgda_jax.datasets.arms import arm_joints, random_arm_mjcf, reachable_goal


def _arm(n_joints, seed):
    model = mujoco.MjModel.from_xml_string(random_arm_mjcf(n_joints, seed))
    robot = Robot(model, arm_joints(n_joints), "marker")
    return Simulator(robot, MarkerScene(), substeps=4), reachable_goal(robot, 6, seed)


@pytest.mark.parametrize("n", [2, 5, 7])
def test_random_arms_compile_and_their_goals_are_reachable(n):
    sim, goal = _arm(n, seed=n)
    assert sim.n_dof == n and goal.shape == (6, 3)
    # the goal is the marker along a joint-space line: distinct, smooth points
    steps = np.linalg.norm(np.diff(goal, axis=0), axis=1)
    assert np.all(steps > 1e-3) and steps.max() < 3 * steps.min() + 0.05
    with pytest.raises(ValueError, match="2..7"):
        random_arm_mjcf(8)


@pytest.mark.parametrize("strategy, n", [("ie", 7), ("iet", 4)])
def test_every_seed_succeeds_on_a_random_arm(strategy, n):
    sim, goal = _arm(n, seed=n)
    results = run_trials(strategy, sim, goal, 10, tolerance=0.02, population_size=16,
                         max_generations=100)
    failed = [(r.info["seed"], float(r.max_point_error)) for r in results
              if not r.success]
    assert not failed, failed
    # what was reported is what the joints do
    r = results[3]
    np.testing.assert_allclose(np.asarray(sim.execute(r.joints)), r.features, atol=1e-5)
