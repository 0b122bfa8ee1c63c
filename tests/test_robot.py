"""Robot: names -> ids, limits, forward kinematics vs MuJoCo C and the TEO facts."""

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import Robot, model_path

TEO_RIGHT = [
    "r_shoulder_flexion",
    "r_shoulder_abduction",
    "r_upper_arm_rotation",
    "r_elbow",
    "r_forearm_rotation",
    "r_wrist",
]
TEO_ALL = ["trunk_axial", "trunk_frontal", *TEO_RIGHT] + [
    j.replace("r_", "l_", 1) for j in TEO_RIGHT
]
SHOULDER_R = np.array([0.0, -0.34692, 0.4982])
ARM = 0.329 + 0.202 + 0.267


def _c_marker(robot: Robot, genes: np.ndarray) -> np.ndarray:
    """Marker position from MuJoCo C (float64) at the same posture."""
    data = mujoco.MjData(robot.mj_model)
    data.qpos[:] = np.asarray(robot.qpos(jnp.asarray(genes, jnp.float32)), np.float64)
    mujoco.mj_kinematics(robot.mj_model, data)
    return data.site_xpos[robot.site_id].copy()


CASES = [
    ("teo.xml", TEO_ALL, "marker", None),
    ("teo.xml", TEO_ALL, "marker_left", None),
    (
        "teo.xml",
        ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"],
        "marker",
        {"r_forearm_rotation": math.pi / 4, "r_wrist": 0.3, "trunk_axial": -0.2},
    ),
    ("tiny_arm.xml", ["yaw", "shoulder", "elbow"], "marker", None),
    ("tiny_arm.xml", ["elbow", "shoulder"], "marker", {"yaw": 0.7}),
]


@pytest.mark.parametrize("kinematics", ["chain", "mjx"])
@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}-{c[2]}-{len(c[1])}")
def test_marker_matches_mujoco_c(case, kinematics):
    name, joints, site, fixed = case
    robot = Robot.from_mjcf(
        model_path(name), joints, site, fixed, kinematics=kinematics
    )
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    genes = rng.uniform(lo, hi, size=(20, robot.n_dof)).astype(np.float32)
    got = np.asarray(jax.jit(jax.vmap(robot.marker_position))(jnp.asarray(genes)))
    want = np.stack([_c_marker(robot, g) for g in genes])
    np.testing.assert_allclose(got, want, atol=1e-5)
    assert np.ptp(want, axis=0).max() > 0.1  # the postures really differ


def test_limits_from_model():
    robot = Robot.from_mjcf(model_path("teo.xml"), TEO_RIGHT, "marker")
    want = np.deg2rad(
        [[-45, 70], [-70, 15], [-10, 75], [-10, 100], [-90, 90], [-10, 100]]
    )
    np.testing.assert_allclose(robot.lower, want[:, 0], rtol=1e-6)
    np.testing.assert_allclose(robot.upper, want[:, 1], rtol=1e-6)
    left = Robot.from_mjcf(
        model_path("teo.xml"),
        [j.replace("r_", "l_", 1) for j in TEO_RIGHT],
        "marker_left",
    )
    want = np.deg2rad(
        [[-75, 45], [-15, 70], [-10, 75], [-100, 10], [-90, 90], [-100, 10]]
    )
    np.testing.assert_allclose(left.lower, want[:, 0], rtol=1e-6)
    np.testing.assert_allclose(left.upper, want[:, 1], rtol=1e-6)


def test_qpos_writes_genes_and_fixed_values():
    robot = Robot.from_mjcf(
        model_path("teo.xml"),
        ["r_elbow", "r_shoulder_flexion"],
        "marker",
        fixed={"r_forearm_rotation": 0.5},
    )
    qpos = np.asarray(robot.qpos(jnp.array([0.1, 0.2])))
    m = robot.mj_model
    adr = {
        mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j): m.jnt_qposadr[j]
        for j in range(m.njnt)
    }
    assert qpos[adr["r_elbow"]] == pytest.approx(0.1)
    assert qpos[adr["r_shoulder_flexion"]] == pytest.approx(0.2)
    assert qpos[adr["r_forearm_rotation"]] == pytest.approx(0.5)
    assert np.count_nonzero(qpos) == 3


@pytest.fixture(scope="module")
def teo_right():
    return Robot.from_mjcf(model_path("teo.xml"), TEO_ALL, "marker")


def _teo(robot, **deg):
    genes = np.zeros(robot.n_dof, np.float32)
    for k, v in deg.items():
        genes[robot.joint_names.index(k)] = np.deg2rad(v)
    return np.asarray(robot.marker_position(jnp.asarray(genes)))


def test_teo_hand_checked_postures(teo_right):
    r = teo_right
    # all zeros: arm straight down from the shoulder
    np.testing.assert_allclose(_teo(r), SHOULDER_R - [0, 0, ARM], atol=1e-5)
    # elbow 90: forearm + marker point forward (x), elbow under the shoulder
    np.testing.assert_allclose(
        _teo(r, r_elbow=90), SHOULDER_R + [0.202 + 0.267, 0, -0.329], atol=1e-5
    )
    # shoulder flexion 90: the whole arm forward
    np.testing.assert_allclose(
        _teo(r, r_shoulder_flexion=90), SHOULDER_R + [ARM, 0, 0], atol=1e-5
    )
    # shoulder abduction -90 (right arm out to the side, -y)
    np.testing.assert_allclose(
        _teo(r, r_shoulder_abduction=-90), SHOULDER_R + [0, -ARM, 0], atol=1e-5
    )
    # wrist 90 with the forearm down: the marker (0.267) points forward from the wrist
    np.testing.assert_allclose(
        _teo(r, r_wrist=90), SHOULDER_R + [0.267, 0, -0.329 - 0.202], atol=1e-5
    )
    # forearm rotation alone does not move a marker on the forearm axis
    np.testing.assert_allclose(_teo(r, r_forearm_rotation=45), _teo(r), atol=1e-6)
    # trunk axial 90: the right shoulder swings to +x around the trunk axis
    np.testing.assert_allclose(
        _teo(r, trunk_axial=90), [0.34692, 0.0, 0.4982 - ARM], atol=1e-5
    )


def test_teo_left_arm_mirrors_right():
    left = Robot.from_mjcf(model_path("teo.xml"), TEO_ALL, "marker_left")
    right = Robot.from_mjcf(model_path("teo.xml"), TEO_ALL, "marker")
    mirror = np.array([1.0, -1.0, 1.0])
    # the left joints' ranges mean mirrored motions: flexion/elbow/wrist negated
    for r_deg, l_deg in [
        (
            {"r_shoulder_flexion": 60, "r_elbow": 80},
            {"l_shoulder_flexion": -60, "l_elbow": -80},
        ),
        (
            {"r_shoulder_abduction": -40, "r_wrist": 30},
            {"l_shoulder_abduction": 40, "l_wrist": -30},
        ),
        (
            {"r_shoulder_flexion": 30, "r_upper_arm_rotation": 50, "r_elbow": 60},
            {"l_shoulder_flexion": -30, "l_upper_arm_rotation": 50, "l_elbow": -60},
        ),
    ]:
        np.testing.assert_allclose(
            _teo(left, **l_deg), _teo(right, **r_deg) * mirror, atol=1e-5
        )


def test_other_arm_by_configuration_alone(tmp_path):
    xml = """<mujoco><compiler angle="radian"/><worldbody><body name="a" pos="0 0 1">
      <joint name="slide" type="slide" axis="1 0 0" range="-0.5 0.5"/>
      <joint name="turn" axis="0 0 1" range="-1 1"/>
      <geom size="0.1"/>
      <site name="tip" pos="0.4 0 0"/></body></worldbody></mujoco>"""
    path = tmp_path / "other.xml"
    path.write_text(xml)
    robot = Robot.from_mjcf(path, ["turn", "slide"], "tip")
    np.testing.assert_allclose(robot.lower, [-1, -0.5])
    got = np.asarray(robot.marker_position(jnp.array([np.pi / 2, 0.3])))
    np.testing.assert_allclose(got, [0.3, 0.4, 1.0], atol=1e-6)


def test_bad_inputs_name_the_problem(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.xml"):
        Robot.from_mjcf(tmp_path / "nope.xml", ["a"], "marker")
    with pytest.raises(FileNotFoundError, match="nope.xml"):
        model_path("nope.xml")
    teo = model_path("teo.xml")
    with pytest.raises(KeyError, match="r_knee"):
        Robot.from_mjcf(teo, ["r_elbow", "r_knee"], "marker")
    with pytest.raises(KeyError, match="pen_tip"):
        Robot.from_mjcf(teo, ["r_elbow"], "pen_tip")
    with pytest.raises(KeyError, match="r_ankle"):
        Robot.from_mjcf(teo, ["r_elbow"], "marker", fixed={"r_ankle": 0.1})
    with pytest.raises(ValueError, match="twice"):
        Robot.from_mjcf(teo, ["r_elbow", "r_elbow"], "marker")
    with pytest.raises(ValueError, match="kinematics"):
        Robot.from_mjcf(teo, ["r_elbow"], "marker", kinematics="fast")
    robot = Robot.from_mjcf(teo, ["r_elbow", "r_wrist"], "marker")
    with pytest.raises(ValueError, match=r"expected \(2,\)"):
        robot.marker_position(jnp.zeros(3))


# --- ball and free joints anywhere in the model (issue 12) ------------------------

# The marker's chain crosses a ball joint (off-centre anchor, tilted body) that is
# not evolved: it is held at its start quaternion.
BALL_IN_CHAIN = """<mujoco><compiler angle="radian"/><worldbody>
  <body name="base" pos="0.1 0 0.4" quat="0.9 0.1 0.2 -0.1"><geom size="0.05"/>
    <joint name="h1" axis="0 0 1" range="-2 2"/>
    <body name="cup" pos="0.3 0 0" euler="0.2 -0.3 0.5"><geom size="0.05"/>
      <joint name="ball" type="ball" pos="0.02 0 0.01"/>
      <body name="fore" pos="0.25 0.03 0"><geom size="0.05"/>
        <joint name="h2" axis="0 1 0" range="-2 2"/>
        <joint name="s1" type="slide" axis="1 0 0" range="-0.1 0.1"/>
        <site name="tip" pos="0.15 0 0.02"/>
      </body></body></body></worldbody>
  <keyframe><key name="bent" qpos="0.3  2 0.4 -0.6 1  -0.2 0.05"/></keyframe>
</mujoco>"""

# A free-floating base (placed and tilted by its body pose) carrying the arm, a ball
# joint on the way to the marker.
FREE_BASE = """<mujoco><compiler angle="radian"/><worldbody>
  <body name="torso" pos="0.2 -0.3 1.0" quat="0.8 0.3 -0.2 0.4"><geom size="0.1"/>
    <freejoint name="root"/>
    <body name="arm" pos="0 0.2 0"><geom size="0.05"/>
      <joint name="h1" axis="1 0 0" range="-2 2"/>
      <body name="wrist" pos="0 0 -0.3"><geom size="0.05"/>
        <joint name="ball" type="ball"/>
        <body name="hand" pos="0 0 -0.2"><geom size="0.05"/>
          <joint name="h2" axis="0 1 0" range="-2 2"/>
          <site name="tip" pos="0.1 0 -0.05"/>
        </body></body></body></body></worldbody>
  <keyframe><key name="bent"
    qpos="1 2 3  0 1 1 0  0.4  0.5 0.5 -0.5 0.5  -0.3"/></keyframe>
</mujoco>"""

# Free and ball objects elsewhere in the tree, before the arm: they shift the arm's
# qpos addresses and must keep valid quaternions in the posture.
FREE_OBJECT = """<mujoco><compiler angle="radian"/><worldbody>
  <body name="box" pos="1 1 0.2" euler="0 0 0.8"><freejoint/>
    <geom type="box" size="0.05 0.05 0.05"/></body>
  <body name="pendulum" pos="-1 0 1"><joint name="swing" type="ball"/>
    <geom size="0.05" pos="0 0 -0.2"/></body>
  <body name="arm" pos="0 0 0.5"><geom size="0.05"/>
    <joint name="h1" axis="0 0 1" range="-2 2"/>
    <body name="fore" pos="0.3 0 0"><geom size="0.05"/>
      <joint name="h2" axis="0 1 0" range="-2 2"/>
      <site name="tip" pos="0.2 0 0"/></body></body></worldbody>
  <keyframe><key name="bent"
    qpos="0 0 0.5  3 0 0 4  0 0 1 1  0.1 0.2"/></keyframe>
</mujoco>"""

BALL_FREE_CASES = {
    "ball_in_chain": (BALL_IN_CHAIN, ["h1", "h2", "s1"]),
    "free_base": (FREE_BASE, ["h2", "h1"]),
    "free_object": (FREE_OBJECT, ["h1", "h2"]),
}


BALL, FREE = int(mujoco.mjtJoint.mjJNT_BALL), int(mujoco.mjtJoint.mjJNT_FREE)


def _scale_key_quaternions(m, factor):
    """Scale the keyframe's ball/free quaternions in place (MuJoCo's compiler
    normalizes them, so a non-unit or zero one can only come from an edited model)."""
    for j in range(m.njnt):
        kind = int(m.jnt_type[j])
        if kind in (BALL, FREE):
            end = m.jnt_qposadr[j] + (7 if kind == FREE else 4)
            m.key_qpos[0, end - 4 : end] *= factor


def _mj_site(m, qpos_start, robot, genes):
    """MuJoCo C's site position from the model's own start posture (not the robot's
    qpos0: mj_kinematics normalizes quaternions itself)."""
    data = mujoco.MjData(m)
    data.qpos[:] = qpos_start
    data.qpos[robot.qpos_adr] = genes
    mujoco.mj_kinematics(m, data)
    return data.site_xpos[robot.site_id].copy()


# Every case on the chain back-end; "mjx" (a compile each, seconds) from qpos0 on
# every model and from the keyframe on the one with the most quaternions.
BALL_FREE_RUNS = [(c, "chain", k) for c in BALL_FREE_CASES for k in (None, "bent")] + [
    (c, "mjx", None) for c in BALL_FREE_CASES
] + [("free_base", "mjx", "bent")]


@pytest.mark.parametrize("case,kinematics,keyframe", BALL_FREE_RUNS)
def test_ball_and_free_joints_match_mj_kinematics(case, kinematics, keyframe):
    xml, joints = BALL_FREE_CASES[case]
    m = mujoco.MjModel.from_xml_string(xml)
    _scale_key_quaternions(m, 2.5)  # non-unit start quaternions
    robot = Robot(m, joints, "tip", kinematics=kinematics, keyframe=keyframe)
    start = m.qpos0 if keyframe is None else m.key_qpos[0]
    qpos0 = np.asarray(robot.qpos0, np.float64)
    # every ball/free quaternion of the posture is a unit one
    n_quats = 0
    for j in range(m.njnt):
        kind = int(m.jnt_type[j])
        if kind in (BALL, FREE):
            end = m.jnt_qposadr[j] + (7 if kind == FREE else 4)
            assert np.linalg.norm(qpos0[end - 4 : end]) == pytest.approx(1, abs=1e-6)
            n_quats += 1
    assert n_quats == {"ball_in_chain": 1, "free_base": 2, "free_object": 2}[case]
    rng = np.random.default_rng(1)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    genes = rng.uniform(lo, hi, size=(8, robot.n_dof)).astype(np.float32)
    got = np.asarray(jax.jit(jax.vmap(robot.marker_position))(jnp.asarray(genes)))
    want = np.stack([_mj_site(m, start, robot, g) for g in genes])
    np.testing.assert_allclose(got, want, atol=2e-5)
    assert np.ptp(want, axis=0).max() > 0.05  # the genes really move the marker
    assert np.abs(want).max(axis=1).min() > 0.1  # and it is not at the origin


@pytest.mark.parametrize("kinematics", ["chain", "mjx"])
def test_a_zero_quaternion_start_is_an_error_naming_the_joint(kinematics):
    m = mujoco.MjModel.from_xml_string(BALL_IN_CHAIN)
    _scale_key_quaternions(m, 0.0)  # e.g. a posture built from zeros
    with pytest.raises(ValueError, match=r"ball joint 'ball' in the model: its "
                       r"quaternion \[[-0., ]+\] in keyframe 'bent' is zero"):
        Robot(m, ["h1", "h2"], "tip", kinematics=kinematics, keyframe="bent")
    from cgda_jax.sim.chain import chain_ops

    with pytest.raises(ValueError, match="ball joint 'ball' in qpos0: quaternion"):
        chain_ops(m, m.key_qpos[0], ["h1"], "tip")


# --- fixed joint values and paths (issue 12) --------------------------------------


def test_fixed_values_must_be_finite_and_within_range(tmp_path):
    teo = model_path("teo.xml")
    arm = ["r_shoulder_flexion", "r_elbow"]
    for bad in (float("nan"), float("inf")):
        with pytest.raises(ValueError, match=rf"fixed joint 'r_wrist' in .*teo\.xml: "
                           rf"value {bad} is not finite"):
            Robot.from_mjcf(teo, arm, "marker", fixed={"r_wrist": bad})
    # r_forearm_rotation's range is [-90, 90] deg: 45 (degrees meant) is refused
    with pytest.raises(ValueError, match=(
        r"fixed joint 'r_forearm_rotation' .*: value 45 rad \(2578\.31 deg\) is "
        r"outside the joint's range \[-1\.5708, 1\.5708\] rad \(\[-90, 90\] deg\)$"
    )):
        Robot.from_mjcf(teo, arm, "marker", fixed={"r_forearm_rotation": 45})
    with pytest.raises(ValueError, match=r"'r_wrist' .*: value 'x' is not a number"):
        Robot.from_mjcf(teo, arm, "marker", fixed={"r_wrist": "x"})
    # a rounding excursion is clipped onto the limit
    hi = np.deg2rad(90.0)
    robot = Robot.from_mjcf(teo, arm, "marker",
                            fixed={"r_forearm_rotation": hi + 5e-7})
    adr = robot.mj_model.jnt_qposadr[
        mujoco.mj_name2id(robot.mj_model, mujoco.mjtObj.mjOBJ_JOINT,
                          "r_forearm_rotation")]
    assert robot._qpos0_np[adr] == pytest.approx(hi, abs=1e-12)
    # a slide's range is in metres; an unlimited hinge takes any finite angle
    xml = """<mujoco><worldbody><body><geom size="0.1"/>
      <joint name="s" type="slide" axis="1 0 0" range="-0.1 0.1"/>
      <joint name="free_turn" axis="0 0 1"/><joint name="h" axis="0 1 0"/>
      <site name="tip" pos="0.2 0 0"/></body></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    with pytest.raises(ValueError, match=r"'s' .*: value 0\.5 m is outside the "
                       r"joint's range \[-0\.1, 0\.1\] m$"):
        Robot(m, ["h"], "tip", fixed={"s": 0.5})
    Robot(m, ["h"], "tip", fixed={"free_turn": 12.0})


def test_tilde_model_paths_are_expanded(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    (tmp_path / "arm.xml").write_text(model_path("tiny_arm.xml").read_text())
    robot = Robot.from_mjcf("~/arm.xml", ["yaw", "shoulder", "elbow"], "marker")
    assert robot.source == str(tmp_path / "arm.xml")
    world = Robot.from_world("~/arm.xml", [], ["yaw"], "marker")
    assert world.mj_model.nq == robot.mj_model.nq
