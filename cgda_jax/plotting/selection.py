"""Selection: the z-scores of features or demonstrations against alpha
(`cgda_jax.select`; the authors' ``plot_zscores``)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from cgda_jax.plotting._base import finish, plt

__all__ = ["plot_zscores"]


def plot_zscores(
    panels: Mapping[str, tuple[Sequence[str], Sequence[float]]],
    alpha: float,
    *,
    what: str = "feature",
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Bars of z-scores, one panel per action, with ``alpha`` drawn.

    A bar above the dashed ``alpha`` line is discarded (drawn red), the others
    are kept (blue); a NaN z-score (all values equal) is written as "n/a".

    Args:
        panels: panel title (the action) -> (names, z-scores) of its features or
            demonstrations.
        alpha: the threshold.
        what: what the bars are ("feature" or "demonstration"), for the x label.
        title: figure title.
    """
    if not panels:
        raise ValueError("plot_zscores: no panels")
    n = len(panels)
    ncol = min(n, 2)
    nrow = -(-n // ncol)
    widest = max(len(names) for names, _ in panels.values())
    fig, axes = plt.subplots(
        nrow, ncol, figsize=(max(3.5, 0.45 * widest + 1.4) * ncol, 3.4 * nrow + 0.4),
        squeeze=False, sharey=True)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax, (name, (labels, z)) in zip(axes.flat, panels.items()):
        z = np.asarray(z, dtype=float)
        if z.shape != (len(labels),):
            raise ValueError(f"plot_zscores: panel {name!r} has {len(labels)} names "
                             f"but z-scores of shape {z.shape}")
        finite = np.isfinite(z)
        shown = np.where(finite, z, 0.0)
        colors = ["tab:red" if f and v > alpha else "tab:blue"
                  for f, v in zip(finite, shown)]
        ax.bar(np.arange(len(z)), shown, color=colors, alpha=0.75)
        for i in np.flatnonzero(~finite):
            ax.text(i, 0.0, "n/a", ha="center", va="bottom", fontsize=7)
        ax.axhline(alpha, color="tab:red", linestyle="--", lw=1.5,
                   label=f"alpha = {alpha:g} (above: discarded)")
        ax.axhline(0.0, color="0.4", lw=0.6)
        ax.set_xticks(range(len(labels)), list(labels), rotation=60, ha="right",
                      fontsize=7)
        ax.set_xlabel(what, fontsize=8)
        ax.set_title(name, fontsize=9)
        ax.tick_params(axis="y", labelsize=7)
    for row in axes:
        row[0].set_ylabel("z-score [standard deviations]", fontsize=8)
    axes[0][0].legend(fontsize=7, loc="upper left")
    if title:
        fig.suptitle(title, fontsize=10)
    return finish(fig, path)
