"""Feasibility from a config (issue 21): `[feasibility]`, `robot.limits`,
`strategy.feasibility`, and what a run's folder says about its motion."""

import json
import pathlib

import numpy as np
import pytest

from cgda_jax.cli import main
from cgda_jax.experiment import ConfigError, load_config, validate_config
from cgda_jax.experiment.build import build_goal, build_simulator

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[1] / "experiments"
CLEAN = str(EXPERIMENTS / "clean_ie.toml")


def test_defaults_judge_every_run_with_teo_limits():
    cfg = load_config(CLEAN)
    assert cfg.strategy.feasibility and cfg.feasibility.penetration == 0.005
    sim = build_simulator(cfg)
    lim = sim.feasibility.limits
    np.testing.assert_allclose(lim.velocity, 3.0)
    np.testing.assert_allclose(lim.effort, 30.0)
    assert lim.source["velocity"][0] == "mjcf custom velocity_limit"
    assert sim.approach_s > sim.move_s
    assert build_simulator(load_config(CLEAN, ["strategy.feasibility=false"])
                           ).feasibility is None


def test_config_limits_override_the_model(tmp_path):
    cfg = load_config(CLEAN, ["robot.limits.velocity=2.0",
                              "robot.limits.effort.r_elbow=20.0"])
    lim = build_simulator(cfg).feasibility.limits
    np.testing.assert_allclose(lim.velocity, 2.0)
    np.testing.assert_allclose(lim.effort, [30.0, 30.0, 20.0])
    assert lim.source["velocity"] == ("config",) * 3
    assert lim.source["effort"][:2] == ("mjcf actuatorfrcrange",) * 2


@pytest.mark.parametrize("overrides, match", [
    (["feasibility.penetration=-0.01"], r"key 'feasibility.penetration' must be"),
    (["feasibility.samples=0"], r"key 'feasibility.samples' must be >= 1"),
    (["robot.limits.speed=3"], r"key 'robot.limits.speed': unknown"),
    (["feasibility.tracking_deg=0"], r"key 'feasibility.tracking_deg' must be"),
    (["feasibility.saturation=1.5"], r"key 'feasibility.saturation' must be in"),
])
def test_bad_feasibility_settings_name_the_key(overrides, match):
    with pytest.raises(ConfigError, match=match):
        validate_config(load_config(CLEAN, overrides))


@pytest.mark.parametrize("overrides, match", [
    (["robot.limits.velocity.r_knee=2"], r"robot.limits.*r_knee"),
    (["robot.limits.velocity=-2"], r"robot.limits.*-2"),
    (['feasibility.exclude=["no_such_geom"]'], r"feasibility.exclude.*no_such_geom"),
])
def test_bad_limits_and_excludes_are_named_when_built(overrides, match):
    with pytest.raises(ConfigError, match=match):
        build_simulator(load_config(CLEAN, overrides))


def test_feasibility_off_is_the_unconstrained_run():
    """strategy.feasibility = false: the simulator and result of the paper's
    execution (no violation carried, no feasibility in the result)."""
    cfg = load_config(CLEAN, ["strategy.feasibility=false"])
    sim = build_simulator(cfg)
    assert sim.init_state().violation is None
    goal, _, _ = build_goal(cfg)
    from cgda_jax import run_ie

    res = run_ie(sim, goal, population_size=16, max_generations=30, seed=0)
    assert "feasible" not in res.info


def test_run_folder_reports_the_motion(tmp_path):
    out = tmp_path / "run"
    code = main(["run", CLEAN, "--out", str(out), "--set", "output.render=false",
                 "--set", "strategy.max_generations=80"])
    assert code in (0, 1)
    result = json.loads((out / "result.json").read_text())
    motion = result["motion"]
    joints = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
    assert motion["joints"] == joints and set(motion["peak_speed"]) == set(joints)
    assert motion["limits"]["velocity"]["r_elbow"] == 3.0
    if result["info"]["feasible"]:  # the strategy's check and the report agree
        assert max(motion["peak_speed"].values()) <= 3.0 * (1 + 1e-5)
    report = (out / "report.md").read_text()
    assert "## Feasibility" in report and "peak speed [rad/s]" in report
    assert (out / "plots" / "motion.png").is_file()
    with np.load(out / "arrays.npz") as z:
        assert z["motion_q"].shape[1] == 3 and z["motion_t"].ndim == 1
