"""Distances between two feature trajectories: DTW and Euclidean (paper eq. 3-7).

Every function takes ONE pair of trajectories; batch with ``jax.vmap`` at the call
site, e.g. ``jax.vmap(dtw, in_axes=(0, None))(candidates, reference)``.

DTW is computed by a ``lax.scan`` over the anti-diagonals of the accumulated-cost
matrix: diagonal ``d`` holds the cells ``(i, d - i)``, which depend only on the two
previous diagonals, so each scan step is one vectorised update of length ``N``. The
local costs of a diagonal are computed inside the step from ``x`` and a reversed,
padded copy of ``y`` (a contiguous ``dynamic_slice``), so the ``N x M`` cost matrix is
never materialised.

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

from cgda_jax.checks import check_finite

__all__ = ["dtw", "dtw_multi", "euclidean", "resample", "soft_dtw"]

# A large finite value for "unreachable" cells: inf would turn into NaN under grad.
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
    dtype = jnp.result_type(x, y)
    return x.astype(dtype), y.astype(dtype)


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

    def step(carry, d):
        prev2, prev1 = carry
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
        return (prev1, new), None

    (_, last), _ = jax.lax.scan(step, (prev2, prev1), jnp.arange(n + m - 1))
    return last[..., n]


def _abs_cost(xd: jax.Array, yd: jax.Array) -> jax.Array:
    return jnp.abs(xd - yd)


def _euclid_cost(xd: jax.Array, yd: jax.Array) -> jax.Array:
    return jnp.sqrt(jnp.sum((xd - yd) ** 2, axis=0))


def _safe_euclid_cost(xd: jax.Array, yd: jax.Array) -> jax.Array:
    """`_euclid_cost` with a finite gradient (0) where the two samples coincide."""
    sq = jnp.sum((xd - yd) ** 2, axis=0)
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


def _soft_min(gamma: float) -> Callable[[jax.Array, jax.Array, jax.Array], jax.Array]:
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
            ``y`` (the message names the input and the index).

    Examples:
        >>> import jax.numpy as jnp
        >>> float(dtw(jnp.array([0.0, 1.0, 2.0]), jnp.array([0.0, 1.0, 1.0, 2.0])))
        0.0
    """
    x, y = _pair(x, y, "dtw")
    per_dim = _accumulated_cost(x, y, _abs_cost)
    return _nan_unless_finite(jnp.sum(per_dim) / (x.shape[0] + y.shape[0]), x, y)


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
    return _nan_unless_finite(_accumulated_cost(x, y, _euclid_cost), x, y)


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
        ValueError: as `dtw`, or gamma <= 0.

    References:
        Cuturi & Blondel, "Soft-DTW: a Differentiable Loss Function for
        Time-Series", ICML 2017.
    """
    if not float(gamma) > 0:
        raise ValueError(f"soft_dtw: gamma must be > 0, got {gamma}")
    x, y = _pair(x, y, "soft_dtw")
    combine = _soft_min(float(gamma))
    if multi:
        value = _accumulated_cost(x, y, _safe_euclid_cost, combine)
    else:
        per_dim = _accumulated_cost(x, y, _abs_cost, combine)
        value = jnp.sum(per_dim) / (x.shape[0] + y.shape[0])
    return _nan_unless_finite(value, x, y)


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
    diff = resample(x, n) - resample(y, n)
    return _nan_unless_finite(jnp.sqrt(jnp.sum(diff**2)), x, y)
