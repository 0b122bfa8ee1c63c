"""Experiment configs (defaults, TOML, --set, errors) and recognition runs."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from cgda_jax.experiment import (
    ConfigError,
    ExperimentConfig,
    dump_config,
    load_config,
    run_experiment,
    validate_config,
)

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[1] / "experiments"


def _write(tmp_path, text, name="exp.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_defaults_file_and_overrides_layer(tmp_path):
    p = _write(tmp_path, 'kind = "execution"\n[strategy]\nname = "iet"\ntolerance = 3\n')
    cfg = load_config(p, ["strategy.population_size=64", "robot.fixed.r_wrist=10"])
    assert cfg.name == "exp"  # from the file name
    assert cfg.kind == "execution" and cfg.strategy.name == "iet"
    assert cfg.strategy.tolerance == 3.0 and isinstance(cfg.strategy.tolerance, float)
    assert cfg.strategy.population_size == 64
    assert cfg.robot.fixed == {"r_wrist": 10.0}  # no default: TEO's configs set it
    assert cfg.strategy.max_generations == ExperimentConfig().strategy.max_generations
    # the dumped config loads back to the same values
    again = load_config(_write(tmp_path, dump_config(cfg), "again.toml"))
    assert again == cfg


@pytest.mark.parametrize(
    "text, match",
    [
        ("[strategy]\npopulation = 3\n", r"exp.toml: unknown key 'strategy.population'"),
        ("[strategy]\npopulation_size = 'big'\n", r"exp.toml: key 'strategy.population_size': expected int"),
        ("[data]\ninterval_s = true\n", r"key 'data.interval_s': expected float"),
        ("[robot]\njoints = 'r_elbow'\n", r"key 'robot.joints': expected list"),
        ("strategy = 3\n", r"key 'strategy' must be a table"),
        ("kind = \n", r"not valid TOML"),
    ],
)
def test_file_errors_name_key_and_file(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        load_config(_write(tmp_path, text))


def test_override_and_validation_errors(tmp_path):
    with pytest.raises(ConfigError, match="unknown key 'output.folder'"):
        load_config(None, ["output.folder=x"])
    with pytest.raises(ConfigError, match="expected key=value"):
        load_config(None, ["strategy.seed"])
    with pytest.raises(FileNotFoundError, match="config file not found"):
        load_config(tmp_path / "missing.toml")
    cfg = load_config(None, ["kind=execution", "data.source=clean_circle",
                             "robot.model=/no/such/robot.xml"])
    with pytest.raises(FileNotFoundError, match="/no/such/robot.xml"):
        validate_config(cfg)
    cfg = load_config(None, ["kind=execution", "data.source=xgnitive",
                             f"data.data_dir={tmp_path / 'absent'}"])
    with pytest.raises(FileNotFoundError, match="absent"):
        validate_config(cfg)
    with pytest.raises(ConfigError, match="'strategy.name'"):
        validate_config(load_config(None, ["kind=execution", "data.source=paint_ramp",
                                           "strategy.name=ga"]))


@pytest.mark.parametrize("path", sorted(EXPERIMENTS.glob("*.toml")), ids=lambda p: p.stem)
def test_every_experiment_file_is_valid(path, monkeypatch, tmp_path):
    if "xgnitive" in path.stem:
        monkeypatch.setenv("CGDA_XGNITIVE_DIR", str(tmp_path))  # any existing folder
    validate_config(load_config(path))


@pytest.mark.parametrize("name", ["recognition_all_features", "recognition_spatial"])
def test_recognition_recognizes_every_test_action(name, tmp_path):
    cfg = load_config(EXPERIMENTS / f"{name}.toml", ["output.plots=false"])
    result = run_experiment(cfg, tmp_path)
    assert result["recognized"] == result["truth"] == ["MOVE", "ROTATE", "CLEAN", "PAINT"]
    assert result["accuracy"] == 1.0
    costs = np.asarray(result["cost_matrix"])
    assert costs.shape == (4, 4)
    # every diagonal cost is clearly below the rest of its row
    off = costs + np.diag([np.inf] * 4)
    assert np.all(np.diag(costs) * 1.5 < off.min(axis=1))
    saved = json.loads((tmp_path / "result.json").read_text())
    assert saved["accuracy"] == 1.0 and saved["actions"] == result["actions"]
    assert (tmp_path / "config.toml").is_file() and (tmp_path / "report.md").is_file()
    assert np.load(tmp_path / "arrays.npz")["cost_matrix"].shape == (4, 4)


TINY_RUN = ["kind=execution", "data.source=paint_ramp", "data.goal_points=3",
            "scene.kind=paint", "strategy.name=iet", "strategy.population_size=8",
            "strategy.max_generations=10", "strategy.tolerance=40", "robot.substeps=2"]


def test_render_switch_writes_gif_and_frame_strip_or_nothing(tmp_path):
    cfg = load_config(None, TINY_RUN + ["output.plots=false"])
    result = run_experiment(cfg, tmp_path / "on")
    if not result["render"]["ok"]:
        pytest.skip(f"no offscreen OpenGL here: {result['render']['reason']}")
    assert (tmp_path / "on/plots/execution.gif").stat().st_size > 1000
    assert (tmp_path / "on/plots/frames.png").stat().st_size > 2000
    assert "![robot executing](plots/execution.gif)" in (tmp_path / "on/report.md").read_text()
    import imageio.v3 as iio

    gif = iio.imread(tmp_path / "on/plots/execution.gif", index=None)
    mp4 = np.stack(list(iio.imiter(tmp_path / "on/plots/execution.mp4")))
    assert gif.shape[1:] == mp4.shape[1:] == (480, 640, 3)
    # start + a frame per kinematic sub-step (at most 4 for paint) per waypoint, 3
    # goal points; the paint wall raises the 2 sub-steps asked for to bound the path
    from cgda_jax.experiment.figures import PAINT_FRAMES_PER_WAYPOINT

    substeps = json.loads((tmp_path / "on/result.json").read_text())["substeps"]
    assert PAINT_FRAMES_PER_WAYPOINT == 4
    assert substeps >= 2 and len(mp4) == 1 + 3 * min(substeps, 4)
    off = run_experiment(load_config(None, TINY_RUN + ["output.plots=false",
                                                       "output.render=false"]), tmp_path / "off")
    assert "render" not in off and not (tmp_path / "off/plots").exists()


@pytest.mark.slow  # 33 s in CI; the render switch test stays
def test_missing_gl_gives_one_warning_not_a_crash(tmp_path):
    # EGL requested while PyOpenGL is pinned to another platform: no GL context
    env = dict(os.environ, MUJOCO_GL="egl", PYOPENGL_PLATFORM="osmesa", JAX_PLATFORMS="cpu",
               CGDA_JAX_CACHE=str(tmp_path / "cache"))
    sets = [a for s in TINY_RUN + ["output.plots=false"] for a in ("--set", s)]
    proc = subprocess.run(
        [sys.executable, "-m", "cgda_jax.cli", "run", *sets, "--out", str(tmp_path / "r"),
         "--quiet", "--no-cache", str(EXPERIMENTS / "paint_iet.toml")],
        env=env, capture_output=True, text=True, timeout=300, check=False,
    )
    assert proc.returncode in (0, 1), proc.stderr  # 1: goal not met; never a crash
    assert "Traceback" not in proc.stderr
    warn = [x for x in proc.stderr.splitlines() if "frames not rendered" in x]
    assert len(warn) == 1 and "output.render=false" in warn[0], proc.stderr
    saved = json.loads((tmp_path / "r/result.json").read_text())
    assert saved["render"]["ok"] is False
    assert "Frames not rendered" in (tmp_path / "r/report.md").read_text()


def test_the_demo_runs_the_experiment_files_of_the_same_name():
    """`cgda demo` keeps its own tables (it must run from a wheel); they hold the
    settings of ``experiments/NAME.toml`` (a re-tuned file without its demo twin
    would show users another run than the one documented)."""
    from cgda_jax.builtin import resolve_config
    from cgda_jax.experiment import load_config
    from cgda_jax.experiment.demo_suite import demo_configs

    for cfg in demo_configs():
        exp = load_config(resolve_config(cfg.name))
        for section in ("data", "robot", "strategy", "feasibility", "recognition"):
            assert getattr(cfg, section) == getattr(exp, section), (cfg.name, section)
        assert cfg.scene.kind == exp.scene.kind
