"""Recognition on the real TEO recordings (xgnitive), from the wrist force sensor
(issue 41): `data.source = "xgnitive"` for recognition and the leave-one-out split."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from cgda_jax.experiment import ConfigError, load_config

CONFIG = pathlib.Path(__file__).parents[1] / "experiments/recognition_xgnitive_force.toml"


def test_leave_one_out_on_the_jr3_stream(xgnitive_dir, monkeypatch, tmp_path):
    """Every repetition of both actions is a query once; its row is its cost against
    the actions generalized without it (a library that includes it gives another
    row), and the run reads the jr3 columns in N."""
    from cgda_jax.data import load_xgnitive
    from cgda_jax.experiment import run_experiment
    from cgda_jax.generalization import generalize, sample_actions
    from cgda_jax.recognition import ActionLibrary, cost_matrix

    monkeypatch.setenv("CGDA_XGNITIVE_DIR", str(xgnitive_dir))
    cfg = load_config(CONFIG, ["recognition.n_samples=32", "output.plots=false"])
    res = run_experiment(cfg, tmp_path / "run")
    demos = {a: load_xgnitive(xgnitive_dir, a, "jr3", ["Fx", "Fy", "Fz"])
             for a in ("paint", "iron")}
    assert res["queries"] == [d.name for v in demos.values() for d in v]
    assert res["truth"] == ["paint"] * 4 + ["iron"] * 4
    assert res["feature_labels"] == ["Fx [N]", "Fy [N]", "Fz [N]"]
    costs = np.asarray(res["cost_matrix"])
    assert costs.shape == (8, 2)

    def row(train, query):
        lib = ActionLibrary.from_demonstrations(train, 3.0, "paper")
        q = np.asarray(sample_actions([generalize([query], 3.0, "paper")], 32))
        c = np.asarray(cost_matrix(list(q), lib, "dtw", 32))[0]
        return c[[list(lib.names).index(a) for a in res["actions"]]]

    query = demos["iron"][0]  # the fifth row
    without = {"paint": demos["paint"], "iron": demos["iron"][1:]}
    np.testing.assert_allclose(costs[4], row(without, query), rtol=1e-6)
    assert not np.allclose(costs[4], row(demos, query), rtol=1e-3)
    recognized = [res["actions"][i] for i in costs.argmin(axis=1)]
    assert recognized == res["recognized"]
    assert res["accuracy"] == np.mean([a == b for a, b in zip(recognized, res["truth"])])


def test_xgnitive_recognition_checks(xgnitive_dir, monkeypatch):
    """A first-n split needs a query left for every action (paint's right arm has
    3 recordings); an unknown split is named."""
    from cgda_jax.experiment.validate import check_experiment

    monkeypatch.setenv("CGDA_XGNITIVE_DIR", str(xgnitive_dir))
    cfg = load_config(CONFIG, ["recognition.split=first", "data.n_train=3",
                               "data.stream=teo/rightArm", "data.columns=['X','Y','Z']"])
    with pytest.raises(ConfigError, match=r"data.n_train'=3: 'paint' has 3 repetitions"):
        check_experiment(cfg)
    with pytest.raises(ConfigError, match="recognition.split"):
        check_experiment(load_config(CONFIG, ["recognition.split=random"]))
