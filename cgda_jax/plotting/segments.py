"""A segmented recording: its features over time, each recognized action shaded and
labelled (`cgda_jax.segmentation.segment`)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from cgda_jax.plotting._base import as_curve, finish, plt

__all__ = ["plot_segmentation"]

TIME_S = "time [s]"


def plot_segmentation(
    recording,
    segments: Sequence,
    *,
    names: Sequence[str] | None = None,
    title: str | None = None,
    truth: Sequence[tuple[str, float, float]] | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """One panel per feature over the recording's time; every segment shaded in its
    action's colour and named at the top.

    Args:
        recording: a Demonstration (``times (T,)`` in seconds, ``features (T, F)``).
        segments: what `cgda_jax.segmentation.segment` returns (``action``, ``start``,
            ``end`` in seconds).
        names: the F axis labels, units included (``"X [mm]"``); default the
            recording's feature names.
        title: figure title.
        truth: the true ``(action, start, end)`` of each action (seconds), drawn
            as dashed lines at the starts and dotted ones at the ends.
        path: PNG file to write.
    """
    t = np.asarray(recording.times, float)
    x = as_curve(recording.features)
    labels = list(names) if names is not None else list(recording.feature_names)
    actions = list(dict.fromkeys(s.action for s in segments))
    colours = {a: plt.get_cmap("tab10")(k % 10) for k, a in enumerate(actions)}
    n = x.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(9.0, 1.15 * n + 1.2), sharex=True,
                             squeeze=False)
    for i, ax in enumerate(axes[:, 0]):
        for s in segments:
            ax.axvspan(s.start, s.end, color=colours[s.action], alpha=0.22, lw=0)
        for _, start, end in truth or ():
            ax.axvline(start, color="0.3", lw=0.7, ls="--")
            ax.axvline(end, color="0.3", lw=0.7, ls=":")
        ax.plot(t, x[:, i], color="0.15", lw=0.8)
        ax.set_ylabel(labels[i], fontsize=7, rotation=0, ha="right", va="center")
        ax.tick_params(labelsize=7)
        ax.margins(x=0)
    top = axes[0, 0]
    for s in segments:
        top.text((s.start + s.end) / 2, 1.04, s.action,
                 transform=top.get_xaxis_transform(), ha="center", va="bottom", fontsize=8, color=colours[s.action],
                 fontweight="bold")
    axes[-1, 0].set_xlabel(TIME_S, fontsize=8)
    fig.suptitle(title or f"{recording.name}: {len(segments)} actions recognized",
                 fontsize=10)
    return finish(fig, path)
