"""Generalization: demonstrations -> one representative feature trajectory.

Paper section 2.1: (1) rescale each repetition's time to [0, 1]; (2) pool all
samples and average them in N temporal intervals; (3) join the interval means with
a linear radial-basis-function interpolant ``f(t) = sum_i w_i |t - t_i|`` whose
weights solve the N x N system ``f(t_j) = knot_j``.

The binning runs on the host in float64 NumPy (it is data preparation, done once);
the resulting :class:`GeneralizedAction` is a JAX pytree evaluated with jit-able JAX.

Knot times: the linear RBF through distinct knots does not depend on their order, so
unsorted knot times are sorted (together with their knots) before evaluation; two
equal knot times make the interpolant ambiguous (a singular system) and are refused
with ``ValueError`` in eager calls, and give NaN under ``jit`` / ``vmap``.  Eager calls
also refuse a NaN or an infinity in ``knot_times``, ``knots`` or ``t`` (see
`cgda_jax.checks`).

References:
    Morante et al., "Humanoid Robot Imitation through Continuous Goal-Directed
    Actions: An Evolutionary Approach", Advanced Robotics 2015, section 2.1.
    Buhmann, "Radial Basis Functions", Cambridge University Press 2003.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.checks import FLOAT32_MAX, check_finite, is_traced
from cgda_jax.data import Demonstration, validate_demonstrations
from cgda_jax.sizes import MAX_KNOTS, SizeError, check_elements

__all__ = [
    "GeneralizedAction",
    "generalize",
    "generalize_streams",
    "rbf_interpolate",
    "rbf_weights",
    "sample_actions",
]


def _check_knots(knot_times: jax.Array, knots: jax.Array) -> jax.Array:
    knots = jnp.asarray(knots)
    if knots.ndim == 1:
        knots = knots[:, None]
    if jnp.ndim(knot_times) != 1 or knots.ndim != 2:
        raise ValueError(
            f"knot_times must be (N,) and knots (N, F); got "
            f"{jnp.shape(knot_times)} and {knots.shape}"
        )
    if knots.shape[0] != jnp.shape(knot_times)[0] or knots.shape[0] < 2:
        raise ValueError(
            f"need N >= 2 knots with matching times; got knot_times "
            f"{jnp.shape(knot_times)} and knots {knots.shape}"
        )
    return knots


def _check_knot_times(knot_times: jax.Array, dtype, where: str) -> None:
    """Eager calls: refuse non-finite or repeated knot times (naming both indices);
    a no-op on tracers."""
    if is_traced(knot_times):
        return
    check_finite(knot_times, "knot_times", where=where)
    kt = np.asarray(knot_times).astype(dtype)  # the values actually used
    order = np.argsort(kt, kind="stable")
    same = np.flatnonzero(np.diff(kt[order]) == 0)
    if same.size:
        i, j = sorted(int(k) for k in order[same[0] : same[0] + 2])
        raise ValueError(
            f"{where}: knot_times[{i}] and knot_times[{j}] are both {kt[i]:g} "
            f"(in {jnp.dtype(dtype).name}); knot times must be distinct"
        )


def _repeated(sorted_times: jax.Array) -> jax.Array:
    """Scalar bool: two equal neighbours in sorted knot times."""
    return jnp.any(jnp.diff(sorted_times) == 0)


def rbf_weights(knot_times: jax.Array, knots: jax.Array) -> jax.Array:
    """Weights of the linear RBF through the knots (paper eq. 2).

    Args:
        knot_times: (N,) distinct knot times, in any order.
        knots: (N, F) knot values.

    Returns:
        (N, F) weights ``w`` solving ``|t_j - t_i| w = knots`` (in the order given);
        NaN under ``jit`` if two knot times are equal.

    Raises:
        ValueError: bad shapes; in eager calls also repeated or non-finite knot
            times, or non-finite knots (the message names the input).
    """
    knots = _check_knots(knot_times, knots)
    _check_knot_times(knot_times, knots.dtype, "rbf_weights")
    check_finite(knots, "knots", where="rbf_weights")
    return _solve_weights(knot_times, knots)


@jax.jit
def _solve_weights(knot_times: jax.Array, knots: jax.Array) -> jax.Array:
    """The weights of `rbf_weights` (checked inputs): one program per shape."""
    t = jnp.asarray(knot_times, knots.dtype)
    w = jnp.linalg.solve(jnp.abs(t[:, None] - t[None, :]), knots)
    return jnp.where(_repeated(jnp.sort(t)), jnp.nan, w)


@jax.jit
def _evaluate(
    knot_times: jax.Array, knots: jax.Array, weights: jax.Array, t: jax.Array
) -> jax.Array:
    """Evaluate ``sum_i w_i |t - t_i|`` in a cancellation-free form.

    In one dimension the linear RBF through sorted knots is exactly the piecewise
    linear interpolant between them, extended beyond the outer knots with slopes
    ``-sum(w)`` (left) and ``+sum(w)`` (right). This form is what is evaluated: it
    is mathematically identical to the weighted sum but does not lose float32
    precision to large alternating weights.  Knots are sorted by time first (the RBF
    does not depend on their order); repeated knot times give NaN.

    Jitted: one program per shape in eager calls (not one per operation), inlined
    when called under a trace.
    """
    weight_sum = jnp.sum(weights, axis=0)
    t = jnp.asarray(t, knots.dtype)
    kt = jnp.asarray(knot_times, knots.dtype)
    order = jnp.argsort(kt)
    kt, knots = kt[order], knots[order]
    n = kt.shape[0]
    # "compare_all": a (T, N) comparison, compiled in a fraction of the default
    # loop's time (N is small); the same indices
    seg = jnp.searchsorted(kt, t, side="right", method="compare_all")
    seg = jnp.clip(seg - 1, 0, n - 2)
    t0, t1 = kt[seg], kt[seg + 1]
    frac = jnp.clip((t - t0) / (t1 - t0), 0.0, 1.0)[:, None]
    inner = knots[seg] * (1 - frac) + knots[seg + 1] * frac
    left = knots[0] + (kt[0] - t)[:, None] * weight_sum
    right = knots[-1] + (t - kt[-1])[:, None] * weight_sum
    out = jnp.where(
        (t < kt[0])[:, None], left, jnp.where((t > kt[-1])[:, None], right, inner)
    )
    return jnp.where(_repeated(kt), jnp.nan, out)


def rbf_interpolate(knot_times: jax.Array, knots: jax.Array, t: jax.Array) -> jax.Array:
    """Linear RBF interpolant (``phi(r) = r``, no polynomial) through the knots.

    Args:
        knot_times: (N,) distinct knot times, in any order (they are sorted together
            with their knots: the interpolant does not depend on the order).
        knots: (N, F) knot values.
        t: (T,) query times.

    Returns:
        (T, F) interpolated values; exactly ``knots`` at ``knot_times``.  Under
        ``jit`` / ``vmap``: NaN if two knot times are equal, and non-finite values
        where an input is not finite.

    Raises:
        ValueError: bad shapes; in eager calls also two equal knot times (the message
            names both indices), or a NaN or an infinity in ``knot_times``, ``knots``
            or ``t`` (named, with its index).

    Examples:
        >>> import jax.numpy as jnp
        >>> rbf_interpolate(jnp.array([1.0, 0.0]), jnp.array([2.0, 0.0]),
        ...                 jnp.array([0.25])).tolist()
        [[0.5]]
    """
    knots = _check_knots(knot_times, knots)
    _check_knot_times(knot_times, knots.dtype, "rbf_interpolate")
    check_finite(knots, "knots", where="rbf_interpolate")
    check_finite(t, "t", where="rbf_interpolate")
    return _evaluate(knot_times, knots, rbf_weights(knot_times, knots), t)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class GeneralizedAction:
    """A generalized action: knots joined by a linear RBF over normalized time.

    Attributes:
        knot_times: (N,) knot times in [0, 1], increasing.
        knots: (N, F) knot values (interval means).
        weights: (N, F) RBF weights (paper eq. 2).
        feature_names: (F,) feature names (static).
        name: action name (static).
    """

    knot_times: jax.Array
    knots: jax.Array
    weights: jax.Array
    feature_names: tuple[str, ...] = dataclasses.field(
        default=(), metadata=dict(static=True)
    )
    name: str = dataclasses.field(default="action", metadata=dict(static=True))

    @property
    def n_knots(self) -> int:
        return self.knots.shape[0]

    @property
    def n_features(self) -> int:
        return self.knots.shape[1]

    def __call__(self, t: jax.Array) -> jax.Array:
        """Evaluate at normalized times.

        Args:
            t: (T,) normalized times (values outside [0, 1] extrapolate linearly).

        Returns:
            (T, F) feature values.
        """
        if not isinstance(t, jax.Array):  # host data: no transfer program
            t = np.asarray(t)
        if t.ndim != 1:
            raise ValueError(f"t must be 1-D (T,), got shape {t.shape}")
        return _evaluate(self.knot_times, self.knots, self.weights, t)

    def sample(self, n: int) -> jax.Array:
        """(n, F) values at ``n`` equally spaced normalized times in [0, 1]."""
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        k = int(self.knot_times.shape[0])
        check_elements(int(n) * (k + self.n_features), "n",
                       f"{int(n):,} samples x {k} knots")
        return _sample(self.knot_times, self.knots, self.weights, int(n))


def sample_actions(actions: Sequence[GeneralizedAction], n: int) -> jax.Array:
    """(A, n, F) several actions (same F, any knot counts) at ``n`` equally spaced
    normalized times: `GeneralizedAction.sample` of each, stacked, as one program
    (not one per action shape).

    Raises:
        ValueError: no actions, ``n < 1``, or different feature counts.
    """
    actions = tuple(actions)
    if not actions:
        raise ValueError("sample_actions: no actions given")
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    k = max(int(a.knot_times.shape[0]) for a in actions)
    check_elements(len(actions) * int(n) * (k + actions[0].n_features), "n",
                   f"{len(actions)} actions x {int(n):,} samples x {k} knots")
    counts = {a.n_features for a in actions}
    if len(counts) > 1:
        raise ValueError(
            f"sample_actions: the actions have different feature counts {counts}"
        )
    return _sample_all(actions, int(n))


@functools.partial(jax.jit, static_argnums=1)
def _sample_all(actions: tuple[GeneralizedAction, ...], n: int) -> jax.Array:
    # one evaluation per action (vmapping the actions of one knot count compiled
    # slower, not faster)
    return jnp.stack([_sample(a.knot_times, a.knots, a.weights, n) for a in actions])


@functools.partial(jax.jit, static_argnums=3)
def _sample(
    knot_times: jax.Array, knots: jax.Array, weights: jax.Array, n: int
) -> jax.Array:
    """`GeneralizedAction.sample` as one program per (knots, n) shape (arrays, not
    the action: its static name would make one program per action)."""
    t = jnp.linspace(0.0, 1.0, n, dtype=knots.dtype)
    return _evaluate(knot_times, knots, weights, t)


def _bin_means(
    demos: Sequence[Demonstration], n_bins: int, method: str
) -> np.ndarray:
    """(N, F) means of the pooled samples per normalized-time interval."""
    t = np.concatenate([d.normalized_times for d in demos])
    x = np.concatenate([d.features for d in demos])
    if method == "xgnitive":
        # Half-open bins [k/N, (k+1)/N) with the edges computed as their script
        # did, ``(1.0 / N) * k``; samples at or beyond the last edge are dropped.
        edges = (1.0 / n_bins) * np.arange(n_bins + 1)
        idx = np.searchsorted(edges, t, side="right") - 1
    else:
        # Half-open bins, the last one closed so that t = 1 is kept.
        idx = np.minimum(np.floor(t * n_bins).astype(np.int64), n_bins - 1)
    keep = (idx >= 0) & (idx < n_bins)
    counts = np.bincount(idx[keep], minlength=n_bins)
    empty = np.flatnonzero(counts == 0)
    if empty.size:
        k = int(empty[0])
        raise ValueError(
            f"interval {k} of {n_bins} (normalized time [{k / n_bins:.4g}, "
            f"{(k + 1) / n_bins:.4g})) holds no samples of any demonstration; "
            f"use a larger interval_s or more densely sampled demonstrations"
        )
    sums = np.zeros((n_bins, x.shape[1]))
    np.add.at(sums, idx[keep], x[keep])
    return sums / counts[:, None]


def _check_float32_result(
    values: np.ndarray, what: str, names: Sequence[str]
) -> None:
    """Refuse (N, F) float64 results that become inf in float32, naming the feature."""
    bad = ~(np.abs(values) <= FLOAT32_MAX)
    if bad.any():
        k, f = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(
            f"generalize: {what} {k} of feature {f} ({names[f]!r}) is "
            f"{values[k, f]:g}, beyond float32's range (+/-{FLOAT32_MAX:.4g}); "
            f"rescale that feature (e.g. other units)"
        )


def generalize(
    demos: Sequence[Demonstration],
    interval_s: float = 1.0,
    method: str = "paper",
    name: str = "action",
) -> GeneralizedAction:
    """Generalize the repetitions of one action (paper section 2.1).

    Args:
        demos: repetitions of one action (same feature names).
        interval_s: seconds of demonstration per interval (paper: 1 s).
        method: ``"paper"``: N = round(mean duration / interval_s), knots at the
            interval centres ``(k + 0.5) / N``, last interval closed. ``"xgnitive"``:
            the CGDA authors' later script (xgnitive ``cgda-generalization.py``):
            N = int(mean(ceil(duration))) // interval_s, half-open intervals
            ``[k/N, (k+1)/N)`` (samples at t = 1 dropped), knots placed at
            ``linspace(0, 1, N)`` as their RBF call did.
        name: name of the resulting action.

    Returns:
        The GeneralizedAction (float32 JAX arrays).

    Raises:
        ValueError: bad demonstrations, fewer than 2 intervals, an empty interval,
            an unknown method, or knots or weights beyond float32's range (the
            message names the feature).

    Examples:
        >>> import numpy as np
        >>> t = np.linspace(0, 4, 41)
        >>> d = Demonstration(t, np.sin(t)[:, None], ("s",))
        >>> generalize([d], interval_s=1.0).knots.shape
        (4, 1)
    """
    if not isinstance(demos, Demonstration):
        demos = list(demos)  # a generator is read once
    validate_demonstrations(demos)
    if not np.isfinite(interval_s) or interval_s <= 0:
        raise ValueError(f"interval_s must be a positive number, got {interval_s}")
    if method == "paper":
        mean_duration = float(np.mean([d.duration for d in demos]))
        n_bins = int(round(mean_duration / interval_s))
    elif method == "xgnitive":
        mean_duration = float(np.mean([np.ceil(d.duration) for d in demos]))
        n_bins = int(int(mean_duration) // interval_s)
    else:
        raise ValueError(f"unknown method {method!r}; expected 'paper' or 'xgnitive'")
    if n_bins < 2:
        raise ValueError(
            f"mean demonstration duration {mean_duration:.4g} s with interval_s="
            f"{interval_s} gives {n_bins} interval(s); need at least 2 "
            f"(use a smaller interval_s)"
        )
    if n_bins > MAX_KNOTS:  # before the bins and the knots x knots system exist
        raise SizeError(
            f"interval_s: {interval_s:g} s cuts the {mean_duration:.4g} s "
            f"demonstrations into {n_bins:,} intervals, more than {MAX_KNOTS:,} (an "
            f"RBF system of {n_bins:,} x {n_bins:,}); use a larger interval_s")
    means = _bin_means(demos, n_bins, method)
    if method == "xgnitive":
        knot_times = np.linspace(0.0, 1.0, n_bins)
    else:
        knot_times = (np.arange(n_bins) + 0.5) / n_bins
    weights = np.linalg.solve(np.abs(knot_times[:, None] - knot_times[None, :]), means)
    _check_float32_result(means, "knot (interval mean)", demos[0].feature_names)
    _check_float32_result(weights, "RBF weight", demos[0].feature_names)
    # float32 on the host, then one transfer each (no conversion program per shape)
    return GeneralizedAction(
        knot_times=jax.device_put(knot_times.astype(np.float32)),
        knots=jax.device_put(means.astype(np.float32)),
        weights=jax.device_put(weights.astype(np.float32)),
        feature_names=demos[0].feature_names,
        name=name,
    )


def generalize_streams(
    streams: Sequence[Sequence[Demonstration]],
    interval_s: float = 1.0,
    method: str = "paper",
    name: str = "action",
) -> GeneralizedAction:
    """Generalize the same repetitions recorded as several streams, each on its own
    time base, and put their features side by side.

    Each stream is generalized by `generalize` with its own times (its own start and
    duration), as the CGDA authors did for TEO's arm and wrist-force streams (their
    iron goal ``target_iron[9][4]`` is the arm's X, Y, Z and the jr3's Fz, each
    generalized separately).  The streams must give the same number of knots; the
    linear RBF system depends on the knot times only, so the stacked weights are
    those of one generalization of all the columns.

    Args:
        streams: per stream, its repetitions (the same feature names within it).
        interval_s, method, name: as `generalize`.

    Returns:
        A GeneralizedAction with the streams' features in order.

    Raises:
        ValueError: no stream, or streams giving different numbers of knots (the
            message names both).
    """
    if not streams:
        raise ValueError("generalize_streams: no streams")
    parts = [generalize(demos, interval_s, method, name) for demos in streams]
    counts = [p.n_knots for p in parts]
    if len(set(counts)) > 1:
        raise ValueError(f"generalize_streams: the streams give {counts} knots at "
                         f"interval_s={interval_s:g} (their durations differ); "
                         "each must give the same number")
    return GeneralizedAction(
        knot_times=parts[0].knot_times,
        knots=jnp.concatenate([p.knots for p in parts], axis=1),
        weights=jnp.concatenate([p.weights for p in parts], axis=1),
        feature_names=tuple(n for p in parts for n in p.feature_names),
        name=name,
    )
