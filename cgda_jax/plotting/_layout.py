"""Figure layouts without `Figure.tight_layout`'s extra pass where it can be done:
a 3-D plot's margins, a panel grid's fixed margins (checked once drawn)."""

from __future__ import annotations

import os

import numpy as np
from matplotlib.figure import Figure

from cgda_jax.plotting._base import DPI, finish

#: A panel grid's room, in inches, left of each panel (its y tick labels and label;
#: tight_layout gives 0.6-0.7 for the demo's recognition figures), between rows (no
#: x tick labels there), right of the last column, for the time axis and above the
#: top y tick labels (half a label).
GRID_SIDE_IN, GRID_ROW_GAP_IN, GRID_RIGHT_IN = 0.75, 0.22, 0.19
GRID_XAXIS_IN, GRID_TOP_IN = 0.52, 0.06


def _title_in(title: str | None, pad_in: float) -> float:
    """Room for a suptitle's lines (12 pt) above the axes, as tight_layout gives."""
    return pad_in + (0.09 + 0.23 * len(title.splitlines()) if title else 0.0)


def title_margins(fig: Figure, title: str | None, pad_in: float = 0.15) -> None:
    """Margins of a figure whose one axes keeps its labels inside its area (a 3-D
    plot from `equal_3d`): ``pad_in`` inches around, and room for the suptitle's
    lines at the top, as `Figure.tight_layout` places them, without its layout pass.
    """
    w, h = fig.get_size_inches()
    top = _title_in(title, pad_in)
    fig.subplots_adjust(left=pad_in / w, right=1 - pad_in / w, bottom=pad_in / h,
                        top=1 - top / h)


def tight_above(fig: Figure, bottom_in: float) -> None:
    """`Figure.tight_layout` leaving ``bottom_in`` inches free at the bottom (for a
    figure legend), in one layout pass.

    The same subplot parameters as ``tight_layout(rect=(0, bottom_in / height, 1,
    1))``, which measures every axes twice (its second pass sees the same axes
    again); here the first pass's bottom margin is raised and the row spacing kept
    in inches.
    """
    fig.set_dpi(DPI)
    fig.tight_layout()
    p = fig.subplotpars
    rows = fig.axes[0].get_subplotspec().get_gridspec().nrows if fig.axes else 1
    bottom = p.bottom + bottom_in / fig.get_figheight()
    if rows > 1:
        gap = p.hspace * (p.top - p.bottom) / (rows + p.hspace * (rows - 1))
        axes_h = (p.top - bottom - gap * (rows - 1)) / rows
        fig.subplots_adjust(bottom=bottom, hspace=gap / axes_h)
    else:
        fig.subplots_adjust(bottom=bottom)


def grid_margins(fig: Figure, nrow: int, ncol: int, title: str | None,
                 bottom_in: float) -> None:
    """Fixed margins of an ``nrow`` x ``ncol`` panel grid with ``bottom_in`` inches
    free below the time axis (a figure legend); `save_grid` checks they fit."""
    w, h = fig.get_size_inches()
    top = _title_in(title, 0.15) + GRID_TOP_IN
    bottom = bottom_in + GRID_XAXIS_IN
    axes_w = (w - GRID_SIDE_IN - GRID_RIGHT_IN - GRID_SIDE_IN * (ncol - 1)) / ncol
    axes_h = (h - top - bottom - GRID_ROW_GAP_IN * (nrow - 1)) / nrow
    fig.subplots_adjust(left=GRID_SIDE_IN / w, right=1 - GRID_RIGHT_IN / w,
                        bottom=bottom / h, top=1 - top / h,
                        wspace=GRID_SIDE_IN / axes_w, hspace=GRID_ROW_GAP_IN / axes_h)


def _drawn_labels(axis) -> list:
    """The tick labels drawn (ticks inside the view), as the last draw placed them."""
    lo, hi = sorted(axis.get_view_interval())
    eps = 1e-9 * max(abs(lo), abs(hi), 1.0)
    return [t.label1 for t in axis.majorTicks if lo - eps <= t.get_loc() <= hi + eps]


def _texts_fit(fig: Figure, grid: np.ndarray) -> bool:
    """Once drawn: every panel's tick labels and axis labels right of the panel to
    its left (or the figure's edge), inside the figure, clear of the suptitle and
    the legend; no offset text."""
    renderer = fig.canvas.get_renderer()
    gap = 0.05 * fig.dpi
    others = [a.get_window_extent(renderer) for a in [*fig.texts, *fig.legends]
              if a.get_visible() and (not hasattr(a, "get_text") or a.get_text())]
    for (row, col), ax in np.ndenumerate(grid):
        if not ax.get_visible():
            continue
        if any(a.offsetText.get_visible() and a.offsetText.get_text()
               for a in (ax.xaxis, ax.yaxis)):
            return False
        texts = [t for t in [*_drawn_labels(ax.yaxis), ax.yaxis.label,
                             *_drawn_labels(ax.xaxis), ax.xaxis.label]
                 if t.get_visible() and t.get_text()]
        boxes = [t.get_window_extent(renderer) for t in texts]
        left_limit = grid[row, col - 1].bbox.x1 if col else 0.0
        if boxes and (min(b.x0 for b in boxes) < left_limit + gap
                      or max(b.x1 for b in boxes) > fig.bbox.width
                      or max(b.y1 for b in boxes) > fig.bbox.height
                      or any(b.overlaps(o) for b in boxes for o in others)):
            return False
    return True


def save_grid(fig: Figure, grid: np.ndarray, path: str | os.PathLike | None,
              bottom_in: float) -> Figure:
    """Save a panel grid laid out by `grid_margins`; where its labels do not fit
    (long tick labels, an offset text) laid out by `tight_above` and saved again.
    Without a ``path``: `tight_above` (nothing is drawn to check)."""
    if path is None:
        tight_above(fig, bottom_in)
        return finish(fig, None, tight=False)
    finish(fig, path, tight=False)
    if not _texts_fit(fig, grid):
        tight_above(fig, bottom_in)
        finish(fig, path, tight=False)
    return fig
