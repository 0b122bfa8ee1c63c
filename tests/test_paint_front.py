"""The paint wall is a solid board painted from the front only (issue 21)."""

import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import PaintWall
from cgda_jax.sim.scenes import front_segment_distance2


def _dense_front_distance(points, a, b, front, n=20001):
    """NumPy reference: min distance from each point to the samples of a -> b that
    lie on the front side of the plane through that point (inf where none)."""
    ts = np.linspace(0.0, 1.0, n)[:, None]
    samples = a + ts * (b - a)  # (n, 3)
    rel = samples[None] - points[:, None]  # (S, n, 3)
    d = np.linalg.norm(rel, axis=-1)
    d = np.where(rel @ front >= 0, d, np.inf)
    return d.min(axis=1)


def test_front_segment_distance_matches_dense_sampling():
    rng = np.random.default_rng(0)
    points = rng.normal(0, 0.3, (12, 3))
    for k in range(40):
        front = rng.normal(size=3)
        front /= np.linalg.norm(front)
        a = rng.normal(0, 0.3, 3)
        b = a + rng.normal(0, 0.3, 3)
        got = np.sqrt(np.asarray(front_segment_distance2(
            jnp.asarray(points, jnp.float32), jnp.asarray(a, jnp.float32),
            jnp.asarray(b, jnp.float32), jnp.asarray(front, jnp.float32))))
        want = _dense_front_distance(points, a, b, front)
        both = np.isfinite(want)
        # inf exactly where no sample is in front (up to the sampling step)
        step = np.linalg.norm(b - a) / 20000
        assert np.all(np.isfinite(got) | ~both)
        np.testing.assert_allclose(got[both], want[both], atol=1e-5 + step)
    # a segment parallel to the plane: all in front or all behind
    p = np.zeros((1, 3), np.float32)
    f = jnp.asarray([-1.0, 0.0, 0.0])
    behind = front_segment_distance2(p, jnp.asarray([0.1, -1, 0.0]),
                                     jnp.asarray([0.1, 1, 0.0]), f)
    ahead = front_segment_distance2(p, jnp.asarray([-0.1, -1, 0.0]),
                                    jnp.asarray([-0.1, 1, 0.0]), f)
    assert np.isinf(np.asarray(behind)).all()
    np.testing.assert_allclose(np.sqrt(np.asarray(ahead)), [0.1], atol=1e-6)


def test_a_square_reached_from_behind_is_not_painted():
    wall = PaintWall.grid()  # squares at x = 0.6, front towards the robot (-x)
    c = np.asarray(wall.centres[5], np.float32)
    state = wall.init_state()
    behind = c + np.float32([0.05, 0.0, 0.0])
    ahead = c + np.float32([-0.05, 0.0, 0.0])
    assert not np.asarray(wall.update(state, jnp.asarray(behind))).any()
    assert np.asarray(wall.update(state, jnp.asarray(ahead)))[5]
    # a sweep behind the board, through the centre's neighbourhood: nothing
    path = np.stack([c + [0.05, -0.1, 0.0], c + [0.05, 0.1, 0.0]]).astype(np.float32)
    assert not np.asarray(wall.sweep(state, path)).any()
    # a sweep that comes through the board from behind: the front part paints
    # only what it passes in front (square 5 from 4 cm in front)
    through = np.stack([c + [0.1, 0.0, 0.0], c + [-0.04, 0.0, 0.0]]).astype(np.float32)
    painted = np.asarray(wall.sweep(state, through))
    assert painted[5] and painted.sum() == 1


def test_board_sits_behind_the_squares_and_covers_them():
    wall = PaintWall.grid(thickness=0.03, margin=0.05)
    b = wall.board
    lo, hi = b["pos"] - b["size"], b["pos"] + b["size"]
    np.testing.assert_allclose([lo[0], hi[0]], [0.6, 0.63], atol=1e-9)  # x: front face
    c = wall.centres
    assert np.all(lo[1:] <= c[:, 1:].min(0) - 0.1 - 0.05 + 1e-6)
    assert np.all(hi[1:] >= c[:, 1:].max(0) + 0.1 + 0.05 - 1e-6)
    assert PaintWall.grid(thickness=0).board is None
    kinds = [d[0] for d in wall.decorations(wall.init_state())]
    assert kinds.count("box") == 17  # 16 squares + the board


def test_bad_wall_parameters_are_named():
    with pytest.raises(ValueError, match="thickness"):
        PaintWall.grid(thickness=-0.01)
    with pytest.raises(ValueError, match="coordinate axis"):
        PaintWall(np.zeros((1, 3)), normal=(1.0, 1.0, 0.0))
    with pytest.raises(ValueError, match="normal"):
        PaintWall(np.zeros((1, 3)), normal=(0.0, 0.0, 0.0))
