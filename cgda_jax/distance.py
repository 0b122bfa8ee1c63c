"""Distances between two feature trajectories: DTW and Euclidean (paper eq. 3-7).

Every function takes ONE pair of trajectories; batch with ``jax.vmap`` at the call
site, e.g. ``jax.vmap(dtw, in_axes=(0, None))(candidates, reference)``.

DTW is computed by a ``lax.scan`` over the anti-diagonals of the accumulated-cost
matrix: diagonal ``d`` holds the cells ``(i, d - i)``, which depend only on the two
previous diagonals, so each scan step is one vectorised update of length ``N``. The
local costs of a diagonal are computed inside the step from ``x`` and a reversed,
padded copy of ``y`` (a contiguous ``dynamic_slice``), so the ``N x M`` cost matrix is
never materialised.

Every finite input, however large or small: each function scales its inputs by a
power of two (exact) so that their largest magnitude is in [1, 2) (`dtw`: per
feature, the others: per pair), computes there, and scales the result back. So no
local cost, square or accumulated cost overflows while the distance itself fits the
dtype, the "unreachable" border value is always above every reachable cost, and tiny
inputs (1e-30) do not vanish in their squares. A distance beyond the dtype's range
(``dtw_multi`` of two float32 trajectories 3e38 apart) is refused by an eager call
(``ValueError`` naming the function) and is ``inf`` under ``jit``. Two bounds
remain, both far below float32's own rounding of the inputs: values below the
smallest normal number (1.2e-38 in float32) count as 0 (XLA on a CPU flushes them),
and a value more than 2**126 times smaller than the largest of its feature (`dtw`)
or pair (the others) counts as 0; either changes a result by at most
``(N + M) * sqrt(F) * 2**-124 * max|x|, |y|``. Float16 / bfloat16 inputs are computed
in float32.

Non-finite inputs: an eager call with a NaN or an infinity in ``x`` or ``y`` raises
``ValueError`` naming the input and the index of the bad value; a traced call (under
``jit``, ``vmap``, ``scan``) returns NaN instead, without a host sync.  Wrap a jitted
distance with `cgda_jax.checks.checked` (or `cgda_jax.checks.checkified`) to learn
which input was bad.

References:
    Morante et al., "Humanoid Robot Imitation through Continuous Goal-Directed
    Actions: An Evolutionary Approach", Advanced Robotics 2015, section 2.2.
    Sakoe & Chiba, "Dynamic programming algorithm optimization for spoken word
    recognition", IEEE TASSP 1978.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from cgda_jax.checks import check_finite, is_traced
from cgda_jax.sizes import check_elements

__all__ = ["dtw", "dtw_multi", "dtw_per_feature", "euclidean", "point_sum", "resample",
           "soft_dtw"]

# A large finite value for "unreachable" cells: inf would turn into NaN under grad.
# The inputs are scaled to magnitudes below 2 first (`_scale_exponents`), so every
# reachable accumulated cost is below 4 * sqrt(F) * (N + M), far below it.
_BIG = 1e30


def _as_2d(x: jax.Array, name: str) -> jax.Array:
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.float32)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2:
        raise ValueError(f"{name} must have shape (T,) or (T, F), got {x.shape}")
    if x.shape[0] < 1:
        raise ValueError(f"{name} is empty (shape {x.shape})")
    return x


def _pair(
    x: jax.Array, y: jax.Array, where: str
) -> tuple[jax.Array, jax.Array]:
    check_finite(x, "x", where=where)  # eager calls only: a no-op on tracers
    check_finite(y, "y", where=where)
    x, y = _as_2d(x, "x"), _as_2d(y, "y")
    if x.shape[1] != y.shape[1]:
        raise ValueError(
            f"x and y have different feature counts: x {x.shape}, y {y.shape}"
        )
    dtype = jnp.result_type(x, y, jnp.float32)  # float16 / bfloat16 in float32
    return x.astype(dtype), y.astype(dtype)


def _pow2(e: jax.Array, dtype) -> jax.Array:
    """``2.0 ** e`` exactly, built from its bits (``e`` inside the dtype's normal
    exponent range)."""
    info = jnp.finfo(dtype)
    bias = int(info.maxexp) - 1
    int_t = jnp.int64 if jnp.dtype(dtype).itemsize == 8 else jnp.int32
    bits = (e.astype(int_t) + bias) << int(info.nmant)
    return jax.lax.bitcast_convert_type(bits, dtype)


def _times_pow2(v: jax.Array, k: jax.Array) -> jax.Array:
    """``v * 2**k`` exactly (but for over- / underflow of the result), in two
    factors so that each is a normal number of the dtype."""
    half = k // 2
    return v * _pow2(half, v.dtype) * _pow2(k - half, v.dtype)


def _scale_exponents(x: jax.Array, y: jax.Array, per_feature: bool) -> jax.Array:
    """``k`` with ``max(|x|, |y|) / 2**k`` in [1, 2) (0 for all-zero inputs), per
    feature (F,) or for the pair (); no gradient flows through it."""
    axis = 0 if per_feature else None
    top = jnp.maximum(jnp.max(jnp.abs(x), axis=axis), jnp.max(jnp.abs(y), axis=axis))
    _, e = jnp.frexp(jax.lax.stop_gradient(top))  # top = f * 2**e, f in [0.5, 1)
    return jnp.where(top > 0, e - 1, 0)


def _refuse_overflow(value: jax.Array, where: str) -> jax.Array:
    """An eager call whose (finite) inputs give a distance beyond the dtype's range
    is refused; under ``jit`` it stays ``inf``."""
    if not is_traced(value) and not bool(jnp.all(jnp.isfinite(value))):
        top = float(jnp.finfo(value.dtype).max)
        raise ValueError(
            f"{where}: the distance of 'x' and 'y' is beyond the {value.dtype} range "
            f"(larger than {top:.3g}); scale both trajectories down")
    return value


def _nan_unless_finite(value: jax.Array, x: jax.Array, y: jax.Array) -> jax.Array:
    """``value``, or NaN where ``x`` or ``y`` holds a NaN or an infinity (traced
    calls; eager ones were refused by `_pair`)."""
    ok = jnp.all(jnp.isfinite(x)) & jnp.all(jnp.isfinite(y))
    return jnp.where(ok, value, jnp.asarray(jnp.nan, value.dtype))


def _accumulated_cost(
    x: jax.Array,
    y: jax.Array,
    local_cost: Callable[[jax.Array, jax.Array], jax.Array],
    combine: Callable[[jax.Array, jax.Array, jax.Array], jax.Array] | None = None,
    ends: tuple[jax.Array, jax.Array] | None = None,
) -> jax.Array:
    """Final cell D(N-1, M-1) of the DTW accumulated-cost matrix.

    Args:
        x: (N, F) first trajectory.
        y: (M, F) second trajectory.
        local_cost: maps time-last aligned samples ``x[i]``, ``y[d - i]`` of shape
            (F, N) to the local costs of those cells, shape (*C, N) (``C`` = extra
            cost dims kept separate, e.g. one DTW per feature).
        combine: how a cell combines its three predecessors ``D(i-1, j)``,
            ``D(i, j-1)``, ``D(i-1, j-1)``; default their minimum (soft-DTW: a
            soft minimum).
        ends: valid lengths ``(n, m)`` (traced ints, ``1 <= n <= N``,
            ``1 <= m <= M``) of end-padded inputs: the result is then the cell
            D(n-1, m-1), which depends on ``x[:n]`` and ``y[:m]`` only.

    Returns:
        (*C,) accumulated cost of the optimal warping path.
    """
    n, m = x.shape[0], y.shape[0]
    # Time-last layout keeps the long axis contiguous (F is often tiny).
    xt = x.T
    # y reversed and padded by n on both sides: y[d - i] for i = 0..n-1 is the
    # contiguous slice y_pad[:, n + m - 1 - d : n + m - 1 - d + n].
    y_pad = jnp.pad(y[::-1].T, ((0, 0), (n, n)))
    rows = jnp.arange(n)
    cost_shape = local_cost(xt[:, :1], y_pad[:, :1]).shape[:-1]
    big = jnp.asarray(_BIG, x.dtype)
    # Diagonals carry one extra leading slot for the border row i = -1.
    border = jnp.full((*cost_shape, 1), big)
    prev2 = jnp.full((*cost_shape, n + 1), big).at[..., 0].set(0.0)  # d = -2
    prev1 = jnp.full((*cost_shape, n + 1), big)  # d = -1

    # the end cell (n-1, m-1) lies on diagonal n + m - 2, in slot n
    end_d, end_slot = (n + m - 2, n) if ends is None else (ends[0] + ends[1] - 2,
                                                           ends[0])

    def step(carry, d):
        prev2, prev1, found = carry
        y_diag = jax.lax.dynamic_slice_in_dim(y_pad, n + m - 1 - d, n, axis=1)
        c = local_cost(xt, y_diag)
        j = d - rows
        valid = (j >= 0) & (j < m)
        if combine is None:
            best = jnp.minimum(
                jnp.minimum(prev1[..., :-1], prev1[..., 1:]), prev2[..., :-1]
            )
        else:
            best = combine(prev1[..., :-1], prev1[..., 1:], prev2[..., :-1])
        new = jnp.concatenate([border, jnp.where(valid, c + best, big)], axis=-1)
        if ends is not None:
            at_end = jax.lax.dynamic_index_in_dim(new, end_slot, -1, keepdims=False)
            found = jnp.where(d == end_d, at_end, found)
        return (prev1, new, found), None

    found = jnp.zeros(cost_shape, x.dtype)
    (_, last, found), _ = jax.lax.scan(
        step, (prev2, prev1, found), jnp.arange(n + m - 1))
    return last[..., n] if ends is None else found


def _abs_cost(xd: jax.Array, yd: jax.Array) -> jax.Array:
    return jnp.abs(xd - yd)


def _euclid_cost(xd: jax.Array, yd: jax.Array) -> jax.Array:
    return jnp.sqrt(jnp.sum((xd - yd) ** 2, axis=0))


def _safe_euclid_cost(xd: jax.Array, yd: jax.Array) -> jax.Array:
    """`_euclid_cost` with a finite gradient (0) where the two samples coincide."""
    sq = jnp.sum((xd - yd) ** 2, axis=0)
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def _soft_min(gamma: float | jax.Array) -> Callable[[jax.Array, jax.Array, jax.Array], jax.Array]:
    """``-gamma log(exp(-a/gamma) + exp(-b/gamma) + exp(-c/gamma))``, shifted by the
    hard minimum so that it stays finite (and its gradient too) when some or all of
    the three are the "unreachable" value."""

    def combine(a, b, c):
        m = jnp.minimum(jnp.minimum(a, b), c)
        z = (jnp.exp(-(a - m) / gamma) + jnp.exp(-(b - m) / gamma)
             + jnp.exp(-(c - m) / gamma))
        return m - gamma * jnp.log(z)

    return combine


def dtw(x: jax.Array, y: jax.Array) -> jax.Array:
    """Per-dimension DTW score of the paper (eq. 5-6).

    For each feature separately: local cost ``|x_i - y_j|``, accumulated cost
    ``D(i, j) = c(i, j) + min(D(i-1, j), D(i, j-1), D(i-1, j-1))``, normalised cost
    ``D(N, M) / (N + M)``; the score is the sum over features.

    Args:
        x: (N, F) or (N,) first trajectory.
        y: (M, F) or (M,) second trajectory (same F, any M).

    Returns:
        Scalar score (0 for identical trajectories); NaN under ``jit`` / ``vmap`` if
        ``x`` or ``y`` holds a NaN or an infinity.

    Raises:
        ValueError: bad shapes, or (eager calls) a NaN or an infinity in ``x`` or
            ``y`` (the message names the input and the index), or a distance beyond
            the dtype's range (under ``jit``: ``inf``).

    Examples:
        >>> import jax.numpy as jnp
        >>> float(dtw(jnp.array([0.0, 1.0, 2.0]), jnp.array([0.0, 1.0, 1.0, 2.0])))
        0.0
    """
    x, y = _pair(x, y, "dtw")
    per_dim = _per_feature(x, y, None)
    return _refuse_overflow(_nan_unless_finite(jnp.sum(per_dim), x, y), "dtw")


def _per_feature(
    x: jax.Array, y: jax.Array, ends: tuple[jax.Array, jax.Array] | None
) -> jax.Array:
    """(F,) normalised DTW cost of each feature of the prepared pair."""
    k = _scale_exponents(x, y, per_feature=True)
    per_dim = _accumulated_cost(
        _times_pow2(x, -k), _times_pow2(y, -k), _abs_cost, ends=ends)
    total = (x.shape[0] + y.shape[0]) if ends is None else (ends[0] + ends[1])
    return _times_pow2(per_dim / jnp.asarray(total, per_dim.dtype), k)


def _length(length: int | jax.Array | None, full: int, name: str) -> jax.Array:
    """A valid length as an int32 array, checked where it is concrete."""
    if length is None:
        return jnp.asarray(full, jnp.int32)
    if not is_traced(length):
        value = int(length)
        if not 1 <= value <= full:
            raise ValueError(
                f"dtw_per_feature: {name} must be in [1, {full}], got {value}")
    return jnp.asarray(length, jnp.int32)


def dtw_per_feature(
    x: jax.Array,
    y: jax.Array,
    x_length: int | jax.Array | None = None,
    y_length: int | jax.Array | None = None,
) -> jax.Array:
    """The per-feature terms of `dtw`, for end-padded trajectories too.

    Feature ``f`` gives the 1-D DTW of ``x[:n, f]`` and ``y[:m, f]`` with local
    cost ``|x_i - y_j|``, normalised by ``n + m``; `dtw` is their sum. With the
    valid lengths ``n = x_length`` and ``m = y_length`` (traced values allowed),
    trajectories of different lengths padded to one shape share one compiled
    program, so ``jax.vmap`` batches them (the padding is never read, but must be
    finite: pad with zeros or the last sample).

    Args:
        x: (N, F) or (N,) first trajectory (padded after sample ``n``).
        y: (M, F) or (M,) second trajectory (same F).
        x_length: valid samples of ``x``, in [1, N]; default N.
        y_length: valid samples of ``y``, in [1, M]; default M.

    Returns:
        (F,) costs; NaN under ``jit`` / ``vmap`` if ``x`` or ``y`` holds a NaN or
        an infinity.

    Raises:
        ValueError: as `dtw`, or a concrete length outside its range.

    Examples:
        >>> import jax.numpy as jnp
        >>> x = jnp.array([[0.0, 1.0], [2.0, 1.0], [9.0, 9.0]])  # 1 padding row
        >>> dtw_per_feature(x, jnp.array([[0.0, 1.0], [2.0, 2.0]]), x_length=2)
        Array([0.  , 0.25], dtype=float32)
    """
    x, y = _pair(x, y, "dtw_per_feature")
    ends = (_length(x_length, x.shape[0], "x_length"),
            _length(y_length, y.shape[0], "y_length"))
    per_dim = _per_feature(x, y, ends)
    value = _refuse_overflow(_nan_unless_finite(per_dim, x, y), "dtw_per_feature")
    return value


def dtw_multi(x: jax.Array, y: jax.Array) -> jax.Array:
    """Multi-dimensional DTW: Euclidean local cost over the feature vector.

    This is the variant the CGDA authors' C++ execution code used as fitness:
    ``c(i, j) = ||x_i - y_j||_2`` and the unnormalised accumulated cost ``D(N, M)``.

    Args:
        x: (N, F) or (N,) first trajectory.
        y: (M, F) or (M,) second trajectory.

    Returns:
        Scalar accumulated cost; NaN under ``jit`` / ``vmap`` for non-finite input.

    Raises:
        ValueError: as `dtw`.
    """
    x, y = _pair(x, y, "dtw_multi")
    k = _scale_exponents(x, y, per_feature=False)
    value = _accumulated_cost(_times_pow2(x, -k), _times_pow2(y, -k), _euclid_cost)
    value = _times_pow2(value, k)
    return _refuse_overflow(_nan_unless_finite(value, x, y), "dtw_multi")


def soft_dtw(
    x: jax.Array, y: jax.Array, gamma: float = 0.01, *, multi: bool = False
) -> jax.Array:
    """Soft-DTW: DTW with the minimum replaced by a soft minimum, differentiable.

    The recursion is ``R(i, j) = c(i, j) + softmin_gamma(R(i-1, j), R(i, j-1),
    R(i-1, j-1))`` with ``softmin_gamma(a, b, c) = -gamma log(e^{-a/gamma} +
    e^{-b/gamma} + e^{-c/gamma})`` (Cuturi & Blondel 2017). The local cost and the
    normalisation are those of `dtw` (``multi=False``: per feature ``|x_i - y_j|``,
    summed over features, divided by N + M) or of `dtw_multi` (``multi=True``:
    ``||x_i - y_j||_2``, unnormalised), so as ``gamma -> 0`` it tends to that DTW
    (it is never above it: the soft minimum is at most the minimum, by at most
    ``gamma log 3`` per cell). `jax.grad` works through it, also where two
    samples coincide (the Euclidean cost's gradient is taken as 0 there).

    Args:
        x: (N, F) or (N,) first trajectory.
        y: (M, F) or (M,) second trajectory (same F).
        gamma: smoothing, > 0 (a Python float; same units as the local cost).
        multi: the local cost of `dtw_multi` instead of `dtw`.

    Returns:
        Scalar; NaN under ``jit`` / ``vmap`` for non-finite input.

    Raises:
        ValueError: as `dtw`, or gamma <= 0 or outside float32's normal range.

    References:
        Cuturi & Blondel, "Soft-DTW: a Differentiable Loss Function for
        Time-Series", ICML 2017.
    """
    tiny = float(jnp.finfo(jnp.float32).tiny)
    if not tiny <= float(gamma) <= float(jnp.finfo(jnp.float32).max):
        raise ValueError(f"soft_dtw: gamma must be a float32 number > 0, from {tiny:.3g} "
                         f"to {float(jnp.finfo(jnp.float32).max):.3g}, got {gamma}")
    x, y = _pair(x, y, "soft_dtw")
    # soft_dtw_gamma(s x, s y) = s * soft_dtw_{gamma / s}(x, y): computed at a scale
    # where no cost overflows (see the module docstring)
    k = _scale_exponents(x, y, per_feature=not multi)
    xs, ys = _times_pow2(x, -k), _times_pow2(y, -k)
    g = _times_pow2(jnp.full(k.shape, float(gamma), x.dtype), -k)
    if multi:
        value = _accumulated_cost(xs, ys, _safe_euclid_cost, _soft_min(g))
        value = _times_pow2(value, k)
    else:
        per_dim = _accumulated_cost(xs, ys, _abs_cost, _soft_min(g[:, None]))
        value = jnp.sum(_times_pow2(per_dim / (x.shape[0] + y.shape[0]), k))
    return _refuse_overflow(_nan_unless_finite(value, x, y), "soft_dtw")


def resample(x: jax.Array, n: int) -> jax.Array:
    """Linearly resample a uniformly sampled trajectory to ``n`` samples.

    Sample ``k`` of a length-``T`` trajectory is taken to lie at normalised time
    ``k / (T - 1)``; the output lies at ``linspace(0, 1, n)`` (both ends included).

    Args:
        x: (T, F) or (T,) trajectory, T >= 2 (T = 1 only if n = 1).
        n: number of output samples (static).

    Returns:
        (n, F) or (n,) resampled trajectory.
    """
    x = jnp.asarray(x)
    flat = x.ndim == 1
    x2 = _as_2d(x, "x")
    t_len = x2.shape[0]
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    check_elements(int(n) * x2.shape[1], "n", f"{int(n):,} samples x {x2.shape[1]} "
                   "features")
    if t_len == n:
        out = x2
    elif t_len < 2:
        raise ValueError(f"cannot resample a trajectory of {t_len} sample to {n}")
    else:
        pos = jnp.linspace(0.0, 1.0, n, dtype=x2.dtype) * (t_len - 1)
        i0 = jnp.clip(jnp.floor(pos).astype(jnp.int32), 0, t_len - 2)
        frac = (pos - i0)[:, None]
        out = x2[i0] * (1 - frac) + x2[i0 + 1] * frac
    return out[:, 0] if flat else out


def euclidean(x: jax.Array, y: jax.Array, n_samples: int | None = None) -> jax.Array:
    """Euclidean discrepancy of the paper (eq. 7) after time normalisation.

    Both trajectories are resampled (linear interpolation) to ``n_samples`` equally
    spaced normalised times in [0, 1]; the result is the L2 norm over all samples and
    features, ``||X - Y||``.

    Args:
        x: (N, F) or (N,) first trajectory.
        y: (M, F) or (M,) second trajectory.
        n_samples: common number of samples; default ``max(N, M)``.

    Returns:
        Scalar distance; NaN under ``jit`` / ``vmap`` for non-finite input.

    Raises:
        ValueError: as `dtw`.
    """
    x, y = _pair(x, y, "euclidean")
    n = max(x.shape[0], y.shape[0]) if n_samples is None else int(n_samples)
    k = _scale_exponents(x, y, per_feature=False)
    diff = resample(_times_pow2(x, -k), n) - resample(_times_pow2(y, -k), n)
    value = _times_pow2(jnp.sqrt(jnp.sum(diff**2)), k)
    return _refuse_overflow(_nan_unless_finite(value, x, y), "euclidean")


def point_sum(
    x: jax.Array,
    y: jax.Array,
    weights: jax.Array | None = None,
    n_samples: int | None = None,
) -> jax.Array:
    """Sum over time of the weighted Euclidean distance between matching points.

    ``sum_t sqrt(sum_f (w_f (x_tf - y_tf))^2)`` after resampling both trajectories
    (as `euclidean`) to ``n_samples`` normalised times.  With weights
    ``(1, 1, 1, 1/300)`` over (X [m], Y [m], Z [m], Fz [N]) and equal lengths it is
    the CGDA authors' iron fitness, ``sum sqrt(dX^2 + dY^2 + dZ^2 + (dFz/300)^2)``
    (xgnitive ``programs/cgdaExecution/CgdaIronFitnessFunction.cpp``).

    Args:
        x: (N, F) or (N,) first trajectory.
        y: (M, F) or (M,) second trajectory.
        weights: (F,) per-feature weights (default all 1), finite and >= 0.
        n_samples: common number of samples; default ``max(N, M)``.

    Returns:
        Scalar distance; NaN under ``jit`` / ``vmap`` for non-finite input.

    Raises:
        ValueError: as `dtw`; weights of the wrong shape.
    """
    x, y = _pair(x, y, "point_sum")
    if weights is not None:
        w = jnp.asarray(weights, x.dtype)
        if w.shape != (x.shape[1],):
            raise ValueError(f"point_sum: weights has shape {w.shape}, expected "
                             f"({x.shape[1]},) (one per feature)")
        x, y = x * w, y * w
    n = max(x.shape[0], y.shape[0]) if n_samples is None else int(n_samples)
    k = _scale_exponents(x, y, per_feature=False)
    diff = resample(_times_pow2(x, -k), n) - resample(_times_pow2(y, -k), n)
    value = _times_pow2(jnp.sum(jnp.sqrt(jnp.sum(diff**2, axis=-1))), k)
    return _refuse_overflow(_nan_unless_finite(value, x, y), "point_sum")
