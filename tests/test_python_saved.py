"""A result saved from Python (`ExecutionResult.save`, the README's snippet) is a
results folder like ``cgda run``'s: ``cgda plot``, ``cgda export`` and `load_run`
open it, and its ``config.toml`` builds the same simulator again
(`cgda_jax.sim.description`)."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys
import types

import numpy as np
import pytest

import cgda_jax as cg
from cgda_jax.experiment.build import build_simulator
from cgda_jax.experiment.config import load_config
from cgda_jax.results_folder.rules import FolderError
from cgda_jax.sim.description import NotDescribable, describe

REPO = pathlib.Path(__file__).resolve().parents[1]
TEO_ARM = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]


def cgda(*args, cwd):
    env = {**os.environ, "JAX_PLATFORMS": "cpu",
           "PYTHONPATH": os.pathsep.join(
               p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}
    return subprocess.run([sys.executable, "-m", "cgda_jax.cli", *map(str, args)],
                          env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=600, check=False)


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """The README's snippet (a short search: the folder is what is tested)."""
    cwd = tmp_path_factory.mktemp("readme")
    demos = cg.datasets.clean_circle_demos(n=6, seed=0)
    goal = np.asarray(cg.generalize(demos, interval_s=1.0).knots)
    robot = cg.Robot.from_mjcf(cg.model_path("teo.xml"), TEO_ARM, "marker",
                               fixed={"r_forearm_rotation": np.deg2rad(45)})
    sim = cg.Simulator(robot, cg.MarkerScene(), feasibility=True)
    res = cg.run_ie(sim, goal, population_size=8, tolerance=0.02,
                    max_generations=3)
    folder = res.save(cwd / "results" / "my_clean")
    return cwd, folder, res, sim


def test_load_run_reads_a_python_saved_result_and_rebuilds_its_simulator(saved):
    _, folder, res, sim = saved
    assert sorted(p.name for p in folder.iterdir()) == [
        "arrays.npz", "config.toml", "result.json"]
    run = cg.load_run(folder)
    assert run.kind == "execution" and run.name == "my_clean"
    assert run.config.strategy.name == "ie" and run.config.strategy.population_size == 8
    assert run.config.robot.fixed == {"r_forearm_rotation": pytest.approx(45.0)}
    assert run.result["feature_labels"] == ["X [m]", "Y [m]", "Z [m]"]
    np.testing.assert_array_equal(run.arrays["joints"], res.joints)
    again = run.simulator()
    assert again.waypoint_s == sim.waypoint_s and again.substeps == sim.substeps
    np.testing.assert_array_equal(np.asarray(again.robot.qpos0),
                                  np.asarray(sim.robot.qpos0))
    assert again.feasibility.limits.as_dict() == sim.feasibility.limits.as_dict() | {
        "source": again.feasibility.limits.as_dict()["source"]}
    np.testing.assert_array_equal(run.replay(again), np.asarray(
        sim.execute(np.asarray(res.joints, np.float32)), np.float64))
    back = run.execution_result()
    assert back.setup["feature_names"] == ["X", "Y", "Z"]


def test_cgda_plot_and_export_open_a_python_saved_result(saved):
    cwd, folder, _, _ = saved
    out = cgda("plot", folder, "--no-render", cwd=cwd)
    assert out.returncode == 0, out.stderr
    pngs = sorted(p.name for p in (folder / "plots").glob("*.png"))
    assert {"goal_vs_executed.png", "point_errors.png", "fitness.png"} <= set(pngs)
    assert (folder / "report.md").is_file()
    exp = cgda("export", folder, "--format", "csv", "--no-check", cwd=cwd)
    assert exp.returncode == 0, exp.stderr
    lines = (folder / "trajectory.csv").read_text().splitlines()
    assert len(lines) > 100 and any("r_elbow" in line for line in lines[:5])


def test_a_paint_grid_and_an_object_scene_are_described_exactly():
    robot = cg.Robot.from_mjcf(cg.model_path("teo.xml"), TEO_ARM, "marker")
    wall = cg.PaintWall.grid(radius=0.1, ys=(-0.7, -0.5, -0.3), zs=(0.4, 0.6))
    sim = cg.Simulator(robot, wall, substeps=4, waypoint_s=0.5, feasibility=True)
    tables = describe(sim)  # the board, an obstacle of the scene's: a config's
    cfg = load_config(overrides=["kind=execution"])
    from cgda_jax.experiment.config import merge_table

    merge_table(cfg, tables)
    again = build_simulator(cfg)
    np.testing.assert_array_equal(again.scene.centres, wall.centres)
    assert again.scene.radius == wall.radius and again.substeps == sim.substeps
    assert again.waypoint_s == 0.5
    assert again.feasibility.collider.pair_names == sim.feasibility.collider.pair_names
    scene = cg.ObjectScene([{"site": "marker", "quantity": "xyz"}])
    assert describe(cg.Simulator(robot, scene))["scene"] == {
        "kind": "objects", "features": [{"site": "marker", "quantity": "xyz"}]}


def test_a_simulator_a_config_cannot_describe_is_said_by_the_readers(tmp_path):
    import mujoco

    path = cg.model_path("tiny_arm.xml")
    robot = cg.Robot(mujoco.MjModel.from_xml_path(str(path)),
                     ["yaw", "shoulder", "elbow"], "marker")
    with pytest.raises(NotDescribable, match="compiled model"):
        describe(cg.Simulator(robot, cg.MarkerScene()))
    sim = cg.Simulator(robot, cg.MarkerScene())
    goal = np.asarray(sim.execute(np.zeros((2, 3), np.float32)), np.float64)
    res = cg.run_ie(sim, goal, population_size=4, max_generations=1)
    folder = res.save(tmp_path / "r")
    assert not (folder / "config.toml").exists()
    assert "compiled model" in json.loads((folder / "result.json").read_text())[
        "not_described"]
    with pytest.raises(FolderError, match="config.toml missing .*compiled model"):
        cg.load_run(folder)
    with pytest.raises(NotDescribable, match="of its own"):
        describe(types.SimpleNamespace(feature_names=("x",)))
