"""Joint offsets estimated from the measured tool (cgda_jax.reality.calibrate): the
mismatched world measures its marker with MuJoCo C at the offset joints; the fit on
the robot's own forward kinematics recovers the offsets, and the closed loop that
uses them ends nearer the goal than the one that takes the encoders as they read."""

import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.reality.calibrate import OffsetEstimate, estimate_offsets
from cgda_jax.reality.control_trajectory import trajectory_of
from cgda_jax.reality.mismatch import Mismatch, MismatchedWorld
from cgda_jax.reality.protocol import Measurement, RealityError, measure
from cgda_jax.strategies.closed_loop import run_oet_closed_loop

JOINTS = ["yaw", "shoulder", "elbow"]
WAYPOINTS = np.array([[0.1, 0.2, 0.1], [0.3, 0.4, 0.2], [0.5, 0.5, 0.3]], np.float32)
KW = {"population_size": 16, "tolerance": 0.01, "max_generations": 80, "seed": 0}
OFFSETS_DEG = {"yaw": 2.0, "shoulder": -3.0, "elbow": 1.5}


@pytest.fixture(scope="module")
def sim():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")
    return Simulator(robot, MarkerScene(), mode="dynamic", waypoint_s=0.5,
                     physics="mujoco")


def _pairs(sim, mismatch):
    """(joints, tool) measured by the world at its start and at WAYPOINTS."""
    world = MismatchedWorld(sim, mismatch)
    first = measure(world)
    got = measure(world, trajectory_of(sim, WAYPOINTS))
    return (np.concatenate([first.joints, got.joints]),
            np.concatenate([first.marker, got.marker]), world)


def test_the_offsets_are_recovered_from_the_world_s_tool(sim):
    joints, tool, world = _pairs(sim, Mismatch(joint_offset_deg=OFFSETS_DEG))
    want = np.rad2deg(world.drawn["joint_offset"])
    np.testing.assert_allclose(want, [2.0, -3.0, 1.5])
    # the encoders read the commanded frame: the model's FK there misses the tool
    fk = np.stack([np.asarray(sim.robot.marker_position(q)) for q in joints])
    assert np.linalg.norm(fk - tool, axis=1).max() > 0.005
    # an exact tool (noise 10 um: the prior towards zero does not pull)
    got, residual = estimate_offsets(sim.robot, joints, tool, noise=1e-5)
    np.testing.assert_allclose(np.rad2deg(got), want, atol=0.02)
    assert residual < 1e-5
    # one posture is enough for three joints and a 3-D point (away from singular)
    one, _ = estimate_offsets(sim.robot, joints[-1:], tool[-1:], noise=1e-5)
    np.testing.assert_allclose(np.rad2deg(one), want, atol=0.05)
    # with the default 2 mm the prior holds back what 4 postures cannot resolve
    # on this small arm: the fit is within that noise, the estimate less exact
    loose, residual = estimate_offsets(sim.robot, joints, tool)
    assert residual < 0.002 and np.abs(np.rad2deg(loose) - want).max() > 0.05
    # a world without offsets: nothing estimated
    joints0, tool0, _ = _pairs(sim, Mismatch())
    zero, _ = estimate_offsets(sim.robot, joints0, tool0)
    assert np.abs(np.rad2deg(zero)).max() < 0.01


def test_with_a_noisy_tool_the_estimate_improves_with_postures(sim):
    mm = Mismatch(joint_offset_deg=OFFSETS_DEG, marker_noise=0.002, seed=3)
    joints, tool, _ = _pairs(sim, mm)
    assert np.abs(tool - _pairs(sim, Mismatch(joint_offset_deg=OFFSETS_DEG))[1]
                  ).max() > 1e-4  # the noise is there
    est = OffsetEstimate(sim.robot)
    errs = [np.abs(np.rad2deg(est.add(q, p)) - [2.0, -3.0, 1.5]).max()
            for q, p in zip(joints, tool, strict=True)]
    assert est.pairs == 4 and len(est.history) == 4
    assert errs[-1] < 1.0  # degrees, from 2 mm on a ~0.3 m arm
    assert est.residual < 0.005


def test_bad_pairs_are_refused(sim):
    with pytest.raises(ValueError, match=r"joints \(2, 2\) and markers \(2, 3\)"):
        estimate_offsets(sim.robot, np.zeros((2, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="NaN or inf"):
        estimate_offsets(sim.robot, np.full((1, 3), np.nan), np.zeros((1, 3)))


class _Tool:
    """The world, its tool measured wrong (shape or NaN) at the first execute."""

    def __init__(self, sim, marker):
        self.world, self.marker = MismatchedWorld(sim), marker
        self.feature_names = self.world.feature_names
        self.joint_names = self.world.joint_names

    def reset(self):
        return self.world.reset()

    def execute(self, trajectory):
        got = self.world.execute(trajectory)
        return Measurement(got.features, got.joints, self.marker(got.marker))


@pytest.mark.parametrize(("marker", "match"), [
    (lambda m: m[:, :2], r"measured the tool \(marker\) \(1, 2\); expected \(1, 3\)"),
    (lambda m: np.full_like(m, np.nan), "measured NaN or inf marker"),
])
def test_a_wrong_tool_measurement_stops_the_run(sim, marker, match):
    goal = np.asarray(sim.execute(WAYPOINTS), np.float64)
    with pytest.raises(RealityError, match=match):
        run_oet_closed_loop(sim, goal, _Tool(sim, marker), **KW)


class _NoTool:
    """The world, measuring features and joints only (no tracker on the hand)."""

    def __init__(self, world):
        self.world = world
        self.feature_names, self.joint_names = world.feature_names, world.joint_names

    def reset(self):
        return Measurement(*self.world.reset()[:2])

    def execute(self, trajectory):
        return Measurement(*self.world.execute(trajectory)[:2])


def test_the_calibrated_closed_loop_ends_nearer_the_goal(sim):
    goal = np.asarray(sim.execute(WAYPOINTS), np.float64)
    mm = Mismatch(joint_offset_deg=OFFSETS_DEG, marker_noise=0.001, seed=1)
    cal = run_oet_closed_loop(sim, goal, MismatchedWorld(sim, mm), **KW)
    raw = run_oet_closed_loop(sim, goal, MismatchedWorld(sim, mm), calibrate=False,
                              **KW)
    blind = run_oet_closed_loop(sim, goal, _NoTool(MismatchedWorld(sim, mm)), **KW)
    info = cal.info["calibration"]
    assert info["pairs"] == len(cal.joints) + 1  # the start and every step
    # the estimate (2 mm assumed, 1 mm measured) is within a degree on this small
    # arm, and the calibrated model predicts the world's tool better than the
    # encoders do at every measured posture
    np.testing.assert_allclose(info["offsets_deg"], [2.0, -3.0, 1.5], atol=1.0)
    steps = cal.info["closed_loop"]
    world = MismatchedWorld(sim, Mismatch(joint_offset_deg=OFFSETS_DEG))
    measure(world)
    tool = measure(world, trajectory_of(sim, np.asarray(steps["commanded_joints"])))
    off = np.deg2rad(info["offsets_deg"])
    for q, p in zip(tool.joints, tool.marker, strict=True):
        assert (np.linalg.norm(np.asarray(sim.robot.marker_position(q + off)) - p)
                < 0.5 * np.linalg.norm(np.asarray(sim.robot.marker_position(q)) - p))
    assert raw.info["calibration"] is None and "calibrate=False" in raw.info[
        "calibration_why"]
    assert blind.info["calibration"] is None and "does not measure the tool" in \
        blind.info["calibration_why"]
    # the same plan without the tool, whether switched off or not measured
    np.testing.assert_allclose(raw.features, blind.features, atol=1e-9)
    # the offsets, known from the start, no longer cost the first point (the raw
    # loop corrects them from its first measurement on)
    assert cal.point_errors[0] < 0.5 * raw.point_errors[0]
    assert cal.max_point_error < raw.max_point_error
    # what the robot was sent: the model's plan less the applied offsets
    sent = np.asarray(steps["commanded_joints"])
    applied = np.deg2rad(np.asarray(steps["offsets_deg"]))
    np.testing.assert_allclose(sent[1:] + applied[:-1], cal.joints[1:], atol=1e-5)
