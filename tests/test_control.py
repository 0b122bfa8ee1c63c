"""Control that fits the actuators: motors through a joint-space PD with gravity
compensation, position servos as the model has them, both against a plain MuJoCo C
``mj_step`` loop computing the same law; refusals by name; tracking in the report."""

import logging
import types

import jax
import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator
from cgda_jax.experiment.build import build_simulator
from cgda_jax.experiment.compute import motion_check
from cgda_jax.experiment.config import ConfigError, load_config
from cgda_jax.experiment.report import control_lines, motion_lines
from cgda_jax.sim.control import Control, plan_control
from cgda_jax.sim.limits import read_limits
from cgda_jax.sim.motion_check import tracking_note

# A two-link arm pitching about y, horizontal (the heaviest gravity load) at zero.
ARM = """
<mujoco model="arm">
  <compiler angle="radian"/>
  <option timestep="0.002" gravity="0 0 -9.81" integrator="Euler"/>
  <default><joint damping="0.05" armature="0.01"/>
    <geom contype="0" conaffinity="0" density="800"/></default>
  <worldbody>
    <body name="l1" pos="0 0 0.1">
      <joint name="shoulder" axis="0 1 0" range="-2 2"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
      <body name="l2" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0" range="-2.5 2.5"/>
        <geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.025"/>
        <site name="tip" pos="0.25 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>{}</actuator>
</mujoco>
"""
MOTORS = ('<motor name="m1" joint="shoulder" gear="2" ctrlrange="-10 10"/>'
          '<motor name="m2" joint="elbow" ctrlrange="-8 8"/>')
SERVOS = ('<position name="p1" joint="shoulder" kp="200" kv="9.7" forcerange="-20 20"/>'
          '<position name="p2" joint="elbow" kp="80" kv="2.5" forcerange="-8 8"/>')
JOINTS = ["shoulder", "elbow"]
WAYPOINTS = np.array([[0.6, -0.8], [-0.4, 1.2], [0.2, 0.3]], np.float32)


@pytest.fixture(scope="module")
def arms(tmp_path_factory):
    folder = tmp_path_factory.mktemp("arms")
    out = {}
    weak = MOTORS.replace('ctrlrange="-8 8"', 'ctrlrange="-0.3 0.3"')
    for name, acts in (("motor", MOTORS), ("servo", SERVOS), ("bare", ""),
                       ("weak", weak),
                       ("pair", SERVOS + '<velocity name="v2" joint="elbow" kv="1"/>'),
                       ("tendon", MOTORS + '<motor name="t" tendon="tnd"/>')):
        xml = ARM.format(acts)
        if name == "tendon":
            xml = xml.replace("<actuator>", '<tendon><fixed name="tnd"><joint '
                              'joint="elbow" coef="1"/></fixed></tendon><actuator>')
        (folder / f"{name}.xml").write_text(xml)
        out[name] = folder / f"{name}.xml"
    return out


def c_loop(path, sim, waypoints, gravity=True):
    """The law by hand on the user's own model: a plain ``mj_step`` loop applying
    ``clip(kp (q_ref - q) - kd qdot + qfrc_bias(q, 0), lo, hi)`` through one plain
    unlimited motor per joint (the model's own actuators removed), float64.

    Returns: (marker at each waypoint's end (N, 3), qpos at each end (N, nq))."""
    spec = mujoco.MjSpec.from_file(str(path))
    for act in list(spec.actuators):
        spec.delete(act)
    for j in JOINTS:
        spec.add_actuator(name=f"tau_{j}", target=j,
                          trntype=mujoco.mjtTrn.mjTRN_JOINT).set_to_motor()
    m = spec.compile()
    d, rest = mujoco.MjData(m), mujoco.MjData(m)
    drives = [sim.physics.control.drive(j) for j in JOINTS]
    kp, kd = (np.array([getattr(dr, k) for dr in drives]) for k in ("kp", "kd"))
    lo, hi = (np.array([dr.force[i] for dr in drives]) for i in (0, 1))
    prev, marks, ends = np.zeros(2), [], []
    for w in np.asarray(waypoints, np.float64):
        for a in sim.reference_profiles()[1]:
            ref = prev + float(a) * (w - prev)
            rest.qpos[:] = d.qpos  # qfrc_bias at zero velocity: gravity alone
            mujoco.mj_forward(m, rest)
            g = rest.qfrc_bias if gravity else 0.0
            d.ctrl[:] = np.clip(kp * (ref - d.qpos) - kd * d.qvel + g, lo, hi)
            mujoco.mj_step(m, d)
        prev = w
        mujoco.mj_kinematics(m, d)
        marks.append(d.site_xpos[0].copy())
        ends.append(d.qpos.copy())
    return np.array(marks), np.array(ends)


def ends_of(sim, waypoints):
    """qpos at each waypoint's end (N, DoF) and the features (N, 3)."""
    state, ends, feats = sim.init_state(), [], []
    step = jax.jit(sim.step)
    for w in waypoints:
        state, f = step(state, w)
        ends.append(np.asarray(state.data[:sim.physics.nq], np.float64))
        feats.append(np.asarray(f))
    return np.array(ends), np.array(feats)


@pytest.mark.parametrize("arm, control, backend", [
    ("motor", None, "mujoco"), ("motor", None, "mjx"),
    ("servo", {"mode": "pd"}, "mujoco"), ("bare", {"mode": "pd", "kp": 150.0,
                                                    "force_limit": 15.0}, "mujoco")])
def test_pd_equals_a_plain_mj_step_loop_with_the_same_law(arms, arm, control,
                                                          backend):
    robot = Robot.from_mjcf(arms[arm], JOINTS, "tip")
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics=backend,
                    waypoint_s=0.3, control=control)
    assert [d.kind for d in sim.physics.control.drives] == ["pd", "pd"]
    feats, state = jax.jit(sim.rollout)(WAYPOINTS)
    want, qpos = c_loop(arms[arm], sim, WAYPOINTS)
    tol = 1e-6 if backend == "mujoco" else 1e-4  # float64 C / float32 MJX
    np.testing.assert_allclose(np.asarray(feats), want, atol=tol)
    np.testing.assert_allclose(np.asarray(state.data[:2]), qpos[-1], atol=tol)


def test_a_motor_arm_and_a_servo_arm_reach_the_same_commanded_postures(arms):
    """Tolerance: the motor arm's PD (gravity compensated) ends each 0.5 s waypoint
    within 0.1 deg of it; the position servos (same gains, no compensation) within
    1.5 deg, their gravity sag g / kp; the two within 1.5 deg of each other."""
    ends = {}
    for arm in ("motor", "servo"):
        sim = Simulator(Robot.from_mjcf(arms[arm], JOINTS, "tip"), MarkerScene(),
                        mode="dynamic", physics="mujoco", waypoint_s=0.5)
        ends[arm] = ends_of(sim, WAYPOINTS)[0]
        kinds = [d.kind for d in sim.physics.control.drives]
        assert kinds == (["pd"] * 2 if arm == "motor" else ["position"] * 2)
    err = {k: np.degrees(np.abs(v - WAYPOINTS)) for k, v in ends.items()}
    assert err["motor"].max() < 0.1, err["motor"]
    assert 0.3 < err["servo"].max() < 1.5, err["servo"]  # it sags, a little
    assert np.degrees(np.abs(ends["motor"] - ends["servo"])).max() < 1.5


@pytest.mark.parametrize("gravity", [True, False])
def test_gravity_compensation_holds_a_posture(arms, gravity):
    """The arm held horizontal from rest for 1 s: with compensation its tip drifts
    less than 0.1 mm; without, it sags by the PD's g / kp (more than 3 mm)."""
    robot = Robot.from_mjcf(arms["motor"], JOINTS, "tip")
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=1.0, control={"gravity": gravity})
    state = sim.init_state()
    ctrl = np.repeat(np.asarray(sim.physics.ctrl_of(sim.physics.qpos0))[None], 500, 0)
    _, sens = sim.backend.segment(state.data, ctrl)
    drift = np.linalg.norm(np.asarray(sens)[:, :3] - np.asarray(state.marker), axis=1)
    if gravity:
        assert drift.max() < 1e-4, drift.max()
    else:
        assert drift.max() > 3e-3, drift.max()


def test_drives_come_from_the_actuators_and_the_config(arms):
    m = mujoco.MjModel.from_xml_path(str(arms["motor"]))
    plan = plan_control(m, m.qpos0, JOINTS)
    sh, el = plan.drives
    assert (sh.actuator, sh.actuator_kind, sh.force) == ("m1", "motor", (-20.0, 20.0))
    assert sh.kp == pytest.approx(20.0 / 0.1) and el.force == (-8.0, 8.0)
    plan = plan_control(m, m.qpos0, JOINTS, {"kp": {"elbow": 30.0}, "kd": 1.0,
                                             "force_limit": 5.0})
    assert plan.drives[1].kp == 30.0 and plan.drives[1].kd == 1.0
    assert plan.drives[0].force == (-5.0, 5.0) and plan.drives[0].kp == 50.0
    servo = mujoco.MjModel.from_xml_path(str(arms["servo"]))
    d = plan_control(servo, servo.qpos0, JOINTS).drives[0]
    assert (d.kind, d.kp, d.kd, d.gravity) == ("position", 200.0, 9.7, False)
    d = plan_control(servo, servo.qpos0, JOINTS, {"mode": "pd"}).drives[0]
    assert (d.kind, d.kp, d.kd, d.gravity) == ("pd", 200.0, 9.7, True)
    # the feasibility's effort limit of a motor: gear x ctrlrange, as the PD's
    lim = read_limits(m, JOINTS)
    np.testing.assert_array_equal(lim.effort, [20.0, 8.0])
    assert lim.source["effort"] == ("mjcf ctrlrange:m1", "mjcf ctrlrange:m2")
    lines = "\n".join(control_lines(plan.as_dict()))
    assert "| shoulder | joint-space PD | m1 (motor) | 50 | 1 | +-5 | yes |" in lines


def test_joints_that_cannot_be_driven_are_refused_by_name(arms):
    def build(arm, control=None):
        return Simulator(Robot.from_mjcf(arms[arm], JOINTS, "tip"), MarkerScene(),
                         mode="dynamic", physics="mujoco", control=control)

    with pytest.raises(ValueError, match=r"joints \['shoulder', 'elbow'\].*no "
                                         r"actuator.*mode = \"pd\""):
        build("bare")
    with pytest.raises(ValueError, match="joint 'shoulder'.*no gain for its PD"):
        build("bare", {"mode": "pd"})
    with pytest.raises(ValueError, match=r"'elbow' \(p2, v2\).*several actuators"):
        build("pair")
    assert build("pair", {"mode": "pd"}).physics.model.nu == 2  # one PD each
    with pytest.raises(ValueError, match=r"actuators \['t'\].*tendon"):
        build("tendon")
    with pytest.raises(ValueError, match=r"control kp: joints \['wrist'\]"):
        build("motor", {"kp": {"wrist": 3.0}})
    with pytest.raises(ValueError, match="control mode 'servo'"):
        Control(mode="servo")


def test_a_joint_that_cannot_reach_its_commands_is_named_once(arms, caplog):
    """The weak elbow (0.3 N m) cannot hold the forearm up (0.55 N m at rest): the
    run's motion check names it, with its force limit, once."""
    robot = Robot.from_mjcf(arms["weak"], JOINTS, "tip")
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.5)
    res = types.SimpleNamespace(joints=WAYPOINTS[:2])
    with caplog.at_level(logging.WARNING, logger="cgda_jax"):
        motion, _ = motion_check(sim, res)
        motion_check(sim, res)
    said = [r.getMessage() for r in caplog.records if "commanded" in r.getMessage()]
    assert len(said) == 1, said
    assert "joint 'elbow' ends waypoint" in said[0]
    assert "at its force limit" in said[0] and "-0.3" in said[0]
    assert motion["tracking_error_deg"]["elbow"] > 20.0
    assert motion["tracking_error_deg"]["shoulder"] < 2.0
    assert np.shape(motion["tracking_deg_per_waypoint"]) == (2, 2)
    assert "**Tracking:**" in "\n".join(motion_lines(motion, None))
    # the same arm with its full motors reaches them: nothing to say
    strong = Simulator(Robot.from_mjcf(arms["motor"], JOINTS, "tip"), MarkerScene(),
                       mode="dynamic", physics="mujoco", waypoint_s=0.5)
    ends, _ = ends_of(strong, WAYPOINTS[:2])
    err = np.abs(ends - WAYPOINTS[:2])
    assert np.degrees(err).max() < 0.1
    assert tracking_note(strong, err, np.zeros_like(err)) is None


def test_robot_control_in_a_config(arms, tmp_path):
    p = tmp_path / "arm.toml"
    p.write_text(f'kind = "execution"\n[robot]\nmodel = "{arms["bare"]}"\n'
                 'joints = ["shoulder", "elbow"]\nmarker_site = "tip"\n'
                 'mode = "dynamic"\nphysics = "mujoco"\n[robot.control]\n'
                 'mode = "pd"\nforce_limit = { shoulder = 20.0, elbow = 8.0 }\n')
    sim = build_simulator(load_config(p, ["robot.control.kd.elbow=2.0"]))
    assert [(d.kind, d.force[1]) for d in sim.physics.control.drives] == [
        ("pd", 20.0), ("pd", 8.0)]
    assert sim.physics.control.drives[1].kd == 2.0
    with pytest.raises(ConfigError, match="robot.control.gain"):
        load_config(p, ["robot.control.gain=3"])
    with pytest.raises(ConfigError, match="key 'robot.control'.*damping_ratio"):
        build_simulator(load_config(p, ["robot.control.damping_ratio=0"]))


def test_the_report_says_whether_a_pd_carries_gravity(arms):
    servo = mujoco.MjModel.from_xml_path(str(arms["servo"]))
    lines = "\n".join(control_lines(plan_control(servo, servo.qpos0, JOINTS).as_dict()))
    assert "no joint-space PD (every held joint is a position servo" in lines
    assert "gravity compensation in the PD" not in lines
    motor = mujoco.MjModel.from_xml_path(str(arms["motor"]))
    lines = "\n".join(control_lines(plan_control(motor, motor.qpos0, JOINTS).as_dict()))
    assert "gravity compensation in the PD on" in lines
