"""Configs with objects: [world], scene.kind = "objects", object data sources; the
goal, simulator and goal path they build; one-line errors naming the key."""

import pathlib

import numpy as np
import pytest

from cgda_jax.experiment import (
    ConfigError,
    dump_config,
    load_config,
    validate_config,
)
from cgda_jax.experiment.build import build_goal, build_simulator, goal_path_points

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[1] / "experiments"

BOX = """
kind = "execution"
[data]
source = "move_box"
start = [0.45, 0.0]
end = [0.45, -0.25]
duration_s = 3.0
[robot]
model = "tiny_arm.xml"
joints = ["yaw", "shoulder", "elbow"]
fixed = {}
mode = "dynamic"  # only contact moves the box (kinematic mode refuses the feature)
[world]
contact_geoms = []
[[world.objects]]
piece = "table"
pos = [0.45, 0.0, 0.0]
[[world.objects]]
piece = "box"
pos = [0.45, 0.0, 0.04]
[scene]
kind = "objects"
goal_path = true
goal_path_z = 0.0
[[scene.features]]
body = "box"
quantity = "xy"
"""


def _cfg(tmp_path, text=BOX, overrides=()):
    p = tmp_path / "exp.toml"
    p.write_text(text)
    return load_config(p, list(overrides))


def test_world_and_object_scene_keys_load_dump_and_build(tmp_path):
    cfg = _cfg(tmp_path)
    assert cfg.world.objects[1] == {"piece": "box", "pos": [0.45, 0.0, 0.04]}
    assert cfg.scene.features == [{"body": "box", "quantity": "xy"}]
    validate_config(cfg)
    again = load_config(_write(tmp_path, dump_config(cfg)))
    assert again == cfg
    goal, demos, _ = build_goal(cfg)
    assert demos[0].feature_names == ("box.x [m]", "box.y [m]")  # the scene's columns
    assert goal.shape[1] == 2 and np.linalg.norm(goal[-1] - goal[0]) > 0.2
    sim = build_simulator(cfg, goal=goal)
    assert sim.feature_names == ("box.x [m]", "box.y [m]")
    path = sim.scene.goal_path
    np.testing.assert_allclose(path, np.column_stack([goal, np.zeros(len(goal))]))
    feats = np.asarray(sim.execute(np.zeros((2, 3), np.float32)))
    np.testing.assert_allclose(feats, [[0.45, 0.0]] * 2, atol=1e-6)


def _write(tmp_path, text, name="again.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_valve_goal_path_is_drawn_at_the_rim(tmp_path):
    text = (BOX.replace('source = "move_box"', 'source = "rotate_valve"')
            .replace("start = [0.45, 0.0]", "start = [0.0]")
            .replace("end = [0.45, -0.25]", "end = [1.6]")
            .replace('piece = "box"\npos = [0.45, 0.0, 0.04]',
                     'piece = "valve"\npos = [0.45, 0.0, 0.0]\nradius = 0.1')
            .replace('body = "box"\nquantity = "xy"', 'joint = "valve"\nquantity = "angle"')
            .replace("goal_path_z = 0.0", 'goal_path_site = "valve/rim"'))
    cfg = _cfg(tmp_path, text)
    validate_config(cfg)
    goal, _, _ = build_goal(cfg)
    assert goal.shape[1] == 1 and goal[-1, 0] - goal[0, 0] > np.radians(80)
    sim = build_simulator(cfg, goal=goal)
    path = sim.scene.goal_path
    # the rim site (radius 0.1, 2 cm up) turned to each goal angle about the hinge
    want = np.column_stack([0.45 + 0.1 * np.cos(goal[:, 0]), 0.1 * np.sin(goal[:, 0]),
                            np.full(len(goal), 0.02)])
    np.testing.assert_allclose(path, want, atol=1e-6)
    no_site = _cfg(tmp_path, text.replace('goal_path_site = "valve/rim"', ""))
    with pytest.raises(ConfigError, match="scene.goal_path_site"):
        build_simulator(no_site, goal=goal)
    assert goal_path_points(no_site.__class__(), None, None, goal) is None


@pytest.mark.parametrize(
    "overrides, match",
    [
        (["world.objects=[{piece = 'crate', pos = [0, 0, 0]}]"],
         r"key 'world.objects': unknown object piece 'crate'"),
        (["world.objects=[{piece = 'box', pos = [0, 0, 0], colour = 1}]"],
         r"key 'world.objects': .*unknown key\(s\) \['colour'\]"),
        (["world.contact_geoms=['hand']"], r"key 'world.contact_geoms': .*'hand'"),
        (["scene.features=[{body = 'boxx', quantity = 'xy'}]"],
         r"key 'scene.features': the move_box|key 'scene.features': body 'boxx'"),
        (["scene.features=[{body = 'box'}]"],
         r"key 'scene.features\[0\]': .*missing key 'quantity'"),
        (["scene.features=[]"], r"key 'scene.features' is empty"),
        (["scene.kind=marker", "scene.goal_path=false"],
         r"key 'scene.kind': data.source = 'move_box' gives object features"),
        (["data.start=[0.1]"], r"key 'data.start': move_box takes \[x, y\]"),
        (["scene.goal_path_site='nowhere'"],
         r"key 'scene.goal_path_site': site 'nowhere' not found"),
        (["world.shapes=[]"], r"unknown key 'world.shapes'"),
    ],
)
def test_mistakes_give_one_line_naming_the_key(tmp_path, overrides, match):
    with pytest.raises(ConfigError, match=match) as err:
        validate_config(_cfg(tmp_path, overrides=overrides))
    assert "\n" not in str(err.value)


def test_unknown_feature_name_lists_the_world(tmp_path):
    cfg = _cfg(tmp_path, overrides=["scene.features=[{body = 'boxx', quantity = 'xy'}]"])
    with pytest.raises(ConfigError, match=r"body 'boxx' not found; the model has bodies"):
        validate_config(cfg)
    cfg = _cfg(tmp_path, overrides=["scene.features=[{body = 'table', quantity = 'xy'}]"])
    validate_config(cfg)
    with pytest.raises(ConfigError, match=r"demonstrations have .*'box.x \[m\]'.*not "
                                          r"\['table.x \[m\]', 'table.y \[m\]'\]"):
        build_goal(cfg)


@pytest.mark.parametrize("name", ["move_push_box", "iiwa14_move_push_box", "rotate_valve"])
def test_object_experiments_build(name):
    cfg = load_config(EXPERIMENTS / f"{name}.toml")
    validate_config(cfg)
    goal, _, _ = build_goal(cfg)
    sim = build_simulator(cfg, 1.5, goal)
    assert goal.shape[1] == sim.n_features and len(goal) >= 5
    assert all("[" in n for n in sim.feature_names)  # units in the names
    assert sim.mode == "dynamic" and sim.scene.goal_path.shape == (len(goal), 3)
    span = np.abs(goal[-1] - goal[0])
    if name.endswith("move_push_box"):
        assert np.linalg.norm(goal[-1] - goal[0]) >= 0.20
    else:
        assert span[0] >= np.radians(90)


def test_start_posture_of_evolved_joints(tmp_path):
    from cgda_jax import MarkerScene, Robot, Simulator, model_path, run_iet

    path = model_path("tiny_arm.xml")
    robot = Robot.from_mjcf(path, ["yaw", "shoulder", "elbow"], "marker",
                            start={"elbow": 0.5})
    np.testing.assert_allclose(robot.start_genes, [0, 0, 0.5])
    for mode in ("kinematic", "dynamic"):
        sim = Simulator(robot, MarkerScene(), mode=mode, physics="mujoco")
        state = sim.init_state()
        np.testing.assert_allclose(state.genes, [0, 0, 0.5])
        if mode == "dynamic":
            np.testing.assert_allclose(state.data[sim.physics.gene_qadr], [0, 0, 0.5])
    with pytest.raises(ValueError, match="start value for 'wrist'.*not an evolved"):
        Robot.from_mjcf(path, ["yaw"], "marker", start={"wrist": 0.1})
    with pytest.raises(ValueError, match="outside its range"):
        Robot.from_mjcf(path, ["yaw"], "marker", start={"yaw": 3.0})
    cfg = _cfg(tmp_path, overrides=["robot.start={elbow = 30.0}"])
    sim = build_simulator(cfg, goal=build_goal(cfg)[0])
    np.testing.assert_allclose(sim.robot.start_genes, [0, 0, np.radians(30)], atol=1e-6)
    # IET's warm start: each point's first evolution from the previous posture
    kin = Simulator(robot, MarkerScene(), substeps=2)
    goal = np.stack([np.asarray(robot.marker_position(np.float32([0.1 * i, 0.2, 0.5])))
                     for i in range(3)])
    res = run_iet(kin, goal, population_size=8, max_generations=40, tolerance=0.02,
                  warm_start=True, algorithm_params={"std_init": 0.1})
    assert res.success and res.info["warm_start"] is True
