"""Feature trajectories: demonstrations and their generalization (paper Fig. 2, 7),
goal against executed per point (Fig. 5, 6, 10)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from cgda_jax.plotting._base import (
    DEMO,
    EXEC,
    GOAL,
    POINT_AXIS,
    as_curve,
    equal_3d,
    finish,
    integer_axis,
    knot_curve,
    plt,
    point_numbers,
    select,
)
from cgda_jax.plotting._layout import grid_margins, save_grid, title_margins
from cgda_jax.plotting.units import common_unit

__all__ = ["plot_demonstrations", "plot_goal_vs_executed"]

TIME_AXIS = "normalized time (0 = start, 1 = end)"
TIME_TICKS = np.linspace(0.0, 1.0, 6)
LEGEND_IN = 0.35  # below the panels: the figure legend


def _normalized(times) -> np.ndarray:
    t = np.asarray(times, dtype=float)
    return (t - t[0]) / max(t[-1] - t[0], 1e-12)


def _generalization(generalized):
    """(curve t, curve, knot t, knots) of a GeneralizedAction, or of an (N, F) array
    of points spread evenly over [0, 1]; None without one."""
    if generalized is None:
        return None
    if hasattr(generalized, "knot_times"):
        t, curve = knot_curve(generalized)
        kt = np.sort(np.asarray(generalized.knot_times, float))
        knots = as_curve(generalized.knots)[np.argsort(generalized.knot_times)]
        return t, curve, kt, knots
    g = as_curve(generalized)
    t = np.linspace(0.0, 1.0, len(g))
    return t, g, t, g


def plot_demonstrations(
    demos: Sequence,
    generalized=None,
    executed=None,
    *,
    features: Sequence[str | int] | None = None,
    names: Sequence[str] | None = None,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Demonstrations (grey), their generalization (blue, knots marked), an execution
    (red).

    The generalization is drawn between its first and last knot only (over the
    demonstrations' normalized time, as in the paper; the linear RBF beyond them is
    an extrapolation). An execution of as many points as knots is drawn at the knot
    times. With three selected features the trajectories are drawn in 3-D feature
    space (paper Fig. 2 and 7); otherwise one panel per feature over normalized time.

    Args:
        demos: Demonstrations (``times (T_k,)``, ``features (T_k, F)``).
        generalized: a GeneralizedAction (or anything with ``knot_times`` and
            ``knots``), or an array (N, F) spread over [0, 1].
        executed: executed feature trajectory (N, F), e.g. ``ExecutionResult.features``.
        features: names or indices of the features to draw (default: all).
        names: the F axis labels, units included (``"X [m]"``); default the
            demonstrations' feature names.
        title: figure title (name the experiment).
        path: PNG file to write.
    """
    gen = _generalization(generalized)
    n_feat = (as_curve(demos[0].features).shape[1] if demos
              else gen[1].shape[1] if gen else as_curve(executed).shape[1])
    own = tuple(demos[0].feature_names) if demos and hasattr(
        demos[0], "feature_names") else tuple(f"f{i}" for i in range(n_feat))
    cols = select(own, features)
    labels = list(names) if names is not None else list(own)
    ex = None if executed is None else as_curve(executed)[:, cols]
    if gen is not None:
        gt, gcurve, kt, knots = gen
        gcurve, knots = gcurve[:, cols], knots[:, cols]
    ex_t = None
    if ex is not None:
        ex_t = kt if gen is not None and len(kt) == len(ex) else np.linspace(
            0.0, 1.0, len(ex))
    n_demo = len(demos)
    demo_label = f"demonstrations ({n_demo})"
    if len(cols) == 3:
        fig = plt.figure(figsize=(6.4, 5.4))
        ax = fig.add_subplot(projection="3d")
        for k, d in enumerate(demos):
            f = as_curve(d.features)[:, cols]
            ax.plot(*f.T, color=DEMO, lw=0.6, alpha=0.6,
                    label=demo_label if k == 0 else None)
        if gen is not None:
            ax.plot(*gcurve.T, color=GOAL, lw=2.2, label="generalization (linear RBF)")
            ax.scatter(*knots.T, color=GOAL, s=16, label=f"knots ({len(knots)})")
        if ex is not None:
            ax.plot(*ex.T, "-o", color=EXEC, lw=1.6, ms=3, label="executed")
        equal_3d(ax, [as_curve(d.features)[:, cols] for d in demos]
                 + [c for c in ((gcurve if gen else None), ex) if c is not None])
        ax.set_xlabel(labels[cols[0]], labelpad=8)
        ax.set_ylabel(labels[cols[1]], labelpad=8)
        ax.set_zlabel(labels[cols[2]], labelpad=8)
        ax.legend(loc="upper left", fontsize=8)
    else:
        n = len(cols)
        ncol = min(n, 4)
        nrow = -(-n // ncol)
        fig, axes = plt.subplots(nrow, ncol, figsize=(3.4 * ncol, 2.6 * nrow + 0.6),
                                 squeeze=False)
        for i, c in enumerate(cols):
            ax = axes.flat[i]
            for k, d in enumerate(demos):
                ax.plot(_normalized(d.times), as_curve(d.features)[:, c], color=DEMO,
                        lw=0.7, alpha=0.7, label=demo_label if k == 0 else None)
            if gen is not None:
                ax.plot(gt, gcurve[:, i], color=GOAL, lw=2,
                        label="generalization (linear RBF)")
                ax.plot(kt, knots[:, i], "o", color=GOAL, ms=3.5,
                        label=f"knots ({len(knots)})")
            if ex is not None:
                ax.plot(ex_t, ex[:, i], "s", color=EXEC, ms=3.5, label="executed")
            ax.set_ylabel(labels[c], fontsize=8)
            ax.set_xlim(-0.02, 1.02)
            ax.set_xticks(TIME_TICKS)
            ax.tick_params(labelsize=7)
            if i + ncol < n:  # the panel below shows the same time axis
                ax.tick_params(labelbottom=False)
            else:
                ax.set_xlabel(TIME_AXIS, fontsize=8)
        for ax in list(axes.flat)[n:]:
            ax.set_visible(False)
        handles, texts = axes.flat[0].get_legend_handles_labels()
        fig.legend(handles, texts, loc="lower center", ncol=len(texts), fontsize=8,
                   frameon=False)
        if title:
            fig.suptitle(title)
        grid_margins(fig, nrow, ncol, title, LEGEND_IN)
        return save_grid(fig, axes, path, LEGEND_IN)
    if title:
        fig.suptitle(title)
    title_margins(fig, title)
    return finish(fig, path, tight=False)


def plot_goal_vs_executed(
    goal,
    executed,
    feature_names: Sequence[str] | None = None,
    *,
    tolerance: float | None = None,
    tolerance_unit: str | None = None,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """One panel per feature: goal (blue) vs executed (red) per point (Fig. 5/6/10).

    Points are numbered from 1 (`cgda_jax.plotting.FIRST_POINT`).

    Args:
        goal: reference feature trajectory (N, F).
        executed: executed features (N, F) (or (M, F): drawn on its own point axis).
        feature_names: F axis labels, units included (``"X [m]"``; a
            `cgda_jax.Simulator`'s ``feature_labels``).
        tolerance: if given, shades goal +/- tolerance in each panel (the tolerance
            bounds the Euclidean error of a point, hence each feature's error too).
        tolerance_unit: its unit, for the legend (default: the unit the feature
            names share, ``"m"`` for ``X [m]``, ``Y [m]``, ``Z [m]``).
    """
    g, e = as_curve(goal), as_curve(executed)
    if g.shape[1] != e.shape[1]:
        raise ValueError(f"goal {g.shape} and executed {e.shape} have different F")
    names = list(feature_names) if feature_names is not None else [
        f"feature {i}" for i in range(g.shape[1])
    ]
    f = g.shape[1]
    fig, axes = plt.subplots(f, 1, figsize=(6.4, 2.1 * f + 0.9), squeeze=False,
                             sharex=True)
    x = point_numbers(len(g))
    for i, ax in enumerate(axes[:, 0]):
        ax.plot(x, g[:, i], "-o", color=GOAL, ms=3, label="goal (generalized)")
        ax.plot(point_numbers(len(e)), e[:, i], "-s", color=EXEC, ms=3,
                label="executed")
        if tolerance is not None:
            ax.fill_between(x, g[:, i] - tolerance, g[:, i] + tolerance, color=GOAL,
                            alpha=0.15, lw=0)
        ax.set_ylabel(names[i], fontsize=9)
        integer_axis(ax.xaxis)
    handles, texts = axes[0, 0].get_legend_handles_labels()
    if tolerance is not None:
        tolerance_unit = tolerance_unit or common_unit(names)
        unit = f" {tolerance_unit}" if tolerance_unit else ""
        handles.append(Patch(color=GOAL, alpha=0.15))
        texts.append(f"goal ± tolerance ({tolerance:.4g}{unit})")
    axes[0, 0].legend(handles, texts, fontsize=8)
    axes[-1, 0].set_xlabel(POINT_AXIS)
    if title:
        fig.suptitle(title)
    return finish(fig, path)
