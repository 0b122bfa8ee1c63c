"""Object-effect demonstrations (MOVE: a pushed box, ROTATE: a turned valve):
form, seeds, geometry, and that generalize and recognize work on them unchanged."""

import numpy as np
import pytest

import cgda_jax as cg
from cgda_jax import Demonstration
from cgda_jax.datasets import (
    MOVE_BOX_END,
    MOVE_BOX_START,
    OBJECT_ACTIONS,
    OBJECT_FEATURES,
    VALVE_END,
    move_box_demos,
    object_actions,
    rotate_valve_demos,
)


def test_move_demos_slide_the_box_along_the_path():
    demos = move_box_demos(n=6, seed=2)
    assert len(demos) == 6 and all(isinstance(d, Demonstration) for d in demos)
    assert demos[0].feature_names == ("box.x [m]", "box.y [m]", "box.yaw [rad]")
    durations = [d.duration for d in demos]
    assert len(set(np.round(durations, 3))) == 6  # each repetition its own timing
    for d in demos:
        xy = d.features[:, :2]
        assert np.linalg.norm(xy[:5].mean(0) - MOVE_BOX_START) < 0.01
        assert np.linalg.norm(xy[-5:].mean(0) - MOVE_BOX_END) < 0.015
        assert np.abs(d.features[:, 2]).max() < np.radians(10)  # slides, barely turns
    gen = cg.generalize(demos, interval_s=1.0)
    knots = np.asarray(gen.knots)
    assert 7 <= len(knots) <= 12
    assert np.linalg.norm(knots[-1, :2] - knots[0, :2]) >= 0.20  # a push of >= 20 cm
    assert np.all(np.diff(knots[:, 1]) < 0.005)  # monotone towards the end (-y)
    curved = move_box_demos(n=3, seed=2, curve=0.05, name="crate")
    assert curved[0].feature_names[0] == "crate.x [m]"
    mid = cg.generalize(curved).knots[len(cg.generalize(curved).knots) // 2]
    assert float(mid[0]) > MOVE_BOX_START[0] + 0.03  # bulges to the left of the push


def test_rotate_demos_turn_the_valve_and_seeds_reproduce():
    demos = rotate_valve_demos(n=5, seed=1)
    assert demos[0].feature_names == ("valve.angle [rad]",)
    knots = np.asarray(cg.generalize(demos).knots)[:, 0]
    assert abs(knots[0]) < np.radians(3) and abs(knots[-1] - VALVE_END) < np.radians(4)
    assert abs(knots[-1] - knots[0]) >= np.radians(90)
    assert np.all(np.diff(knots) < np.radians(1))  # turns one way
    again = rotate_valve_demos(n=5, seed=1)
    assert all(np.array_equal(a.features, b.features) for a, b in zip(demos, again))
    assert not np.array_equal(rotate_valve_demos(n=5, seed=2)[0].features,
                              demos[0].features)
    with pytest.raises(ValueError, match="start"):
        move_box_demos(start=[0.1])
    with pytest.raises(ValueError, match="duration_s"):
        rotate_valve_demos(duration_s=0)


def test_object_actions_are_recognized():
    acts = object_actions(n_repetitions=7, seed=0)
    assert tuple(acts) == OBJECT_ACTIONS
    assert all(d.feature_names == OBJECT_FEATURES for v in acts.values() for d in v)
    lib = cg.ActionLibrary.from_demonstrations({a: v[:6] for a, v in acts.items()})
    queries = [np.asarray(cg.generalize([v[6]]).sample(100)) for v in acts.values()]
    rec = cg.recognize(queries, lib, metric="dtw")
    assert rec.names == list(OBJECT_ACTIONS)
    costs = np.asarray(rec.costs)
    off = costs + np.diag([np.inf] * len(costs))
    assert np.all(np.diag(costs) * 5 < off.min(axis=1))
