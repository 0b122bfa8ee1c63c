"""dtw / dtw_multi / euclidean against NumPy references and dtw-python."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax.distance import dtw, dtw_multi, euclidean, resample

SHAPES = [(7, 11, 3), (13, 4, 2), (1, 6, 1), (9, 1, 2), (10, 10, 4), (25, 17, 1)]


def _accumulated_np(x, y, cost):
    """Plain double-loop DTW accumulated cost D(N, M) (float64)."""
    n, m = len(x), len(y)
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(n):
        for j in range(m):
            acc[i + 1, j + 1] = cost(x[i], y[j]) + min(
                acc[i, j + 1], acc[i + 1, j], acc[i, j]
            )
    return acc[n, m]


def dtw_np(x, y):
    per_dim = [
        _accumulated_np(x[:, f], y[:, f], lambda a, b: abs(a - b))
        for f in range(x.shape[1])
    ]
    return sum(per_dim) / (len(x) + len(y))


def dtw_multi_np(x, y):
    return _accumulated_np(x, y, lambda a, b: np.linalg.norm(a - b))


def _pair(n, m, f, seed):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(size=(n, f)), axis=0).astype(np.float32)
    y = np.cumsum(rng.normal(size=(m, f)), axis=0).astype(np.float32)
    return x, y


@pytest.mark.parametrize("n,m,f", SHAPES)
def test_dtw_matches_numpy_double_loop(n, m, f):
    x, y = _pair(n, m, f, seed=n * 100 + m)
    ref = dtw_np(x.astype(float), y.astype(float))
    np.testing.assert_allclose(float(dtw(x, y)), ref, rtol=1e-5)


@pytest.mark.parametrize("n,m,f", SHAPES)
def test_dtw_multi_matches_numpy_double_loop(n, m, f):
    x, y = _pair(n, m, f, seed=n * 10 + m)
    ref = dtw_multi_np(x.astype(float), y.astype(float))
    np.testing.assert_allclose(float(dtw_multi(x, y)), ref, rtol=1e-5)


@pytest.mark.parametrize("n,m,f", [(8, 13, 3), (15, 6, 2), (30, 31, 1)])
def test_dtw_matches_dtw_python_symmetric1(n, m, f):
    """dtw-python's symmetric1 step pattern is this recursion; .distance is D(N, M)."""
    dtwpy = pytest.importorskip("dtw")
    x, y = _pair(n, m, f, seed=7 + n)
    xd, yd = x.astype(float), y.astype(float)
    per_dim = [
        dtwpy.dtw(xd[:, k], yd[:, k], step_pattern="symmetric1",
                  dist_method="cityblock").distance
        for k in range(f)
    ]
    np.testing.assert_allclose(float(dtw(x, y)), sum(per_dim) / (n + m), rtol=1e-5)
    multi = dtwpy.dtw(xd, yd, step_pattern="symmetric1", dist_method="euclidean")
    np.testing.assert_allclose(float(dtw_multi(x, y)), multi.distance, rtol=1e-5)


def test_dtw_1d_inputs_equal_single_feature():
    x, y = _pair(9, 5, 1, seed=3)
    assert float(dtw(x[:, 0], y[:, 0])) == pytest.approx(float(dtw(x, y)), rel=1e-6)
    np.testing.assert_allclose(float(dtw(x[:, 0], y[:, 0])), dtw_np(x, y), rtol=1e-5)


@pytest.mark.parametrize("fn", [dtw, dtw_multi, euclidean])
def test_identity_zero_and_symmetry(fn):
    x, y = _pair(12, 19, 3, seed=11)
    assert float(fn(x, x)) == 0.0
    np.testing.assert_allclose(float(fn(x, y)), float(fn(y, x)), rtol=1e-6)
    assert float(fn(x, y)) > 0.0


def test_dtw_time_warped_copy_is_zero():
    # Repeating samples is a valid warping path with zero local cost.
    x = np.sin(np.linspace(0, 3, 20)).astype(np.float32)
    y = np.repeat(x, 2)
    assert float(dtw(x, y)) == 0.0
    assert float(dtw_multi(x, y)) == 0.0


@pytest.mark.parametrize("fn,ref", [(dtw, dtw_np), (dtw_multi, dtw_multi_np)])
def test_dtw_under_jit_and_vmap(fn, ref):
    rng = np.random.default_rng(5)
    cands = rng.normal(size=(6, 14, 3)).astype(np.float32)
    target = rng.normal(size=(9, 3)).astype(np.float32)
    got = jax.jit(jax.vmap(fn, in_axes=(0, None)))(cands, target)
    want = [ref(c.astype(float), target.astype(float)) for c in cands]
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-5)
    # Batched in the second argument too, and both.
    got_y = jax.vmap(fn, in_axes=(None, 0))(target, cands)
    np.testing.assert_allclose(np.asarray(got_y), want, rtol=1e-5)
    got_xy = jax.jit(jax.vmap(fn))(cands, cands[::-1])
    want_xy = [ref(a.astype(float), b.astype(float))
               for a, b in zip(cands, cands[::-1])]
    np.testing.assert_allclose(np.asarray(got_xy), want_xy, rtol=1e-5)


def test_dtw_gradient_is_finite():
    x, y = _pair(10, 8, 2, seed=1)
    for fn in (dtw, dtw_multi):
        g = jax.grad(fn)(jnp.asarray(x), jnp.asarray(y))
        assert g.shape == x.shape
        assert bool(jnp.all(jnp.isfinite(g)))


def euclidean_np(x, y, n):
    t = np.linspace(0, 1, n)

    def res(a):
        ta = np.linspace(0, 1, len(a))
        return np.stack([np.interp(t, ta, a[:, k]) for k in range(a.shape[1])], 1)

    return np.linalg.norm(res(x) - res(y))


@pytest.mark.parametrize("n,m,f,ns", [(7, 11, 3, None), (20, 20, 2, None),
                                      (5, 9, 1, 33), (16, 3, 2, 4)])
def test_euclidean_matches_numpy(n, m, f, ns):
    x, y = _pair(n, m, f, seed=n + m)
    want = euclidean_np(x.astype(float), y.astype(float), ns or max(n, m))
    np.testing.assert_allclose(float(euclidean(x, y, ns)), want, rtol=1e-5)
    got = jax.jit(jax.vmap(lambda a: euclidean(a, y, ns)))(np.stack([x, x + 1]))
    want1 = euclidean_np(x.astype(float) + 1, y.astype(float), ns or max(n, m))
    np.testing.assert_allclose(np.asarray(got), [want, want1], rtol=1e-5)


def test_euclidean_equal_lengths_is_plain_norm():
    x, y = _pair(15, 15, 3, seed=2)
    np.testing.assert_allclose(
        float(euclidean(x, y)), np.linalg.norm(x.astype(float) - y), rtol=1e-6
    )


def test_resample_keeps_ends_and_linear_signals():
    x = np.linspace(0, 1, 7)[:, None] * np.array([[2.0, -3.0]])
    out = np.asarray(resample(x.astype(np.float32), 13))
    np.testing.assert_allclose(out, np.linspace(0, 1, 13)[:, None] * [[2.0, -3.0]],
                               atol=1e-6)


def test_distance_errors():
    x = np.zeros((5, 3), np.float32)
    with pytest.raises(ValueError, match="different feature counts"):
        dtw(x, np.zeros((4, 2), np.float32))
    with pytest.raises(ValueError, match=r"shape \(T,\) or \(T, F\)"):
        dtw_multi(np.zeros((2, 2, 2)), x)
    with pytest.raises(ValueError, match="y is empty"):
        dtw(x, np.zeros((0, 3), np.float32))
    with pytest.raises(ValueError, match="cannot resample"):
        euclidean(x[:1], x)


# --- non-finite inputs (issue 12): eager error, NaN under jit, checked helper -----

DISTANCES = [dtw, dtw_multi, euclidean]


@pytest.mark.parametrize("fn", DISTANCES, ids=lambda f: f.__name__)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_eager_error_names_input_and_index(fn, bad):
    x, y = _pair(6, 5, 2, seed=3)
    xb = x.copy()
    xb[4, 1] = bad
    with pytest.raises(ValueError, match=rf"{fn.__name__}: input 'x' has a "
                       rf"non-finite value -?{bad} at index \[4, 1\]"):
        fn(xb, y)
    y1 = y[:, 0].copy()
    y1[2] = bad  # a 1-D input: the index is in the caller's shape
    with pytest.raises(ValueError, match=r"input 'y' .* at index \[2\]"):
        fn(x[:, 0], y1)


@pytest.mark.parametrize("fn", DISTANCES, ids=lambda f: f.__name__)
def test_non_finite_input_under_jit_and_vmap_is_nan(fn):
    x, y = _pair(6, 5, 2, seed=4)
    good = float(fn(x, y))
    jfn = jax.jit(fn)
    for bad in (np.nan, np.inf, -np.inf):
        xb, yb = x.copy(), y.copy()
        xb[0, 0], yb[3, 1] = bad, bad
        assert np.isnan(float(jfn(xb, y))) and np.isnan(float(jfn(x, yb)))
    batch = np.stack([x, xb, x])
    got = np.asarray(jax.jit(jax.vmap(fn, in_axes=(0, None)))(batch, y))
    assert np.isnan(got[1])
    np.testing.assert_allclose(got[[0, 2]], good, rtol=1e-6)
    # the jitted kernel holds no host callback: the hot path never syncs
    assert "callback" not in str(jax.make_jaxpr(fn)(x, y))


def test_checked_distance_names_the_input_and_the_batch_index():
    from cgda_jax.checks import checked

    x, y = _pair(6, 5, 2, seed=5)
    xb = np.stack([x, x, x])
    xb[2, 3, 0] = np.nan
    batched = checked(jax.vmap(dtw, in_axes=(0, None)))
    with pytest.raises(ValueError, match=r"dtw: input 'x' has a non-finite value nan "
                       r"at index \[2, 3, 0\]"):
        batched(xb, y)
    np.testing.assert_allclose(np.asarray(batched(np.stack([x, x, x]), y)),
                               float(dtw(x, y)), rtol=1e-6)
    eucl = checked(euclidean, static_argnames=("n_samples",))
    y_inf = y.copy()
    y_inf[1, 1] = np.inf
    with pytest.raises(ValueError, match=r"euclidean: input 'y' .* at index \[1, 1\]"):
        eucl(x, y_inf, n_samples=8)
    np.testing.assert_allclose(float(eucl(x, y, n_samples=8)),
                               float(euclidean(x, y, 8)), rtol=1e-6)


# --- every finite float32 input (issue 25): exact, or refused by name -------------

MAGNITUDES = [1e-30, 1e-20, 1e-3, 1e19, 1e30, 1e31, 1e36]


@pytest.mark.parametrize("scale", MAGNITUDES)
def test_distances_are_exact_at_every_finite_magnitude(scale):
    """The border value (1e30) used to be below the costs of large inputs: s = 1e31
    gave wrong distances; squares overflowed from 1e19 and vanished below 1e-19."""
    x, y = _pair(9, 7, 3, seed=11)
    x, y = (x * np.float32(scale)), (y * np.float32(scale))
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(y))
    x64, y64 = x.astype(float), y.astype(float)
    for fn, ref in ((dtw, dtw_np(x64, y64)), (dtw_multi, dtw_multi_np(x64, y64)),
                    (euclidean, euclidean_np(x64, y64, 9))):
        np.testing.assert_allclose(float(fn(x, y)), ref, rtol=1e-5,
                                   err_msg=f"{fn.__name__} at {scale:g}")
        np.testing.assert_allclose(float(jax.jit(fn)(x, y)), ref, rtol=1e-5)


def test_features_of_very_different_magnitudes_are_each_exact():
    # dtw scales each feature apart: a 1e-20 feature beside a 1e30 one still counts
    x = np.array([[1e30, 0.0], [2e30, 1e-20], [1e30, 3e-20]], np.float32)
    y = np.array([[1e30, 1e-20], [2e30, 0.0]], np.float32)
    ref = dtw_np(x.astype(float), y.astype(float))
    np.testing.assert_allclose(float(dtw(x, y)), ref, rtol=1e-5)
    per_feature = [dtw_np(x[:, [f]].astype(float), y[:, [f]].astype(float))
                   for f in range(2)]
    assert per_feature[1] > 0  # the small feature's share is kept, not lost
    np.testing.assert_allclose(float(dtw(x[:, 1], y[:, 1])), per_feature[1], rtol=1e-5)


@pytest.mark.parametrize("fn", [dtw, dtw_multi, euclidean], ids=lambda f: f.__name__)
def test_largest_float32_inputs_are_exact_or_refused_by_name(fn):
    big = np.float32(3e38)
    x, y = np.full((4, 1), big), np.full((3, 1), -big)
    ref = {dtw: dtw_np, dtw_multi: dtw_multi_np}.get(fn)
    ref = ref(x.astype(float), y.astype(float)) if ref else euclidean_np(
        x.astype(float), y.astype(float), 4)
    if ref <= np.finfo(np.float32).max:  # dtw: 6e38 per cell / (N + M) fits
        np.testing.assert_allclose(float(fn(x, y)), ref, rtol=1e-5)
        return
    with pytest.raises(ValueError, match=rf"{fn.__name__}: the distance of 'x' and "
                       r"'y' is beyond the float32 range"):
        fn(x, y)
    assert float(jax.jit(fn)(x, y)) == np.inf  # traced: inf, never a wrong number


def test_dtw_of_the_largest_inputs_fits_after_normalisation():
    x = np.full((5, 2), np.float32(3e38))
    y = np.full((5, 2), np.float32(-3e38))
    # per cell 6e38 (beyond float32), D / (N + M) = 3e38 per feature: the sum of two
    # features (6e38) no longer fits and is refused
    with pytest.raises(ValueError, match="dtw: the distance .* beyond the float32"):
        dtw(x, y)
    np.testing.assert_allclose(float(dtw(x[:, 0], y[:, 0])), 3e38, rtol=1e-5)


def test_scaled_distances_keep_their_gradient():
    x, y = _pair(8, 6, 2, seed=12)
    for scale in (1e-20, 1.0, 1e30):
        for fn in (dtw, dtw_multi):
            g = np.asarray(jax.grad(fn)(jnp.asarray(x * scale), jnp.asarray(y * scale)))
            g1 = np.asarray(jax.grad(fn)(jnp.asarray(x), jnp.asarray(y)))
            np.testing.assert_allclose(g, g1, rtol=1e-5, atol=1e-6)  # homogeneous
