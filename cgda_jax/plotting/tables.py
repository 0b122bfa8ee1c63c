"""Recognition: the cost matrix of test against generalized actions (Tables 2-4)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from cgda_jax.plotting._base import finish, plt

__all__ = ["plot_cost_matrix"]


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
        label: what the numbers are, with their unit (colorbar label), e.g.
            ``"DTW cost [mm]"``.
        title: figure title (name the experiment: several matrices look alike).
    """
    m = np.asarray(matrix, dtype=float)
    if m.shape != (len(queries), len(references)):
        raise ValueError(
            f"matrix shape {m.shape} does not match {len(queries)} queries x "
            f"{len(references)} references"
        )
    fig, ax = plt.subplots(
        figsize=(1.1 * len(references) + 2.6, 1.1 * len(queries) + 1.9))
    positive = np.maximum(m, 1e-12)
    lo, hi = positive.min(), positive.max()
    norm = LogNorm(lo, hi if hi > lo else lo * 10)
    image = ax.imshow(positive, cmap="viridis_r", norm=norm)
    bar = fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04)
    bar.set_label(f"{label} (log scale)\nbright = low = similar", fontsize=8)
    bar.ax.tick_params(which="both", labelsize=7)
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
    ax.xaxis.set_label_position("top")
    ax.set_xlabel("generalized action (bold: lowest cost of the row = recognized)",
                  fontsize=8)
    ax.set_ylabel("test action", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10, pad=12)
    return finish(fig, path)
