"""A user's own robot, the small things first: the marker as a point on any body, the
start posture moved into the joints' ranges, config paths relative to the config
file, and no TEO-specific ``fixed`` default."""

import logging
import math
import shutil
import tomllib

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.builtin import experiments_dir
from cgda_jax.experiment.build import build_simulator
from cgda_jax.experiment.config import ConfigError, ExperimentConfig, load_config
from cgda_jax.experiment.demo_suite import demo_configs
from cgda_jax.sim.marker import MARKER_POINT_SITE

JOINTS = ["yaw", "shoulder", "elbow"]
POINT = [0.05, -0.02, 0.11]  # on link2, off its axis


def _c_point(model: mujoco.MjModel, qpos: np.ndarray, body: str, pos) -> np.ndarray:
    """MuJoCo C's point fixed on ``body``: ``xpos + xmat @ pos`` (float64)."""
    d = mujoco.MjData(model)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(model, d)
    b = model.body(body).id
    return d.xpos[b] + d.xmat[b].reshape(3, 3) @ np.asarray(pos, np.float64)


@pytest.mark.parametrize("kinematics", ["chain", "mjx"])
def test_marker_on_a_body_is_mujocos_point_on_that_body(kinematics):
    path = model_path("tiny_arm.xml")
    robot = Robot.from_mjcf(path, JOINTS, {"body": "link2", "pos": POINT},
                            kinematics=kinematics)
    assert robot.marker_site == MARKER_POINT_SITE
    assert robot.marker == {"body": "link2", "pos": POINT}
    plain = mujoco.MjModel.from_xml_path(str(path))  # the user's model, no site
    rng = np.random.default_rng(1)
    for genes in rng.uniform(robot.lower, robot.upper, (20, 3)):
        want = _c_point(plain, genes, "link2", POINT)
        got = np.asarray(robot.marker_position(jnp.asarray(genes, jnp.float32)))
        np.testing.assert_allclose(got, want, atol=2e-6)
    # the other back-end keeps the same point
    other = robot.with_kinematics("mjx" if kinematics == "chain" else "chain")
    g = jnp.asarray([0.3, -0.4, 0.8], jnp.float32)
    np.testing.assert_allclose(np.asarray(other.marker_position(g)),
                               np.asarray(robot.marker_position(g)), atol=2e-6)


def test_marker_on_a_body_in_physics_reads_the_same_point():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS,
                            {"body": "link2", "pos": POINT})
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.1)
    feats, state = sim.rollout(np.radians([[20.0, 30.0, 40.0]]).astype(np.float32))
    qpos = np.asarray(state.data[:sim.physics.nq], np.float64)  # nothing welded
    plain = mujoco.MjModel.from_xml_path(str(model_path("tiny_arm.xml")))
    np.testing.assert_allclose(np.asarray(feats[-1]),
                               _c_point(plain, qpos, "link2", POINT), atol=1e-5)


def test_marker_errors_name_the_problem():
    path = model_path("tiny_arm.xml")
    with pytest.raises(KeyError, match=r"marker body 'hand' not found.*'link2'"):
        Robot.from_mjcf(path, JOINTS, {"body": "hand", "pos": POINT})
    with pytest.raises(ValueError, match="either 'site'.*or 'body'"):
        Robot.from_mjcf(path, JOINTS, {"body": "link2", "site": "marker"})
    with pytest.raises(ValueError, match="marker pos.*3 finite numbers"):
        Robot.from_mjcf(path, JOINTS, {"body": "link2", "pos": [0, 1]})
    with pytest.raises(KeyError, match=r"site 'tip' not found.*body = NAME"):
        Robot.from_mjcf(path, JOINTS, "tip")
    compiled = mujoco.MjModel.from_xml_path(str(path))
    with pytest.raises(ValueError, match="without its MJCF.*from_mjcf"):
        Robot(compiled, JOINTS, {"body": "link2", "pos": POINT})
    assert Robot.from_mjcf(path, JOINTS, {"site": "marker"}).marker_site == "marker"


ARM_OUT_OF_RANGE = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="a">
      <joint name="j1" axis="0 1 0" range="0.2 1.0"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.02"/>
      <body name="b" pos="0 0 0.3">
        <joint name="j2" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.2" size="0.02"/>
        <site name="tip" pos="0 0 0.2"/>
      </body>
    </body>
  </worldbody>
  <keyframe><key name="far" qpos="0.5 4.0"/></keyframe>
</mujoco>
"""


def test_a_start_posture_outside_a_range_is_moved_into_it_and_said(tmp_path, caplog):
    path = tmp_path / "arm.xml"
    path.write_text(ARM_OUT_OF_RANGE)
    with caplog.at_level(logging.WARNING, logger="cgda_jax"):
        robot = Robot.from_mjcf(path, ["j1", "j2"], "tip")
        Robot.from_mjcf(path, ["j1", "j2"], "tip")  # said once, not per build
    said = [r.getMessage() for r in caplog.records if "'j1'" in r.getMessage()]
    assert len(said) == 1, said
    assert "outside its range" in said[0] and "starts from 0.2 rad" in said[0]
    np.testing.assert_allclose(robot.start_genes, [0.2, 0.0], atol=1e-7)
    # an unlimited hinge is wrapped: the same posture, within [-pi, pi)
    key = Robot.from_mjcf(path, ["j1", "j2"], "tip", keyframe="far")
    np.testing.assert_allclose(key.start_genes, [0.5, 4.0 - 2 * math.pi], atol=1e-6)
    # a start value given outside the range is refused, naming the joint
    with pytest.raises(ValueError, match="start value 1.5 of joint 'j1'"):
        Robot.from_mjcf(path, ["j1", "j2"], "tip", start={"j1": 1.5})


def test_model_and_data_paths_are_relative_to_the_config_file(tmp_path, monkeypatch):
    folder = tmp_path / "project"
    (folder / "robots").mkdir(parents=True)
    shutil.copy(model_path("tiny_arm.xml"), folder / "arm.xml")
    shutil.copy(model_path("tiny_arm.xml"), folder / "robots" / "arm2.xml")
    (folder / "data").mkdir()
    text = ('kind = "execution"\n[data]\nsource = "clean_circle"\n'
            'data_dir = "data"\n[robot]\nmodel = "{}"\n'
            'joints = ["yaw", "shoulder", "elbow"]\n')
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # not the config's folder
    for model, want in (("arm.xml", folder / "arm.xml"),
                        ("robots/arm2.xml", folder / "robots" / "arm2.xml")):
        cfg_path = folder / "exp.toml"
        cfg_path.write_text(text.format(model))
        cfg = load_config(cfg_path)
        assert cfg.robot.model == str(want.resolve())
        assert cfg.data.data_dir == str((folder / "data").resolve())
        cfg.robot.marker = {"body": "link2", "pos": POINT}
        assert build_simulator(cfg).robot.source == str(want.resolve())
    # a built-in model's bare name stays one; a --set value is the user's own
    cfg_path.write_text(text.format("tiny_arm.xml"))
    assert load_config(cfg_path).robot.model == "tiny_arm.xml"
    assert load_config(cfg_path, ["robot.model=arm.xml"]).robot.model == "arm.xml"
    # a relative path that is not there is named as the config's folder's
    cfg_path.write_text(text.format("robots/none.xml"))
    with pytest.raises(FileNotFoundError, match="project/robots/none.xml"):
        build_simulator(load_config(cfg_path))


def test_fixed_defaults_to_nothing_and_teos_configs_set_theirs():
    assert ExperimentConfig().robot.fixed == {}
    for path in sorted(experiments_dir().glob("*.toml")):
        robot = tomllib.loads(path.read_text()).get("robot")
        if robot is not None:  # every execution config on TEO says what it holds
            assert "fixed" in robot, path.name
    for cfg in demo_configs():
        if cfg.kind == "execution":
            assert cfg.robot.fixed == {"r_forearm_rotation": 45.0}, cfg.name
    cfg = ExperimentConfig(kind="execution")
    cfg.robot.marker = {"body": "r_hand"}
    cfg.robot.marker_site = "marker_left"
    with pytest.raises(ConfigError, match="'robot.marker' and 'robot.marker_site'"):
        build_simulator(cfg)
