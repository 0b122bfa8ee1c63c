"""Synthetic demonstrations: seed reproducibility and the paper's stated geometry."""

import numpy as np
import pytest

from cgda_jax import Demonstration
from cgda_jax.datasets import (
    ACTIONS,
    ARM_FEATURES,
    MARKER_FEATURES,
    clean_circle_demos,
    paint_ramp,
    select_features,
    synthetic_actions,
    synthetic_arm_actions,
)


@pytest.fixture(scope="module")
def marker():
    return synthetic_actions(seed=3)


def _col(d, name):
    return d.features[:, d.feature_names.index(name)]


def _rest(d, names, end):
    """Mean of the named features over the first/last 5 samples (the person pauses)."""
    cols = [d.feature_names.index(n) for n in names]
    rows = d.features[-5:] if end else d.features[:5]
    return rows[:, cols].mean(0)


def _circle_fit(p):
    """Least-squares (Kasa) circle through 2-D points (T, 2) -> centre (2,), radius."""
    a = np.column_stack([2 * p, np.ones(len(p))])
    b = (p**2).sum(1)
    (cx, cy, c), *_ = np.linalg.lstsq(a, b, rcond=None)
    return np.array([cx, cy]), np.sqrt(c + cx**2 + cy**2)


def test_shapes_names_and_count(marker):
    assert list(marker) == list(ACTIONS)
    for action, demos in marker.items():
        assert len(demos) == 7
        for k, d in enumerate(demos):
            assert isinstance(d, Demonstration)
            assert d.name == f"{action}-{k + 1}"
            assert tuple(d.feature_names) == MARKER_FEATURES
            assert d.features.shape == (len(d.times), 8)
            assert np.all(np.isfinite(d.features))
            assert np.all(np.diff(d.times) > 0)
    arm = synthetic_arm_actions(n_repetitions=2, seed=3)
    assert tuple(arm["MOVE"][0].feature_names) == ARM_FEATURES
    assert arm["MOVE"][0].features.shape[1] == 12


def test_seed_reproducible():
    a, b = synthetic_actions(seed=5), synthetic_actions(seed=5)
    c = synthetic_actions(seed=6)
    for action in ACTIONS:
        for x, y, z in zip(a[action], b[action], c[action]):
            np.testing.assert_array_equal(x.features, y.features)
            np.testing.assert_array_equal(x.times, y.times)
            assert x.features.shape != z.features.shape or not np.allclose(
                x.features, z.features
            )
    np.testing.assert_array_equal(
        clean_circle_demos(seed=2)[0].features, clean_circle_demos(seed=2)[0].features
    )


def test_repetitions_vary_like_a_human(marker):
    durations = [d.times[-1] for d in marker["CLEAN"]]
    assert np.std(durations) > 0.3  # different speeds and durations


def test_move_is_30cm_straight(marker):
    for d in marker["MOVE"]:
        step = _rest(d, "XYZ", True) - _rest(d, "XYZ", False)
        assert abs(np.linalg.norm(step) - 300.0) < 8.0, d.name
        xy = d.features[:, :2] - _rest(d, "XY", False)
        u = step[:2] / np.linalg.norm(step[:2])
        off_line = np.abs(xy[:, 0] * u[1] - xy[:, 1] * u[0])
        assert off_line.max() < 20.0, d.name  # straight: noise only


def test_rotate_is_90_degrees_in_place(marker):
    for d in marker["ROTATE"]:
        turn = _rest(d, ["angle"], True) - _rest(d, ["angle"], False)
        assert abs(turn[0] - 90.0) < 3.0, d.name
        assert d.features[:, :3].std(0).max() < 10.0, d.name  # about its CoM


def test_clean_is_one_30cm_circle(marker):
    for d in marker["CLEAN"]:
        _, r = _circle_fit(d.features[:, :2])
        assert abs(2 * r - 300.0) < 6.0, d.name
        start, end = _rest(d, "XY", False), _rest(d, "XY", True)
        assert np.linalg.norm(end - start) < 10.0, d.name  # one full revolution
        assert np.ptp(_col(d, "angle")) < 15.0  # orientation kept fixed


def test_paint_changes_colour_in_place(marker):
    for d in marker["PAINT"]:
        hue = _rest(d, ["hue"], True) - _rest(d, ["hue"], False)
        assert hue[0] > 45.0, d.name
        assert d.features[:, :3].std(0).max() < 10.0, d.name


def test_arm_segments_have_constant_length():
    arm = synthetic_arm_actions(n_repetitions=3, seed=1)
    mk = synthetic_actions(n_repetitions=3, seed=1)
    for action in ACTIONS:
        for d, m in zip(arm[action], mk[action]):
            f = d.features.reshape(-1, 4, 3)  # hand, wrist, elbow, shoulder
            upper = np.linalg.norm(f[:, 3] - f[:, 2], axis=-1)
            fore = np.linalg.norm(f[:, 2] - f[:, 1], axis=-1)
            assert abs(upper.mean() - 0.30) < 0.01 and abs(fore.mean() - 0.26) < 0.01
            # the hand is on the object
            hand_to_marker = np.linalg.norm(f[:, 0] - m.features[:, :3] / 1000, axis=-1)
            assert hand_to_marker.max() < 0.12, d.name
    # the same effect with different postures: elbows differ between repetitions
    elbows = [d.features[:5, 6:9].mean(0) for d in arm["ROTATE"]]
    assert max(np.linalg.norm(e - elbows[0]) for e in elbows) > 0.03


def test_clean_circle_demos_geometry():
    centre = np.array([0.55, -0.45, 0.35])
    demos = clean_circle_demos(centre=centre, diameter=0.30, n=6, seed=0)
    assert len(demos) == 6
    for d in demos:
        assert tuple(d.feature_names) == ("X", "Y", "Z")
        x = d.features
        assert abs(x[:, 0].mean() - centre[0]) < 0.015  # vertical plane x = 0.55
        c, r = _circle_fit(x[:, 1:])
        assert abs(2 * r - 0.30) < 0.01
        assert np.linalg.norm(c - centre[1:]) < 0.015


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_clean_circle_default_goal_has_the_papers_nine_points(seed):
    from cgda_jax import generalize

    demos = clean_circle_demos(seed=seed)
    mean_s = np.mean([d.times[-1] - d.times[0] for d in demos])
    assert round(mean_s) == 9
    assert generalize(demos, interval_s=1.0).knots.shape == (9, 3)


def test_select_features_and_errors(marker):
    sel = select_features(marker["MOVE"], ["Z", "X"])
    np.testing.assert_array_equal(sel[0].features[:, 1], marker["MOVE"][0].features[:, 0])
    with pytest.raises(KeyError, match="nope"):
        select_features(marker["MOVE"], ["nope"])
    with pytest.raises(ValueError, match="features"):
        synthetic_actions(features="joints")
    with pytest.raises(ValueError, match="n_repetitions"):
        synthetic_actions(n_repetitions=0)
    with pytest.raises(ValueError, match="centre"):
        clean_circle_demos(centre=(1.0, 2.0))


def test_paint_ramp():
    r = paint_ramp()
    assert r.shape == (17, 1)
    np.testing.assert_allclose(np.diff(r[:, 0]), 6.25)
