"""Rendered frames of an execution as a strip of images (paper Fig. 8, 11)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from cgda_jax.plotting._base import DPI, FIRST_POINT, finish, plt

__all__ = ["plot_frames"]


def _shrunk(frame: np.ndarray, width_px: float) -> np.ndarray:
    """A uint8 frame at least twice as wide as ``width_px`` reduced by a whole
    factor (box filter) to at least ``width_px``: what the PNG shows, for less
    resampling in the figure."""
    k = int(frame.shape[1] // max(width_px, 1.0))
    if k < 2 or frame.dtype != np.uint8 or frame.ndim != 3:
        return frame
    from PIL import Image

    return np.asarray(Image.fromarray(frame).reduce(k))


def plot_frames(
    frames: Sequence,
    *,
    labels: Sequence[str] | None = None,
    ncol: int = 4,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Rendered frames (H, W, 3) as a strip of images (Fig. 8/11).

    Default labels: ``start``, ``point 1``, ``point 2``, ... (the posture before
    any waypoint, then after each; points numbered from 1 as in every figure).
    """
    frames = [np.asarray(f) for f in frames]
    if not frames:
        raise ValueError("plot_frames needs at least one frame")
    if labels is None:
        labels = ["start"] + [f"point {k}" for k in
                              range(FIRST_POINT, FIRST_POINT + len(frames) - 1)]
    ncol = min(ncol, len(frames))
    nrow = -(-len(frames) // ncol)
    aspect = frames[0].shape[0] / max(frames[0].shape[1], 1)
    width = 2.8 * ncol
    height = (2.8 * aspect + 0.3) * nrow
    fig, axes = plt.subplots(nrow, ncol, figsize=(width, height), squeeze=False)
    # fixed margins (no tick labels here): room for the labels and the title only
    top = 1 - ((0.4 if title else 0.0) + 0.25) / height
    fig.subplots_adjust(left=0.1 / width, right=1 - 0.1 / width, bottom=0.05 / height,
                        top=top, wspace=0.06, hspace=0.15)
    cell_px = 2.8 * DPI  # a frame's width in the PNG, at most
    for k, ax in enumerate(axes.flat):
        ax.axis("off")
        if k < len(frames):
            ax.imshow(_shrunk(frames[k], cell_px))
            # a plain text, not set_title: no per-axes title layout pass
            ax.text(0.5, 1.02, labels[k], fontsize=8, ha="center", va="bottom",
                    transform=ax.transAxes)
    if title:
        fig.suptitle(title, y=1 - 0.12 / height, va="top")
    return finish(fig, path, tight=False)
