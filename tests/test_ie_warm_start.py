"""IE ``warm_start``: every point's first try is a local search at the start posture."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.experiment import ConfigError, load_config
from cgda_jax.experiment.rules import check_strategy_options
from cgda_jax.strategies import from_joints, run_ie
from cgda_jax.strategies.ie import LOCAL_STD, IEPlan

JOINTS = ["yaw", "shoulder", "elbow"]


@pytest.fixture(scope="module")
def robot():
    return Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker",
                           start={"shoulder": 1.0, "elbow": 1.2})


@pytest.fixture(scope="module")
def sim(robot):
    return Simulator(robot, MarkerScene(), substeps=4)


@pytest.fixture(scope="module")
def goal(robot):
    """Marker positions of postures near the start posture (away from the middle
    of the joint ranges, where a cold start searches)."""
    start = np.asarray(robot.start_genes, np.float64)
    assert np.abs(start).max() > 0.9
    postures = [start + d for d in ([0.1, -0.1, 0.0], [0.2, -0.15, -0.05],
                                    [0.3, -0.1, -0.15], [0.35, 0.0, -0.2])]
    return np.stack([np.asarray(robot.marker_position(jnp.asarray(q)))
                     for q in postures])


def _first_try(sim, goal, warm):
    plan = IEPlan(sim, goal, algorithm="CMA_ES", population_size=8, tolerance=0.01,
                  max_generations=10, warm_start=warm, restarts=0, stagnation=None)
    return plan.init(jax.random.key(0)).evo.algo


def test_first_try_is_a_local_search_at_the_start_posture(sim, goal):
    warm, cold = _first_try(sim, goal, True), _first_try(sim, goal, False)
    start_u = np.asarray(from_joints(sim.init_state().genes, sim.lower, sim.upper))
    n = len(goal)
    np.testing.assert_allclose(np.asarray(warm.mean), np.tile(start_u, (n, 1)),
                               atol=1e-6)
    np.testing.assert_allclose(np.asarray(cold.mean), 0.0, atol=1e-7)
    np.testing.assert_allclose(np.asarray(warm.std), LOCAL_STD * np.asarray(cold.std),
                               rtol=1e-6)


def test_warm_start_meets_goals_near_the_start_in_fewer_generations(sim, goal):
    kw = {"population_size": 8, "tolerance": 0.01, "max_generations": 60, "seed": 0,
          "restarts": 0}
    warm = run_ie(sim, goal, warm_start=True, **kw)
    cold = run_ie(sim, goal, **kw)
    assert warm.success, warm.point_errors
    assert warm.info["warm_start"] is True and cold.info["warm_start"] is False
    # each point found near the start, not in another branch of the kinematics
    start = np.asarray(sim.init_state().genes)
    assert np.abs(warm.joints - start).max() < 0.8
    w, c = sum(warm.info["point_generations"]), sum(cold.info["point_generations"])
    assert 2 * w < c, (warm.info["point_generations"], cold.info["point_generations"])


def test_warm_start_is_an_ie_config_option():
    cfg = load_config(None, ["strategy.name=ie", "strategy.options.warm_start=true"])
    check_strategy_options(cfg.strategy)
    assert cfg.strategy.options["warm_start"] is True
    with pytest.raises(ConfigError, match="warm_start"):
        check_strategy_options(load_config(
            None, ["strategy.name=ie", "strategy.options.warm_start=3"]).strategy)
