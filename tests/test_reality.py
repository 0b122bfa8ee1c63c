"""The Reality protocol and the mismatched world (issue 22): a world equal to the
model measures what the simulator computes; a mismatched one is seeded and its
joint offsets move the features as executing the offset joints would; a reality
that fails or measures NaN stops with a clear error."""

import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.reality.control_trajectory import time_parameterize, trajectory_of
from cgda_jax.reality.mismatch import Mismatch, MismatchedWorld
from cgda_jax.reality.protocol import Measurement, Reality, RealityError, measure

JOINTS = ["yaw", "shoulder", "elbow"]
WAYPOINTS = np.array([[0.3, 0.5, 0.4], [0.5, 0.7, 0.2], [0.1, 0.6, 0.5]], np.float32)


@pytest.fixture(scope="module")
def sim():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")
    return Simulator(robot, MarkerScene(), mode="dynamic", waypoint_s=0.5,
                     physics="mujoco")


def test_a_world_equal_to_the_model_measures_what_the_simulator_computes(sim):
    world = MismatchedWorld(sim)
    assert isinstance(world, Reality)
    start = measure(world)
    np.testing.assert_allclose(start.features[0], np.asarray(
        sim.robot.marker_position(sim.robot.start_genes)), atol=1e-6)
    traj = trajectory_of(sim, WAYPOINTS)
    got = measure(world, traj)
    want = np.asarray(sim.execute(WAYPOINTS), np.float64)
    np.testing.assert_allclose(got.features, want, atol=2e-3)
    np.testing.assert_allclose(got.joints, WAYPOINTS, atol=np.deg2rad(1.0))
    # the robot stays where it went: the next move starts from there
    moves, holds = [0.3, 0.3], [0.2, 0.2]
    more = time_parameterize(traj.q[-1], WAYPOINTS[:2], moves, holds,
                             joint_names=JOINTS)
    np.testing.assert_allclose(measure(world, more).joints, WAYPOINTS[:2],
                               atol=np.deg2rad(1.0))
    with pytest.raises(ValueError, match="not where the robot was sent"):
        world.execute(traj)  # starts at the start posture, the robot is elsewhere


def test_a_mismatched_world_is_seeded_and_offsets_move_the_features(sim):
    traj = trajectory_of(sim, WAYPOINTS)
    mm = Mismatch(joint_offset_deg=[-3.0, 3.0], seed=5)
    a, b = MismatchedWorld(sim, mm), MismatchedWorld(sim, mm)
    other = MismatchedWorld(sim, Mismatch(joint_offset_deg=[-3.0, 3.0], seed=6))
    off = a.drawn["joint_offset"]
    assert np.all(np.abs(off) <= np.deg2rad(3.0)) and np.any(np.abs(off) > 0.01)
    assert not np.allclose(off, other.drawn["joint_offset"])
    a.reset(), b.reset()
    fa, fb = a.execute(traj), b.execute(traj)
    np.testing.assert_array_equal(fa.features, fb.features)
    # independent: the model executing the offset joints (where the world's are)
    want = np.asarray(sim.execute(WAYPOINTS + off.astype(np.float32)), np.float64)
    np.testing.assert_allclose(fa.features, want, atol=2e-3)
    assert np.abs(fa.features - np.asarray(sim.execute(WAYPOINTS))).max() > 5e-3
    np.testing.assert_allclose(fa.joints, WAYPOINTS, atol=np.deg2rad(1.0))  # encoders
    # noise: seeded, of the stated size
    noisy = MismatchedWorld(sim, Mismatch(noise=0.002, seed=1))
    noisy.reset()
    n1 = noisy.execute(traj).features
    clean = MismatchedWorld(sim)
    clean.reset()
    diff = n1 - clean.execute(traj).features
    assert 0 < np.abs(diff).max() < 0.01


def test_the_world_s_parameters_are_perturbed_as_stated(sim):
    w = MismatchedWorld(sim, Mismatch(mass_scale=2.0, friction_scale=0.5,
                                      gain_scale=[0.8, 0.9], damping_scale=3.0))
    m0 = sim.physics.model
    np.testing.assert_allclose(w.model.body_mass[1:], 2 * m0.body_mass[1:])
    np.testing.assert_allclose(w.model.geom_friction[:, 0], 0.5 * m0.geom_friction[:, 0])
    g = w.drawn["gain_scale"]
    assert 0.8 <= g <= 0.9
    np.testing.assert_allclose(w.model.actuator_gainprm[:, 0],
                               g * m0.actuator_gainprm[:, 0])
    np.testing.assert_allclose(w.model.dof_damping, 3 * m0.dof_damping)
    np.testing.assert_array_equal(sim.physics.model.body_mass, m0.body_mass)


@pytest.mark.parametrize("bad, match", [
    ({"mass_scale": 0}, "must be > 0"), ({"noise": [0.2, 0.1]}, "low > high"),
    ({"joint_offset_deg": "3"}, "expected a number"), ({"masses": 2}, "unknown key"),
])
def test_bad_mismatch_values_name_the_key(bad, match):
    with pytest.raises(ValueError, match=match):
        Mismatch.from_dict(bad)


class _Fake:
    feature_names = ("X", "Y", "Z")
    joint_names = tuple(JOINTS)

    def __init__(self, how):
        self.how = how

    def reset(self):
        if self.how == "raise":
            raise ConnectionError("robot not answering")
        f = np.zeros((1, 3))
        if self.how == "nan":
            f[0, 1] = np.nan
        return Measurement(f, np.zeros((1, 3)))

    def execute(self, trajectory):
        return Measurement(np.zeros((2, 3)), np.zeros((2, 3)))


@pytest.mark.parametrize("how, match", [
    ("raise", "_Fake.reset\\(\\) failed: ConnectionError: robot not answering"),
    ("nan", "_Fake.reset\\(\\) measured NaN or inf features \\(waypoints \\[1\\]\\)"),
])
def test_a_reality_that_fails_or_measures_nan_is_reported(how, match):
    with pytest.raises(RealityError, match=match):
        measure(_Fake(how))


def test_a_measurement_of_the_wrong_shape_is_reported(sim):
    traj = trajectory_of(sim, WAYPOINTS)
    with pytest.raises(RealityError, match="expected \\(3, 3\\) and \\(3, 3\\)"):
        measure(_Fake("ok"), traj)


TINY = ["kind=execution", "data.source=clean_circle", "scene.kind=marker",
        "strategy.feasibility=false", "robot.model=tiny_arm.xml",
        'robot.joints=["yaw", "shoulder", "elbow"]', "robot.fixed={}",
        "robot.mode=dynamic"]


def test_the_reality_table_is_checked_and_seeded():
    from cgda_jax.experiment import ConfigError, load_config
    from cgda_jax.experiment.rules import validate_config

    cfg = load_config(None, TINY + ["reality.enabled=true", "reality.seed=4",
                                    "reality.joint_offset_deg=[-3, 3]",
                                    "reality.mass_scale=2.0", "reality.noise=0.002"])
    validate_config(cfg)
    assert Mismatch.from_dict(cfg.reality.mismatch_table()).draw(3)["mass_scale"] == 2
    with pytest.raises(ConfigError, match="unknown key 'reality.masses'"):
        load_config(None, TINY + ["reality.masses=2"])
    for bad, match in (("reality.friction_scale=0", "friction_scale = 0.0: must be"),
                       ("reality.delay_s=[0.2, 0.1]", "low > high")):
        with pytest.raises(ConfigError, match=match):
            validate_config(load_config(None, TINY + [bad]))
    with pytest.raises(ConfigError, match="needs robot.mode"):
        validate_config(load_config(None, TINY + ["robot.mode=kinematic",
                                                  "reality.enabled=true"]))


def test_open_loop_on_the_mismatched_world_is_judged_per_point(sim):
    import types

    from cgda_jax.experiment.compute import reality_check
    from cgda_jax.experiment.report import reality_rows

    feats = np.asarray(sim.execute(WAYPOINTS), np.float64)
    res = types.SimpleNamespace(strategy="ie", joints=WAYPOINTS, goal=feats,
                                features=feats, tolerance=0.01)
    same = reality_check(sim, res, {})
    assert same["executed"] and same["success"] and same["max_point_error"] < 2e-3
    off = reality_check(sim, res, {"joint_offset_deg": 3.0})
    # independent: the model at the offset joints, against the same goal
    want = np.linalg.norm(np.asarray(sim.execute(
        WAYPOINTS + np.float32(np.deg2rad(3.0))), np.float64) - feats, axis=1)
    np.testing.assert_allclose(off["point_errors"], want, atol=2e-3)
    assert not off["success"]
    row = reality_rows(off, "m")[0]
    assert row.startswith("| open loop on the mismatched world (seed 0")
    assert "success False" in row


def test_joint_offsets_by_name(sim):
    w = MismatchedWorld(sim, Mismatch.from_dict({"joint_offset_deg": {"elbow": 3.0}}))
    np.testing.assert_allclose(w.drawn["joint_offset"], np.deg2rad([0.0, 0.0, 3.0]))
    with pytest.raises(ValueError, match=r"joint\(s\) \['wrist'\] are not the evolved"):
        MismatchedWorld(sim, Mismatch(joint_offset_deg={"wrist": 1.0}))
    with pytest.raises(ValueError, match=r"\['elbow'\] given a range"):
        Mismatch(joint_offset_deg={"elbow": [0.0, 1.0]})
