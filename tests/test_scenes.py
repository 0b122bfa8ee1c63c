"""Scenes: paint counting on hand-built paths, marker features, TEO wall reachability."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, PaintWall, Robot, model_path


def _paint(wall, path):
    """Host reference: run update over a (K, 3) marker path, return state + feature."""
    state = wall.init_state()
    feats = []
    for p in np.asarray(path, np.float32):
        state = wall.update(state, jnp.asarray(p))
        feats.append(float(wall.features(state, jnp.asarray(p))[0]))
    return np.asarray(state), np.array(feats)


def test_teo_wall_geometry():
    wall = PaintWall.grid()
    assert wall.n_squares == 16 and wall.n_features == 1
    assert wall.centres.shape == (16, 3)
    np.testing.assert_allclose(
        sorted(set(wall.centres[:, 1].round(4))), [-0.8, -0.6, -0.4, -0.2]
    )
    # world z 0.32..0.92 with the waist at 0.3 -> 0.02..0.62 in the waist frame
    np.testing.assert_allclose(
        sorted(set(wall.centres[:, 2].round(4))), [0.02, 0.22, 0.42, 0.62]
    )
    np.testing.assert_allclose(wall.centres[:, 0], 0.6)


def test_path_through_one_square_paints_exactly_it():
    wall = PaintWall.grid()
    c = wall.centres[5]
    # a horizontal stroke in front of square 5 at x - 0.1 (within 0.12 of its centre
    # only near the centre; its neighbours are 0.2 m away)
    path = [c + [-0.1, dy, 0.0] for dy in np.linspace(-0.05, 0.05, 11)]
    painted, feats = _paint(wall, path)
    assert painted.tolist() == [i == 5 for i in range(16)]
    np.testing.assert_allclose(feats, 6.25)


def test_revisiting_does_not_double_count_and_painting_sticks():
    wall = PaintWall.grid()
    a, b = wall.centres[0], wall.centres[15]
    far = np.array([0.0, 0.0, -0.5])
    path = [far, a, far, a, a, far, b, far, a]
    painted, feats = _paint(wall, path)
    assert painted.sum() == 2 and painted[0] and painted[15]
    np.testing.assert_allclose(
        feats, [0, 6.25, 6.25, 6.25, 6.25, 6.25, 12.5, 12.5, 12.5]
    )


def test_percentages_are_multiples_of_6_25_and_reach_100():
    wall = PaintWall.grid()
    rng = np.random.default_rng(1)
    path = np.concatenate([wall.centres[rng.permutation(16)], rng.normal(size=(20, 3))])
    _, feats = _paint(wall, path)
    np.testing.assert_allclose(feats / 6.25, np.round(feats / 6.25), atol=1e-6)
    assert feats[15] == 100.0 and np.all(np.diff(feats) >= 0)


def test_radius_is_a_parameter_and_the_boundary_counts():
    c = np.array([[1.0, 0.0, 0.0]])
    wall = PaintWall(c, radius=0.05)
    assert not bool(wall.near(jnp.array([1.0, 0.0, 0.051]))[0])
    assert bool(wall.near(jnp.array([1.0, 0.0, 0.049]))[0])
    assert bool(PaintWall(c, radius=0.2).near(jnp.array([1.0, 0.0, 0.15]))[0])


def test_update_jits_and_vmaps():
    wall = PaintWall.grid()
    markers = jnp.asarray(wall.centres[:4])  # 4 markers, each on one square
    states = jax.vmap(wall.update, in_axes=(None, 0))(wall.init_state(), markers)
    assert states.shape == (4, 16)
    np.testing.assert_array_equal(np.asarray(states), np.eye(4, 16, dtype=bool))
    f = jax.jit(wall.features)(states[0], markers[0])
    assert f.shape == (1,) and float(f[0]) == 6.25


def test_marker_scene():
    scene = MarkerScene()
    assert scene.feature_names == ("X", "Y", "Z") and scene.n_features == 3
    p = jnp.array([0.1, -0.2, 0.3])
    state = scene.update(scene.init_state(), p)
    np.testing.assert_array_equal(np.asarray(scene.features(state, p)), np.asarray(p))


def test_bad_walls():
    with pytest.raises(ValueError, match=r"\(S, 3\)"):
        PaintWall(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="radius"):
        PaintWall(np.zeros((4, 3)), radius=0.0)
    with pytest.raises(ValueError, match="NaN"):
        PaintWall(np.full((1, 3), np.nan))


def test_every_teo_square_reachable_with_the_papers_three_joints():
    """Sample the box of right shoulder flexion, shoulder abduction and elbow
    (forearm rotation 45 deg, the rest 0): every square comes within 0.12 m."""
    robot = Robot.from_mjcf(
        model_path("teo.xml"),
        ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"],
        "marker",
        fixed={"r_forearm_rotation": math.radians(45)},
    )
    wall = PaintWall.grid()
    axes = [np.linspace(lo, hi, 41) for lo, hi in zip(robot.lower, robot.upper)]
    genes = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    markers = jax.jit(jax.vmap(robot.marker_position))(jnp.asarray(genes, jnp.float32))
    dist = jnp.linalg.norm(markers[:, None, :] - wall.centres[None], axis=-1)
    nearest = np.asarray(dist.min(axis=0))
    print("nearest approach per square (mm), rows z 0.32..0.92, columns y -0.8..-0.2:")
    print(np.round(nearest.reshape(4, 4) * 1000).astype(int))
    assert np.all(nearest <= wall.radius), nearest
    # and the scene agrees: the sample set paints the whole wall
    painted = jax.vmap(wall.near)(markers).any(axis=0)
    assert bool(painted.all())
