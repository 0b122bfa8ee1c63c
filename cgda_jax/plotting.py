"""Figures of the paper from host arrays (matplotlib, Agg backend).

Every function takes NumPy-convertible arrays (or objects with ``sample``), returns
the ``matplotlib.figure.Figure`` and, given ``path``, also saves it as a PNG. No JAX
transforms happen here.

================================  ===========================================
paper figure / table              function
================================  ===========================================
Fig. 2, Fig. 7                    :func:`plot_demonstrations`
Tables 2-4                        :func:`plot_cost_matrix`
Fig. 4                            :func:`plot_fitness`
Fig. 5, 6, 10                     :func:`plot_goal_vs_executed`
Fig. 9                            :func:`plot_time_per_point`
Fig. 8, 11                        :func:`plot_frames`
================================  ===========================================
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import matplotlib

if os.environ.get("MPLBACKEND") is None:
    matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

__all__ = [
    "plot_cost_matrix",
    "plot_demonstrations",
    "plot_fitness",
    "plot_frames",
    "plot_goal_vs_executed",
    "plot_time_per_point",
]

_DEMO, _GOAL, _EXEC = "0.25", "tab:blue", "tab:red"


def _finish(fig: Figure, path: str | os.PathLike | None, *, tight: bool = True) -> Figure:
    if tight:  # one extra layout pass (~0.05-0.1 s a figure); skipped for fixed grids
        fig.tight_layout()
    if path is not None:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        fig.savefig(path, dpi=110)
    return fig


def _as_curve(x, n: int = 200) -> np.ndarray:
    """(T, F) host array from an array or a GeneralizedAction (``sample(n)``)."""
    if hasattr(x, "sample"):
        x = _sample_host(x, n)
    x = np.asarray(x, dtype=float)
    return x[:, None] if x.ndim == 1 else x


def _sample_host(action, n: int) -> np.ndarray:
    """``action.sample(n)`` (n, F) evaluated in NumPy: no JAX dispatch or compile.

    A GeneralizedAction's linear RBF through sorted knots is the piecewise linear
    interpolant between them, continued beyond the outer knots with slopes
    -/+ ``sum(weights)``; anything else falls back to ``action.sample(n)``.
    """
    try:
        kt = np.asarray(action.knot_times, dtype=float)
        knots = np.asarray(action.knots, dtype=float)
        slope = np.asarray(action.weights, dtype=float).sum(axis=0)
    except AttributeError:
        return np.asarray(action.sample(n), dtype=float)
    if kt.ndim != 1 or len(kt) < 2 or np.any(np.diff(kt) <= 0):
        return np.asarray(action.sample(n), dtype=float)
    t = np.linspace(0.0, 1.0, n)
    out = np.stack([np.interp(t, kt, knots[:, f]) for f in range(knots.shape[1])], axis=1)
    left, right = t < kt[0], t > kt[-1]
    out[left] = knots[0] + (kt[0] - t[left])[:, None] * slope
    out[right] = knots[-1] + (t[right] - kt[-1])[:, None] * slope
    return out


def _select(names: Sequence[str], features) -> list[int]:
    """Column indices of ``features`` (names or indices; None = all)."""
    if features is None:
        return list(range(len(names)))
    out = []
    for f in features:
        if isinstance(f, str):
            if f not in names:
                raise KeyError(f"feature {f!r} not in {list(names)}")
            out.append(list(names).index(f))
        else:
            out.append(int(f))
    return out


def _equal_3d(ax, curves: Sequence[np.ndarray], min_share: float = 0.4) -> None:
    """True geometry (a circle looks like a circle) with room for every axis' ticks.

    Each axis spans at least ``min_share`` of the largest data range (centred on
    its data), so a flat trajectory does not squeeze one axis' tick labels
    together; at most 3 ticks per axis.
    """
    pts = np.concatenate([np.asarray(c, float).reshape(-1, 3) for c in curves])
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if not len(pts):
        return
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = np.maximum(hi - lo, min_share * max(float((hi - lo).max()), 1e-9))
    mid = (lo + hi) / 2
    for k, setter in enumerate((ax.set_xlim, ax.set_ylim, ax.set_zlim)):
        setter(mid[k] - span[k] / 2, mid[k] + span[k] / 2)
    ax.set_box_aspect(span / span.max(), zoom=0.85)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(nbins=3))
    ax.tick_params(labelsize=8)


def plot_demonstrations(
    demos: Sequence,
    generalized=None,
    executed=None,
    *,
    features: Sequence[str | int] | None = None,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Demonstrations (black), their generalization (blue), an execution (red).

    With three selected features the trajectories are drawn in 3-D feature space as
    in the paper's Fig. 2 and 7; otherwise one panel per feature over normalized time.

    Args:
        demos: Demonstrations (``times (T_k,)``, ``features (T_k, F)``).
        generalized: a GeneralizedAction or an array (N, F); knots are marked.
        executed: executed feature trajectory (N, F), e.g. ``ExecutionResult.features``.
        features: names or indices of the features to draw (default: all).
        title: figure title.
        path: PNG file to write.
    """
    names = tuple(demos[0].feature_names) if demos else tuple(
        f"f{i}" for i in range(_as_curve(generalized).shape[1])
    )
    cols = _select(names, features)
    gen_curve = None if generalized is None else _as_curve(generalized)[:, cols]
    knots = getattr(generalized, "knots", None)
    knots = None if knots is None else np.asarray(knots)[:, cols]
    ex = None if executed is None else _as_curve(executed)[:, cols]
    if len(cols) == 3:
        fig = plt.figure(figsize=(6.4, 5.2))
        ax = fig.add_subplot(projection="3d")
        for k, d in enumerate(demos):
            f = np.asarray(d.features)[:, cols]
            ax.plot(
                *f.T, color=_DEMO, lw=0.6, alpha=0.6,
                label="demonstrations" if k == 0 else None,
            )
        if gen_curve is not None:
            ax.plot(*gen_curve.T, color=_GOAL, lw=2.2, label="generalization")
        if knots is not None:
            ax.scatter(*knots.T, color=_GOAL, s=14)
        if ex is not None:
            ax.plot(*ex.T, "-o", color=_EXEC, lw=1.8, ms=3, label="executed")
        _equal_3d(ax, [np.asarray(d.features)[:, cols] for d in demos]
                  + [c for c in (gen_curve, ex) if c is not None])
        ax.set_xlabel(names[cols[0]], labelpad=6)
        ax.set_ylabel(names[cols[1]], labelpad=6)
        ax.set_zlabel(names[cols[2]], labelpad=6)
        ax.legend(loc="upper left", fontsize=8)
    else:
        n = len(cols)
        ncol = min(n, 4)
        nrow = -(-n // ncol)
        fig, axes = plt.subplots(nrow, ncol, figsize=(3.2 * ncol, 2.4 * nrow), squeeze=False)
        for i, c in enumerate(cols):
            ax = axes.flat[i]
            for d in demos:
                t = np.asarray(d.times, dtype=float)
                t = (t - t[0]) / max(t[-1] - t[0], 1e-12)
                ax.plot(t, np.asarray(d.features)[:, c], color=_DEMO, lw=0.7)
            if gen_curve is not None:
                ax.plot(np.linspace(0, 1, len(gen_curve)), gen_curve[:, i], color=_GOAL, lw=2)
            if ex is not None:
                ax.plot(np.linspace(0, 1, len(ex)), ex[:, i], "-o", color=_EXEC, ms=3)
            ax.set_title(names[c], fontsize=9)
            ax.set_xlabel("normalized time", fontsize=8)
        for ax in list(axes.flat)[n:]:
            ax.set_visible(False)
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


def plot_cost_matrix(
    matrix,
    queries: Sequence[str],
    references: Sequence[str],
    *,
    label: str = "cost",
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Cost matrix (Q, A) as an annotated heatmap, row minima in bold (Tables 2-4).

    Rows are test actions (lower case in the paper), columns generalized ones.
    Colours follow the cost on a log scale (bright = low cost = similar, with a
    colorbar), so costs spanning orders of magnitude stay readable; the lowest
    cost of each row (the recognized action) is printed in bold.

    Args:
        matrix: costs (Q, A).
        queries, references: Q row and A column names.
        label: what the numbers are (colorbar label).
    """
    m = np.asarray(matrix, dtype=float)
    if m.shape != (len(queries), len(references)):
        raise ValueError(
            f"matrix shape {m.shape} does not match {len(queries)} queries x "
            f"{len(references)} references"
        )
    fig, ax = plt.subplots(figsize=(1.3 * len(references) + 2.4, 0.7 * len(queries) + 1.6))
    positive = np.maximum(m, 1e-12)
    lo, hi = positive.min(), positive.max()
    norm = LogNorm(lo, hi if hi > lo else lo * 10)
    image = ax.imshow(positive, cmap="viridis_r", norm=norm)
    bar = fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04)
    bar.set_label(f"{label} (log scale)\nbright = low = similar", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    best = m.argmin(axis=1)
    shown = norm(positive)
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            v = m[i, j]
            text = f"{v:.4g}" if abs(v) < 1e5 else f"{v:.3e}"
            ax.text(
                j, i, text, ha="center", va="center", fontsize=9,
                fontweight="bold" if j == best[i] else "normal",
                color="black" if shown[i, j] < 0.5 else "white",
            )
    ax.set_xticks(range(len(references)), [r.upper() for r in references])
    ax.set_yticks(range(len(queries)), [q.lower() for q in queries])
    ax.xaxis.tick_top()
    if title:
        ax.set_title(title, fontsize=10, pad=24)
    return _finish(fig, path)


def plot_fitness(
    history,
    *,
    labels: Sequence[str] | None = None,
    log: bool = True,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Best fitness per generation, its minimum marked in red (Fig. 4).

    Args:
        history: (G,) for one evolution, or (P, G) for P evolutions (IE / IET
            points); non-finite entries (generations not run) are dropped.
        labels: one label per row when ``history`` is 2-D.
        log: logarithmic y axis (when all values are positive).
    """
    h = np.asarray(history, dtype=float)
    h = h[None] if h.ndim == 1 else h
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    positive = True
    for k, row in enumerate(h):
        g = np.flatnonzero(np.isfinite(row))
        if g.size == 0:
            continue
        y = row[g]
        positive &= bool(np.all(y > 0))
        lab = labels[k] if labels is not None else None
        ax.plot(g, y, lw=1.2 if h.shape[0] == 1 else 0.8, label=lab)
        if h.shape[0] == 1:
            i = int(np.argmin(y))
            ax.plot(g[i], y[i], "o", color="red", ms=7, label=f"min {y[i]:.4g}")
    if log and positive:
        ax.set_yscale("log")
    ax.set_xlabel("generation")
    ax.set_ylabel("best fitness")
    if labels is not None or h.shape[0] == 1:
        ax.legend(fontsize=8, ncol=2 if h.shape[0] > 6 else 1)
    if title:
        ax.set_title(title)
    return _finish(fig, path)


def plot_goal_vs_executed(
    goal,
    executed,
    feature_names: Sequence[str] | None = None,
    *,
    tolerance: float | None = None,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """One panel per feature: goal (blue) vs executed (red) per point (Fig. 5/6/10).

    Args:
        goal: reference feature trajectory (N, F).
        executed: executed features (N, F) (or (M, F): drawn on its own point axis).
        feature_names: F names for the panel titles.
        tolerance: if given, shades goal +/- tolerance in each panel.
    """
    g, e = _as_curve(goal), _as_curve(executed)
    if g.shape[1] != e.shape[1]:
        raise ValueError(f"goal {g.shape} and executed {e.shape} have different F")
    names = list(feature_names) if feature_names is not None else [
        f"feature {i}" for i in range(g.shape[1])
    ]
    f = g.shape[1]
    fig, axes = plt.subplots(f, 1, figsize=(6.0, 2.1 * f + 0.6), squeeze=False, sharex=True)
    for i, ax in enumerate(axes[:, 0]):
        x = np.arange(len(g))
        ax.plot(x, g[:, i], "-o", color=_GOAL, ms=3, label="goal (generalized)")
        ax.plot(np.arange(len(e)), e[:, i], "-s", color=_EXEC, ms=3, label="executed")
        if tolerance is not None:
            ax.fill_between(x, g[:, i] - tolerance, g[:, i] + tolerance, color=_GOAL, alpha=0.15)
        ax.set_ylabel(names[i])
    axes[0, 0].legend(fontsize=8)
    axes[-1, 0].set_xlabel("trajectory point")
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


def plot_time_per_point(
    seconds,
    *,
    ylabel: str = "time per point [s]",
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Time (or generations, evaluations) spent on each point of an IET run (Fig. 9)."""
    s = np.asarray(seconds, dtype=float).ravel()
    fig, ax = plt.subplots(figsize=(6.0, 3.4))
    ax.bar(np.arange(len(s)), s, color="tab:gray")
    ax.set_xlabel("trajectory point")
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    return _finish(fig, path)


def plot_frames(
    frames: Sequence,
    *,
    labels: Sequence[str] | None = None,
    ncol: int = 4,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Rendered frames (H, W, 3) of an execution as a strip of images (Fig. 8/11)."""
    frames = [np.asarray(f) for f in frames]
    if not frames:
        raise ValueError("plot_frames needs at least one frame")
    ncol = min(ncol, len(frames))
    nrow = -(-len(frames) // ncol)
    width, height = 2.6 * ncol, 2.3 * nrow
    fig, axes = plt.subplots(nrow, ncol, figsize=(width, height), squeeze=False)
    # fixed margins (no tick labels here): room for the labels and the title only
    top = 1 - ((0.4 if title else 0.0) + 0.25) / height
    fig.subplots_adjust(left=0.1 / width, right=1 - 0.1 / width, bottom=0.05 / height,
                        top=top, wspace=0.06, hspace=0.15)
    for k, ax in enumerate(axes.flat):
        ax.axis("off")
        if k < len(frames):
            ax.imshow(frames[k])
            # a plain text, not set_title: no per-axes title layout pass
            ax.text(0.5, 1.02, labels[k] if labels is not None else f"point {k}",
                    fontsize=8, ha="center", va="bottom", transform=ax.transAxes)
    if title:
        fig.suptitle(title, y=1 - 0.12 / height, va="top")
    return _finish(fig, path, tight=False)
