"""Dynamic mode: the simulated model, both physics backends against MuJoCo C, start
states from the model, and IE evaluated the way the final execution runs."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path, run_ie
from cgda_jax.sim.physics import Physics, resolve_physics, weldable_joints

TEO_JOINTS = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]


@pytest.fixture(scope="module")
def tiny():
    return Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                           "marker")


@pytest.fixture(scope="module")
def teo():
    return Robot.from_mjcf(model_path("teo.xml"), TEO_JOINTS, "marker",
                           {"r_forearm_rotation": np.radians(45)})


def c_reference(sim, waypoints):
    """MuJoCo C, plain ``mj_step`` loop on the simulated model with the same
    reference controls: features (N, 3) and the final qpos (float64)."""
    phys = sim.physics
    m = phys.model
    d = mujoco.MjData(m)
    d.qpos[:] = phys.qpos0
    prev = d.qpos[phys.act_qadr].copy()
    feats = []
    for w in np.asarray(waypoints, np.float64):
        q = phys.qpos0.copy()
        q[phys.gene_qadr] = w
        target = q[phys.act_qadr]
        for k in range(sim.physics_steps):
            d.ctrl[:] = prev + float(sim._profile[k]) * (target - prev)
            mujoco.mj_step(m, d)
        prev = target
        mujoco.mj_kinematics(m, d)
        feats.append(d.site_xpos[phys.site_id].copy())
    return np.array(feats), d.qpos.copy()


@pytest.mark.parametrize("backend", ["mujoco", "mjx"])
def test_tiny_arm_features_equal_mujoco_c(tiny, backend):
    sim = Simulator(tiny, MarkerScene(), mode="dynamic", physics=backend,
                    waypoint_s=0.3)
    assert sim.backend.name == backend and sim.physics_steps == 150
    wps = np.radians([[30, 20, 40], [-20, 45, 60], [10, -30, -50]]).astype(np.float32)
    feats, state = jax.jit(sim.rollout)(wps)
    want, qpos = c_reference(sim, wps)
    # float32 (MJX) / float64 (C) over 450 steps: 1e-4 m
    np.testing.assert_allclose(np.asarray(feats), want, atol=1e-4)
    np.testing.assert_allclose(np.asarray(state.data[: sim.physics.nq]), qpos,
                               atol=1e-4)
    # it is physics (gravity sag), not a copy of the target
    assert not np.allclose(qpos, wps[-1], atol=1e-4)
    np.testing.assert_allclose(qpos, wps[-1], atol=0.05)


def test_teo_features_equal_mujoco_c_for_each_backend(teo):
    wps = np.radians([[40, -30, 60], [10, -60, 90], [60, 0, 20]]).astype(np.float32)
    sims = {b: Simulator(teo, MarkerScene(), mode="dynamic", physics=b, timestep=0.01,
                         waypoint_s=0.5) for b in ("mujoco", "mjx")}
    want, _ = c_reference(sims["mujoco"], wps)
    for name, sim in sims.items():
        got = np.asarray(jax.jit(sim.execute)(wps))
        np.testing.assert_allclose(got, want, atol=1e-4, err_msg=name)


def test_teo_welds_what_does_not_move_and_keeps_its_kinematics(teo):
    phys = Physics(teo)
    # the paper's 3 joints + the held forearm rotation (45 deg is not its ref, 0)
    kept = {mujoco.mj_id2name(phys.model, mujoco.mjtObj.mjOBJ_JOINT, j)
            for j in range(phys.model.njnt)}
    assert kept == set(TEO_JOINTS) | {"r_forearm_rotation"}
    assert len(phys.welded) == 10 and phys.model.nu == 4
    assert phys.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_AUTORESET
    # same marker as the full model (chain FK) at random postures
    rng = np.random.default_rng(0)
    d = mujoco.MjData(phys.model)
    for genes in rng.uniform(teo.lower, teo.upper, (20, 3)):
        d.qpos[:] = phys.qpos0
        d.qpos[phys.gene_qadr] = genes
        mujoco.mj_kinematics(phys.model, d)
        np.testing.assert_allclose(
            d.site_xpos[phys.site_id],
            np.asarray(teo.marker_position(jnp.asarray(genes, jnp.float32))),
            atol=1e-5)
    assert len(Physics(teo, reduce=False).welded) == 0


def test_dynamic_paint_scene_paints_along_the_physical_path(teo):
    sim = Simulator(teo, PaintWall.grid(), mode="dynamic", physics="mujoco",
                    timestep=0.01)
    wps = np.radians([[60, -20, 30], [60, -60, 30]]).astype(np.float32)
    feats = np.asarray(jax.jit(sim.execute)(wps))
    assert feats.shape == (2, 1) and feats[1, 0] >= feats[0, 0] > 0
    assert feats[0, 0] % 6.25 == 0


_FREE_BALL = """
<mujoco>
  <option timestep="0.002"/>
  <default><geom contype="0" conaffinity="0"/></default>
  <worldbody>
    <body name="link1" pos="0 0 0.05">
      <joint name="yaw" axis="0 0 1" range="-90 90" damping="2"/>
      <joint name="shoulder" axis="0 1 0" range="-90 90" damping="2"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.02"/>
      <site name="marker" pos="0 0 0.3"/>
      <body name="pendulum" pos="0 0 0.3">
        <joint name="ball" type="ball" damping="0.5"/>
        <geom type="capsule" fromto="0 0 0 0.1 0 -0.1" size="0.01"/>
      </body>
    </body>
    <body name="box" pos="0.5 0.2 0.3">
      <freejoint name="box"/>
      <geom type="box" size="0.05 0.05 0.05"/>
    </body>
  </worldbody>
  <actuator>
    <position joint="yaw" kp="50"/>
    <position joint="shoulder" kp="50"/>
  </actuator>
  <keyframe>
    <key name="home" qpos="0.3 0.2  1 0 0 0  0.4 0.1 0.6 1 0 0 0"/>
  </keyframe>
</mujoco>
"""


@pytest.mark.parametrize("backend", ["mujoco", "mjx"])
def test_free_and_ball_joints_start_from_the_model(tmp_path, backend):
    path = tmp_path / "free_ball.xml"
    path.write_text(_FREE_BALL)
    robot = Robot.from_mjcf(path, ["yaw", "shoulder"], "marker")
    m = robot.mj_model
    np.testing.assert_allclose(np.asarray(robot.qpos0), m.qpos0, atol=1e-7)
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics=backend,
                    waypoint_s=0.2)
    state0 = np.asarray(sim.init_state().data)
    # ball quaternion (1 0 0 0) and the box at its body pose with a unit quaternion
    np.testing.assert_allclose(state0[2:6], [1, 0, 0, 0])
    np.testing.assert_allclose(state0[6:13], [0.5, 0.2, 0.3, 1, 0, 0, 0])
    feats, state = sim.rollout(np.radians([[20, 30], [-10, 10]]).astype(np.float32))
    assert np.all(np.isfinite(np.asarray(feats))) and np.all(np.isfinite(state.data))
    q = np.asarray(state.data[: sim.physics.nq])
    assert abs(np.linalg.norm(q[2:6]) - 1) < 1e-4 and abs(np.linalg.norm(q[9:13]) - 1) < 1e-4
    assert q[8] < 0.3 - 0.05  # the free box fell under gravity

    home = Robot.from_mjcf(path, ["yaw"], "marker", keyframe="home")
    np.testing.assert_allclose(np.asarray(home.qpos0), m.key_qpos[0], atol=1e-7)
    sim = Simulator(home, MarkerScene(), mode="dynamic", physics=backend)
    np.testing.assert_allclose(np.asarray(sim.init_state().data)[1], 0.2, atol=1e-6)
    with pytest.raises(KeyError, match="keyframe 'away'.*'home'"):
        Robot.from_mjcf(path, ["yaw"], "marker", keyframe="away")


def test_dynamic_settings_are_checked(tiny):
    with pytest.raises(ValueError, match="physics"):
        Simulator(tiny, MarkerScene(), mode="dynamic", physics="bullet")
    with pytest.raises(ValueError, match="waypoint_s"):
        Simulator(tiny, MarkerScene(), mode="dynamic", waypoint_s=0)
    with pytest.raises(ValueError, match="move_fraction"):
        Simulator(tiny, MarkerScene(), mode="dynamic", move_fraction=1.5)
    with pytest.raises(ValueError, match="timestep"):
        Simulator(tiny, MarkerScene(), mode="dynamic", timestep=-1.0)
    assert resolve_physics("auto") in ("mujoco", "mjx")
    sim = Simulator(tiny, MarkerScene(), mode="dynamic", waypoint_s=0.5, timestep=0.01)
    assert sim.physics_steps == 50 and sim.waypoint_s == pytest.approx(0.5)
    # the reference: minimum jerk to the target, then held
    prof = sim._profile
    assert prof[0] > 0 and np.all(np.diff(prof) >= 0) and prof[29] == 1 == prof[-1]
    m = Robot(tiny.mj_model, ["yaw"], "marker")
    with pytest.raises(ValueError, match="from_mjcf"):
        Simulator(m, MarkerScene(), mode="dynamic")
    assert weldable_joints(tiny.mj_model, np.zeros(3), ["yaw"]) == ["shoulder", "elbow"]


def test_dynamic_ie_on_the_tiny_arm_succeeds_in_sequence(tiny):
    sim = Simulator(tiny, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.4, timestep=0.004)
    # reachable goal: markers of known postures
    postures = np.radians([[20, 30, 40], [40, 20, 60], [60, 10, 70], [30, -20, 50]])
    goal = np.stack([np.asarray(tiny.marker_position(jnp.asarray(p, jnp.float32)))
                     for p in postures])
    res = run_ie(sim, goal, population_size=16, tolerance=0.02, max_generations=150,
                 seed=1)
    assert res.info["sequential_context"] is True
    assert res.success, res.point_errors
    # success is that of the sequential execution: re-execute from the start
    again = np.asarray(sim.execute(res.joints))
    np.testing.assert_allclose(again, res.features, atol=1e-5)
    assert np.all(np.linalg.norm(again - goal, axis=-1) < 0.02)
    # a finer simulation of the same joints gives the same features
    fine = Simulator(tiny, MarkerScene(), mode="dynamic", physics="mujoco",
                     waypoint_s=0.4, timestep=0.001)
    np.testing.assert_allclose(np.asarray(fine.execute(res.joints)), res.features,
                               atol=2e-3)


def test_object_features_from_the_simulated_world_in_every_mode():
    from cgda_jax import ObjectScene

    objs = [{"piece": "table", "pos": [0.5, -0.35, -0.35]},
            {"piece": "box", "pos": [0.45, -0.30, -0.30]}]
    robot = Robot.from_world(model_path("teo.xml"), objs, TEO_JOINTS, "marker",
                             {"r_forearm_rotation": np.radians(45)},
                             contact_geoms=("r_hand", "r_tool"))
    scene = ObjectScene([{"body": "box", "quantity": "xy"},
                         {"body": "box", "quantity": "yaw"},
                         {"site": "marker", "quantity": "z"}])
    wps = np.radians([[30, -20, 40], [50, -20, 60]]).astype(np.float32)
    sim = Simulator(robot, scene, mode="dynamic", physics="mujoco", timestep=0.005,
                    waypoint_s=0.3)
    assert sim.feature_names == ("box.x [m]", "box.y [m]", "box.yaw [rad]",
                                 "marker.z [m]")
    feats = np.asarray(jax.jit(sim.execute)(wps))
    # MuJoCo C reference: same controls, features from mj_forward's state
    phys = sim.physics
    d = mujoco.MjData(phys.model)
    d.qpos[:] = phys.qpos0
    prev = d.qpos[phys.act_qadr].copy()
    for w, got in zip(wps, feats):
        q = phys.qpos0.copy()
        q[phys.gene_qadr] = w
        for k in range(sim.physics_steps):
            d.ctrl[:] = prev + float(sim._profile[k]) * (q[phys.act_qadr] - prev)
            mujoco.mj_step(phys.model, d)
        prev = q[phys.act_qadr]
        mujoco.mj_forward(phys.model, d)
        box = mujoco.mj_name2id(phys.model, mujoco.mjtObj.mjOBJ_BODY, "box")
        yaw = np.arctan2(d.xmat[box][3], d.xmat[box][0])
        want = [*d.xpos[box][:2], yaw, d.site_xpos[phys.site_id][2]]
        np.testing.assert_allclose(got, want, atol=1e-4)
    # kinematic mode: only contact moves the box, so its features would never change:
    # refused by name (issue 25); the world's forward kinematics for the marker
    with pytest.raises(ValueError, match=r"kinematic mode: feature body 'box' \(xy\) "
                       r"never changes.*mode='dynamic'"):
        Simulator(robot, scene)
    marker = ObjectScene([{"site": "marker", "quantity": "z"}])
    kin = np.asarray(Simulator(robot, marker).execute(wps))
    np.testing.assert_allclose(kin[:, 0], [robot.marker_position(jnp.asarray(w))[2]
                                           for w in wps], atol=1e-5)
    with pytest.raises(KeyError, match="boxx"):
        Simulator(robot, ObjectScene([{"body": "boxx", "quantity": "xy"}]),
                  mode="dynamic")
