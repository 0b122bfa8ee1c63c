"""``data.source = "video"``: a recognition config reads a folder of action folders
of recordings, tracks them as ``cgda track`` does and recognizes the held-out ones.

The plumbing only (each action's two repetitions are the same shipped recording,
so the test one is its own training one): the recognition pattern on genuinely
different repetitions is benchmarks/bench_vision.py's."""

import pathlib

import numpy as np
import pytest

pytest.importorskip("cv2")

from cgda_jax.experiment.config import ConfigError, load_config

DATA = pathlib.Path(__file__).resolve().parent / "data" / "vision"


def _library(tmp_path):
    for name in ("move", "rotate", "clean", "paint"):
        folder = tmp_path / "videos" / name.upper()
        folder.mkdir(parents=True)
        for k in (1, 2):
            (folder / f"{name}-{k}").symlink_to(DATA / name)
    cfg = tmp_path / "rec.toml"
    cfg.write_text('kind = "recognition"\n[data]\nsource = "video"\n'
                   'data_dir = "videos"\nn_train = 1\nfeatures = "spatial"\n')
    return cfg


@pytest.mark.slow  # ~60 s on 2 loaded cores: tracking 8 recordings, compiling DTW
def test_video_recognition_config_runs(tmp_path):
    from cgda_jax.experiment.run import run_experiment

    cfg = load_config(_library(tmp_path))
    result = run_experiment(cfg, tmp_path / "out")
    assert result["features"] == ["X_m", "Y_m", "Z_m"]
    costs = np.load(tmp_path / "out" / "arrays.npz")["cost_matrix"]
    assert costs.shape == (4, 4)
    np.testing.assert_array_equal(costs.argmin(axis=1), np.arange(4))


def test_video_config_errors_name_the_key(tmp_path):
    path = _library(tmp_path)
    from cgda_jax.experiment.validate import check_experiment

    with pytest.raises(ConfigError, match="data.colour"):
        load_config(path, ["data.colour=auto"])
    with pytest.raises(ConfigError, match=r"data.n_train' = 2: .* holds 2"):
        check_experiment(load_config(path, ["data.n_train=2"]))
    with pytest.raises(ConfigError, match="data.color"):
        check_experiment(load_config(path, ["data.color=green"]))
    with pytest.raises(ConfigError, match="data.features"):
        check_experiment(load_config(path, ["data.features=arm"]))
    with pytest.raises(FileNotFoundError, match="data.data_dir"):
        check_experiment(load_config(path, [f"data.data_dir={tmp_path / 'none'}"]))
