"""Feature and demonstration selection by DTW z-scores (the CGDA authors' follow-up).

Irrelevant features hurt recognition (paper Tables 2-3). The authors' follow-up
(xgnitive, ``programs/demonstration-feature-selection``) picks what to keep from
the demonstrations of ONE action alone:

* features (`select_features`): for each feature column, the 1-D DTW of every
  ordered pair of demonstrations (``i, j`` both over all demonstrations, so each
  unordered pair twice and each demonstration with itself, which adds 0), summed;
  the z-scores of these per-feature sums (population standard deviation, as
  ``scipy.stats.zscore``); a feature whose z-score exceeds ``alpha`` varies much
  more between the demonstrations than the others and is discarded;
* demonstrations (`select_demonstrations`): each demonstration collapsed to one
  series (the sum over its feature columns at each sample), the DTW of every
  ordered pair, the column sums of that dissimilarity matrix normalised to sum 1,
  their z-scores; a demonstration whose z-score exceeds ``alpha`` is an outlier.

The DTW is the authors' (and `cgda_jax.distance.dtw`'s per feature): local cost
``|x_i - y_j|``, steps (1, 0), (0, 1), (1, 1), accumulated cost divided by
``N + M``. Before it, each demonstration is normalised as the authors' scripts
offer (`NORMALIZATIONS`): ``"none"``; ``"minmax"`` each demonstration's columns to
[0, 1] (a constant column to 0); ``"standardized"`` each demonstration's columns to
zero mean and unit (population) standard deviation (a constant column to 0);
``"whole-experiment"`` every column divided by its largest value over all the
demonstrations (not its largest magnitude: a negative maximum flips the sign, as
in the authors' code).

All pairs of all demonstrations and all features are one jitted call
(`jax.vmap` of `cgda_jax.distance.dtw_per_feature` over the pairs, the
demonstrations padded to one length). Normalisation and z-scores run on the host
in float64; the DTW runs in JAX's float32 (float64 with ``jax_enable_x64``) on
each column shifted by a constant (the mid-range over all demonstrations): DTW
with ``|x - y|`` costs does not change under a common shift, and without it a
nearly constant column (a static arm's pose, 0.3469 m +- 1e-6) would lose its
differences to float32's rounding.

References:
    Morante et al., "Humanoid Robot Imitation through Continuous Goal-Directed
    Actions: An Evolutionary Approach", Advanced Robotics 2015, Tables 2-3.
    roboticslab-uc3m/xgnitive, ``programs/demonstration-feature-selection/src``
    (``main-feature-selector.py``, ``main-demons-selector.py``, ``libtools.py``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from cgda_jax.data import Demonstration, validate_demonstrations
from cgda_jax.distance import dtw_per_feature
from cgda_jax.sizes import MAX_DTW_CELLS, SizeError, check_elements

__all__ = [
    "NORMALIZATIONS",
    "DemonstrationSelection",
    "FeatureSelection",
    "normalize",
    "pairwise_dtw",
    "select_demonstrations",
    "select_features",
    "zscores",
]

#: The normalizations of the authors' scripts (NONE, MINMAX, STANDARDIZED,
#: WHOLE-EXPERIMENT), in lower case; upper case is accepted too.
NORMALIZATIONS: tuple[str, ...] = ("none", "minmax", "standardized", "whole-experiment")


def _check_normalization(normalization: str) -> str:
    norm = str(normalization).lower()
    if norm not in NORMALIZATIONS:
        raise ValueError(
            f"unknown normalization {normalization!r}; expected one of "
            f"{NORMALIZATIONS}")
    return norm


def _check_alpha(alpha: float) -> float:
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not (
            math.isfinite(alpha)):
        raise ValueError(f"alpha must be a finite number, got {alpha!r}")
    return float(alpha)


def _check_demos(demos: Sequence[Demonstration], where: str) -> list[Demonstration]:
    validate_demonstrations(demos)
    demos = list(demos)
    if len(demos) < 2:
        raise ValueError(f"{where}: needs at least 2 demonstrations, got {len(demos)}")
    return demos


def _unit_columns(x: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``x / scale`` per column, a zero scale taken as 1 (as scikit-learn does)."""
    return x / np.where(scale == 0.0, 1.0, scale)


def normalize(demos: Sequence[Demonstration], normalization: str = "none"
              ) -> list[np.ndarray]:
    """The demonstrations' features normalised as the authors' scripts do.

    Args:
        demos: D demonstrations of one action (same features).
        normalization: one of `NORMALIZATIONS` (see the module docstring).

    Returns:
        D float64 arrays, (T_k, F) each.

    Raises:
        ValueError: an unknown normalization, or ``"whole-experiment"`` with a
            column whose largest value over all demonstrations is 0 (named).
    """
    norm = _check_normalization(normalization)
    validate_demonstrations(demos)
    feats = [np.asarray(d.features, np.float64) for d in demos]
    if norm == "minmax":
        return [_unit_columns(f - f.min(axis=0), np.ptp(f, axis=0)) for f in feats]
    if norm == "standardized":
        return [_unit_columns(f - f.mean(axis=0), f.std(axis=0)) for f in feats]
    if norm == "whole-experiment":
        top = np.max(np.concatenate(feats), axis=0)
        if np.any(top == 0.0):
            names = [demos[0].feature_names[i] for i in np.flatnonzero(top == 0.0)]
            raise ValueError(
                f"normalization 'whole-experiment' divides each feature by its "
                f"largest value over all demonstrations, which is 0 for {names}")
        return [f / top for f in feats]
    return feats


def zscores(values: np.ndarray) -> np.ndarray:
    """``(v - mean) / std`` (population std, as ``scipy.stats.zscore``); NaN where
    all values are equal."""
    v = np.asarray(values, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (v - v.mean()) / v.std()


#: The padded length of `pairwise_dtw` is a multiple of this (fewer compiles).
_PAD_TO = 64


@jax.jit
def _pairwise(series: jax.Array, lengths: jax.Array) -> jax.Array:
    """(D, D, C) `dtw_per_feature` of every ordered pair of the padded series
    (D, T, C) with valid lengths (D,)."""
    row = jax.vmap(dtw_per_feature, in_axes=(None, 0, None, 0))
    return jax.vmap(row, in_axes=(0, None, 0, None))(series, series, lengths, lengths)


def pairwise_dtw(series: Sequence[np.ndarray]) -> np.ndarray:
    """Per-column DTW (authors' cost, `dtw_per_feature`) of every ordered pair.

    One jitted call: the series are shifted per column by their common mid-range
    (see the module docstring), padded with zeros to the longest (rounded up to a
    multiple of 64 samples, so that nearby lengths reuse one compiled program) and
    batched with ``vmap``.

    Args:
        series: D arrays (T_k, C) or (T_k,), the same C, T_k >= 1.

    Returns:
        (D, D, C) float64 costs (C dropped for 1-D series); entry (i, j, c) is the
        DTW of column c of series i and series j.

    Raises:
        cgda_jax.sizes.SizeError: more than `cgda_jax.sizes.MAX_DTW_CELLS` DTW
            cells, or a scan carry beyond the memory (before allocating).
    """
    arrs = [np.asarray(s, np.float64) for s in series]
    flat = arrs[0].ndim == 1
    arrs = [a[:, None] if a.ndim == 1 else a for a in arrs]
    stacked = np.concatenate(arrs)
    centre = 0.5 * (stacked.max(axis=0) + stacked.min(axis=0))
    # padded to a multiple of _PAD_TO samples: nearby lengths share one program
    t_max = -(-max(a.shape[0] for a in arrs) // _PAD_TO) * _PAD_TO
    d, c = len(arrs), stacked.shape[1]
    what = f"{d} x {d} pairs x {c} columns x {t_max:,} padded samples"
    if d * d * c * t_max * t_max > MAX_DTW_CELLS:
        raise SizeError(f"pairwise_dtw: {what} is {d * d * c * t_max**2:.3g} DTW "
                        f"cells, more than {MAX_DTW_CELLS:.0e} (about 20 min at 1e9 "
                        "cells/s); decimate the demonstrations")
    check_elements(4 * d * d * c * (t_max + 1), "pairwise_dtw", what)  # the carry
    padded = np.zeros((len(arrs), t_max, stacked.shape[1]))
    for k, a in enumerate(arrs):
        padded[k, : a.shape[0]] = a - centre
    lengths = np.array([a.shape[0] for a in arrs], np.int32)
    out = np.asarray(_pairwise(jnp.asarray(padded), jnp.asarray(lengths)), np.float64)
    return out[..., 0] if flat else out


@dataclasses.dataclass(frozen=True)
class FeatureSelection:
    """Result of `select_features`.

    Attributes:
        feature_names: (F,) the features, in the demonstrations' order.
        distances: (F,) each feature's DTW summed over all ordered pairs.
        pairwise: (D, D, F) the DTW of each ordered pair per feature.
        zscores: (F,) z-scores of ``distances`` (NaN if all are equal).
        selected: (F,) bool, True where the feature is kept (z-score <= alpha or
            NaN), False where it is discarded.
        normalization, alpha: as given.
    """

    feature_names: tuple[str, ...]
    distances: np.ndarray
    pairwise: np.ndarray
    zscores: np.ndarray
    selected: np.ndarray
    normalization: str
    alpha: float

    @property
    def selected_names(self) -> tuple[str, ...]:
        """The kept features, in order."""
        return tuple(n for n, s in zip(self.feature_names, self.selected) if s)

    def apply(self, demos: Sequence[Demonstration]) -> list[Demonstration]:
        """The demonstrations with only the kept feature columns."""
        return [d.select(self.selected_names) for d in demos]


@dataclasses.dataclass(frozen=True)
class DemonstrationSelection:
    """Result of `select_demonstrations`.

    Attributes:
        names: (D,) the demonstrations' names.
        distances: (D, D) DTW of the summed series of each ordered pair.
        dissimilarity: (D,) column sums of ``distances`` divided by their total.
        zscores: (D,) z-scores of ``dissimilarity`` (NaN if all are equal).
        selected: (D,) bool, True where the demonstration is kept (z-score <=
            alpha or NaN), False for an outlier.
        normalization, alpha: as given.
    """

    names: tuple[str, ...]
    distances: np.ndarray
    dissimilarity: np.ndarray
    zscores: np.ndarray
    selected: np.ndarray
    normalization: str
    alpha: float

    def apply(self, demos: Sequence[Demonstration]) -> list[Demonstration]:
        """The kept demonstrations, in order."""
        if len(demos) != len(self.selected):
            raise ValueError(f"the selection is of {len(self.selected)} "
                             f"demonstrations, got {len(demos)}")
        return [d for d, s in zip(demos, self.selected) if s]


def select_features(
    demos: Sequence[Demonstration], normalization: str = "none", alpha: float = 0.5
) -> FeatureSelection:
    """Discard the features whose DTW across demonstrations is an outlier.

    Args:
        demos: D >= 2 demonstrations of one action (same features).
        normalization: one of `NORMALIZATIONS` (case-insensitive).
        alpha: a feature with z-score above it is discarded (authors: 0.5).

    Returns:
        FeatureSelection (distances, z-scores, selected per feature).

    Raises:
        ValueError: fewer than 2 demonstrations, different features, a bad
            normalization or alpha.

    Examples:
        >>> import numpy as np
        >>> from cgda_jax.data import Demonstration
        >>> t = np.linspace(0.0, 1.0, 20)
        >>> demos = [Demonstration(t, np.stack([t, t + 0.01 * k, 5.0 * k * t], 1),
        ...                        ("a", "b", "noise")) for k in range(3)]
        >>> select_features(demos).selected_names
        ('a', 'b')
    """
    where = "select_features"
    demos = _check_demos(demos, where)
    norm, alpha = _check_normalization(normalization), _check_alpha(alpha)
    pairwise = pairwise_dtw(normalize(demos, norm))
    distances = pairwise.sum(axis=(0, 1))
    z = zscores(distances)
    return FeatureSelection(demos[0].feature_names, distances, pairwise, z,
                            ~(z > alpha), norm, alpha)


def select_demonstrations(
    demos: Sequence[Demonstration], normalization: str = "none", alpha: float = 0.5
) -> DemonstrationSelection:
    """Discard the demonstrations that are outliers by DTW to the others.

    Args:
        demos: D >= 2 demonstrations of one action (same features).
        normalization: one of `NORMALIZATIONS` (case-insensitive).
        alpha: a demonstration with z-score above it is discarded (authors: 0.5).

    Returns:
        DemonstrationSelection (distances, dissimilarity, z-scores, selected per
        demonstration).

    Raises:
        ValueError: as `select_features`.
    """
    where = "select_demonstrations"
    demos = _check_demos(demos, where)
    norm, alpha = _check_normalization(normalization), _check_alpha(alpha)
    summed = [f.sum(axis=1) for f in normalize(demos, norm)]
    distances = pairwise_dtw(summed)
    col = distances.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        dissimilarity = col / col.sum()
    z = zscores(dissimilarity)
    return DemonstrationSelection(tuple(d.name for d in demos), distances,
                                  dissimilarity, z, ~(z > alpha), norm, alpha)
