"""How the evolution went: best fitness per generation (paper Fig. 4), effort per
point (Fig. 9) and each point's error against the tolerance."""

from __future__ import annotations

import os

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import BoundaryNorm
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator

from cgda_jax.plotting._base import (
    EXEC,
    POINT_AXIS,
    finish,
    integer_axis,
    plt,
    point_numbers,
)

__all__ = ["plot_fitness", "plot_point_errors", "plot_time_per_point"]


def _unit(unit: str | None) -> str:
    return f" [{unit}]" if unit else ""


def plot_fitness(
    history,
    *,
    labels=None,
    unit: str | None = None,
    log: bool = True,
    title: str | None = None,
    path: str | os.PathLike | None = None,
    parallel: bool = False,
    tolerance: float | None = None,
    errors=None,
    least_motion: bool = False,
) -> Figure:
    """Best fitness per generation (counted from 1), its minimum marked in red
    (Fig. 4).

    Several evolutions (one per goal point: IE, IET, OET) are drawn each in its
    point's colour (colour bar: the point number, from 1): side by side from
    generation 1 when ``parallel`` (IE: the points evolve together, so the axis
    ends at the slowest point's generations, the run's count), else one after the
    other in run order with thin lines between points (IET, OET: the axis spans
    their summed generations), so that even a point solved in its first generation
    shows as a marker.

    What is plotted is the fitness the evolution ranked by, not always an error:
    ``tolerance`` draws the tolerance (dashed), ``least_motion`` (feasibility on)
    shades the band below it, where a candidate that meets the tolerance is ranked
    by its joint motion (``tolerance * m / (m + 1)``) instead of its error, and
    ``errors`` (one per row) marks each point's executed error (the result's) at
    the end of its evolution. The y axis is logarithmic only where the values
    span more than a decade (else a linear axis keeps its labels readable).

    Args:
        history: (G,) for one evolution, or (P, G) for P evolutions; non-finite
            entries (generations not run) are dropped.
        labels: unused beyond one evolution (kept for compatibility): points are
            named by the colour bar.
        unit: the fitness' unit (e.g. ``"m"`` for a distance in metres).
        log: logarithmic y axis (when all values are positive and span a decade).
        parallel: the P evolutions ran side by side (IE).
        tolerance: the point tolerance (fitness units), drawn dashed.
        errors: (P,) each evolution's executed point error, marked with an x.
        least_motion: shade the band below ``tolerance`` as a motion rank.
    """
    del labels
    h = np.asarray(history, dtype=float)
    h = h[None] if h.ndim == 1 else h
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    shown = [h_row[np.isfinite(h_row)] for h_row in h]
    handles, names = [], []
    ends = []  # (x, row) of each evolution's last generation
    if h.shape[0] == 1:
        g = np.flatnonzero(np.isfinite(h[0]))
        y = h[0, g]
        g = g + 1  # generations counted from 1
        ax.plot(g, y, "-", lw=1.3, color="tab:blue", label="best fitness so far")
        if g.size:
            i = int(np.argmin(y))
            ax.plot(g[i], y[i], "o", color="red", ms=7,
                    label=f"minimum {y[i]:.4g}{' ' + unit if unit else ''} "
                    f"(generation {g[i]})")
            ends.append((g[-1], 0))
        ax.set_xlabel("generation")
    else:
        p = h.shape[0]
        cmap = plt.get_cmap("viridis", p)
        norm = BoundaryNorm(np.arange(p + 1) + 0.5, p)
        start = 0
        for k, row in enumerate(h):
            g = np.flatnonzero(np.isfinite(row))
            if g.size == 0:
                continue
            x = start + g + 1  # generations counted from 1
            ax.plot(x, row[g], "-o", color=cmap(k), lw=1.0, ms=2.5)
            ends.append((x[-1], k))
            if parallel:
                continue
            start += int(g[-1]) + 1
            if k < p - 1:
                ax.axvline(start + 0.5, color="0.85", lw=0.6, zorder=0)
        bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, pad=0.02)
        bar.set_label(POINT_AXIS, fontsize=8)
        bar.ax.yaxis.set_major_locator(MaxNLocator(integer=True, nbins=8))
        bar.ax.tick_params(labelsize=7)
        if parallel:
            ax.set_xlabel("generation (the points evolve side by side)")
            handles.append(Line2D([], [], color="0.3", marker="o", ms=2.5, lw=1.0))
            names.append("best fitness so far, one evolution per point")
        else:
            ax.set_xlabel("generation (the points' evolutions in run order)")
            handles += [Line2D([], [], color="0.3", marker="o", ms=2.5, lw=1.0),
                        Line2D([], [], color="0.85", lw=0.6)]
            names += ["best fitness so far, one evolution per point",
                      "next point's evolution starts"]
    u = f" {unit}" if unit else ""
    if tolerance is not None and np.isfinite(tolerance):
        handles.append(ax.axhline(tolerance, color="0.3", ls="--", lw=0.9))
        names.append(f"tolerance {tolerance:.4g}{u}")
    if errors is not None:
        err = np.asarray(errors, dtype=float).ravel()
        xs = [x for x, k in ends if k < err.size and np.isfinite(err[k])]
        ys = [err[k] for x, k in ends if k < err.size and np.isfinite(err[k])]
        if xs:
            handles.append(ax.plot(xs, ys, "x", color="red", ms=6, mew=1.5)[0])
            names.append("executed point error (the result's)")
            shown.append(np.asarray(ys))
    values = np.concatenate([y for y in shown if y.size] or [np.ones(1)])
    if log and np.all(values > 0) and values.max() > 10 * values.min():
        ax.set_yscale("log")
    elif least_motion or np.any(values <= 0):
        ax.set_ylim(bottom=0.0)
    if least_motion and tolerance is not None and np.isfinite(tolerance):
        bottom, top = ax.get_ylim()
        handles.append(ax.axhspan(bottom, tolerance, color="tab:green", alpha=0.1,
                                  lw=0))
        names.append("below: ranked by joint motion, not an error")
        ax.set_ylim(bottom, top)
    if h.shape[0] == 1:
        handles = ax.get_legend_handles_labels()[0] + handles
        names = ax.get_legend_handles_labels()[1] + names
    ax.legend(handles, names, fontsize=8)
    integer_axis(ax.xaxis)
    ax.set_ylabel("best fitness" + _unit(unit))
    if title:
        ax.set_title(title, fontsize=10)
    return finish(fig, path)


def plot_time_per_point(
    seconds,
    *,
    ylabel: str = "time per point [s]",
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Time (or generations, evaluations) spent on each point of an IET run (Fig. 9);
    points numbered from 1."""
    s = np.asarray(seconds, dtype=float).ravel()
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    x = point_numbers(len(s))
    ax.bar(x, s, color="tab:gray")
    ax.set_xlim(x[0] - 0.6, x[-1] + 0.6)
    ax.set_xlabel(POINT_AXIS)
    ax.set_ylabel(ylabel)
    integer_axis(ax.xaxis)
    if np.all(np.isfinite(s)) and np.allclose(s, np.round(s)):
        integer_axis(ax.yaxis)
    if title:
        ax.set_title(title, fontsize=10)
    return finish(fig, path)


def plot_point_errors(
    errors,
    tolerance: float,
    *,
    unit: str | None = None,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Each goal point's error (bars, green within the tolerance, red beyond it) and
    the tolerance (dashed line); points numbered from 1, a point without any
    finite execution marked with a red cross at the top."""
    e = np.asarray(errors, dtype=float).ravel()
    x = point_numbers(len(e))
    finite = np.isfinite(e)
    ok = finite & (e < tolerance)
    bad = finite & ~ok
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    u = f" {unit}" if unit else ""
    ax.axhline(tolerance, color="black", ls="--", lw=1.0,
               label=f"tolerance {tolerance:.4g}{u}")
    # bars, and a marker on each (an error of 0 still shows)
    for mask, colour, text in ((ok, "tab:green", "within tolerance"),
                               (bad, EXEC, "beyond tolerance")):
        if mask.any():
            ax.bar(x[mask], e[mask], width=0.6, color=colour, alpha=0.55)
            ax.plot(x[mask], e[mask], "o", color=colour, ms=4, label=text,
                    clip_on=False, zorder=3)
    top = max(tolerance, float(e[finite].max()) if finite.any() else 0.0) * 1.15
    if (~finite).any():
        ax.plot(x[~finite], np.full((~finite).sum(), top * 0.97), "x",
                color=EXEC, ms=8, mew=2, label="no finite execution")
    ax.set_ylim(0, top)
    ax.set_xlim(x[0] - 0.6, x[-1] + 0.6)
    ax.set_xlabel(POINT_AXIS)
    ax.set_ylabel("point error" + _unit(unit))
    integer_axis(ax.xaxis)
    ax.legend(fontsize=8, loc="upper left")
    if title:
        ax.set_title(title, fontsize=10)
    return finish(fig, path)
