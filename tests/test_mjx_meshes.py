"""MJX on meshed models: kinematics without collisions, physics with the pairs the
task does not need turned off, or an error naming the pair it needs."""

import logging

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator
from cgda_jax.sim.mjx_prep import unsupported_pairs

# The arm's forearm is a mesh; the base a cylinder and the floor a plane with a margin,
# both colliding with it: pairs MJX cannot collide (cylinder - mesh; a mesh's margin).
MESHED = """
<mujoco model="meshed">
  <compiler angle="radian"/>
  <option timestep="0.002" integrator="Euler"/>
  <asset>
    <mesh name="slab" vertex="0 -0.02 -0.02  0.25 -0.02 -0.02  0 0.02 -0.02
                               0.25 0.02 -0.02  0 -0.02 0.02  0.25 -0.02 0.02
                               0 0.02 0.02  0.25 0.02 0.02"/>
  </asset>
  <default><joint damping="0.1" armature="0.01"/><geom density="800"/></default>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1" margin="0.01"/>
    <geom name="base" type="cylinder" size="0.05 0.05" pos="0 0 0.05"/>
    <body name="l1" pos="0 0 0.6">
      <joint name="shoulder" axis="0 1 0" range="-2 2"/>
      <geom name="upper" type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"
            contype="0" conaffinity="0"/>
      <body name="l2" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0" range="-2.5 2.5"/>
        <geom name="forearm" type="mesh" mesh="slab"/>
        <site name="tip" pos="0.25 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="p1" joint="shoulder" kp="200" kv="10"/>
    <position name="p2" joint="elbow" kp="80" kv="3"/>
  </actuator>
</mujoco>
"""
JOINTS = ["shoulder", "elbow"]
WAYPOINTS = np.array([[-0.5, 0.4], [-0.2, -0.6]], np.float32)  # well above the floor


@pytest.fixture(scope="module")
def meshed(tmp_path_factory):
    path = tmp_path_factory.mktemp("meshed") / "meshed.xml"
    path.write_text(MESHED)
    return path


def test_the_model_has_pairs_mjx_refuses(meshed):
    m = mujoco.MjModel.from_xml_path(str(meshed))
    whys = sorted(why for _, _, why in unsupported_pairs(m))
    assert whys == ["collisions", "margin"]  # base - forearm, floor - forearm
    with pytest.raises(NotImplementedError):
        from mujoco import mjx

        mjx.put_model(m, impl="jax")


def test_mjx_kinematics_needs_no_collisions(meshed):
    robot = Robot.from_mjcf(meshed, JOINTS, "tip", kinematics="mjx")
    d = mujoco.MjData(robot.mj_model)
    fk = jax.jit(robot.marker_position)
    for genes in np.random.default_rng(0).uniform(-1.5, 1.5, (8, 2)):
        d.qpos[:] = genes
        mujoco.mj_kinematics(robot.mj_model, d)
        np.testing.assert_allclose(np.asarray(fk(jnp.asarray(genes, jnp.float32))),
                                   d.site_xpos[robot.site_id], atol=2e-6)


def test_mjx_physics_turns_off_the_pairs_the_task_does_not_need(meshed, caplog):
    robot = Robot.from_mjcf(meshed, JOINTS, "tip")
    with caplog.at_level(logging.WARNING, logger="cgda_jax"):
        sims = {b: Simulator(robot, MarkerScene(), mode="dynamic", physics=b,
                             waypoint_s=0.2) for b in ("mujoco", "mjx")}
    said = [r.getMessage() for r in caplog.records if "turned off" in r.getMessage()]
    assert len(said) == 1 and "base (cylinder) - forearm (mesh)" in said[0]
    assert "floor (plane) - forearm (mesh)" in said[0]
    feats = {b: np.asarray(jax.jit(s.execute)(WAYPOINTS)) for b, s in sims.items()}
    # no contact happens on this path: both backends give the same features
    np.testing.assert_allclose(feats["mjx"], feats["mujoco"], atol=1e-4)


def test_a_pair_the_task_needs_is_named_with_the_way_out(tmp_path):
    path = tmp_path / "margin.xml"  # the forearm (a mesh) with a margin
    path.write_text(MESHED.replace('mesh="slab"', 'mesh="slab" margin="0.005"'))
    robot = Robot.from_world(path, [{"piece": "table", "pos": [0.5, 0.0, 0.3]}],
                             JOINTS, "tip", contact_geoms=["forearm"])
    assert robot.object_bodies == ("table",)
    with pytest.raises(ValueError, match=r"MJX does not implement a mesh's margin.*"
                                         r"needs the pair table \(box\) - forearm "
                                         r"\(mesh\).*physics=\"mujoco\""):
        Simulator(robot, MarkerScene(), mode="dynamic", physics="mjx")
    # kinematic mode's object features: MJX kinematics of the world, no collisions
    data = robot.kinematics_data(robot.qpos(jnp.asarray([0.3, -0.2], jnp.float32)))
    d = mujoco.MjData(robot.mj_model)
    d.qpos[:] = np.asarray(robot.qpos(jnp.asarray([0.3, -0.2], jnp.float32)))
    mujoco.mj_kinematics(robot.mj_model, d)
    np.testing.assert_allclose(np.asarray(data.xpos), d.xpos, atol=2e-6)
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.05)  # MuJoCo C collides them
    assert np.all(np.isfinite(np.asarray(sim.execute(WAYPOINTS[:1]))))
