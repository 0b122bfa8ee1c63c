"""Issue 24's "done when", as a new user would do it: an MJCF arm of their own (mesh
geoms, ``<motor>`` actuators, no site at the tool) beside a config that names it by a
relative path, run with ``cgda run`` in kinematic and in dynamic mode."""

import json

import mujoco
import numpy as np
import pytest

from cgda_jax.cli import main


def _box_mesh(name: str, hx: float, hy: float, hz: float) -> str:
    corners = [(sx * hx, sy * hy, sz * hz) for sx in (-1, 1) for sy in (-1, 1)
               for sz in (-1, 1)]
    return (f'<mesh name="{name}" vertex="'
            + " ".join(f"{x:g} {y:g} {z:g}" for x, y, z in corners) + '"/>')


# A 3-joint arm (base yaw, shoulder and elbow pitch) whose links are meshes, driven by
# torque motors, with a floor; nothing marks the tool: the config puts the marker on
# the last link's body.
ARM = f"""
<mujoco model="user_arm">
  <compiler angle="degree"/>
  <option timestep="0.005" gravity="0 0 -9.81"/>
  <asset>
    {_box_mesh("base", 0.05, 0.05, 0.05)}
    {_box_mesh("turret", 0.03, 0.03, 0.01)}
    {_box_mesh("upper", 0.02, 0.02, 0.12)}
    {_box_mesh("fore", 0.018, 0.018, 0.10)}
  </asset>
  <default><joint damping="0.5" armature="0.01" limited="true"/></default>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <body name="pedestal" pos="0 0 0.05">
      <geom type="mesh" mesh="base" density="500"/>
    </body>
    <body name="turret" pos="0 0 0.12">
      <geom type="mesh" mesh="turret" density="500"/>
      <joint name="yaw" axis="0 0 1" range="-120 120"/>
      <body name="upper" pos="0 0 0.03">
        <joint name="shoulder" axis="0 1 0" range="-90 90"/>
        <geom type="mesh" mesh="upper" pos="0 0 0.12" density="500"/>
        <body name="fore" pos="0 0 0.24">
          <joint name="elbow" axis="0 1 0" range="0 140"/>
          <geom type="mesh" mesh="fore" pos="0 0 0.10" density="500"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="yaw" joint="yaw" ctrlrange="-20 20"/>
    <motor name="shoulder" joint="shoulder" ctrlrange="-20 20"/>
    <motor name="elbow" joint="elbow" ctrlrange="-10 10"/>
  </actuator>
</mujoco>
"""

CONFIG = """
kind = "execution"

[data]
source = "clean_circle"
centre = [0.25, 0.0, 0.35]
diameter = 0.10
n_demos = 4
interval_s = 1.5

[robot]
model = "models/user_arm.xml"
joints = ["yaw", "shoulder", "elbow"]
marker = {{ body = "fore", pos = [0.0, 0.0, 0.20] }}
start = {{ shoulder = 30.0, elbow = 60.0 }}
mode = "{mode}"
physics = "mujoco"

[strategy]
name = "ie"
population_size = 16
tolerance = 0.02
max_generations = 60
options = {{ warm_start = true }}
"""


@pytest.fixture(scope="module")
def user_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("user")
    (folder / "models").mkdir()
    (folder / "models" / "user_arm.xml").write_text(ARM)
    model = mujoco.MjModel.from_xml_path(str(folder / "models" / "user_arm.xml"))
    assert model.nsite == 0 and (model.geom_type == mujoco.mjtGeom.mjGEOM_MESH).sum() == 4
    assert set(model.actuator_gaintype) == {0} and model.actuator_biastype.max() == 0
    return folder


@pytest.mark.parametrize("mode", ["kinematic", "dynamic"])
def test_a_users_meshed_motor_arm_runs_from_a_config(user_folder, mode, monkeypatch):
    config = user_folder / f"arm_{mode}.toml"
    config.write_text(CONFIG.format(mode=mode))
    out = user_folder / f"results_{mode}"
    monkeypatch.chdir(user_folder.parent)  # the model path is the config's, not ours
    code = main(["run", str(config), "--out", str(out), "--quiet"])
    result = json.loads((out / "result.json").read_text())
    assert code == 0, result.get("point_errors")
    assert result["success"] and max(result["point_errors"]) < 0.02
    assert result["motion"]["feasible"], result["motion"]
    report = (out / "report.md").read_text()
    if mode == "dynamic":  # the motors are driven through the joint-space PD
        assert "joint-space PD" in report or "| pd |" in report.lower(), report
        assert result["replay"]["success"]
    np.testing.assert_array_less(np.abs(np.asarray(result["point_errors"])), 0.02)


def test_a_joint_held_by_a_contact_is_reported_with_the_contact(user_folder):
    """The same arm with its turret resting on the pedestal (a modelling slip):
    friction holds the base joint, and the tracking note names the contact."""
    from cgda_jax import MarkerScene, Robot, Simulator
    from cgda_jax.sim.motion_check import motion_report

    xml = (ARM.replace('<body name="turret" pos="0 0 0.12">',
                       '<body name="turret" pos="0 0 0.11">')
           .replace('<geom type="mesh" mesh="base"', '<geom name="pedestal" type="mesh" '
                    'mesh="base"')
           .replace('<geom type="mesh" mesh="turret"', '<geom name="turret" type="mesh" '
                    'mesh="turret"'))
    path = user_folder / "models" / "resting.xml"
    path.write_text(xml)
    robot = Robot.from_mjcf(path, ["yaw", "shoulder", "elbow"],
                            {"body": "fore", "pos": [0.0, 0.0, 0.2]},
                            start={"shoulder": 0.5, "elbow": 1.0})
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=1.0)
    joints = np.array([[1.0, 0.5, 1.0], [-0.5, 0.6, 1.1]], np.float32)
    note = motion_report(sim, joints)["tracking_note"]
    assert note and "joint 'yaw'" in note, note
    assert "touched" in note and ("turret - pedestal" in note
                                  or "pedestal - turret" in note), note
