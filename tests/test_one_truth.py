"""One truth across a run's outputs: the generations of the report, the progress
line and the fitness plot; the fitness plotted against the point errors."""

import io
import re

import numpy as np
import pytest

from cgda_jax import plotting
from cgda_jax.experiment import load_config, run_experiment
from cgda_jax.progress import ProgressLine

# IE with feasibility on the tiny arm's clean circle, small: some points need
# restarts (5 generations a try)
CLEAN = ["kind=execution", "data.source=clean_circle", "scene.kind=marker",
         "strategy.name=ie", "strategy.population_size=8",
         "strategy.max_generations=5", "strategy.tolerance=0.03",
         "strategy.options.restarts=1", "robot.substeps=2", "output.render=false",
         "robot.model=tiny_arm.xml", 'robot.joints=["yaw", "shoulder", "elbow"]',
         "robot.fixed={}"]


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs") / "clean"
    stream = io.StringIO()
    line = ProgressLine("clean", stream=stream, interval_s=0.0)
    drawn = {}
    real = plotting.plot_fitness

    def keep(*args, **kwargs):
        drawn["fig"] = fig = real(*args, **kwargs)
        return fig

    mp = pytest.MonkeyPatch()
    mp.setattr(plotting, "plot_fitness", keep)
    try:
        result = run_experiment(load_config(None, CLEAN), folder, line)
    finally:
        mp.undo()
    line.close()
    return result, folder, stream.getvalue(), drawn["fig"]


def test_generations_agree_in_report_progress_and_plot(clean_run):
    result, folder, progress, fig = clean_run
    g = result["generations"]
    per_point = result["info"]["point_generations"]
    assert g == max(per_point) and g > 0
    # the progress line ends on the result's count (not the chunks driven)
    last = progress.strip().splitlines()[-1]
    assert re.match(rf"\[clean\] gen {g} \|", last), last
    # the report's row gives it with what it counts
    report = (folder / "report.md").read_text()
    row = next(x for x in report.splitlines() if x.startswith("| generations |"))
    assert row.startswith(f"| generations | {g} (the slowest point's")
    assert f"{sum(per_point)} over all {len(per_point)} points" in row
    # the fitness plot: the points side by side, its axis ends at the same count
    ax = fig.axes[0]
    xs = np.concatenate([ln.get_xdata() for ln in ax.lines if ln.get_marker() == "o"])
    assert xs.min() == 1 and xs.max() == g
    assert f"({g} generations)" in ax.get_title()


def test_progress_says_done_and_met_apart(clean_run):
    result, folder, progress, _ = clean_run
    last = progress.strip().splitlines()[-1]
    n = result["points"]
    met = sum(e < result["tolerance"] for e in result["point_errors"])
    assert f"| done {n}/{n} | met {met}/{n} |" in last
    report = (folder / "report.md").read_text()
    assert ("**Not met.** " in report) == (not result["success"])


def test_fitness_plot_marks_the_point_errors_not_the_motion_rank(clean_run):
    result, _, _, fig = clean_run
    ax = fig.axes[0]
    crosses = [ln for ln in ax.lines if ln.get_marker() == "x"]
    assert len(crosses) == 1
    np.testing.assert_allclose(np.sort(crosses[0].get_ydata()),
                               np.sort(result["point_errors"]), rtol=1e-6)
    texts = ax.get_legend().get_texts()
    labels = [t.get_text() for t in texts]
    assert f"tolerance {result['tolerance']:.4g} m" in labels
    assert "below: ranked by joint motion, not an error" in labels
    assert "executed point error (the result's)" in labels
    # the band where the plotted fitness is a motion rank ends at the tolerance
    band = [p for p in ax.patches if p.get_label() != "_nolegend_"] or ax.patches
    top = max(p.get_extents().y1 for p in band)
    tol_px = ax.transData.transform((0.0, result["tolerance"]))[1]
    assert abs(top - tol_px) < 1.0


def test_fitness_axis_is_linear_over_less_than_a_decade(tmp_path):
    h = np.array([[3.0, 2.0, 1.2, np.nan], [2.5, 1.0, 0.6, 0.6]])
    fig = plotting.plot_fitness(h, unit="%", tolerance=3.125, errors=[0.0, 0.0],
                                least_motion=True, path=tmp_path / "p.png")
    ax = fig.axes[0]
    assert ax.get_yscale() == "linear" and ax.get_ylim()[0] == 0.0
    assert len([t for t in ax.get_yticks() if 0 <= t <= ax.get_ylim()[1]]) >= 4
    fig = plotting.plot_fitness(h, unit="%", tolerance=3.125, parallel=True)
    xs = np.concatenate([ln.get_xdata() for ln in fig.axes[0].lines
                         if ln.get_marker() == "o"])
    assert xs.max() == 4  # side by side: the longest evolution, not 3 + 4
    fig = plotting.plot_fitness(h, unit="%")
    xs = np.concatenate([ln.get_xdata() for ln in fig.axes[0].lines
                         if ln.get_marker() == "o"])
    assert xs.max() == 7  # in run order: 3 + 4


def test_cgda_list_reads_the_stop_rule_from_the_config():
    from cgda_jax.builtin import experiment_lines, experiments_dir
    from cgda_jax.experiment import load_config

    for line in experiment_lines():
        name = line.split()[0]
        cfg = load_config(str(experiments_dir() / f"{name}.toml"))
        said = re.findall(r"(\d+) stagnant generations", line)
        if said:
            assert int(said[0]) == cfg.strategy.options["stagnation"], line
    fte = next(x for x in experiment_lines() if x.startswith("clean_fte "))
    assert "Stops after 50 stagnant generations (at most 500)." in fte


def test_motion_table_shows_the_approach_apart():
    """A failed run whose points share one posture: all its travel is the approach."""
    from cgda_jax.experiment.report import motion_lines

    none = {"r_elbow": None}
    motion = {
        "joints": ["r_elbow"], "feasible": True, "problems": [],
        "limits": {"velocity": none, "acceleration": none, "effort": none},
        "approach_s": 1.0, "move_s": 0.6, "duration_s": 6.4, "max_step_deg": 90.0,
        "moves_over_max_step": 0, "peak_speed": {"r_elbow": 1.0},
        "peak_acceleration": {"r_elbow": 2.0}, "travel_deg": {"r_elbow": 100.0},
        "approach_deg": {"r_elbow": 100.0}, "largest_step_deg": {"r_elbow": 0.0},
    }
    lines = motion_lines(motion, None)
    head = next(x for x in lines if x.startswith("| joint"))
    assert ("| approach [deg] | largest move after it [deg] | travel, approach "
            "included [deg] |") in head
    assert next(x for x in lines if x.startswith("| r_elbow")).endswith(
        "| 100 | 0 | 100 |")


def test_a_robot_without_limits_is_warned_and_its_report_says_so(caplog):
    import cgda_jax as cg
    from cgda_jax.experiment.report import motion_lines
    from cgda_jax.sim.feasibility import Feasibility

    robot = cg.Robot.from_mjcf(cg.model_path("tiny_arm.xml"),
                               ["yaw", "shoulder", "elbow"], "marker")
    with caplog.at_level("WARNING", logger="cgda_jax"):
        Feasibility(robot)
    text = caplog.text
    assert "no speed limit for yaw, shoulder, elbow" in text
    assert "[robot.limits]" in text and '"feasible" then means' in text
    caplog.clear()
    with caplog.at_level("WARNING", logger="cgda_jax"):
        f = Feasibility(robot, {"velocity": 3.0})
    assert "no speed limit" not in caplog.text and f.limits.unlimited() is None
    assert "no effort limit" in Feasibility(robot, {"velocity": 3.0}).limits.unlimited(
        effort=True)
    none = {"yaw": None}
    motion = {"joints": ["yaw"], "feasible": True, "problems": [],
              "limits": {"velocity": none, "acceleration": none, "effort": none},
              "approach_s": 1.0, "move_s": 0.6, "duration_s": 6.4,
              "max_step_deg": 90.0, "moves_over_max_step": 0,
              "peak_speed": {"yaw": 5.35}, "peak_acceleration": {"yaw": 2.0},
              "travel_deg": {"yaw": 10.0}, "largest_step_deg": {"yaw": 5.0}}
    report = "\n".join(motion_lines(motion, None))
    assert "**No speed limit** for yaw" in report and "`[robot.limits]`" in report


def test_an_unreachable_goal_fails_with_a_hint():
    from cgda_jax.experiment.report import not_met_hint

    cfg = load_config(None, CLEAN)
    far = {"kind": "execution", "success": False, "tolerance": 0.02,
           "error_unit": "m", "point_errors": [0.61, 0.618, 0.6], "info": {}}
    hint = not_met_hint(cfg, far)
    assert hint.startswith("0 of 3 points within the tolerance; the farthest, point "
                           "2, ends 0.618 m away")
    assert "strategy.options.reach_check=true" in hint and "data.centre" in hint
    checked = dict(far, info={"unreachable_points": [{"point": 0}, {"point": 1}]})
    assert "the reach check found 2 point(s) out of the arm's reach" in not_met_hint(
        cfg, checked)
    close = dict(far, point_errors=[0.01, 0.025, 0.015])
    assert "2 of 3 points" in not_met_hint(cfg, close)
    assert not_met_hint(cfg, dict(far, success=True)) is None
    # the progress line of such a run: every point done, none met
    stream = io.StringIO()
    ProgressLine("far", stream=stream)({"generations": 600, "points_done": 9,
                                         "points_met": 0, "points": 9, "done": True})
    assert "[far] gen 600 | done 9/9 | met 0/9 |" in stream.getvalue()


def test_exported_trajectory_carries_the_fixed_joints_and_the_start(tmp_path):
    import cgda_jax as cg
    from cgda_jax.reality.control_trajectory import trajectory_of
    from cgda_jax.reality.files import load_trajectory, save_trajectory, to_json_dict

    joints = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
    robot = cg.Robot.from_mjcf(cg.model_path("teo.xml"), joints, "marker",
                               fixed={"r_forearm_rotation": np.deg2rad(45)})
    sim = cg.Simulator(robot, cg.MarkerScene())
    start = np.asarray(robot.start_genes, np.float64)
    traj = trajectory_of(sim, start[None] + np.array([[0.2, -0.1, 0.3]]), rate=50.0)
    doc = to_json_dict(traj)
    info = doc["info"]
    assert info["fixed_joints"] == pytest.approx({"r_forearm_rotation": np.pi / 4})
    assert list(info["start_posture"]) == joints
    np.testing.assert_allclose(list(info["start_posture"].values()), doc["start"])
    np.testing.assert_allclose(doc["joint_trajectory"]["points"][0]["positions"],
                               doc["start"])
    words = info["before_first_point"]
    assert "r_forearm_rotation = 0.7854" in words and "start_posture" in words
    back = load_trajectory(save_trajectory(traj, tmp_path / "t.json"))
    assert back.info["fixed_joints"] == info["fixed_joints"]


def test_default_camera_frames_the_goal_and_the_arm():
    import math

    import cgda_jax as cg
    from cgda_jax.experiment import ConfigError
    from cgda_jax.experiment.figures import _arm_points, _camera, check_camera

    joints = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
    robot = cg.Robot.from_mjcf(cg.model_path("teo.xml"), joints, "marker",
                               fixed={"r_forearm_rotation": np.deg2rad(45)})
    sim = cg.Simulator(robot, cg.MarkerScene())
    angles = np.linspace(0, 2 * np.pi, 9)
    goal = np.stack([0.55 + 0 * angles, -0.45 + 0.15 * np.cos(angles),
                     0.35 + 0.15 * np.sin(angles)], axis=1)
    q = np.tile(np.asarray(robot.start_genes), (9, 1)) + 0.3
    view = _camera(sim, goal, q)
    az, el = math.radians(view["azimuth"]), math.radians(view["elevation"])
    forward = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                        math.sin(el)])
    eye = view["lookat"] - view["distance"] * forward
    assert eye[0] > 0.55  # in front of the robot (it faces +x), not behind it
    for p in np.vstack([goal, _arm_points(sim, q)]):
        ray = (p - eye) / np.linalg.norm(p - eye)
        assert math.degrees(math.acos(ray @ forward)) < 22.5  # MuJoCo's fovy / 2
    # [output] camera wins over the default, and is checked
    assert _camera(sim, goal, q, {"azimuth": 10.0})["azimuth"] == 10.0
    with pytest.raises(ConfigError, match="output.camera.zoom"):
        check_camera({"zoom": 2})
    with pytest.raises(ConfigError, match="output.camera.lookat"):
        check_camera({"lookat": [0, 1]})
    with pytest.raises(ConfigError, match="output.camera.distance"):
        check_camera({"distance": -1})


def test_video_captions_say_which_point_was_reached(clean_run):
    from cgda_jax.experiment.figures import _captions
    from cgda_jax.experiment.load import load_run

    result, folder, _, _ = clean_run
    run = load_run(str(folder))
    text = _captions(run, run.simulator())
    err = result["point_errors"][2]
    assert text(3, (), True) == (f"{run.name}: point 3 of {result['points']} reached, "
                                 f"error {1e3 * err:.1f} mm")
    assert text(3, (), False) == f"{run.name}: moving to point 3 of {result['points']}"
    assert text(0, (), False) == f"{run.name}: start"


def test_generations_row_says_what_it_counts():
    from cgda_jax.experiment.report import generations_text

    ie = {"strategy": "ie", "generations": 999,
          "info": {"point_generations": [999, 3, 5], "point_tries": [5, 1, 1]}}
    assert generations_text(ie, 200) == (
        "999 (the slowest point's: the points evolve side by side; 1007 over all 3 "
        "points; 5 tries of at most 200)")
    iet = {"strategy": "iet", "generations": 17,
           "info": {"point_generations": [1] * 17}}
    assert generations_text(iet, 200) == (
        "17 (summed over the 17 points in run order; at most 200 a try)")
    fte = {"strategy": "fte", "generations": 120, "info": {"tries": 2}}
    assert generations_text(fte, 500) == "120 (2 tries, at most 500 in all)"
