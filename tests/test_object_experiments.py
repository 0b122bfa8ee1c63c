"""The two object experiments on TEO (issue 10), as `cgda run` runs them (slow: about
15 s each on 2 CPU cores; benchmarks/bench_objects.py runs 10 seeds of each)."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[1] / "experiments"


@pytest.mark.slow
@pytest.mark.parametrize("name, seed", [("move_push_box", 0), ("move_push_box", 3),
                                        ("rotate_valve", 0), ("rotate_valve", 5)])
def test_object_experiment_succeeds_and_replays(name, seed, tmp_path):
    env = dict(os.environ, JAX_PLATFORMS="cpu", CGDA_JAX_CACHE=str(tmp_path / "cache"))
    proc = subprocess.run(
        [sys.executable, "-m", "cgda_jax.cli", "run", str(EXPERIMENTS / f"{name}.toml"),
         "--set", f"strategy.seed={seed}", "--set", "output.render=false",
         "--out", str(tmp_path / "r"), "--quiet"],
        env=env, capture_output=True, text=True, timeout=600, check=False,
    )
    assert proc.returncode == 0, proc.stderr
    res = json.loads((tmp_path / "r/result.json").read_text())
    assert res["success"] and res["replay"]["success"]
    arrays = np.load(tmp_path / "r/arrays.npz")
    goal, feats = arrays["goal"], arrays["features"]
    assert np.all(np.linalg.norm(goal - feats, axis=1) < res["tolerance"])
    if name == "move_push_box":
        assert res["feature_names"] == ["box.x [m]", "box.y [m]"]
        assert np.linalg.norm(feats[-1] - feats[0]) > 0.18  # the box really moved
    else:
        assert res["feature_names"] == ["valve.angle [rad]"]
        assert feats[0, 0] - feats[-1, 0] > np.radians(85)  # and turned one way
        assert np.all(np.diff(feats[:, 0]) < np.radians(2))
