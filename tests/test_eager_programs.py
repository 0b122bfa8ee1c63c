"""Eager calls on the set-up and after-run paths compile one program each, not one
per operation (every eager ``jnp`` op is its own XLA compile on first use of a
shape: hundreds of them made an empty-cache ``cgda demo`` seconds slower).

Each check uses shapes no other test uses, so that the programs are new here.
"""

import logging

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path
from cgda_jax.data import Demonstration
from cgda_jax.generalization import generalize, rbf_interpolate, sample_actions
from cgda_jax.recognition import ActionLibrary, cost_matrix


def compiled(caplog, fn, *args):
    """(result, names of the programs compiled while calling fn(*args))."""
    caplog.clear()
    with jax.log_compiles(True), caplog.at_level(logging.WARNING, logger="jax"):
        out = jax.block_until_ready(fn(*args))
    names = [r.getMessage().split("jit(", 1)[1].split(")", 1)[0]
             for r in caplog.records if r.getMessage().startswith("Compiling jit(")]
    return out, names


def demo(seconds: float, seed: int, n_features: int = 2) -> Demonstration:
    t = np.linspace(0.0, seconds, int(seconds * 20) + 1)
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(size=(len(t), n_features)), axis=0)
    return Demonstration(t, x, tuple(f"f{k}" for k in range(n_features)))


def test_sample_actions_matches_each_action_in_order():
    actions = [generalize([demo(s, k)]) for k, s in enumerate((4.2, 6.0, 4.4, 8.1))]
    assert len({a.n_knots for a in actions}) == 3  # two share a knot count
    got = np.asarray(sample_actions(actions, 23))
    want = np.stack([np.asarray(a.sample(23)) for a in actions])
    np.testing.assert_array_equal(got, want)


def test_sample_actions_refuses_bad_input():
    a = generalize([demo(4.0, 0)])
    with pytest.raises(ValueError, match="no actions"):
        sample_actions([], 5)
    with pytest.raises(ValueError, match="n must be >= 1"):
        sample_actions([a], 0)
    with pytest.raises(ValueError, match="different feature counts"):
        sample_actions([a, generalize([demo(4.0, 1, n_features=3)])], 5)


def test_generalized_action_is_one_program_per_shape(caplog):
    action = generalize([demo(13.0, 3)])  # 13 knots: a shape of its own
    _, names = compiled(caplog, action.sample, 41)
    assert names == ["_sample"]
    _, names = compiled(caplog, action, np.linspace(-0.2, 1.2, 43))
    assert names == ["_evaluate"]
    _, names = compiled(caplog, action.sample, 41)  # cached
    assert names == []


def test_rbf_interpolate_is_two_programs(caplog):
    kt = np.linspace(0.0, 1.0, 14)
    kv = np.random.default_rng(1).normal(size=(14, 2)).astype(np.float32)
    _, names = compiled(caplog, rbf_interpolate, kt, kv, np.linspace(0, 1, 45))
    assert sorted(set(names) - {"stage"}) == ["_evaluate", "_solve_weights"], names
    assert len(names) <= 3, names  # + at most the transfer of the knots


def test_cost_matrix_is_one_program(caplog):
    lib = ActionLibrary([generalize([demo(s, k)], name=f"a{k}")
                         for k, s in enumerate((5.0, 7.0))])
    queries = [demo(6.0, 5), np.random.default_rng(2).normal(size=(30, 2))]
    costs, names = compiled(caplog, cost_matrix, queries, lib, "euclidean", 47)
    assert names == ["_pairwise"]
    assert costs.shape == (2, 2) and np.all(np.isfinite(costs))


def test_simulator_set_up_and_replay_are_one_program_each(caplog):
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    wall = PaintWall.grid(x=0.25, ys=(-0.2, 0.0, 0.2), zs=(0.0, 0.2, 0.5),
                          root_height=0.0, path_tolerance=None)
    for scene in (MarkerScene(), wall):
        sim = Simulator(robot, scene, substeps=7)
        _, names = compiled(caplog, sim.init_state, jnp.full(3, 0.1))
        assert names == ["_start"]
        feats, names = compiled(caplog, sim.execute, np.zeros((11, 3), np.float32))
        assert names == ["_rollout_checked"]
        assert feats.shape == (11, scene.n_features)
    pts = np.random.default_rng(3).uniform(-0.5, 0.5, (13, 3)).astype(np.float32)
    _, names = compiled(caplog, wall.near_segment, pts[:-1], pts[1:])
    assert names == ["_near_segment"]
