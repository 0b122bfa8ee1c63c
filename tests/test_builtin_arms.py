"""The built-in arms (models/panda.xml, models/iiwa14.xml) against their published
tables, and MJX on every shipped model: ``kinematics="mjx"`` and ``physics="mjx"``
give MuJoCo C's features within the backends' tolerance.

Only the table checks run in the default suite (< 1 s); the collision and MJX checks
compile one program per model (20-120 s each on the loaded 2-core machine) and are
``slow``."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.sim.collision import Collider
from cgda_jax.sim.limits import read_limits

JOINTS7 = [f"joint{i}" for i in range(1, 8)]
# (model, evolved joints, marker site, keyframe)
SHIPPED = {
    "tiny_arm.xml": (["yaw", "shoulder", "elbow"], "marker", None),
    "teo.xml": (["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow",
                 "r_forearm_rotation"], "marker", None),
    "panda.xml": (JOINTS7, "tool", "home"),
    "iiwa14.xml": (JOINTS7, "tool", "home"),
}


def _mdh(a, d, alpha, theta):
    """Craig's modified DH transform (NumPy)."""
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array([[ct, -st, 0, a], [st * ca, ct * ca, -sa, -sa * d],
                     [st * sa, ct * sa, ca, ca * d], [0, 0, 0, 1]])


def _rot(axis, angle):
    """Rodrigues rotation matrix (NumPy)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _tool_positions(path, qs):
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    out = []
    for q in qs:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        out.append(d.site("tool").xpos.copy())
    return m, np.array(out)


def test_the_panda_follows_frankas_dh_table_and_limits():
    # Franka's published modified-DH table; the hand's TCP 0.1034 m beyond the flange
    table = [(0, .333, 0), (0, 0, -np.pi / 2), (0, .316, np.pi / 2),
             (.0825, 0, np.pi / 2), (-.0825, .384, -np.pi / 2), (0, 0, np.pi / 2),
             (.088, 0, np.pi / 2)]
    lo = [-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973]
    hi = [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973]
    qs = np.random.default_rng(0).uniform(lo, hi, (50, 7))
    m, tool = _tool_positions(model_path("panda.xml"), qs)
    for q, p in zip(qs, tool):
        T = np.eye(4)
        for (a, d, alpha), theta in zip(table, q):
            T = T @ _mdh(a, d, alpha, theta)
        np.testing.assert_allclose(p, (T @ _mdh(0, .107 + .1034, 0, 0))[:3, 3],
                                   atol=1e-9)
    np.testing.assert_allclose(m.jnt_range, np.c_[lo, hi])
    lim = read_limits(m, JOINTS7)
    np.testing.assert_allclose(lim.velocity, [2.175] * 4 + [2.61] * 3, rtol=1e-6)
    np.testing.assert_allclose(lim.acceleration, [15, 7.5, 10, 12.5, 15, 20, 20])
    np.testing.assert_allclose(lim.effort, [87] * 4 + [12] * 3)
    assert all(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
               for a in range(m.nu)) and m.nu == 7
    assert np.all(m.actuator_biastype == int(mujoco.mjtBias.mjBIAS_NONE))  # motors
    # the home keyframe: Franka's documented end-effector pose there (0.307, 0, 0.487)
    d = mujoco.MjData(m)
    d.qpos[:] = m.key("home").qpos
    mujoco.mj_kinematics(m, d)
    np.testing.assert_allclose(d.site("tool").xpos, [0.3069, 0, 0.4869], atol=2e-4)
    # Gaz et al. 2019 link masses
    np.testing.assert_allclose(m.body_mass[1:8], [4.970684, 0.646926, 3.228604,
                                                  3.587895, 1.225946, 1.666555,
                                                  0.735522])


def test_the_iiwa_follows_kukas_dimensions_and_limits():
    # product of exponentials from KUKA's dimensions: joints 2, 4, 6 at 0.36, 0.78 and
    # 1.18 m on the vertical, the flange 1.306 m, the 0.1 m tool beyond it; only the
    # axes' signs are read from the model (at all-zeros)
    m = mujoco.MjModel.from_xml_path(str(model_path("iiwa14.xml")))
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    axes = d.xaxis.copy()
    heights = [0.1575, 0.36, 0.5645, 0.78, 0.9645, 1.18, 1.261]
    np.testing.assert_allclose(d.xanchor, np.c_[np.zeros((7, 2)), heights], atol=1e-9)
    np.testing.assert_allclose(np.abs(axes), np.tile([[0, 0, 1], [0, 1, 0]], (4, 1))[:7],
                               atol=1e-9)
    lo = np.radians([-170, -120, -170, -120, -170, -120, -175])
    qs = np.random.default_rng(1).uniform(lo, -lo, (50, 7))
    _, tool = _tool_positions(model_path("iiwa14.xml"), qs)
    for q, p in zip(qs, tool):
        x = np.array([0, 0, 1.406])
        for j in range(6, -1, -1):  # tip first: x -> R_j (x - c_j) + c_j
            c = np.array([0, 0, heights[j]])
            x = _rot(axes[j], q[j]) @ (x - c) + c
        np.testing.assert_allclose(p, x, atol=1e-9)
    np.testing.assert_allclose(m.jnt_range[:, 1], -lo, atol=1e-5)
    lim = read_limits(m, JOINTS7)
    np.testing.assert_allclose(np.degrees(lim.velocity),
                               [85, 85, 100, 75, 130, 135, 135], rtol=1e-5)
    np.testing.assert_allclose(lim.effort, [320, 320, 176, 176, 110, 40, 40])
    assert np.all(m.actuator_biastype == int(mujoco.mjtBias.mjBIAS_AFFINE))  # servos


@pytest.mark.slow
@pytest.mark.parametrize("name", ["panda.xml", "iiwa14.xml"])
def test_the_home_posture_is_clear_of_self_collision(name):
    joints, site, key = SHIPPED[name]
    robot = Robot.from_mjcf(model_path(name), joints, site, keyframe=key)
    col = Collider(robot)
    d, k = col.min_distance(jnp.asarray(robot.start_genes))
    assert float(d) > 0.01, col.pair_names[int(k)]
    assert not col.skipped


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SHIPPED))
def test_mjx_kinematics_equals_mujoco_c_on_every_shipped_model(name):
    joints, site, key = SHIPPED[name]
    robot = Robot.from_mjcf(model_path(name), joints, site, keyframe=key,
                            kinematics="mjx")
    m = robot.mj_model
    lo, hi = m.jnt_range[robot.joint_ids].T
    fk = jax.jit(robot.marker_position)
    d = mujoco.MjData(m)
    for genes in np.random.default_rng(2).uniform(lo, hi, (4, len(joints))):
        d.qpos[:] = np.asarray(robot.qpos(jnp.asarray(genes, jnp.float32)))
        mujoco.mj_kinematics(m, d)
        np.testing.assert_allclose(np.asarray(fk(jnp.asarray(genes, jnp.float32))),
                                   d.site_xpos[robot.site_id], atol=5e-6)


@pytest.mark.slow
@pytest.mark.parametrize("name", [
    "tiny_arm.xml", "teo.xml",
    # the Panda (motors through the PD, gravity compensation) and the iiwa (force-limited
    # servos) under implicitfast: 33 mm / 8.4 mm apart with plain mjx.step, which keeps
    # a saturated actuator's velocity derivative (cgda_jax.sim.mjx_step)
    "panda.xml", "iiwa14.xml",
])
def test_mjx_physics_equals_mujoco_c_on_every_shipped_model(name):
    joints, site, key = SHIPPED[name]
    robot = Robot.from_mjcf(model_path(name), joints, site, keyframe=key)
    m = robot.mj_model
    lo, hi = m.jnt_range[robot.joint_ids].T
    mid = np.asarray(robot.start_genes)
    way = np.clip(mid + np.random.default_rng(3).uniform(-0.2, 0.2, (2, len(joints))),
                  lo, hi).astype(np.float32)
    feats = {}
    for backend in ("mujoco", "mjx"):
        sim = Simulator(robot, MarkerScene(), mode="dynamic", physics=backend,
                        waypoint_s=0.1, timestep=0.01)
        feats[backend] = np.asarray(jax.jit(sim.execute)(jnp.asarray(way)))
    assert np.all(np.isfinite(feats["mujoco"]))
    # the backends' stated tolerance (float32 MJX vs float64 MuJoCo C): 1e-4 m
    np.testing.assert_allclose(feats["mjx"], feats["mujoco"], atol=1e-4)
