"""generalize / GeneralizedAction / rbf_interpolate."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax.data import Demonstration, load_xgnitive
from cgda_jax.generalization import GeneralizedAction, generalize, rbf_interpolate


def curve(s):
    """A 2-feature reference curve of normalized time s in [0, 1]."""
    s = np.asarray(s)
    return np.stack([np.sin(2 * np.pi * s), 3 * s**2 - 1], axis=-1)


def test_rbf_passes_through_knots_and_matches_scipy():
    interp = pytest.importorskip("scipy.interpolate")
    rng = np.random.default_rng(0)
    kt = np.sort(rng.uniform(0, 1, 9))
    kv = rng.normal(size=(9, 2))
    at_knots = np.asarray(jax.jit(rbf_interpolate)(kt, kv, kt))
    np.testing.assert_allclose(at_knots, kv, atol=1e-6)
    tq = np.linspace(-0.3, 1.3, 77)
    got = np.asarray(rbf_interpolate(kt, kv, tq))
    for f in range(2):
        want = interp.Rbf(kt, kv[:, f], function="linear")(tq)
        np.testing.assert_allclose(got[:, f], want, atol=1e-4, rtol=1e-4)


def test_generalized_action_weights_solve_paper_system():
    t = np.linspace(0, 10, 201)
    demo = Demonstration(t, curve(t / 10), ("a", "b"))
    g = generalize([demo], interval_s=1.0)
    kt = np.asarray(g.knot_times, float)
    phi = np.abs(kt[:, None] - kt[None, :])
    np.testing.assert_allclose(phi @ np.asarray(g.weights), np.asarray(g.knots),
                               atol=1e-4)
    # Evaluation equals the explicit weighted sum of eq. 1.
    tq = np.linspace(0, 1, 31)
    explicit = np.abs(tq[:, None] - kt[None, :]) @ np.asarray(g.weights, float)
    np.testing.assert_allclose(np.asarray(g(tq)), explicit, atol=1e-4)
    np.testing.assert_allclose(np.asarray(g(g.knot_times)), np.asarray(g.knots),
                               atol=1e-6)


def test_paper_binning_matches_numpy_loop():
    rng = np.random.default_rng(1)
    demos = []
    for k, dur in enumerate([9.3, 10.4, 11.1]):
        t = np.sort(rng.uniform(0, dur, 60))
        t[0], t[-1] = 0.0, dur
        demos.append(Demonstration(t + 5 * k, rng.normal(size=(60, 2)), ("a", "b"),
                                   f"d{k}"))
    g = generalize(demos, interval_s=2.0)
    n = round(np.mean([9.3, 10.4, 11.1]) / 2.0)
    assert g.n_knots == n
    ts = np.concatenate([d.normalized_times for d in demos])
    xs = np.concatenate([d.features for d in demos])
    for k in range(n):
        hi = (k + 1) / n
        inside = (ts >= k / n) & ((ts < hi) if k < n - 1 else (ts <= 1))
        np.testing.assert_allclose(np.asarray(g.knots[k]), xs[inside].mean(0),
                                   rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.asarray(g.knot_times), (np.arange(n) + 0.5) / n,
                               atol=1e-7)


def test_shifted_and_time_warped_copies_recover_the_curve():
    rng = np.random.default_rng(2)
    demos = []
    for k, (dur, start) in enumerate([(18.0, 0.0), (22.0, 100.0), (20.0, -7.5)]):
        s = np.linspace(0, 1, 400) ** (1.0 + 0.1 * (k - 1))  # mild time warp
        s_warped = np.linspace(0, 1, 400)
        feats = curve(s) + 0.002 * rng.normal(size=(400, 2))
        demos.append(Demonstration(start + dur * s_warped, feats, ("a", "b"), f"r{k}"))
    g = generalize(demos, interval_s=0.5)
    tq = np.linspace(0.05, 0.95, 50)
    # A piecewise-linear fit of a smooth curve: error bounded by the interval size
    # and the warp; three warps of +-10 % average out to the middle one.
    np.testing.assert_allclose(np.asarray(g(tq)), curve(tq), atol=0.03)


def test_copies_shifted_in_time_give_the_same_knots():
    t = np.linspace(0, 5, 501)
    d = Demonstration(t, curve(t / 5), ("a", "b"), "d")
    shifted = Demonstration(t + 1234.5, d.features, ("a", "b"), "shifted")
    g1 = generalize([d], interval_s=0.5)
    g2 = generalize([d, shifted, d], interval_s=0.5)
    assert g1.n_knots == 10
    np.testing.assert_allclose(np.asarray(g2.knots), np.asarray(g1.knots), atol=1e-6)


def test_generalized_action_is_a_jittable_pytree():
    t = np.linspace(0, 6, 61)
    g = generalize([Demonstration(t, curve(t / 6), ("a", "b"))], interval_s=1.0)
    leaves = jax.tree_util.tree_leaves(g)
    assert len(leaves) == 3
    out = jax.jit(lambda a, tt: a(tt))(g, jnp.linspace(0, 1, 7))
    assert out.shape == (7, 2)
    s = jax.jit(lambda a: a.sample(11))(g)
    np.testing.assert_allclose(np.asarray(s), np.asarray(g(jnp.linspace(0, 1, 11))),
                               atol=1e-7)
    assert g.feature_names == ("a", "b")
    assert isinstance(jax.tree_util.tree_map(lambda x: x, g), GeneralizedAction)


def test_generalize_errors():
    t = np.linspace(0, 3, 4)
    d = Demonstration(t, t[:, None], ("a",), "short")
    with pytest.raises(ValueError, match="need at least 2"):
        generalize([d], interval_s=5.0)
    with pytest.raises(ValueError, match=r"interval 1 of 3 .* holds no samples"):
        sparse = Demonstration(np.array([0.0, 0.1, 2.9, 3.0]), np.zeros(4), ("a",))
        generalize([sparse], interval_s=1.0)
    with pytest.raises(ValueError, match="interval_s must be a positive"):
        generalize([d], interval_s=0.0)
    with pytest.raises(ValueError, match="unknown method"):
        generalize([d], method="spline")
    with pytest.raises(ValueError, match="no demonstrations"):
        generalize([])
    other = Demonstration(t, t[:, None], ("b",), "other")
    with pytest.raises(ValueError, match="'other' has feature names"):
        generalize([d, other])
    with pytest.raises(ValueError, match="need N >= 2 knots"):
        rbf_interpolate(np.array([0.5]), np.array([[1.0]]), np.array([0.1]))


@pytest.mark.parametrize(
    "action,stream,columns,interval,saved",
    [
        ("paint", "paintSquaresOnScreen", ["percent"], 10,
         "percentage-painted-centers.txt"),
        ("iron", "teo/rightArm", ["X", "Y", "Z", "ax", "ay", "az", "angle"], 3,
         "rightArm-centers.txt"),
        ("iron", "jr3", ["Fx", "Fy", "Fz"], 3, "jr3-centers.txt"),
    ],
)
def test_xgnitive_method_reproduces_authors_results(
    xgnitive_dir, action, stream, columns, interval, saved
):
    demos = load_xgnitive(xgnitive_dir, action, stream, columns)
    assert len(demos) == 4
    g = generalize(demos, interval_s=interval, method="xgnitive")
    want = np.loadtxt(xgnitive_dir / "xgnitive_derived/generalization_results" / saved)
    want = want.reshape(len(want), -1)
    shape = (13, 1) if action == "paint" else (9, len(columns))
    assert g.knots.shape == want.shape == shape
    np.testing.assert_allclose(np.asarray(g.knots), want, atol=1e-5, rtol=0)
    np.testing.assert_allclose(np.asarray(g.knot_times), np.linspace(0, 1, len(want)))
    # The paper method bins differently, so it must NOT reproduce them exactly.
    gp = generalize(demos, interval_s=interval)
    assert not np.allclose(np.asarray(gp.knots)[: len(want)], want, atol=1e-5)


# --- knot-time and float32 guards (issue 12) --------------------------------------


def test_rbf_unsorted_knot_times_are_sorted_with_their_knots():
    from cgda_jax.generalization import rbf_weights

    rng = np.random.default_rng(3)
    kt = np.sort(rng.uniform(0, 1, 6)).astype(np.float32)
    knots = rng.normal(size=(6, 2)).astype(np.float32)
    t = np.linspace(-0.2, 1.2, 15, dtype=np.float32)
    want = np.asarray(rbf_interpolate(kt, knots, t))
    perm = np.array([3, 0, 5, 1, 4, 2])
    np.testing.assert_allclose(
        np.asarray(rbf_interpolate(kt[perm], knots[perm], t)), want, atol=1e-5
    )
    np.testing.assert_allclose(
        np.asarray(jax.jit(rbf_interpolate)(kt[perm], knots[perm], t)), want, atol=1e-5
    )
    # the weights are the same system, row-permuted
    np.testing.assert_allclose(np.asarray(rbf_weights(kt[perm], knots[perm])),
                               np.asarray(rbf_weights(kt, knots))[perm], rtol=1e-4)


def test_rbf_repeated_or_non_finite_knot_times_are_refused():
    from cgda_jax.generalization import rbf_weights

    kt = np.array([0.0, 0.7, 0.3, 0.7], np.float32)
    knots = np.arange(8.0, dtype=np.float32).reshape(4, 2)
    t = np.linspace(0, 1, 5, dtype=np.float32)
    msg = r"knot_times\[1\] and knot_times\[3\] are both 0\.7 .*must be distinct"
    with pytest.raises(ValueError, match="rbf_interpolate: " + msg):
        rbf_interpolate(kt, knots, t)
    with pytest.raises(ValueError, match="rbf_weights: " + msg):
        rbf_weights(kt, knots)
    # equal only once cast to the knots' float32
    with pytest.raises(ValueError, match=r"knot_times\[0\] and knot_times\[1\]"):
        rbf_interpolate(np.array([0.1, 0.1 + 1e-12, 0.5]), knots[:3], t)
    assert np.isnan(np.asarray(jax.jit(rbf_interpolate)(kt, knots, t))).all()
    assert np.isnan(np.asarray(jax.jit(rbf_weights)(kt, knots))).all()
    with pytest.raises(ValueError, match=r"input 'knot_times' has a non-finite value "
                       r"nan at index \[2\]"):
        rbf_interpolate(np.array([0.0, 1.0, np.nan]), knots[:3], t)
    inf_knot = knots[:3].copy()
    inf_knot[1, 0] = np.inf
    with pytest.raises(ValueError, match=r"input 'knots' .* inf at index \[1, 0\]"):
        rbf_interpolate(kt[:3], inf_knot, t)
    with pytest.raises(ValueError, match=r"input 't' .* nan at index \[4\]"):
        rbf_interpolate(kt[:3], knots[:3], np.append(t[:4], np.nan))


def test_generalize_refuses_results_beyond_float32_naming_the_feature():
    t = np.linspace(0, 4, 41)
    # +/-3e38 alternating every half second: each value fits float32, but the RBF
    # weights (slope changes) do not
    wild = np.where((t * 2).astype(int) % 2 == 0, 3e38, -3e38)
    d = Demonstration(t, np.stack([np.sin(t), wild], 1), ("calm", "wild"))
    with pytest.raises(ValueError, match=r"generalize: RBF weight \d+ of feature 1 "
                       r"\('wild'\) is -?[\d.]+e\+39, beyond float32's range"):
        generalize([d], interval_s=0.5)
    g = generalize([d.select(["calm"])], interval_s=0.5)
    assert np.isfinite(np.asarray(g.knots)).all()
