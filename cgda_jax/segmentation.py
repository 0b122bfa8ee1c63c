"""Segmentation: one long recording -> the sequence of library actions in it.

The paper (2.2) names recognition's use: "determining tasks as action sequences by
splitting tasks into smaller and simpler actions". `segment` splits a recording
in which several library actions follow each other (with or without pauses) into
``(action, start, end)`` segments by a segmental search:

1. The recording is averaged onto a grid of ``G + 1`` points ``step_s`` apart (box
   means of the samples within half a step; linear interpolation where a step holds
   none).
2. Every candidate segment ``[s, s + L]`` of the grid (``L`` from the shortest to the
   longest allowed duration) is resampled to ``n_samples`` and compared with every
   library action by the recognition metric (`cgda_jax.recognition.METRICS`: the
   paper's DTW by default). Both are taken *relative to their first sample*: an
   action in a sequence starts where the previous one left the object, not where
   its demonstrations started. Each feature is in units of its noise: the
   recording's, or the library's where that is larger (a rendered or finely
   tracked recording is cleaner than the demonstrations were; in units of its own
   tiny noise, the library's residual wiggle in features that do not change
   decided the labels). A pause is one more label, ``"rest"``: the
   object held where the segment started (a constant template). One batched
   ``vmap`` call gives the (S, L, A + 1) costs.
3. A dynamic programme over the boundaries (one ``lax.scan`` over the grid) picks
   the segmentation of least total cost, each segment's cost weighted by its
   duration (a per-second mismatch), with no two rests in a row.
4. The boundaries are refined on the recording's own samples (`refine_boundaries`):
   DTW places a boundary only roughly (it lets an action absorb a neighbouring
   pause or slow end almost for free by stretching the held end of its template),
   so around each gap between two actions (and before the first, after the last)
   the samples are fitted by an explicit model of a human motion's ends: the object
   held still, then leaving (or, before, reaching) its rest along a minimum-jerk
   profile (Flash & Hogan 1985) over the action's duration; the end and start
   times of least residual are searched jointly, on every sample within a share of
   the action's duration of the search's boundaries. Where a feature changes
   monotonically over an action (its net change is most of its range), that change
   is the profile's amplitude: fixed, the profile's curvature places the onset (a
   free amplitude lets a steep end pass for a longer, larger profile and the
   boundary slide into the pause after it); a feature that goes and comes back
   (CLEAN's circle) has its amplitude fitted (linear least squares); a feature
   the library's action does not move is held still, and a feature's drift where
   no action moves it (light that dims) is removed first. The ends are continuous
   times (fitted between the samples) reported as the samples at rest either side
   of each motion.

Rests are dropped from the result; each action segment says its start and end in
the recording's time unit (seconds) and its cost.

References:
    Morante et al., "Humanoid Robot Imitation through Continuous Goal-Directed
    Actions: An Evolutionary Approach", Advanced Robotics 2015, section 2.2.
    Sakoe, "Two-level DP-matching -- a dynamic programming-based pattern matching
    algorithm for connected word recognition", IEEE TASSP 1979.
    Flash & Hogan, "The coordination of arm movements: an experimentally confirmed
    mathematical model", J. Neuroscience 1985 (the minimum-jerk profile).
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.data import Demonstration
from cgda_jax.numerics import min_jerk_np
from cgda_jax.recognition import METRICS, ActionLibrary
from cgda_jax.sizes import check_recognition

__all__ = [
    "REST", "Segment", "best_segmentation", "execute_sequence", "refine_boundaries",
    "segment", "segment_costs",
]

#: Label of a pause (the object held still) in `segment_costs` and
#: `best_segmentation`; never an action name of the result.
REST = "rest"

#: Default number of grid steps over the whole recording.
_GRID_STEPS = 200
#: Candidate starts whose segments are compared in one vectorised step.
_STARTS_PER_CHUNK = 64
#: `refine_boundaries`: a boundary moves at most this share of its action's
#: (search) duration; the samples fitted reach this share into each action.
_REACH = 0.25
_INTO = 0.2
#: `refine_boundaries`: rounds of refitting (each centres its window on the last).
_ROUNDS = 10
#: (end, start) pairs of candidate times fitted in one vectorised step.
_PAIRS_PER_CHUNK = 512
#: `refine_boundaries`: candidate times per side in the coarse pass.
_COARSE = 24
#: `refine_boundaries`: an action's net change is measured on the samples within
#: this share of its duration of each end (medians) ...
_LEVEL = 0.05
#: ... and fixed in the fit for the features whose net change is at least this
#: share of their range over the action (the others go and come back: fitted).
_MONOTONE = 0.8
#: `refine_boundaries`: a feature an action moves by less than this many units of
#: the library's noise (the range of its knots) is held still in that action's fit.
_MOVES = 10.0
#: `refine_boundaries`: each sample interval is split in this many candidate times
#: in the last pass (the model is continuous in time; at 8 fps a sample is 3-5 % of
#: a short action).
_SUBSAMPLE = 4


class Segment(NamedTuple):
    """One recognized action of a recording."""

    action: str  # library action name
    start: float  # seconds, the recording's clock
    end: float  # seconds
    cost: float  # the metric's cost of the segment against the action


def _grid(recording: Demonstration, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(G + 1,) grid times and (G + 1, F) box means of the recording there."""
    t = recording.times
    n_steps = max(int(np.floor(recording.duration / step_s + 1e-9)), 1)
    grid_t = t[0] + step_s * np.arange(n_steps + 1)
    x = recording.features
    lo = np.searchsorted(t, grid_t - step_s / 2, side="left")
    hi = np.searchsorted(t, grid_t + step_s / 2, side="right")
    csum = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    count = (hi - lo)[:, None]
    interp = np.stack([np.interp(grid_t, t, x[:, f]) for f in range(x.shape[1])], 1)
    means = (csum[hi] - csum[lo]) / np.maximum(count, 1)
    return grid_t, np.where(count > 0, means, interp)


def _check_inputs(recording, library, metric, n_samples) -> None:
    if not isinstance(library, ActionLibrary):
        raise ValueError(f"segment: library is {type(library).__name__}, not an "
                         "ActionLibrary")
    if len(library) == 0:
        raise ValueError("segment: the action library has no actions")
    if REST in library.names:
        raise ValueError(f"segment: {REST!r} names the pauses; rename that action")
    if not isinstance(recording, Demonstration):
        raise ValueError(f"segment: the recording is {type(recording).__name__}, not "
                         "a Demonstration (load it with load_csv or build one)")
    if recording.feature_names != library.feature_names:
        raise ValueError(
            f"segment: recording {recording.name!r} has features "
            f"{recording.feature_names} but the library has {library.feature_names}")
    if metric not in METRICS:
        raise ValueError(f"segment: unknown metric {metric!r}; expected one of "
                         f"{tuple(METRICS)}")
    if isinstance(n_samples, bool) or int(n_samples) != n_samples or n_samples < 2:
        raise ValueError(f"segment: n_samples must be a whole number >= 2, got "
                         f"{n_samples!r}")


def _lengths(duration: float, step_s: float, durations_s) -> tuple[np.ndarray, int]:
    """Segment lengths in grid steps (1 to the longest: a rest may be short) and the
    shortest action's."""
    lo, hi = (4 * step_s, duration) if durations_s is None else durations_s
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
        raise ValueError(f"segment: durations_s must be (shortest, longest) seconds "
                         f"with 0 < shortest <= longest, got {durations_s!r}")
    first = max(int(np.ceil(lo / step_s - 1e-9)), 1)
    last = int(np.floor(min(hi, duration) / step_s + 1e-9))
    if last < first:
        raise ValueError(f"segment: recording of {duration:.4g} s has no room for an "
                         f"action of {lo:g} s to {hi:g} s on a grid of {step_s:g} s")
    return np.arange(1, last + 1), first


def segment_costs(
    recording: Demonstration,
    library: ActionLibrary,
    *,
    metric: str = "dtw",
    n_samples: int = 16,
    step_s: float | None = None,
    durations_s: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, jax.Array]:
    """Cost of every candidate segment of the recording as every label.

    Args: as `segment`.

    Returns:
        ``(grid_times (G + 1,), lengths (L,) in grid steps (1, 2, ... the
        longest), costs (G, L, A + 1))``: ``costs[s, k, a]`` is the metric's cost
        of grid points ``s .. s + lengths[k]`` (resampled to ``n_samples``, less
        its first sample; each feature in units of the larger of the recording's
        and the library's noise) against action ``a`` (``library.names`` order; the last
        label is `REST`, a constant template), ``inf`` where the segment runs past
        the recording's end or is an action shorter than the shortest duration.
    """
    _check_inputs(recording, library, metric, n_samples)
    if step_s is None:
        step_s = recording.duration / _GRID_STEPS
    if not (np.isfinite(step_s) and step_s > 0):
        raise ValueError(f"segment: step_s must be a positive number of seconds, "
                         f"got {step_s!r}")
    grid_t, grid_x = _grid(recording, float(step_s))
    lengths, shortest = _lengths(recording.duration, float(step_s), durations_s)
    n_starts = grid_t.shape[0] - 1
    # the work of S x L queries against A + 1 templates, before anything is built
    check_recognition(n_starts * lengths.shape[0], len(library) + 1, int(n_samples),
                      recording.n_features, name="step_s", metric=metric)
    # the grid padded to whole chunks (held at its last value): recordings of
    # similar lengths share one program
    padded = -(-n_starts // _STARTS_PER_CHUNK) * _STARTS_PER_CHUNK + 1
    grid_p = np.concatenate([grid_x, np.repeat(grid_x[-1:], padded - n_starts - 1, 0)])
    scale = _scale(recording, library)
    costs = _segment_costs(METRICS[metric], int(n_samples),
                           jnp.asarray(grid_p / scale, jnp.float32),
                           jnp.int32(n_starts + 1),
                           jnp.asarray(lengths, jnp.int32), jnp.int32(shortest),
                           _templates(library, int(n_samples)) / scale)
    return grid_t, lengths, costs[:n_starts]


def _noise(recording: Demonstration) -> np.ndarray:
    """(F,) each feature's scale: its noise (standard deviation) in the recording,
    from the median absolute second difference of its samples (a smooth motion adds
    almost nothing there), at least 1e-3 of its range (noise-free features); 1 for a
    constant feature."""
    x = recording.features
    d2 = np.diff(x, n=2, axis=0)
    sigma = (np.median(np.abs(d2), axis=0) / (0.6745 * np.sqrt(6.0))
             if d2.shape[0] else np.zeros(x.shape[1]))
    sigma = np.maximum(sigma, 1e-3 * np.ptp(x, axis=0))
    return np.where(sigma > 0, sigma, 1.0)


def _scale(recording: Demonstration, library: ActionLibrary | None) -> np.ndarray:
    """(F,) the unit of each feature in the search and the refinement: the larger
    of its noise in the recording and in the library (a tracked video can be
    cleaner than the demonstrations were; a feature constant up to rounding has
    no noise of its own)."""
    noise = _noise(recording)
    return noise if library is None else np.maximum(noise, _library_noise(library))


def _library_noise(library: ActionLibrary) -> np.ndarray:
    """(F,) each feature's noise in the library's actions: `_noise`'s estimator
    on the second differences of every action's knots, pooled (most knots of most
    features are at rest or smooth, so the median is their noise)."""
    d2 = np.concatenate([np.diff(np.asarray(a.knots, np.float64), n=2, axis=0)
                         for a in library.values()])
    if not d2.shape[0]:
        return np.zeros(len(library.feature_names))  # actions of 2 knots or fewer
    return np.median(np.abs(d2), axis=0) / (0.6745 * np.sqrt(6.0))


def _templates(library: ActionLibrary, n: int) -> jax.Array:
    """(A, n, F) each action at ``n`` equally spaced normalized times, held at its
    first and last knot outside them: the linear RBF (paper eq. 1, no polynomial
    term) extrapolates there along no data, and a segment is compared relative to
    its first sample."""
    t = np.linspace(0.0, 1.0, n, dtype=np.float32)
    return jnp.stack([
        a(np.clip(t, a.knot_times[0], a.knot_times[-1])) for a in library.values()])


@functools.partial(jax.jit, static_argnums=(0, 1))
def _segment_costs(metric, n: int, grid_x: jax.Array, n_points: jax.Array,
                   lengths: jax.Array, shortest: jax.Array,
                   templates: jax.Array) -> jax.Array:
    """(P - 1, L, A + 1) costs of the segments of the first ``n_points`` points of
    the padded grid (P, F) (``inf`` past them, and for actions shorter than
    ``shortest`` steps); see `segment_costs`."""
    refs = templates - templates[:, :1]  # each action relative to its start
    refs = jnp.concatenate([refs, jnp.zeros_like(refs[:1])])  # REST: held still
    frac = jnp.linspace(0.0, 1.0, n, dtype=grid_x.dtype)
    points = jnp.arange(grid_x.shape[0], dtype=grid_x.dtype)

    def one(start, length):
        # the grid points start .. start + length, resampled to n
        pos = jnp.minimum(start + frac * length, grid_x.shape[0] - 1)
        seg = jax.vmap(lambda col: jnp.interp(pos, points, col), 1, 1)(grid_x)
        seg = seg - seg[:1]
        costs = jax.vmap(metric, in_axes=(None, 0))(seg, refs)
        costs = jnp.where(length < shortest, costs.at[:-1].set(jnp.inf), costs)
        return jnp.where(start + length < n_points, costs, jnp.inf)

    per_start = jax.vmap(jax.vmap(one, in_axes=(None, 0)), in_axes=(0, None))
    # starts in chunks: one chunk's DTWs are one vectorised scan
    chunks = jnp.arange(grid_x.shape[0] - 1).reshape(-1, _STARTS_PER_CHUNK)
    costs = jax.lax.map(lambda s: per_start(s, lengths), chunks)
    return costs.reshape(-1, *costs.shape[2:])


def best_segmentation(
    costs: jax.Array | np.ndarray, lengths: np.ndarray
) -> tuple[list[tuple[int, int, int]], float]:
    """The segmentation of least duration-weighted cost (dynamic programming).

    Segments cover the grid from point 0 to point G without gaps; segment ``[s, s +
    lengths[k]]`` labelled ``a`` costs ``costs[s, k, a] * lengths[k]``; the last
    label is `REST`, which may not follow a rest.

    Args:
        costs: (G, L, A + 1) as `segment_costs` returns.
        lengths: (L,) segment lengths in grid steps, increasing, >= 1.

    Returns:
        ``([(start, end, label), ...], total)``: grid indices and label indices,
        in order, and the least total cost (``inf``: no segmentation exists).
    """
    costs = jnp.asarray(costs, jnp.float32)
    lengths = np.asarray(lengths, np.int64)
    g = costs.shape[0]
    act, rest, back_act, back_rest = _programme(costs, jnp.asarray(lengths, jnp.int32))
    act, rest = np.asarray(act), np.asarray(rest)
    back_act, back_rest = np.asarray(back_act), np.asarray(back_rest)
    total = float(min(act[g], rest[g]))
    if not np.isfinite(total):
        return [], total
    out = []
    e, in_rest = g, bool(rest[g] < act[g])
    while e > 0:
        if in_rest:
            k, label = int(back_rest[e]), costs.shape[2] - 1
        else:
            k, label = (int(v) for v in back_act[e])
        s = e - int(lengths[k])
        out.append((s, e, label))
        in_rest = False if in_rest else bool(rest[s] < act[s])
        e = s
    return out[::-1], total


@jax.jit
def _programme(costs: jax.Array, lengths: jax.Array):
    """Forward pass of `best_segmentation`: least totals ending in an action
    (G + 1,) and in a rest (G + 1,), and their choices: (G + 1, 2) (length
    index, action) and (G + 1,) (length index)."""
    g, n_len, n_lab = costs.shape
    weighted = costs * lengths[None, :, None].astype(costs.dtype)
    inf = jnp.asarray(jnp.inf, costs.dtype)
    act0 = jnp.full(g + 1, inf).at[0].set(0.0)  # the empty start: anything follows
    rest0 = jnp.full(g + 1, inf)

    def step(carry, e):
        act, rest = carry
        starts = e - lengths
        ok = starts >= 0
        s = jnp.maximum(starts, 0)
        w = weighted[s, jnp.arange(n_len)]  # (L, A + 1)
        before = jnp.where(ok, jnp.minimum(act[s], rest[s]), inf)
        via_act = before[:, None] + w[:, :-1]  # (L, A)
        via_rest = jnp.where(ok, act[s], inf) + w[:, -1]  # (L,)
        flat = jnp.argmin(via_act)
        k_rest = jnp.argmin(via_rest)
        act = act.at[e].set(via_act.reshape(-1)[flat])
        rest = rest.at[e].set(via_rest[k_rest])
        choice = jnp.stack([flat // (n_lab - 1), flat % (n_lab - 1)])
        return (act, rest), (choice, k_rest)

    (act, rest), (choice, k_rest) = jax.lax.scan(
        step, (act0, rest0), jnp.arange(1, g + 1))
    back_act = jnp.concatenate([jnp.zeros((1, 2), choice.dtype), choice])
    back_rest = jnp.concatenate([jnp.zeros((1,), k_rest.dtype), k_rest])
    return act, rest, back_act, back_rest


def segment(
    recording: Demonstration,
    library: ActionLibrary,
    *,
    metric: str = "dtw",
    n_samples: int = 16,
    step_s: float | None = None,
    durations_s: tuple[float, float] | None = None,
    refine: bool = True,
) -> list[Segment]:
    """The sequence of library actions in one recording (segmental search).

    Args:
        recording: the long recording (times in seconds; features named as the
            library's).
        library: the actions to look for (at least one).
        metric: a recognition metric: ``"dtw"`` (paper), ``"dtw_multi"`` or
            ``"euclidean"``.
        n_samples: samples of each candidate segment and action compared.
        step_s: grid step in seconds, the precision of the boundaries (default:
            the recording's duration / 200).
        durations_s: (shortest, longest) duration in seconds of an action (default:
            4 grid steps to the whole recording); a rest lasts one grid step to the
            longest. A range close to the actions' durations is faster and safer.
        refine: refine the boundaries on the recording's samples
            (`refine_boundaries`, the default); ``False`` keeps the search's grid
            points.

    Returns:
        The recognized actions in time order; pauses between them are left out.

    Raises:
        ValueError: a recording that is not a Demonstration or whose features
            differ from the library's, an empty library, a bad metric, sample
            count, step or duration range, or a recording that no segmentation
            covers.
        cgda_jax.sizes.SizeError: too many candidate segments for the memory or
            the DTW work (a larger step_s or a narrower durations_s fits).

    Examples:
        >>> import numpy as np
        >>> t = np.linspace(0.0, 4.0, 81)
        >>> up = Demonstration(t, np.minimum(t, 2.0), ("x",), "up")
        >>> lib = ActionLibrary.from_demonstrations({"up": [up]})
        >>> x = np.r_[np.minimum(t[:41], 2), 2 + np.minimum(t[1:41], 2)]  # up, up
        >>> segs = segment(Demonstration(t, x, ("x",)), lib, step_s=0.1)
        >>> [(s.action, round(s.start, 1), round(s.end, 1)) for s in segs]
        [('up', 0.0, 1.8), ('up', 1.8, 4.0)]

        (At one constant speed nothing marks the junction at 2 s; a human's
        motion slows down between two actions, which `refine_boundaries` fits.)
    """
    grid_t, lengths, costs = segment_costs(
        recording, library, metric=metric, n_samples=n_samples, step_s=step_s,
        durations_s=durations_s)
    path, total = best_segmentation(costs, lengths)
    if not np.isfinite(total):
        step = grid_t[1] - grid_t[0]
        raise ValueError(
            f"segment: recording {recording.name!r} ({recording.duration:.4g} s) "
            f"cannot be split into actions and rests of at most "
            f"{lengths[-1] * step:.4g} s; allow longer segments (durations_s)")
    costs = np.asarray(costs)
    index = {int(v): k for k, v in enumerate(lengths)}
    found = [
        Segment(library.names[a], float(grid_t[s]), float(grid_t[e]),
                float(costs[s, index[e - s], a]))
        for s, e, a in path if a < len(library)
    ]
    return refine_boundaries(recording, found, library) if refine else found


def _fit_gap(t, y, end, start, box_end, box_start):
    """The (end, start) times of least residual around one gap.

    ``end``: (estimate, duration, amplitudes (F,)) of the action before the gap,
    or None (the gap opens the recording); ``start``: the same for the action
    after it, or None (it closes the recording). ``box_*``: (lowest, highest)
    allowed time. The samples from ``_INTO`` durations before the end to
    ``_INTO`` after the start (1 s of rest where a side is missing) are fitted by,
    per feature, a constant plus an amplitude times the minimum-jerk descent
    ending at ``t1`` (over the previous action's duration) plus one times the rise
    starting at ``t0``; ``t1 <= t0``. An amplitude is the given one (the action's
    net change, negated for the descent) where that is finite, fitted where it
    is NaN. Returns ``(t1, t0)``, None for a missing side.
    """
    lo = end[0] - _INTO * end[1] if end else start[0] - 1.0
    hi = start[0] + _INTO * start[1] if start else end[0] + 1.0
    keep = (t >= lo) & (t <= hi)
    tt, yy = t[keep], y[keep]
    c1 = tt[(tt >= box_end[0]) & (tt <= box_end[1])] if end else np.array([np.nan])
    c0 = (tt[(tt >= box_start[0]) & (tt <= box_start[1])] if start
          else np.array([np.nan]))
    # coarse to fine: every few samples, then every sample around the best
    stride = max(int(np.ceil(max(c1.size, c0.size) / _COARSE)), 1)
    arg = _best_pair(tt, yy, end, start, c1[::stride], c0[::stride])
    if stride > 1 and arg is not None:
        half = stride * (t[1] - t[0])
        arg = _best_pair(tt, yy, end, start,
                         c1[np.abs(c1 - arg[0]) <= half] if end else c1,
                         c0[np.abs(c0 - arg[1]) <= half] if start else c0)
    if arg is None:  # the window missed the allowed range
        return (end[0] if end else None), (start[0] if start else None)
    # between the samples: the profiles' ends are continuous times
    step = float(np.median(np.diff(tt))) if tt.size > 1 else 0.0
    off = step * np.linspace(-1.0, 1.0, 2 * _SUBSAMPLE + 1)

    def near(v, box):
        return np.clip(np.clip(v + off, *box), tt[0], tt[-1])

    arg = _best_pair(tt, yy, end, start, near(arg[0], box_end) if end else c1,
                     near(arg[1], box_start) if start else c0) or arg
    return (float(arg[0]) if end else None), (float(arg[1]) if start else None)


def _sample_at(t, time, *, after: bool) -> float:
    """The first sample time at or after ``time`` (``after``), else the last at or
    before it (the recording's ends where none is)."""
    tol = 1e-9 * max(abs(float(time)), 1.0)
    if after:
        return float(t[min(np.searchsorted(t, time - tol, side="left"), t.size - 1)])
    return float(t[max(np.searchsorted(t, time + tol, side="right") - 1, 0)])


def _best_pair(tt, yy, end, start, c1, c0):
    """`_fit_gap`'s search over the candidate end times ``c1`` and start times
    ``c0`` (``[nan]`` for a missing side): the (t1, t0) of least residual, or None
    when no pair is allowed. The features are fitted in groups by which of their
    amplitudes are fixed: the fixed profiles are subtracted, the constant and the
    free amplitudes solved by least squares."""
    t1, t0 = (v.ravel() for v in np.meshgrid(c1, c0, indexing="ij"))
    ok = np.isnan(t1) | np.isnan(t0) | (t1 <= t0)
    t1, t0 = t1[ok], t0[ok]
    if t1.size == 0:
        return None
    best, arg = np.inf, None
    amp1 = end[2] if end else np.full(yy.shape[1], np.nan)
    amp0 = start[2] if start else np.full(yy.shape[1], np.nan)
    groups = [(f1, f0, np.flatnonzero((np.isnan(amp1) == f1) & (np.isnan(amp0) == f0)))
              for f1 in (False, True) for f0 in (False, True)]
    groups = [g for g in groups if g[2].size]
    for i in range(0, t1.size, _PAIRS_PER_CHUNK):
        a, b = t1[i:i + _PAIRS_PER_CHUNK], t0[i:i + _PAIRS_PER_CHUNK]
        m1 = (min_jerk_np((a[:, None] - tt[None]) / end[1]) if end
              else np.zeros((a.size, tt.size)))
        m0 = (min_jerk_np((tt[None] - b[:, None]) / start[1]) if start
              else np.zeros((a.size, tt.size)))
        residual = np.zeros(a.size)
        for free1, free0, f in groups:
            yf = yy[None, :, f]
            if not free1 and end:
                yf = yf - m1[:, :, None] * amp1[f]
            if not free0 and start:
                yf = yf - m0[:, :, None] * amp0[f]
            cols = [np.ones((a.size, tt.size))]
            if free1 and end:
                cols.append(m1)
            if free0 and start:
                cols.append(m0)
            x = np.stack(cols, -1)  # (pairs, samples, basis)
            xt = x.transpose(0, 2, 1)
            gram = xt @ x + 1e-12 * np.eye(x.shape[-1])
            rhs = xt @ yf
            residual += (np.sum(yf**2, axis=(1, 2))
                         - np.sum(rhs * np.linalg.solve(gram, rhs), axis=(1, 2)))
        j = int(np.argmin(residual))
        if residual[j] < best:
            best, arg = residual[j], (a[j], b[j])
    return arg


def _amplitude(t, y, start, end, duration):
    """(F,) each feature's net change over the action ``start .. end`` (medians of
    the samples within ``_LEVEL`` of its duration of each end), NaN for a feature
    whose net change is below ``_MONOTONE`` of its range over the action (it goes
    and comes back: its amplitude is fitted)."""
    half = _LEVEL * duration
    before = np.median(y[(t >= start - half) & (t <= start)], axis=0)
    after = np.median(y[(t >= end) & (t <= end + half)], axis=0)
    inside = y[(t >= start) & (t <= end)]
    delta = after - before
    span = np.ptp(inside, axis=0) if inside.shape[0] else np.abs(delta)
    return np.where(np.abs(delta) >= _MONOTONE * span, delta, np.nan)


def _moved_features(library: ActionLibrary | None, segments: Sequence[Segment],
                    n_features: int) -> list[np.ndarray]:
    """(F,) booleans per segment: the features its action moves, by the library
    (the range of the action's knots at least ``_MOVES`` times the library's noise
    of the feature, and the feature of the largest such ratio in any case: with
    few knots the noise estimate holds the motion's own curvature); every feature
    without a library."""
    if library is None:
        return [np.ones(n_features, bool)] * len(segments)
    noise = _library_noise(library)
    moved = {}
    for name, a in library.items():
        span = np.ptp(np.asarray(a.knots, np.float64), axis=0)
        ratio = np.where(noise > 0, span / np.where(noise > 0, noise, 1.0),
                         np.where(span > 0, np.inf, 0.0))
        moved[name] = (ratio >= _MOVES) | (ratio == ratio.max())
    return [moved[s.action] for s in segments]


def _drift(t, y, segments, moves) -> np.ndarray:
    """(F,) each feature's drift (units per second) where no action moves it: the
    least-squares slope within the segments whose action holds it still, pooled
    (each segment its own level); 0 where every segment moves it."""
    num = np.zeros(y.shape[1])
    den = np.zeros(y.shape[1])
    for s, m in zip(segments, moves):
        inside = (t >= s.start) & (t <= s.end)
        if inside.sum() < 2:
            continue
        dt = t[inside] - t[inside].mean()
        dy = y[inside] - y[inside].mean(axis=0)
        num += np.where(m, 0.0, dt @ dy)
        den += np.where(m, 0.0, dt @ dt)
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def refine_boundaries(recording: Demonstration, segments: Sequence[Segment],
                      library: ActionLibrary | None = None) -> list[Segment]:
    """The segments' starts and ends refined on the recording's samples.

    Each gap between two segments (and the stretches before the first and after
    the last) is fitted by the object at rest between a minimum-jerk end of the
    action before and a minimum-jerk start of the action after (`segment`, step
    4), each feature in units of its noise (in the recording, or in the library
    where given and larger: as the search), on the samples from 0.2 of the
    actions' durations inside them; a feature's amplitude is the action's net
    change (medians of the samples within 5 % of its duration of the given start
    and end) where that is at least 80 % of the feature's range over the action,
    fitted otherwise. With a library, a feature the action does not move (its
    knots' range under 10 times the library's noise of it, and not the action's
    most moved feature) is held still in that
    action's fit, and each feature's drift where no action moves it (the pooled
    slope inside those segments: light that dims) is taken out of the recording
    first. The end and start times (the end not after the start) within ``0.25``
    of each action's duration of the given boundaries (the end's and the next
    start's ranges joined: one gap) are chosen jointly by least residual, on the
    samples and then between them (a quarter sample apart), the window recentred
    and refitted, with each action's duration and net change measured anew, until
    it settles (at most 10 rounds). Each start is then reported as the last
    sample at or before the fitted time, each end as the first at or after it
    (the samples at rest either side of the motion); back to back, where the two
    cross, as the samples either side of the junction.

    Args:
        recording: the recording the segments were found in.
        segments: its action segments in time order (as `segment` with
            ``refine=False`` returns them).
        library: the library they were found with (`segment` passes it): its
            noise is each feature's least unit, its actions say which features
            each moves. None: the recording's noise only, every feature moved.

    Returns:
        The same segments with refined ``start`` and ``end`` (seconds, times of
        the recording's samples); actions and costs unchanged.
    """
    if not segments:
        return []
    t = recording.times
    y = recording.features / _scale(recording, library)
    n = len(segments)
    dur = [s.end - s.start for s in segments]
    box = [[s.start - _REACH * d, s.start + _REACH * d, s.end - _REACH * d,
            s.end + _REACH * d] for s, d in zip(segments, dur)]
    # the end and the start around one gap share their ranges: where the search
    # misplaced the gap, the junction may lie in either one's (a short search
    # segment's own range is short)
    for g in range(1, n):
        lo, hi = min(box[g - 1][2], box[g][0]), max(box[g - 1][3], box[g][1])
        box[g - 1][2:], box[g][:2] = [lo, hi], [lo, hi]
    starts = [s.start for s in segments]
    ends = [s.end for s in segments]
    moves = _moved_features(library, segments, y.shape[1])
    # a feature drifting where no action moves it (light that dims): detrended
    y = y - np.outer(t - t[0], _drift(t, y, segments, moves))
    for _ in range(_ROUNDS):
        dur = [b - a for a, b in zip(starts, ends)]  # the profiles' durations
        amp = [np.where(m, _amplitude(t, y, a, b, d), 0.0)
               for m, a, b, d in zip(moves, starts, ends, dur)]
        new_starts, new_ends = list(starts), list(ends)
        for g in range(n + 1):
            before = (ends[g - 1], dur[g - 1], -amp[g - 1]) if g > 0 else None
            after = (starts[g], dur[g], amp[g]) if g < n else None
            t1, t0 = _fit_gap(t, y, before, after,
                              box[g - 1][2:] if g > 0 else None,
                              box[g][:2] if g < n else None)
            if g > 0:
                new_ends[g - 1] = t1
            if g < n:
                new_starts[g] = t0
        if new_starts == starts and new_ends == ends:
            break
        starts, ends = new_starts, new_ends
    # reported as samples: the last at rest before each motion, the first after
    # it; back to back, where these cross, the samples either side of the junction
    starts = [_sample_at(t, v, after=False) for v in starts]
    ends = [_sample_at(t, v, after=True) for v in ends]
    for g in range(1, n):
        if ends[g - 1] > starts[g]:
            ends[g - 1], starts[g] = starts[g], ends[g - 1]
    return [s._replace(start=float(a), end=float(b))
            for s, a, b in zip(segments, starts, ends)]


def execute_sequence(
    sim: Any,
    goals: Sequence[Any],
    run: Callable[..., Any] | Sequence[Callable[..., Any]],
    *,
    carry_state: bool = True,
    **settings: Any,
) -> list[Any]:
    """Execute goals one after another, each starting where the previous left the
    object.

    Goal ``k > 0`` is moved (every point by the same offset) so that its first point
    is the last feature point that execution ``k - 1`` reached; the first goal is
    executed as given. With ``carry_state`` (the default), execution ``k > 0`` also
    starts from the simulator state in which execution ``k - 1`` ended: its posture
    and its scene's state (the paint wall's painted squares), so a second PAINT
    goes on painting the wall the first one left, from where the arm stands. That
    state is what the strategy's simulator gives as `init_state()`, where every
    strategy starts its executions. A thin composition: each goal is one call of
    a strategy.

    Args:
        sim: the simulator every goal is executed on (same features as the goals).
        goals: K goal feature trajectories (N_k, F), e.g. the knots of the
            recognized actions (``library[s.action].knots`` for each `Segment`).
        run: a strategy function (`cgda_jax.strategies.run_ie`, ``run_iet``, ...)
            called as ``run(sim, goal, **settings)``, or one per goal.
        carry_state: start each execution after the first from the previous one's
            final state (its joints replayed on the simulator); False: every
            execution starts from ``sim.init_state()``.
        **settings: passed to every call (population_size, tolerance, seed, ...).

    Returns:
        The K `cgda_jax.strategies.ExecutionResult`s in order; result ``k``'s
        ``goal`` is the moved goal it executed.

    Raises:
        ValueError: no goals, a goal that is not (N, F) with the simulator's
            feature count, or a run list of another length.
    """
    goals = [np.asarray(g, np.float64) for g in goals]
    if not goals:
        raise ValueError("execute_sequence: no goals given")
    runs = list(run) if isinstance(run, Sequence) else [run] * len(goals)
    if len(runs) != len(goals):
        raise ValueError(f"execute_sequence: {len(runs)} strategies for "
                         f"{len(goals)} goals")
    n_features = getattr(sim, "n_features", None)
    for k, g in enumerate(goals):
        if g.ndim != 2 or g.shape[0] < 1 or (
                n_features is not None and g.shape[1] != n_features):
            raise ValueError(f"execute_sequence: goal {k} has shape {g.shape}; "
                             f"expected (N, {n_features}) for this simulator")
    results, here, current = [], None, sim
    for goal, fn in zip(goals, runs):
        if here is not None:
            goal = goal - goal[0] + here
        result = fn(current, goal, **settings)
        results.append(result)
        here = np.asarray(result.features)[-1]
        joints = np.asarray(result.joints)
        if carry_state and np.all(np.isfinite(joints)):
            final = current.rollout(joints, current.init_state())[1]
            current = _continued(sim, final)
    return results


def _continued(sim: Any, state: Any) -> Any:
    """A shallow copy of ``sim`` whose `init_state()` (no posture given) is
    ``state``, a previous execution's final state, with its feasibility
    violations cleared (each execution is judged on its own moves)."""
    if getattr(state, "violation", None) is not None:
        zero = jnp.float32(0.0)
        state = state.replace(violation=zero, move_violation=zero)
    other = copy.copy(sim)

    def init_state(genes0=None):
        return state if genes0 is None else sim.init_state(genes0)

    other.init_state = init_state
    return other
