"""Closed-form box distances (cgda_jax.sim.box_distances) against MuJoCo C and brute
force, and the feasibility check's cheap mode (``Collider.distances(exact=False)``)."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import Robot, model_path
from cgda_jax.sim import box_distances as bd
from cgda_jax.sim import primitive_distances as df
from cgda_jax.sim.collision import Collider, Obstacle

TWO_BOXES = """<mujoco><worldbody>
  <body name="A" mocap="true"><geom name="a" type="box" size="0.05 0.1 0.03"/></body>
  <body name="B" mocap="true"><geom name="b" type="box" size="0.2 0.02 0.08"/></body>
</worldbody></mujoco>"""
BOX_CYLINDER = TWO_BOXES.replace('type="box" size="0.2 0.02 0.08"',
                                 'type="cylinder" size="0.12 0.02"')


def _random_box_pairs(n, seed, xml=TWO_BOXES):
    """MuJoCo's distance of geoms a and b in n random relative poses, and our
    inputs."""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(seed)
    ref, args = [], []
    for _ in range(n):
        for k in range(2):
            q = rng.normal(size=4)
            d.mocap_quat[k] = q / np.linalg.norm(q)
        d.mocap_pos[1] = rng.uniform(-0.3, 0.3, 3)
        mujoco.mj_kinematics(m, d)
        ref.append(mujoco.mj_geomDistance(m, d, 0, 1, 10.0, None))
        args.append([x.copy() for x in (
            m.geom_size[0], d.geom_xmat[0].reshape(3, 3), d.geom_xpos[0],
            m.geom_size[1], d.geom_xmat[1].reshape(3, 3), d.geom_xpos[1])])
    cols = [jnp.asarray(np.stack([a[k] for a in args]), jnp.float32) for k in range(6)]
    return np.asarray(ref), cols


def test_box_box_depth_is_mujocos_and_clearance_a_lower_bound():
    ref, args = _random_box_pairs(1500, seed=1)
    sat = np.asarray(jax.jit(jax.vmap(bd.box_box_sat))(*args))
    exact = np.asarray(jax.jit(jax.vmap(
        lambda sa, Ra, pa, sb, Rb, pb: df.pair_distance("box", "box", sa, Ra, pa,
                                                        sb, Rb, pb)))(*args))
    pen, sep = ref < -1e-4, ref > 1e-4
    assert pen.sum() > 100 and sep.sum() > 1000
    # in penetration: the shortest separating translation, as MuJoCo measures it
    np.testing.assert_allclose(sat[pen], ref[pen], atol=1e-6)
    np.testing.assert_allclose(exact[pen], ref[pen], atol=1e-6)
    # separated: positive, never above the distance; exact mode is the distance
    assert np.all(sat[sep] > 0) and np.all(sat[sep] <= ref[sep] + 1e-6)
    assert np.mean(np.abs(sat[sep] - ref[sep]) < 1e-5) > 0.3  # face cases exact
    assert np.max(np.abs(sat[sep] - ref[sep])) > 1e-3  # vertex cases below it
    bound = df.error_bound("box", [0.05, 0.1, 0.03], "box", [0.2, 0.02, 0.08])
    assert np.max(np.abs(exact[sep] - ref[sep])) <= bound


def test_box_cylinder_bound_is_never_above_mujoco_and_near_its_depth():
    ref, args = _random_box_pairs(1500, seed=4, xml=BOX_CYLINDER)
    fast = np.asarray(jax.jit(jax.vmap(bd.box_cylinder_sat))(*args))
    cheap = np.asarray(jax.jit(jax.vmap(
        lambda sa, Ra, pa, sb, Rb, pb: df.pair_distance(
            "cylinder", "box", sb, Rb, pb, sa, Ra, pa, exact=False)))(*args))
    np.testing.assert_array_equal(cheap, fast)  # either order
    pen, sep = ref < -1e-4, ref > 1e-4
    assert pen.sum() > 100 and sep.sum() > 1000
    assert np.all(fast <= ref + 1e-6)  # a lower bound, penetration never shallower
    gap = ref[pen] - fast[pen]
    assert np.max(gap) < 1e-3 and np.mean(gap < 1e-4) > 0.85
    assert np.all(fast[sep] > -1e-3)


def test_box_box_sat_parallel_boxes_stay_finite():
    eye, size = jnp.eye(3), jnp.array([0.1, 0.1, 0.1])
    for gap in (0.05, -0.03):  # face to face, axes parallel: cross axes are 0
        v = bd.box_box_sat(size, eye, jnp.zeros(3), size, eye,
                           jnp.array([0.2 + gap, 0.0, 0.0]))
        assert float(v) == pytest.approx(gap, abs=1e-6)


def test_segment_box_min_equals_a_dense_search():
    rng = np.random.default_rng(0)
    n = 400
    h = rng.uniform(0.01, 0.2, (n, 3)).astype(np.float32)
    a = rng.uniform(-0.3, 0.3, (n, 3)).astype(np.float32)
    b = (a + rng.normal(0, 0.2, (n, 3))).astype(np.float32)
    b[:40] = a[:40]  # points
    b[40:80, 1:] = a[40:80, 1:]  # parallel to an axis
    ours = np.asarray(jax.jit(jax.vmap(bd.segment_box_min))(h, a, b))
    ts = np.linspace(0.0, 1.0, 20001)[:, None]
    for i in range(n):
        x = a[i] + ts * (b[i] - a[i]).astype(np.float64)
        q = np.abs(x) - h[i]
        dense = (np.linalg.norm(np.maximum(q, 0), axis=1)
                 + np.minimum(q.max(axis=1), 0)).min()
        # never above the true minimum, within the dense grid's step below it
        step = np.linalg.norm(b[i] - a[i]) / 20000
        assert dense - step - 1e-6 <= ours[i] <= dense + 1e-6, i
    assert np.mean(ours < 0) > 0.05  # segments through the box are covered


def test_cheap_mode_changes_only_separated_box_pairs():
    robot = Robot.from_mjcf(
        model_path("teo.xml"),
        ["r_shoulder_flexion", "r_shoulder_abduction", "r_upper_arm_rotation",
         "r_elbow", "r_forearm_rotation", "r_wrist"], "marker")
    board = Obstacle("board", "box", (0.3, -0.4, 0.2), (0.02, 0.3, 0.3),
                     (0.966, 0.0, 0.259, 0.0))
    post = Obstacle("post", "cylinder", (0.25, -0.45, 0.0), (0.06, 0.2),
                    (0.9, 0.2, 0.3, 0.0))
    col = Collider(robot, [board, post])
    rng = np.random.default_rng(2)
    genes = jnp.asarray(rng.uniform(np.asarray(robot.lower), np.asarray(robot.upper),
                                    (300, 6)), jnp.float32)
    exact = np.asarray(jax.jit(jax.vmap(col.distances))(genes))
    cheap = np.asarray(jax.jit(jax.vmap(
        lambda q: col.distances(q, exact=False)))(genes))
    boxes = np.array([t == ("box", "box") for t in col.pair_types])
    cyl = np.array([set(t) == {"box", "cylinder"} for t in col.pair_types])
    same = ~boxes & ~cyl
    assert boxes.any() and cyl.any() and same.any()
    np.testing.assert_allclose(cheap[:, same], exact[:, same], atol=1e-6)
    e, c = exact[:, boxes], cheap[:, boxes]
    assert (e < 0).any() and (e > 0).any()
    np.testing.assert_allclose(c[e <= 0], e[e <= 0], atol=1e-6)
    assert np.all(c[e > 0] <= e[e > 0] + 1e-6) and np.all(c[e > 1e-5] > 0)
    # box-cylinder: a lower bound of the exact mode's value (the feature search's
    # depth is the deepest feature point, never deeper than the true depth)
    e, c = exact[:, cyl], cheap[:, cyl]
    assert (e < 0).any() and np.all(c <= e + 1e-5)
