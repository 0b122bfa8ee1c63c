"""Gradient polish and reachability (optax through the differentiable kinematics)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path, run_ie
from cgda_jax.strategies.refine import descend, reachability

JOINTS = ["yaw", "shoulder", "elbow"]


@pytest.fixture(scope="module")
def sim():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")
    return Simulator(robot, MarkerScene(), substeps=4)


@pytest.fixture(scope="module")
def goal(sim):
    postures = np.radians([[20, 30, 40], [-40, 50, 60], [60, -10, 70]])
    return np.stack([np.asarray(sim.robot.marker_position(jnp.asarray(p, jnp.float32)))
                     for p in postures])


@pytest.mark.parametrize("method", ["adam", "lbfgs"])
def test_descend_finds_the_minimum_and_never_worsens(method):
    target = jnp.array([0.3, -0.2])

    def loss(u):
        return jnp.sum((u - target) ** 2) + 0.1 * jnp.sum(u**4)

    u, value = jax.jit(lambda u0: descend(loss, u0, method=method, steps=200,
                                          learning_rate=0.05))(jnp.zeros(2))
    # NumPy reference: fixed point of the gradient, by Newton on each coordinate
    ref = np.zeros(2)
    for _ in range(50):
        g = 2 * (ref - np.asarray(target)) + 0.4 * ref**3
        ref -= g / (2 + 1.2 * ref**2)
    np.testing.assert_allclose(np.asarray(u), ref, atol=2e-3)
    # started at the optimum, it stays (the best iterate includes the start)
    u2, v2 = descend(loss, jnp.asarray(ref, jnp.float32), method=method, steps=20)
    assert float(v2) <= float(loss(jnp.asarray(ref, jnp.float32))) + 1e-12
    assert float(value) == pytest.approx(float(loss(jnp.asarray(ref))), abs=1e-6)


@pytest.mark.parametrize("method", ["adam", "lbfgs"])
def test_ie_polish_brings_points_far_below_tolerance(sim, goal, method):
    kw = dict(population_size=8, tolerance=0.02, max_generations=60, seed=1)
    plain = run_ie(sim, goal, **kw)
    polished = run_ie(sim, goal, refine=method, **kw)
    assert plain.success and polished.success
    assert polished.info["refine"] == method
    assert np.all(polished.point_errors <= plain.point_errors + 1e-7)
    assert polished.point_errors.max() < 1e-3 < plain.point_errors.max()
    # the reported features are those of executing the reported joints
    again = np.asarray(sim.execute(polished.joints))
    np.testing.assert_allclose(again, polished.features, atol=1e-6)


def test_reachability_reports_unreachable_points_and_spares_them(sim, goal):
    far = goal.copy()
    far[1] = [2.0, 0.0, 0.3]  # the arm reaches 0.6 m from its base
    reach = reachability(sim, far, 0.02)
    assert reach["unreachable"] == [1]
    # nearest approach: the marker at full stretch towards (2, 0, 0.3)
    base = np.array([0.0, 0.0, 0.05])
    want = np.linalg.norm(far[1] - base) - 0.55
    assert reach["nearest"][1] == pytest.approx(want, abs=0.01)
    assert np.all(reach["nearest"][[0, 2]] < 0.02)
    res = run_ie(sim, far, population_size=8, tolerance=0.02, max_generations=60,
                 reach_check=True)
    assert not res.success
    assert [p["index"] for p in res.info["unreachable_points"]] == [1]
    assert res.info["point_generations"][1] == 0  # no budget spent there
    assert np.all(res.point_errors[[0, 2]] < 0.02)
    assert res.point_errors[1] == pytest.approx(want, abs=0.01)


def test_refine_and_reach_need_independent_points(sim, goal):
    paint = Simulator(sim.robot, PaintWall.grid(), substeps=4)
    with pytest.raises(ValueError, match="independent points"):
        run_ie(paint, np.array([[0.0], [6.25]]), refine="adam")
    with pytest.raises(ValueError, match="refine='newton'"):
        run_ie(sim, goal, refine="newton")
