"""Robot + object pieces composed with MjSpec (cgda_jax.sim.world)."""

import mujoco
import numpy as np
import pytest

from cgda_jax.sim._mujoco_env import mjx_module
from cgda_jax.sim.features import FeatureSet, add_sensors
from cgda_jax.sim.robot import model_path
from cgda_jax.sim.world import compile_world, compose_world, list_pieces

# In TEO's waist frame: a table in front of the right arm, a box on it, a valve.
TEO_OBJECTS = [
    {"piece": "table", "pos": [0.45, -0.3, -0.1]},
    {"piece": "box", "pos": [0.4, -0.3, -0.06], "euler": [0, 0, 30]},
    {"piece": "valve", "pos": [0.45, 0.0, -0.1], "damping": 0.2},
]


@pytest.fixture(scope="module")
def teo_pair():
    plain = mujoco.MjModel.from_xml_path(str(model_path("teo.xml")))
    world = compile_world(model_path("teo.xml"), TEO_OBJECTS,
                          contact_geoms=["r_hand", "r_tool"])
    return plain, world


def test_builtin_pieces():
    assert list_pieces() == ("box", "iron", "table", "valve")


def test_robot_kinematics_unchanged(teo_pair):
    plain, world = teo_pair
    dp, dw = mujoco.MjData(plain), mujoco.MjData(world)
    rng = np.random.default_rng(0)
    joints = [plain.joint(j).name for j in range(plain.njnt)]
    bodies = [plain.body(b).name for b in range(1, plain.nbody)]
    for _ in range(20):
        for name in joints:
            lo, hi = plain.joint(name).range
            q = rng.uniform(lo, hi)
            dp.qpos[plain.joint(name).qposadr[0]] = q
            dw.qpos[world.joint(name).qposadr[0]] = q
        mujoco.mj_kinematics(plain, dp)
        mujoco.mj_kinematics(world, dw)
        for site in ("marker", "marker_left"):
            np.testing.assert_allclose(dw.site(site).xpos, dp.site(site).xpos,
                                       atol=1e-12)
        for body in bodies:
            np.testing.assert_allclose(dw.body(body).xpos, dp.body(body).xpos,
                                       atol=1e-12)
            np.testing.assert_allclose(dw.body(body).xquat, dp.body(body).xquat,
                                       atol=1e-12)


def test_names_poses_and_joints(teo_pair):
    _, m = teo_pair
    box = m.joint("box")
    assert box.type[0] == mujoco.mjtJoint.mjJNT_FREE
    qpos = m.qpos0[box.qposadr[0]:box.qposadr[0] + 7]
    np.testing.assert_allclose(qpos[:3], [0.4, -0.3, -0.06])
    assert np.linalg.norm(qpos[3:]) == pytest.approx(1.0)
    np.testing.assert_allclose(qpos[3:], [np.cos(np.pi / 12), 0, 0, np.sin(np.pi / 12)])
    valve = m.joint("valve")
    assert valve.type[0] == mujoco.mjtJoint.mjJNT_HINGE
    assert m.dof_damping[valve.dofadr[0]] == pytest.approx(0.2)
    for site in ("box/centre", "valve/rim"):
        assert m.site(site).id >= 0
    # the table top's surface lies at the table's pos z; the box collides with it
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    assert d.geom("table").xpos[2] + m.geom("table").size[2] == pytest.approx(-0.1)
    table, boxg = m.geom("table"), m.geom("box")
    assert table.contype[0] & boxg.conaffinity[0]
    # robot contacts only on the named geoms
    assert m.geom("r_tool").contype[0] == 2 and m.geom("r_hand").conaffinity[0] == 1
    assert m.geom("l_tool").contype[0] == 0 and m.geom("chest").conaffinity[0] == 0


def test_piece_parameters():
    m = compile_world(model_path("tiny_arm.xml"), [
        {"piece": "table", "name": "desk", "pos": [0, 0, 0],
         "size": [0.2, 0.3, 0.03], "height": 0.5, "friction": 0.8},
        {"piece": "box", "pos": [0, 0, 0.05], "size": [0.02, 0.03, 0.05],
         "mass": 0.2, "rgba": [0, 1, 0, 1]},
        {"piece": "valve", "pos": [1, 0, 0], "euler": [90, 0, 0], "radius": 0.15},
    ])
    np.testing.assert_allclose(m.geom("desk").size, [0.2, 0.3, 0.03])
    assert m.geom("desk").friction[0] == pytest.approx(0.8)
    leg = m.geom("desk/leg1")
    assert leg.pos[2] - leg.size[1] == pytest.approx(-0.5)  # feet at -height
    np.testing.assert_allclose(m.geom("box").size, [0.02, 0.03, 0.05])
    assert m.body("box").mass[0] == pytest.approx(0.2)
    np.testing.assert_allclose(m.site("valve/rim").pos[0], 0.15)
    np.testing.assert_allclose(m.geom("valve/handle").pos[0], 0.15)
    # euler in degrees: the valve's hinge axis turned from z to -y
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(d.joint("valve").xaxis, [0, -1, 0], atol=1e-12)


def test_sensors_on_composed_world_and_mjx_support(teo_pair):
    spec = compose_world(model_path("teo.xml"), TEO_OBJECTS,
                         contact_geoms=["r_hand", "r_tool"])
    feats = [{"body": "box", "quantity": "xy"}, {"body": "box", "quantity": "yaw"},
             {"joint": "valve", "quantity": "angle"}]
    add_sensors(spec, feats)
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    fs = FeatureSet(m, feats)
    np.testing.assert_allclose(fs.from_sensordata(d.sensordata),
                               [0.4, -0.3, np.pi / 6, 0.0], atol=1e-6)
    # every colliding geom pair is one MJX's JAX back-end implements
    mjx_module().put_model(teo_pair[1], impl="jax")


PUSH_OBJECTS = [
    {"piece": "table", "pos": [0.35, 0, 0], "size": [0.25, 0.4, 0.02], "height": 0.3},
    {"piece": "box", "pos": [0.42, 0.10, 0.03], "size": [0.03, 0.03, 0.03],
     "mass": 0.1},
]


def _push(contact_geoms):
    """Sweep the tiny arm (horizontal) 25 deg about z into a box on a table."""
    m = compile_world(model_path("tiny_arm.xml"), PUSH_OBJECTS,
                      contact_geoms=contact_geoms)
    d = mujoco.MjData(m)
    d.joint("shoulder").qpos = np.pi / 2  # link along +x at z = 0.05
    d.ctrl[:] = [0.0, np.pi / 2, 0.0]
    mujoco.mj_forward(m, d)
    start, lowest = d.body("box").xpos.copy(), np.inf
    for k in range(1000):  # 2 s: yaw ramps to 25 deg in 1 s, then holds
        d.ctrl[0] = min(k * m.opt.timestep, 1.0) * np.deg2rad(25)
        mujoco.mj_step(m, d)
        lowest = min(lowest, d.body("box").xpos[2])
    return start, d.body("box").xpos.copy(), lowest


def test_push_moves_box_in_the_commanded_direction():
    start, end, lowest = _push(["link1", "link2"])
    assert end[1] - start[1] > 0.05  # the arm sweeps towards +y: the box goes +y
    assert lowest > 0.03 - 0.005  # rests on the table top (z = 0), never sinks
    assert abs(end[2] - 0.03) < 0.005
    start, end, _ = _push([])  # robot contacts off: the arm passes through
    np.testing.assert_allclose(end, start, atol=1e-3)


def test_custom_piece_file(tmp_path):
    path = tmp_path / "lever.xml"
    path.write_text(
        '<mujoco><worldbody><body name="object"><joint name="object" axis="0 0 1"/>'
        '<geom name="object" type="box" size="0.1 0.01 0.01"/>'
        '<site name="tip" pos="0.1 0 0"/></body></worldbody></mujoco>'
    )
    m = compile_world(model_path("tiny_arm.xml"),
                      [{"piece": str(path), "pos": [1, 0, 0]}])
    assert m.joint("lever").id >= 0 and m.site("lever/tip").id >= 0
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['radius'\]"):
        compile_world(model_path("tiny_arm.xml"),
                      [{"piece": str(path), "pos": [1, 0, 0], "radius": 1}])


@pytest.mark.parametrize("obj, match", [
    ({"piece": "crate", "pos": [0, 0, 0]},
     r"unknown object piece 'crate'; the built-in pieces are "
     r"\['box', 'iron', 'table', 'valve'\]"),
    ({"piece": "box", "pos": [0, 0, 0], "colour": "red"},
     r"unknown key\(s\) \['colour'\]; allowed: \['piece', 'name', 'pos', 'body', 'euler', "
     r"'quat', 'size', 'mass', 'friction', 'rgba'\]"),
    ({"piece": "valve", "pos": [0, 0, 0], "size": [1, 1, 1]}, r"\['size'\]"),
    ({"pos": [0, 0, 0]}, "missing key 'piece'"),
    ({"piece": "box"}, "missing key 'pos'"),
    ({"piece": "box", "pos": [0, 0]}, "'pos' must be 3 finite numbers"),
    ({"piece": "box", "pos": [0, 0, 0], "euler": [0, 0, 1], "quat": [1, 0, 0, 0]},
     "'euler' or 'quat', not both"),
    ({"piece": "box", "pos": [0, 0, 0], "size": [0.1, -0.1, 0.1]},
     r"object 0 \('box', piece 'box'\): 'size' must be positive"),
    ({"piece": "table", "pos": [0, 0, 0], "height": 0.01}, "'height' 0.01 must exceed"),
    ({"piece": "box", "name": "link1", "pos": [0, 0, 0]}, "'link1' is already used"),
])
def test_bad_objects_name_the_problem(obj, match):
    with pytest.raises(ValueError, match=match):
        compose_world(model_path("tiny_arm.xml"), [obj])


def test_bad_world_arguments(tmp_path):
    with pytest.raises(ValueError, match="'box' is already used"):
        compose_world(model_path("tiny_arm.xml"),
                      [{"piece": "box", "pos": [0, 0, 0]}] * 2)
    with pytest.raises(KeyError, match=r"contact geom 'hand' not found; the robot has "
                       r"geoms \['base', 'link1', 'link2'\]"):
        compose_world(model_path("tiny_arm.xml"), [], contact_geoms=["hand"])
    with pytest.raises(FileNotFoundError, match="robot MJCF"):
        compose_world(tmp_path / "nope.xml", [])
    with pytest.raises(FileNotFoundError, match="object piece file"):
        compose_world(model_path("tiny_arm.xml"),
                      [{"piece": str(tmp_path / "nope.xml"), "pos": [0, 0, 0]}])


def test_c_rollout_sensordata_gives_the_features():
    """mujoco.rollout's sensordata -> FeatureSet.from_sensordata (vmapped)."""
    import jax
    from mujoco import rollout

    spec = compose_world(model_path("tiny_arm.xml"), PUSH_OBJECTS,
                         contact_geoms=["link1", "link2"])
    feats = [{"body": "box", "quantity": "xy"}, {"site": "marker", "quantity": "xyz"},
             {"joint": "yaw", "quantity": "angle"}]
    add_sensors(spec, feats)
    m = spec.compile()
    fs = FeatureSet(m, feats)
    d = mujoco.MjData(m)
    d.joint("shoulder").qpos = np.pi / 2
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.zeros(mujoco.mj_stateSize(m, full))
    mujoco.mj_getState(m, d, state0, full)
    t = np.arange(1000) * m.opt.timestep
    yaw = np.minimum(t, 1.0) * np.deg2rad(25)
    ctrl = np.stack([yaw, np.full_like(t, np.pi / 2), np.zeros_like(t)], axis=-1)
    states, sensordata = rollout.rollout(m, d, state0[None], ctrl[None])
    features = jax.vmap(fs.from_sensordata)(sensordata[0])  # (T, F)
    assert features.shape == (1000, 6)
    _, end, _ = _push(["link1", "link2"])  # the same push stepped by mj_step
    np.testing.assert_allclose(features[-1, :2], end[:2], atol=1e-5)
    assert features[-1, 5] == pytest.approx(np.deg2rad(25), abs=0.01)
    # the marker is the arm tip, 0.30 + 0.25 m from the yaw axis
    np.testing.assert_allclose(np.hypot(features[-1, 2], features[-1, 3]), 0.55,
                               atol=0.01)
