"""The ironing pieces (issue 41): a tool with a force sensor pressing on a plate, in
physics, reaches a set force."""

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax.experiment.compute import replayed_features
from cgda_jax.sim.simulator import Simulator
from cgda_jax.sim.robot import Robot, model_path
from cgda_jax.sim.scenes import ObjectScene
from cgda_jax.sim.world import compile_world
from cgda_jax.strategies import run_ie

# the tiny arm with an iron (0.2 kg) at the tip of its forearm, sole down when the
# forearm points down, over a plate whose surface is at z = -0.12
OBJECTS = [
    {"piece": "table", "name": "plate", "pos": [0.3, 0.0, -0.12],
     "size": [0.15, 0.15, 0.01], "height": 0.1},
    {"piece": "iron", "body": "link2", "pos": [0, 0, 0.3375], "euler": [180, 0, 0],
     "mass": 0.2},
]
FEATURES = [{"site": "iron/tcp", "quantity": "xyz"},
            {"site": "iron/ft", "quantity": "fz", "frame": "world", "scale": 0.01}]


@pytest.fixture(scope="module")
def sim():
    robot = Robot.from_world(model_path("tiny_arm.xml"), OBJECTS,
                             ["yaw", "shoulder", "elbow"], "marker", {})
    return Simulator(robot, ObjectScene(FEATURES), mode="dynamic", timestep=0.004,
                     waypoint_s=1.0, physics="mujoco")


def test_iron_piece_on_a_hand():
    m = compile_world(model_path("tiny_arm.xml"), OBJECTS)
    iron = m.body("iron")
    assert m.body(int(iron.parentid[0])).name == "link2"  # welded to the forearm
    assert m.body("iron").jntnum[0] == 0
    assert m.geom("iron").contype[0] == 2 and m.geom("iron").conaffinity[0] == 1
    assert float(m.body_subtreemass[iron.id]) == pytest.approx(0.2)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    # the sensor at the tip of the forearm, the tool point 0.0875 m beyond it
    np.testing.assert_allclose(d.site("iron/ft").xpos, d.site("marker").xpos,
                               atol=1e-9)
    np.testing.assert_allclose(d.site("iron/tcp").xpos,
                               d.site("marker").xpos + [0, 0, 0.0875], atol=1e-9)
    with pytest.raises(ValueError, match="'body' 'hand' not found"):
        compile_world(model_path("tiny_arm.xml"),
                      [{"piece": "iron", "body": "hand", "pos": [0, 0, 0]}])


def test_force_feature_reads_weight_and_pressing(sim):
    """In the air the sensor carries the iron's weight (+m g, world z); pressed on
    the plate, the push beyond it."""
    st = sim.init_state()
    _, air = sim.step(st, jnp.radians(jnp.array([0.0, 40.0, 120.0])))
    assert float(air[3]) * 100 == pytest.approx(0.2 * 9.81, abs=0.05)
    _, press = sim.step(st, jnp.radians(jnp.array([0.0, 60.0, 120.0])))
    assert float(press[3]) * 100 < -10.0
    assert float(press[2]) > -0.12  # the tool point stays above the plate's surface


def test_tiny_arm_presses_a_set_force(sim):
    """IE evolves the posture that presses the plate with -15 N (world z) at a set
    point: within 1 N and 1 cm (scale 0.01: 1 N counts as 1 cm, tolerance 0.01)."""
    st = sim.init_state()
    _, air = sim.step(st, jnp.radians(jnp.array([0.0, 45.0, 110.0])))
    _, near = sim.step(st, jnp.radians(jnp.array([0.0, 58.0, 120.0])))
    goal = np.array([np.asarray(air), [*np.asarray(near)[:3], -15.0 * 0.01]])
    res = run_ie(sim, goal, population_size=12, tolerance=0.01, max_generations=30,
                 seed=0)
    feats = np.asarray(res.features)
    assert res.success, res.point_errors
    np.testing.assert_allclose(feats[1, 3] / 0.01, -15.0, atol=1.0)
    np.testing.assert_allclose(feats[:, :3], goal[:, :3], atol=0.01)
    assert feats[0, 3] / 0.01 > 0  # the first point in the air


def test_iron_sets_elliptic_cones_and_replays_agree(sim, tmp_path):
    """The iron's contact model (elliptic cones, impratio 10: static friction
    without the pyramidal cone's creep) is the world's; with it the pressing force
    of a coarse run and of its 4x finer replay agree within 0.15 N (pyramidal
    cones: 0.4 N apart at the hardest press)."""
    m = sim.physics.model
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and m.opt.impratio == 10
    joints = np.radians([[0, 45, 110], [0, 58, 120], [10, 60, 118],
                         [-10, 62, 121]]).astype(np.float32)
    coarse = replayed_features(sim, joints)
    fine = replayed_features(sim.finer(4), joints)
    assert coarse[-1, 3] / 0.01 < -30  # pressing hard
    np.testing.assert_allclose(coarse[:, 3] / 0.01, fine[:, 3] / 0.01, atol=0.15)
    np.testing.assert_allclose(coarse[:, :3], fine[:, :3], atol=1e-4)
    # a robot whose own impratio differs: the piece's cannot be carried over
    text = open(model_path("tiny_arm.xml")).read().replace(
        'integrator="Euler"', 'integrator="Euler" impratio="5"')
    (tmp_path / "arm.xml").write_text(text)
    with pytest.raises(ValueError, match="impratio=10.0 disagrees with the world's "
                                         "impratio=5.0"):
        compile_world(tmp_path / "arm.xml", OBJECTS)


def test_kinematic_mode_refuses_a_force():
    robot = Robot.from_world(model_path("tiny_arm.xml"), OBJECTS,
                             ["yaw", "shoulder", "elbow"], "marker", {})
    with pytest.raises(ValueError, match="only the physics gives one"):
        Simulator(robot, ObjectScene(FEATURES))


def test_sample_positions_places_restart_postures_by_kinematics(sim):
    """IE's ``sample_positions`` (dynamic mode): the restart samples are the drawn
    postures whose tool point (MuJoCo C kinematics, the force column ignored) is
    nearest each goal point's position; restart 1 starts there."""
    import jax

    from cgda_jax.strategies.base import to_joints
    from cgda_jax.strategies.ie import IEPlan, position_kinematics

    cols, positions = position_kinematics(sim)
    assert cols.tolist() == [0, 1, 2]
    goal = np.array([[0.30, 0.02, -0.05, 0.02], [0.25, -0.05, 0.0, -0.1]],
                    np.float32)
    plan = IEPlan(sim, jnp.asarray(goal), population_size=4, restarts=2,
                  restart_samples=64, sample_positions=True)
    assert plan.restart_samples == 64 and plan.n_nearest == 1
    key = jax.random.key(3)
    s = plan.init(key)
    # the reference: the same draws, placed by MuJoCo C, the nearest by xyz
    u = np.asarray(jax.random.uniform(jax.random.fold_in(key, 2**31 - 1), (64, 3),
                                      minval=-1.0, maxval=1.0))
    q = np.asarray(to_joints(jnp.asarray(u), plan.lower, plan.upper), np.float64)
    m = sim.robot.mj_model
    d = mujoco.MjData(m)
    tcp = np.empty((64, 3))
    for k, genes in enumerate(q):
        d.qpos[:] = np.asarray(sim.robot.qpos0)
        d.qpos[np.asarray(sim.robot.qpos_adr)] = genes
        mujoco.mj_kinematics(m, d)
        tcp[k] = d.site("iron/tcp").xpos
    np.testing.assert_allclose(np.asarray(positions(jnp.asarray(q[:5]))), tcp[:5],
                               atol=1e-5)
    nearest = np.argmin(np.linalg.norm(tcp[None] - goal[:, None, :3], axis=-1), 1)
    np.testing.assert_allclose(np.asarray(s.samples[:, 0]), u[nearest], atol=1e-6)
    # restart 1 of point 0 searches around its sample
    evo = plan._try(s.keys[0], plan.goal[0], jax.tree.map(lambda x: x[0],
                    plan.contexts(s.best_u)[0]), 1, None, s.samples[0])
    np.testing.assert_allclose(np.asarray(evo.algo.mean), u[nearest[0]], atol=1e-6)


def test_sample_positions_needs_object_features_in_dynamic_mode():
    from cgda_jax.sim.scenes import MarkerScene
    from cgda_jax.strategies.ie import IEPlan

    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    dyn = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.1, timestep=0.004)
    with pytest.raises(ValueError, match="sample_positions needs dynamic mode"):
        IEPlan(dyn, jnp.zeros((2, 3)), population_size=4, sample_positions=True)
