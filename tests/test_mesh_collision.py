"""Meshes in the collision check: checked as their bounding boxes, against MuJoCo C's
``mj_geomDistance`` on the meshes themselves."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import Robot
from cgda_jax.sim.collision import Collider

JOINTS = ["yaw", "shoulder", "elbow"]


def _box(hx, hy, hz):
    return " ".join(f"{sx * hx:g} {sy * hy:g} {sz * hz:g}"
                    for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1))


OCTAHEDRON = "0.08 0 0 -0.08 0 0 0 0.08 0 0 -0.08 0 0 0 0.08 0 0 -0.08"

# Links as box meshes (or the same boxes as primitives), a post and a diamond
# (an octahedron mesh: its bounding box is larger than it) in the arm's way.
ARM = """
<mujoco model="meshed">
  <compiler angle="degree"/>
  <asset>
    <mesh name="upper" vertex="{upper}"/>
    <mesh name="fore" vertex="{fore}"/>
    <mesh name="post" vertex="{post}"/>
    <mesh name="diamond" vertex="{diamond}"/>
  </asset>
  <worldbody>
    <geom name="post" {post_geom} pos="0.18 0.03 0.25"/>
    <geom name="diamond" type="mesh" mesh="diamond" pos="0.1 -0.3 0.4"/>
    <body name="turret" pos="0 0 0.1">
      <inertial pos="0 0 0" mass="0.5" diaginertia="0.001 0.001 0.001"/>
      <joint name="yaw" axis="0 0 1" range="-150 150"/>
      <body name="upper" pos="0 0 0.02">
        <joint name="shoulder" axis="0 1 0" range="-100 100"/>
        <geom name="upper" {upper_geom} pos="0 0 0.12"/>
        <body name="fore" pos="0 0 0.24">
          <joint name="elbow" axis="0 1 0" range="-150 150"/>
          <geom name="fore" {fore_geom} pos="0 0 0.1" euler="0 0 30"/>
          <site name="tip" pos="0 0 0.2"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
HALF = {"upper": (0.02, 0.03, 0.12), "fore": (0.018, 0.018, 0.1), "post": (0.03, 0.03, 0.25)}


def _model(tmp_path, meshes: bool) -> Robot:
    geoms = {}
    for name, (hx, hy, hz) in HALF.items():
        geoms[f"{name}_geom"] = (f'type="mesh" mesh="{name}"' if meshes else
                                 f'type="box" size="{hx} {hy} {hz}"')
    xml = ARM.format(diamond=OCTAHEDRON, **{k: _box(*v) for k, v in HALF.items()},
                     **geoms)
    path = tmp_path / f"meshed_{meshes}.xml"
    path.write_text(xml)
    return Robot.from_mjcf(path, JOINTS, "tip")


def _postures(robot, n=200, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(np.asarray(robot.lower), np.asarray(robot.upper),
                       (n, robot.n_dof)).astype(np.float32)


def _mujoco(robot, col, genes):
    m, d = robot.mj_model, mujoco.MjData(robot.mj_model)
    ids = [(m.geom(a).id, m.geom(b).id) for a, b in col.pair_names]
    out = np.empty((len(genes), len(ids)))
    for i, g in enumerate(genes):
        d.qpos[:] = robot.qpos0
        d.qpos[np.asarray(robot.qpos_adr)] = g
        mujoco.mj_kinematics(m, d)
        out[i] = [mujoco.mj_geomDistance(m, d, a, b, 10.0, None) for a, b in ids]
    return out


@pytest.fixture(scope="module")
def arms(tmp_path_factory):
    folder = tmp_path_factory.mktemp("meshed")
    return _model(folder, True), _model(folder, False)


def test_meshes_are_checked_not_skipped(arms):
    meshed, boxes = arms
    col = Collider(meshed)
    assert col.skipped == []
    assert set(col.pair_names) == set(Collider(boxes).pair_names)
    assert ("fore", "diamond") in col.pair_names and ("fore", "post") in col.pair_names


def test_box_meshes_equal_their_primitive_boxes_and_mujoco(arms):
    meshed, boxes = arms
    cm, cb = Collider(meshed), Collider(boxes)
    genes = _postures(meshed)
    dm = np.asarray(jax.vmap(cm.distances)(jnp.asarray(genes)))
    db = np.asarray(jax.vmap(cb.distances)(jnp.asarray(genes)))
    order = [cb.pair_names.index(p) for p in cm.pair_names]
    box_pairs = [k for k, p in enumerate(cm.pair_names) if "diamond" not in p]
    np.testing.assert_allclose(dm[:, box_pairs], db[:, order][:, box_pairs], atol=2e-5)
    ref = _mujoco(meshed, cm, genes)[:, box_pairs]
    ours = dm[:, box_pairs]
    apart = ref > 1e-4  # MuJoCo's mesh-mesh distance (its convex collision)
    assert apart.sum() > 100 and (ref < -1e-3).sum() > 10  # both cases occur
    np.testing.assert_allclose(ours[apart], ref[apart], atol=1e-4)
    assert np.all(ours[ref < -1e-3] < 0)  # penetration seen as penetration


def test_a_mesh_that_is_no_box_is_checked_on_the_safe_side(arms):
    meshed, _ = arms
    col = Collider(meshed)
    k = [i for i, p in enumerate(col.pair_names) if "diamond" in p]
    genes = _postures(meshed, 400, seed=1)
    ours = np.asarray(jax.vmap(col.distances)(jnp.asarray(genes)))[:, k]
    ref = _mujoco(meshed, col, genes)[:, k]
    near = ref < 0.1
    assert near.sum() > 20
    # never more lenient than MuJoCo on the true octahedron, and at most the box's
    # corner reach (0.08 (sqrt(3) - 1/sqrt(3)) = 0.092 m) stricter
    assert np.all(ours[near] <= ref[near] + 1e-5)
    assert np.all(ref[near] - ours[near] < 0.093)
    assert np.any(ref[near] - ours[near] > 0.01)  # the box is larger than the mesh
