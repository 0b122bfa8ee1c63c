"""What every figure shares: the Agg backend, saving, curves, point numbering, ticks."""

from __future__ import annotations

import os
from collections.abc import Sequence

import matplotlib

if os.environ.get("MPLBACKEND") is None:
    matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: F401  (re-exported to the modules)
import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

DEMO, GOAL, EXEC = "0.25", "tab:blue", "tab:red"
DPI = 110

#: Goal points are numbered from 1 in every figure, frame strip and report (the
#: start posture is "start", the posture reached after the k-th waypoint "point k").
FIRST_POINT = 1
POINT_AXIS = "goal point (1 = first)"


def finish(fig: Figure, path: str | os.PathLike | None, *, tight: bool = True) -> Figure:
    fig.set_dpi(DPI)  # layout and PNG at one dpi: the text sizes are measured once
    if tight:  # one extra layout pass (~0.05-0.1 s a figure); skipped for fixed grids
        fig.tight_layout()
    if path is not None:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        # zlib level 3: half the time of the default 6, files no larger here
        fig.savefig(path, dpi=DPI, pil_kwargs={"compress_level": 3})
    return fig


def as_curve(x) -> np.ndarray:
    """(T, F) host array from an array (a (T,) array is one feature)."""
    x = np.asarray(x, dtype=float)
    return x[:, None] if x.ndim == 1 else x


def knot_curve(action, n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """A generalized action between its first and last knot: ``(t (n,), (n, F))``.

    The linear RBF through sorted knots is the piecewise linear interpolant between
    them, evaluated here in NumPy (no JAX dispatch). Nothing is drawn beyond the
    outer knots: there the RBF only extrapolates (the paper draws the generalization
    over the demonstrations' normalized time, between the knots).
    """
    kt = np.asarray(action.knot_times, dtype=float)
    knots = as_curve(action.knots)
    order = np.argsort(kt)
    kt, knots = kt[order], knots[order]
    t = np.linspace(kt[0], kt[-1], n)
    return t, np.stack([np.interp(t, kt, knots[:, f]) for f in range(knots.shape[1])],
                       axis=1)


def select(names: Sequence[str], features) -> list[int]:
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


def integer_axis(axis) -> None:
    """Whole-number ticks only (generations, points, counts)."""
    axis.set_major_locator(MaxNLocator(integer=True))


def point_numbers(n: int) -> np.ndarray:
    """The numbers of ``n`` goal points as shown (from `FIRST_POINT`)."""
    return np.arange(FIRST_POINT, FIRST_POINT + n)


def equal_3d(ax, curves: Sequence[np.ndarray], min_share: float = 0.4) -> None:
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
