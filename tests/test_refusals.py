"""Correct or refused, and the dry-run checks what the run checks (issue 25): every
``strategy.options`` value, finite tolerances, a model's numbers, and what kinematic
mode cannot honour (equality constraints, limited tendons, features only contact
moves), each refused by name before a run starts."""

import inspect
import os
import pathlib
import subprocess
import sys
import warnings

import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, ObjectScene, Robot, Simulator, model_path
from cgda_jax.cli import main

REPO = pathlib.Path(__file__).resolve().parents[1]
EXP = REPO / "experiments"  # this checkout's configs, not an installed copy
TINY = (REPO / "models" / "tiny_arm.xml").read_text()
JOINTS = ["yaw", "shoulder", "elbow"]
ON_TINY = ["--set", 'robot.joints=["yaw", "shoulder", "elbow"]', "--set",
           "robot.fixed={}"]


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CGDA_JAX_CACHE", str(tmp_path_factory.getbasetemp() / "jc"))


def dry_run_error(capsys, name, *sets) -> str:
    """``cgda run NAME --dry-run --set ...``: status 2 and one line naming why."""
    args = [a for s in sets for a in ("--set", s)] if sets and "=" in sets[0] else []
    config = REPO / "experiments" / f"{name}.toml"  # this checkout's, not installed
    code = main(["run", str(config), "--dry-run", *(args or sets)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("cgda: error:"), err
    return err


def model_file(tmp_path, text: str, name: str = "arm.xml") -> pathlib.Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# --------------------------------------------------------------------------- options
@pytest.mark.parametrize("name, setting, words", [
    ("clean_ie", "restarts=-1", ["restarts", "must be >= 0, got -1"]),
    ("clean_ie", 'restarts="x"', ["restarts", "a whole number >= 0, got 'x'"]),
    ("clean_ie", "restarts=2.0", ["restarts", "a whole number"]),
    ("clean_ie", 'refine="bogus"', ["refine", "'bogus' is not one of"]),
    ("clean_ie", 'devices="gpu"', ["devices", '"all" or a device count']),
    ("clean_ie", "devices=4096", ["devices", "4096 devices asked"]),
    ("clean_ie", "stagnation=0", ["stagnation", "must be >= 1, got 0"]),
    ("clean_ie", "restart_samples=-1", ["restart_samples", ">= 0"]),
    ("clean_ie", "reach_check=1", ["reach_check", "true or false"]),
    ("clean_ie", "keys=[1, 2]", ["keys", "only a Python caller"]),
    ("paint_iet", "backtracks=-1", ["backtracks", ">= 0"]),
    ("clean_fte", "min_improvement=1.5", ["min_improvement", "in [0, 1)"]),
    ("move_push_box", "aim=0", ["aim", "in (0, 1]"]),
    ("clean_fte", 'init="x"', ["init", "'x' is not one of"]),
    ("clean_fte", "refine_gamma=inf", ["refine_gamma", "finite number > 0"]),
    ("clean_fte", "algorithm_params=3", ["algorithm_params", "table"]),
])
def test_every_option_value_is_checked_by_its_key(capsys, name, setting, words):
    err = dry_run_error(capsys, name, f"strategy.options.{setting}")
    assert f"key 'strategy.options.{words[0]}'" in err
    for w in words[1:]:
        assert w in err


def test_every_strategy_keyword_has_a_kind():
    """A new keyword of a run_* function must say how its config value is checked."""
    from cgda_jax.experiment.rules import OPTION_KINDS, SET_BY_CONFIG, strategy_function

    for name in ("fte", "ie", "iet", "oet"):
        params = inspect.signature(strategy_function(name)).parameters
        missing = [k for k in params if k not in SET_BY_CONFIG and k not in OPTION_KINDS]
        assert not missing, (name, missing)


def test_options_that_need_independent_points_are_refused_in_the_dry_run(capsys):
    err = dry_run_error(capsys, "paint_iet", 'strategy.name="ie"',
                        'strategy.options={ refine = "adam" }')
    assert "key 'strategy.options.refine'" in err and "independent points" in err


def test_tolerance_must_be_finite(capsys, tmp_path):
    from cgda_jax import run_ie

    err = dry_run_error(capsys, "clean_ie", "strategy.tolerance=inf")
    assert "key 'strategy.tolerance' must be a finite number > 0, got inf" in err
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")
    sim = Simulator(robot, MarkerScene(), substeps=2)
    with pytest.raises(ValueError, match="tolerance must be a finite number > 0; got "
                       "inf"):
        run_ie(sim, np.zeros((2, 3)), tolerance=float("inf"))


# --------------------------------------------------------------------------- the model
@pytest.mark.parametrize("old, new, words", [
    ('pos="0 0 0.30"', 'pos="0 0 nan"', ["body 'link2'", "body_pos", "nan"]),
    ('kp="50"', 'kp="1e39"', ["actuator 'yaw'", "actuator_gainprm", "1e+39"]),
    ('damping="2"', 'damping="inf"', ["joint 'yaw'", "dof_damping", "inf"]),
    ('axis="0 1 0" range="-90 90"', 'axis="0 nan 0" range="-90 90"',
     ["joint 'shoulder'", "jnt_axis"]),
    ('timestep="0.002"', 'timestep="nan"', ["option timestep"]),
])
def test_a_models_numbers_must_be_finite_float32(tmp_path, old, new, words):
    assert old in TINY
    path = model_file(tmp_path, TINY.replace(old, new, 1))
    with pytest.raises(ValueError) as err:
        Robot.from_mjcf(path, JOINTS, "marker")
    assert str(err.value).startswith(f"model {path}:")
    for w in words:
        assert w in str(err.value)


def test_the_dry_run_names_the_model_key(capsys, tmp_path):
    path = model_file(tmp_path, TINY.replace('size="0.02"', 'size="1e39"', 1))
    err = dry_run_error(capsys, "clean_ie", f'robot.model="{path}"', *ON_TINY[1::2])
    assert "key 'robot.model'" in err and "geom 'link2'" in err


# --------------------------------------------------------------------------- kinematic
TIED = TINY.replace("</worldbody>", """</worldbody>
  <equality><joint name="tie" joint1="elbow" joint2="shoulder"/></equality>""")
TENDON = TINY.replace("</worldbody>", """</worldbody>
  <tendon><fixed name="coupling" limited="true" range="-0.5 0.5">
    <joint joint="shoulder" coef="1"/><joint joint="elbow" coef="1"/>
  </fixed></tendon>""")


def test_kinematic_mode_refuses_an_equality_constraint_it_would_break(tmp_path):
    """The elbow tied to the shoulder ran "ok" with postures 3.1 rad off the tie."""
    path = model_file(tmp_path, TIED)
    robot = Robot.from_mjcf(path, JOINTS, "marker")
    with pytest.raises(ValueError, match=r"kinematic mode cannot honour the joint "
                       r"equality constraint 'tie' \(ties joints \['elbow', "
                       r"'shoulder'\].*mode='dynamic'"):
        Simulator(robot, MarkerScene())
    # dynamic mode: the physics holds the tie (MuJoCo C stepping the same model)
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.2)
    assert sim.mode == "dynamic"
    # evolving only the yaw: the tied joints stay where the model puts them
    Simulator(Robot.from_mjcf(path, ["yaw"], "marker"), MarkerScene())


def test_kinematic_mode_refuses_a_limited_tendon_over_evolved_joints():
    model = mujoco.MjModel.from_xml_string(TENDON)
    with pytest.raises(ValueError, match=r"kinematic mode cannot honour tendon "
                       r"'coupling' limited to \[-0.5, 0.5\] over \['shoulder', "
                       r"'elbow'\]"):
        Simulator(Robot(model, JOINTS, "marker"), MarkerScene())
    # without a range a tendon only acts through forces, which kinematic mode has none
    free = mujoco.MjModel.from_xml_string(
        TENDON.replace(' limited="true" range="-0.5 0.5"', ""))
    Simulator(Robot(free, JOINTS, "marker"), MarkerScene())


def test_kinematic_mode_refuses_an_object_feature_only_contact_moves():
    objs = [{"piece": "box", "pos": [0.3, 0.0, 0.05], "size": [0.03, 0.03, 0.03]}]
    robot = Robot.from_world(model_path("tiny_arm.xml"), objs, JOINTS, "marker")
    with pytest.raises(ValueError, match=r"kinematic mode: feature body 'box' \(xy\) "
                       r"never changes: none of the evolved joints \['yaw', "
                       r"'shoulder', 'elbow'\] moves body 'box'.*mode='dynamic'"):
        Simulator(robot, ObjectScene([{"body": "box", "quantity": "xy"}]))
    with pytest.raises(ValueError, match=r"feature joint 'yaw' .* never changes"):
        Simulator(Robot.from_world(model_path("tiny_arm.xml"), objs, ["shoulder"],
                                   "marker"),
                  ObjectScene([{"joint": "yaw", "quantity": "angle"}]))
    # a site the arm carries does change
    Simulator(robot, ObjectScene([{"site": "marker", "quantity": "xyz"}]))


@pytest.fixture(scope="module")
def env():
    path = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path, "JAX_PLATFORMS": "cpu"}


@pytest.mark.parametrize("args, words", [
    ([str(EXP / "move_push_box.toml"), "--set", 'robot.mode="kinematic"'],
     ["key 'robot.mode'", "feature body 'box'", "robot.mode = \"dynamic\""]),
    ([str(EXP / "clean_ie.toml"), "--set", "strategy.options.restarts=-1"],
     ["key 'strategy.options.restarts'"]),
    ([str(EXP / "clean_ie.toml"), "--set", "strategy.tolerance=inf"],
     ["key 'strategy.tolerance'"]),
])
def test_cli_refusals_are_one_line(env, args, words):
    proc = subprocess.run([sys.executable, "-m", "cgda_jax.cli", "run", *args,
                           "--dry-run"], env=env, capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    for w in words:
        assert w in proc.stderr


# ------------------------------------------------- caught at --dry-run (issue 43)
@pytest.mark.parametrize("name, sets, words", [
    ("clean_ie_dynamic", ["reality.enabled=true", "reality.seed=-1"],
     ["key 'reality.seed': seed -1 is not in 0 .. 4294967295"]),
    ("clean_ie", ["robot.limits.velocity=1e300"],
     ["key 'robot.limits'", "velocity = 1e+300: outside float32's range"]),
    ("clean_ie", ["data.scale=1e38"],
     ["key 'data.scale': the goal reaches 5.51e+37", "overflow float32"]),
])
def test_what_the_run_would_fail_on_is_refused_by_the_dry_run(capsys, name, sets,
                                                              words):
    """reality.seed=-1 failed after 13 s (status 3); velocity 1e300 became inf with a
    RuntimeWarning; data.scale=1e38 failed blaming the actuator gains."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning either
        err = dry_run_error(capsys, name, *sets)
    for w in words:
        assert w in err


def test_the_dry_run_refuses_a_folder_another_run_holds(capsys, tmp_path):
    """It called the folder valid; the run was then refused."""
    import fcntl

    from cgda_jax.results_folder.rules import hidden_name

    out = tmp_path / "busy"
    lock = tmp_path / hidden_name(out, "lock")
    with open(lock, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        f.write("4242\n")
        f.flush()
        err = dry_run_error(capsys, "clean_ie", "--out", str(out))
    assert f"results folder {out} is in use by another run (pid 4242)" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == [lock.name]


def test_a_model_set_relative_to_the_cwd_is_saved_so_that_it_resolves(
        tmp_path, monkeypatch):
    """--set robot.model="models/x.xml" was saved as given, and `cgda export RUN`
    / `cgda run RUN/config.toml` looked for it inside the results folder."""
    from cgda_jax.experiment import dump_config, load_config

    (tmp_path / "models").mkdir()
    model = model_file(tmp_path / "models", TINY, "x.xml")
    monkeypatch.chdir(tmp_path)
    cfg = load_config(EXP / "clean_ie.toml", ['robot.model="models/x.xml"'])
    assert cfg.robot.model == str(model)
    saved = tmp_path / "run" / "config.toml"
    saved.parent.mkdir()
    saved.write_text(dump_config(cfg))
    monkeypatch.chdir(REPO)
    assert load_config(saved).robot.model == str(model)
    assert load_config(EXP / "clean_ie.toml",
                       ['robot.model="teo.xml"']).robot.model == "teo.xml"  # built-in


def test_api_refusals_name_their_input(tmp_path):
    """soft_dtw blamed the trajectories' scale for gamma; Simulator(robot, None)
    raised AttributeError; generalize(generator) "cannot convert float NaN to
    integer"; model_path("../../../../etc/passwd") returned a path outside."""
    import jax.numpy as jnp

    from cgda_jax import Demonstration, generalize, soft_dtw

    x = jnp.ones((5, 2))
    for gamma in (1e-40, float("inf")):
        with pytest.raises(ValueError, match=r"soft_dtw: gamma must be a float32 "
                           r"number > 0"):
            soft_dtw(x, x, gamma=gamma)
    robot = Robot(mujoco.MjModel.from_xml_string(TINY), JOINTS, "marker")
    with pytest.raises(TypeError, match="Simulator: scene must be a scene"):
        Simulator(robot, None)
    t = np.linspace(0, 4, 41)
    demo = Demonstration(t, np.sin(t)[:, None], ("s",))
    assert generalize(d for d in [demo, demo]).knots.shape == (4, 1)
    with pytest.raises(FileNotFoundError, match="a built-in model is a file name"):
        model_path("../../../../etc/passwd")
    with pytest.raises(FileNotFoundError, match="not a path"):
        model_path("objects/../teo.xml")
