"""Closed-loop OET against a Reality (issue 22 items 4-5): on a world equal to the
model it is OET; on a world with joint offsets it ends nearer the goal than the
open-loop replay of OET's plan there (the same world, MuJoCo C); a reality that
measures NaN or raises stops the run with a RealityError."""

import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.reality.control_trajectory import trajectory_of
from cgda_jax.reality.mismatch import Mismatch, MismatchedWorld
from cgda_jax.reality.protocol import Measurement, RealityError, measure
from cgda_jax.strategies.closed_loop import run_oet_closed_loop
from cgda_jax.strategies import run_oet
from cgda_jax.strategies.oet import ordered_point_errors

JOINTS = ["yaw", "shoulder", "elbow"]
WAYPOINTS = np.array([[0.1, 0.2, 0.1], [0.3, 0.4, 0.2], [0.5, 0.5, 0.3]], np.float32)
KW = {"population_size": 16, "tolerance": 0.01, "max_generations": 80, "seed": 0}


@pytest.fixture(scope="module")
def sim():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")
    return Simulator(robot, MarkerScene(), mode="dynamic", waypoint_s=0.5,
                     physics="mujoco")


@pytest.fixture(scope="module")
def goal(sim):
    return np.asarray(sim.execute(WAYPOINTS), np.float64)


@pytest.fixture(scope="module")
def oet(sim, goal):
    return run_oet(sim, goal, **KW)


def test_on_a_world_equal_to_the_model_it_is_oet(sim, goal, oet):
    # without the correction of the measured offset from the model's prediction
    # (the world follows the exported ruckig moves, up to 2 mm off the model's
    # minimum-jerk ones: the correction would react to that)
    res = run_oet_closed_loop(sim, goal, MismatchedWorld(sim), correct=False, **KW)
    assert res.strategy == "oet" and res.info["loop"] == "closed"
    assert res.features.shape == oet.features.shape
    # the same plan: OET's postures, and the model's predictions its features
    np.testing.assert_allclose(res.joints, oet.joints, atol=1e-4)
    predicted = np.asarray(res.info["closed_loop"]["predicted_features"])
    np.testing.assert_allclose(predicted, oet.features, atol=1e-4)
    # measured: what the same world measures replaying OET's postures in one go
    # (MuJoCo C along the exported trajectory; see test_reality)
    world = MismatchedWorld(sim)
    measure(world)
    replay = measure(world, trajectory_of(sim, oet.joints)).features
    np.testing.assert_allclose(res.features, replay, atol=1e-4)
    np.testing.assert_allclose(res.features, oet.features, atol=2e-3)
    steps = res.info["closed_loop"]
    assert len(steps["planning_s"]) == len(steps["execution_s"]) == len(res.joints)
    assert all(t > 0 for t in steps["planning_s"] + steps["execution_s"])
    # the step errors: the measured features against each step's target point
    targets = np.asarray(res.info["targets"])
    np.testing.assert_allclose(steps["error"], np.linalg.norm(
        res.features - goal[targets], axis=-1), rtol=1e-5, atol=1e-6)


def test_with_joint_offsets_the_closed_loop_ends_nearer_than_the_open_loop(
        sim, goal, oet):
    mm = Mismatch(joint_offset_deg=[-3.0, 3.0], seed=5)
    world = MismatchedWorld(sim, mm)
    measure(world)
    replay = measure(world, trajectory_of(sim, oet.joints)).features
    dist = np.linalg.norm(goal[:, None] - replay[None], axis=-1)
    open_loop = ordered_point_errors(dist, KW["tolerance"])
    res = run_oet_closed_loop(sim, goal, MismatchedWorld(sim, mm), **KW)
    # the offsets cost the open loop several tolerances at the later points
    assert open_loop[1:].min() > 1.5 * KW["tolerance"]
    # the closed loop measures the offset after its first step and corrects it
    assert res.point_errors[-1] < 0.6 * open_loop[-1]
    assert res.point_errors[1:].max() < open_loop[1:].max()
    # its features are the world's, measured: not the model's predictions
    predicted = np.asarray(res.info["closed_loop"]["predicted_features"])
    assert np.abs(predicted - res.features).max() > 1e-3


class _Broken:
    """The world until its second execute, which measures NaN or raises."""

    def __init__(self, sim, how):
        self.world, self.how, self.calls = MismatchedWorld(sim), how, 0
        self.feature_names = self.world.feature_names
        self.joint_names = self.world.joint_names

    def reset(self):
        if self.how == "reset":
            raise ConnectionError("robot not answering")
        return self.world.reset()

    def execute(self, trajectory):
        self.calls += 1
        got = self.world.execute(trajectory)
        if self.calls == 2:
            return Measurement(np.full_like(got.features, np.nan), got.joints)
        return got


@pytest.mark.parametrize(("how", "match"), [
    ("reset", r"_Broken.reset\(\) failed: ConnectionError: robot not answering"),
    ("nan", r"_Broken.execute\(\) measured NaN or inf features"),
])
def test_a_reality_that_fails_stops_the_run(sim, goal, how, match):
    with pytest.raises(RealityError, match=match):
        run_oet_closed_loop(sim, goal, _Broken(sim, how), **KW)


def test_a_reality_of_other_features_is_refused(sim, goal):
    world = MismatchedWorld(sim)
    world.feature_names = ("a", "b")
    with pytest.raises(RealityError, match=r"feature_names \['a', 'b'\] are not"):
        run_oet_closed_loop(sim, goal, world, **KW)


def test_the_report_gives_the_closed_loop_a_row_beside_the_open_loop():
    from cgda_jax.experiment.report import reality_rows

    reality = {"mismatch": {"joint_offset_deg": [3.0, 0.0]}, "seed": 1,
               "executed": True, "point_errors": [0.02, 0.03],
               "max_point_error": 0.03, "success": False,
               "closed_loop": {"point_errors": [0.02, 0.004], "max_point_error": 0.02,
                               "success": False, "steps": 2,
                               "planning_s": [0.5, 0.25], "execution_s": [0.1, 0.1],
                               "relocalized": ["box.x", "box.y"],
                               "not_relocalized": {"marker.x": "on the robot",
                                                   "marker.y": "on the robot"}}}
    rows = reality_rows(reality, "m")
    assert len(rows) == 2 and rows[0].startswith("| open loop")
    assert rows[1].startswith("| closed loop (OET) on the same world | success False")
    assert "per point: 0.02, 0.004; 2 steps, planning 0.75 s, execution 0.2 s" in rows[1]
    assert ("objects re-localized from box.x, box.y (not marker.x, marker.y: on the "
            "robot) |") in rows[1]
    del reality["closed_loop"]  # other strategies: the open loop only
    assert len(reality_rows(reality, "m")) == 1


def test_the_replay_check_judges_oet_steps_in_order(sim, goal):
    """OET executes S steps for N goal points (S != N): the finer replay judges them
    as OET does (`ordered_point_errors`), not step i against point i."""
    import types

    from cgda_jax.experiment.compute import replay_check

    steps = np.concatenate([WAYPOINTS[:1], WAYPOINTS])  # 4 steps, 3 points
    feats = np.asarray(sim.execute(steps), np.float64)
    res = types.SimpleNamespace(strategy="oet", joints=steps, goal=goal,
                                features=feats, tolerance=0.01)
    out = replay_check(sim, res)
    assert out["success"] and out["max_point_error"] < 0.01


def test_a_tighter_step_tolerance_is_judged_at_the_run_s_tolerance(sim, goal):
    world = MismatchedWorld(sim)
    res = run_oet_closed_loop(sim, goal, world, correct=False,
                              **{**KW, "tolerance": 0.02}, step_tolerance=0.005)
    assert res.tolerance == 0.02 and res.info["step_tolerance"] == 0.005
    # the errors and the success are the measured features against the goal at
    # 0.02, in order (independent of the steps' own 0.005)
    dist = np.linalg.norm(goal[:, None] - res.features[None], axis=-1)
    want = ordered_point_errors(dist, 0.02)
    np.testing.assert_allclose(res.point_errors, want, atol=1e-6)
    assert res.success == bool(np.all(want < 0.02))
    with pytest.raises(ValueError, match="step_tolerance must be > 0"):
        run_oet_closed_loop(sim, goal, world, **KW, step_tolerance=float("nan"))


def test_the_reality_section_sets_the_closed_loop_of_cgda_run(sim, goal):
    """``[reality]`` step_tolerance / relocate_objects / correct reach the closed
    loop `cgda run --reality` runs (`closed_loop_check`): its result is that of
    `run_oet_closed_loop` called with them; bad values are config errors."""
    import types

    from cgda_jax.experiment import ConfigError, load_config
    from cgda_jax.experiment.compute import closed_loop_check
    from cgda_jax.experiment.rules import validate_config

    tiny = ["kind=execution", "data.source=clean_circle", "scene.kind=marker",
            "strategy.feasibility=false", "robot.model=tiny_arm.xml",
            'robot.joints=["yaw", "shoulder", "elbow"]', "robot.fixed={}",
            "robot.mode=dynamic", "strategy.name=oet", "strategy.tolerance=0.01",
            "reality.enabled=true"]
    cfg = load_config(None, tiny + ["reality.step_tolerance=0.005",
                                    "reality.correct=false",
                                    "reality.joint_offset_deg=[-3, 3]",
                                    "reality.seed=5"])
    validate_config(cfg)
    assert cfg.reality.loop_options() == {"step_tolerance": 0.005,
                                          "relocate_objects": True, "correct": False,
                                          "calibrate": True}
    assert "step_tolerance" not in cfg.reality.mismatch_table()
    strategy = types.SimpleNamespace(
        algorithm="CMA_ES", population_size=KW["population_size"],
        tolerance=KW["tolerance"], max_generations=KW["max_generations"], seed=0,
        options={})
    got = closed_loop_check(sim, goal, strategy, cfg.reality)
    want = run_oet_closed_loop(
        sim, goal, MismatchedWorld(sim, Mismatch(joint_offset_deg=[-3, 3], seed=5)),
        step_tolerance=0.005, correct=False, **KW)
    np.testing.assert_allclose(got["point_errors"], want.point_errors, atol=1e-9)
    assert got["steps"] == len(want.joints)
    from cgda_jax.experiment.report import reality_rows

    row = reality_rows({"mismatch": {}, "seed": 5, "executed": True,
                        "point_errors": [0.1], "max_point_error": 0.1,
                        "success": False, "closed_loop": got}, "m")[1]
    assert "steps evolved to 0.005, targets not corrected |" in row
    # the world measures its tool: the offsets drawn in [-3, 3] deg are estimated
    assert "; joint offsets estimated from the measured tool: " in row
    off = load_config(None, tiny + ["reality.calibrate=false",
                                    "reality.marker_noise=0.002"]).reality
    assert off.loop_options()["calibrate"] is False
    assert off.mismatch_table()["marker_noise"] == 0.002
    for bad, match in (("reality.step_tolerance=-1", "must be >= 0"),
                       ("reality.step_tolerance=0.05", "above strategy.tolerance")):
        with pytest.raises(ConfigError, match=match):
            validate_config(load_config(None, tiny + [bad]))
