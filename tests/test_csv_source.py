"""``data.source = "csv"`` (and "video") in execution configs: a user's own
demonstrations (e.g. written by ``cgda track --out``) become the goal."""

import pathlib

import numpy as np
import pytest

from cgda_jax.data import save_csv
from cgda_jax.datasets import clean_circle_demos
from cgda_jax.experiment.build import build_goal
from cgda_jax.experiment.config import ConfigError, load_config
from cgda_jax.experiment.validate import check_experiment

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _csv_config(tmp_path, demos, columns):
    folder = tmp_path / "demos"
    folder.mkdir()
    for k, d in enumerate(demos):
        save_csv(d, folder / f"clean-{k}.csv")
    cols = ", ".join(f'"{c}"' for c in columns)
    text = (ROOT / "experiments" / "clean_ie.toml").read_text()
    assert 'source = "clean_circle"' in text
    text = text.replace('source = "clean_circle"',
                        f'source = "csv"\ndata_dir = "demos"\ncolumns = [{cols}]')
    path = tmp_path / "clean_csv.toml"
    path.write_text(text)
    return path


def test_csv_demonstrations_give_the_same_goal_as_the_built_in_ones(tmp_path):
    # the reference: the same demonstrations generalized by the clean_circle source
    ref_cfg = load_config(ROOT / "experiments" / "clean_ie.toml")
    d = ref_cfg.data
    demos = clean_circle_demos(d.centre, d.diameter, d.n_demos, d.seed)
    path = _csv_config(tmp_path, demos, demos[0].feature_names)
    cfg = load_config(path)  # data_dir relative to the config file
    check_experiment(cfg)
    goal, read, _ = build_goal(cfg)
    ref_goal, _, _ = build_goal(ref_cfg)
    assert len(read) == len(demos)
    np.testing.assert_allclose(goal, ref_goal, atol=1e-5)


def test_csv_source_errors_name_the_key_and_file(tmp_path):
    demos = clean_circle_demos(n=2)
    path = _csv_config(tmp_path, demos, [*demos[0].feature_names[:2], "nope"])
    with pytest.raises(ConfigError, match=r"data.columns.*nope"):
        build_goal(load_config(path))
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match=r"data.data_dir.*holds no demonstration CSV"):
        check_experiment(load_config(path, [f"data.data_dir={tmp_path / 'empty'}"]))
    with pytest.raises(FileNotFoundError, match="data.data_dir"):
        check_experiment(load_config(path, [f"data.data_dir={tmp_path / 'missing'}"]))
    with pytest.raises(ConfigError, match="data.data_dir' is empty"):
        check_experiment(load_config(path, ["data.source=video", "data.data_dir="]))
