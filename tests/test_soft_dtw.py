"""Soft-DTW: a NumPy double-loop reference, its gamma -> 0 limit, its gradient."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import dtw, dtw_multi, soft_dtw


def _softmin(a, b, c, gamma):
    v = np.array([a, b, c], dtype=np.float64)
    m = v.min()
    if not np.isfinite(m):
        return np.inf
    return m - gamma * np.log(np.sum(np.exp(-(v - m) / gamma)))


def _reference(x, y, gamma, multi):
    """Soft-DTW by the textbook double loop (Cuturi & Blondel 2017, Algorithm 1)."""
    x = np.asarray(x, np.float64).reshape(len(x), -1)
    y = np.asarray(y, np.float64).reshape(len(y), -1)

    def one(cost):
        n, m = cost.shape
        r = np.full((n + 1, m + 1), np.inf)
        r[0, 0] = 0.0
        for i in range(1, n + 1):
            for j in range(1, m + 1):
                r[i, j] = cost[i - 1, j - 1] + _softmin(
                    r[i - 1, j], r[i, j - 1], r[i - 1, j - 1], gamma)
        return r[n, m]

    if multi:
        return one(np.linalg.norm(x[:, None] - y[None], axis=-1))
    total = sum(one(np.abs(x[:, None, f] - y[None, :, f])) for f in range(x.shape[1]))
    return total / (len(x) + len(y))


@pytest.fixture
def pair():
    rng = np.random.default_rng(0)
    return rng.normal(size=(7, 3)), rng.normal(size=(5, 3))


@pytest.mark.parametrize("multi", [False, True])
@pytest.mark.parametrize("gamma", [0.05, 0.5, 2.0])
def test_matches_the_double_loop_reference(pair, multi, gamma):
    x, y = pair
    got = float(soft_dtw(jnp.asarray(x), jnp.asarray(y), gamma, multi=multi))
    assert got == pytest.approx(_reference(x, y, gamma, multi), rel=1e-5, abs=1e-5)


def test_one_dimensional_and_unequal_lengths():
    x = np.array([0.0, 1.0, 3.0, 2.0])
    y = np.array([0.5, 2.5])
    got = float(soft_dtw(jnp.asarray(x), jnp.asarray(y), 0.3))
    assert got == pytest.approx(_reference(x, y, 0.3, False), rel=1e-5)


@pytest.mark.parametrize("multi, hard", [(False, dtw), (True, dtw_multi)])
def test_tends_to_dtw_as_gamma_goes_to_zero(pair, multi, hard):
    x, y = (jnp.asarray(a) for a in pair)
    want = float(hard(x, y))
    gaps = [want - float(soft_dtw(x, y, g, multi=multi)) for g in (1.0, 0.1, 1e-3)]
    # never above the hard DTW, and the gap shrinks with gamma towards 0
    assert all(g >= -1e-5 for g in gaps)
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] < 1e-3 * max(1.0, want)


def test_gradient_matches_finite_differences(pair):
    x, y = (np.asarray(a, np.float64) for a in pair)
    with jax.enable_x64(True):
        for multi in (False, True):
            f = jax.jit(lambda a, m=multi: soft_dtw(a, jnp.asarray(y), 0.1, multi=m))
            grad = np.asarray(jax.grad(f)(jnp.asarray(x)))
            eps = 1e-6
            steps = np.eye(x.size).reshape(x.size, *x.shape) * eps
            plus = jax.vmap(f)(jnp.asarray(x + steps))
            minus = jax.vmap(f)(jnp.asarray(x - steps))
            num = np.asarray((plus - minus) / (2 * eps)).reshape(x.shape)
            np.testing.assert_allclose(grad, num, rtol=1e-5, atol=1e-7)


def test_gradient_is_finite_on_identical_trajectories():
    x = jnp.asarray(np.linspace(0, 1, 12).reshape(4, 3))
    for multi in (False, True):
        g = jax.grad(lambda a, m=multi: soft_dtw(a, x, 0.01, multi=m))(x)
        assert np.all(np.isfinite(np.asarray(g)))


def test_bad_input_is_refused_like_dtw():
    x = np.zeros((4, 2))
    bad = x.copy()
    bad[2, 1] = np.nan
    msg = r"soft_dtw: input 'y' has a non-finite value nan at index \[2, 1\]"
    with pytest.raises(ValueError, match=msg):
        soft_dtw(x, bad)
    with pytest.raises(ValueError, match="feature counts"):
        soft_dtw(x, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="gamma must be a float32 number > 0"):
        soft_dtw(x, x, 0.0)
    with pytest.raises(ValueError, match="shape"):
        soft_dtw(np.zeros((2, 2, 2)), x)
    # traced: NaN, no error
    out = jax.jit(soft_dtw)(jnp.asarray(x), jnp.asarray(bad))
    assert np.isnan(float(out))
