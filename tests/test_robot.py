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
