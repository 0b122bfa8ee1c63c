"""IE's sequential context keeps its best in-order execution (issue 41, seed 0 of
iron_force_xgnitive): a point is evolved from where its predecessors' bests of the
time leave the arm; when a predecessor's later try replaces its best, a successor
met before may miss in the new context.  The result is the last bests' in-order
execution unless that fails and an earlier generation's bests executed better:
then those (`IEPlan.keep_chain`, `IEPlan.kept_chain`)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.strategies.evolution import from_joints
from cgda_jax.strategies.ie import IEPlan

# the arm does not settle in 0.1 s: where a point starts changes where it ends
POSTURES = np.radians([[20, 30, 40], [40, 20, 60], [60, 10, 70]]).astype(np.float32)


@pytest.fixture(scope="module")
def case():
    tiny = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                           "marker")
    sim = Simulator(tiny, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.1, timestep=0.004)
    goal = np.asarray(sim.execute(POSTURES))  # met exactly by POSTURES in order
    plan = IEPlan(sim, jnp.asarray(goal), population_size=4, tolerance=0.02,
                  restarts=0)
    good = from_joints(jnp.asarray(POSTURES), plan.lower, plan.upper)
    # point 1's best replaced by another posture reaching the same marker in
    # its own context would not help point 2: a different point 1 posture
    moved = good.at[1].set(from_joints(jnp.radians(jnp.array([-40.0, 60, 10])),
                                       plan.lower, plan.upper))
    return sim, goal, plan, good, moved


def _errors(sim, goal, joints):
    return np.linalg.norm(np.asarray(sim.execute(joints)) - goal, axis=-1)


def test_a_changed_predecessor_does_not_lose_the_met_chain(case):
    sim, goal, plan, good, moved = case
    step, finish = jax.jit(plan.step), jax.jit(plan.finish)
    s = plan.init(jax.random.key(0))
    s = s.replace(best_u=good, best_fitness=jnp.zeros(3))
    s, _ = step(s)  # executes the met bests in order: kept
    assert plan.keeps_chain and float(jnp.max(s.chain_error)) < 1e-3
    # a later try of point 1 replaces its best: point 2 (and 1) now miss
    s = s.replace(best_u=moved)
    assert _errors(sim, goal, plan.joints(moved)).max() > 0.02
    out = finish(s)
    assert bool(out["chain"])
    # the result is an in-order execution: the kept chain's, which meets every point
    np.testing.assert_allclose(np.asarray(out["joints"]), POSTURES, atol=1e-5)
    np.testing.assert_allclose(np.asarray(out["features"]),
                               np.asarray(sim.execute(out["joints"])), atol=1e-6)
    assert _errors(sim, goal, out["joints"]).max() < 0.02


def test_a_successful_last_execution_is_kept(case):
    sim, goal, plan, good, moved = case
    step, finish = jax.jit(plan.step), jax.jit(plan.finish)
    s = plan.init(jax.random.key(0))
    s = s.replace(best_u=good, best_fitness=jnp.zeros(3))
    s, _ = step(s)
    # bests that still meet the tolerance (slightly off the exact chain) are the result
    near = good + 0.002
    assert _errors(sim, goal, plan.joints(near)).max() < 0.02
    out = finish(s.replace(best_u=near))
    assert not bool(out["chain"])
    np.testing.assert_allclose(np.asarray(out["joints"]),
                               np.asarray(plan.joints(near)), atol=1e-6)


def test_check_finer_judges_the_bests_at_the_finer_step(case):
    """``check_finer``: the bests' in-order execution at timestep / 4 (MuJoCo C) is
    each point's error too; the coarse chain meets every point exactly, the finer
    one misses point 0 by 10 mm (the 0.1 s waypoints do not settle), so at a 5 mm
    tolerance point 0 is no longer met (and 1, 2 still are)."""
    sim, goal, _, good, _ = case
    fine = np.linalg.norm(np.asarray(sim.finer(4).execute(POSTURES)) - goal, axis=-1)
    assert fine[0] > 0.008 and fine[1:].max() < 0.004  # what the case is about
    plans = {k: IEPlan(sim, jnp.asarray(goal), population_size=4, tolerance=0.005,
                       restarts=0, check_finer=k) for k in (0, 4)}
    assert plans[4].info["check_finer"] == 4 and plans[4].finer.physics.timestep \
        == pytest.approx(0.001)
    np.testing.assert_allclose(
        np.asarray(plans[4].finer_errors(jnp.asarray(POSTURES))), fine, rtol=1e-5,
        atol=1e-7)
    done = {}
    for k, plan in plans.items():
        s = plan.init(jax.random.key(0))
        s = s.replace(best_u=good, best_fitness=jnp.zeros(3))
        s, _ = jax.jit(plan.step)(s)
        done[k] = np.asarray(s.done)
        if k:  # re-scored to the finer error where the best stayed
            kept = np.all(np.asarray(s.best_u) == np.asarray(good), axis=-1)
            assert kept[0]
            np.testing.assert_allclose(np.asarray(s.best_fitness)[kept], fine[kept],
                                       rtol=1e-5)
            assert float(jnp.max(s.chain_error)) == pytest.approx(fine.max(),
                                                                  rel=1e-5)
    assert done[0].all()
    assert done[4].tolist() == [False, True, True]


def test_check_finer_needs_dynamic_mode():
    tiny = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                           "marker")
    sim = Simulator(tiny, MarkerScene())
    goal = jnp.zeros((2, 3))
    with pytest.raises(ValueError, match="check_finer needs dynamic mode"):
        IEPlan(sim, goal, population_size=4, check_finer=4)
    dyn = Simulator(tiny, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.1, timestep=0.004)
    with pytest.raises(ValueError, match="check_finer must be 0"):
        IEPlan(dyn, goal, population_size=4, check_finer=1)
