"""Figures of the paper from host arrays (matplotlib, Agg backend).

Every function takes NumPy-convertible arrays, returns the
``matplotlib.figure.Figure`` and, given ``path``, also saves it as a PNG. No JAX
transforms happen here. Axis labels carry units: pass feature names with their unit
(``"X [m]"``; `units.with_units` adds them from a table). Goal points are numbered
from 1 everywhere (``start`` is the posture before the first waypoint), generations
too.

================================  ===========================================
paper figure / table              function
================================  ===========================================
Fig. 2, Fig. 7                    :func:`plot_demonstrations`
Tables 2-4                        :func:`plot_cost_matrix`
(selection z-scores vs alpha)     :func:`plot_zscores`
Fig. 4                            :func:`plot_fitness`
Fig. 5, 6, 10                     :func:`plot_goal_vs_executed`
Fig. 9                            :func:`plot_time_per_point`
(point errors vs tolerance)       :func:`plot_point_errors`
Fig. 8, 11                        :func:`plot_frames`
(motion against the limits)       :func:`plot_motion`
(a segmented recording)           :func:`plot_segmentation`
================================  ===========================================

Modules: `~cgda_jax.plotting.trajectories`, `~cgda_jax.plotting.convergence`,
`~cgda_jax.plotting.tables`, `~cgda_jax.plotting.selection`,
`~cgda_jax.plotting.segments`, `~cgda_jax.plotting.filmstrip`,
`~cgda_jax.plotting.units`.

Only `units` is imported with the package; the figures (and matplotlib, a second
on a CPU) are imported on first use of a name, so a run that computes without
drawing (or draws later, `cgda_jax.experiment.figures.import_drawing`) does not
wait for them.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from cgda_jax.plotting import units as units

#: Where each figure function lives (imported on first use: `__getattr__`).
_MODULES = {
    "FIRST_POINT": "_base", "POINT_AXIS": "_base", "knot_curve": "_base",
    "plot_fitness": "convergence", "plot_point_errors": "convergence",
    "plot_time_per_point": "convergence", "plot_frames": "filmstrip",
    "plot_motion": "motion", "plot_segmentation": "segments",
    "plot_zscores": "selection", "plot_cost_matrix": "tables",
    "plot_demonstrations": "trajectories", "plot_goal_vs_executed": "trajectories",
}


def __getattr__(name: str) -> Any:
    if name not in _MODULES:
        raise AttributeError(f"module 'cgda_jax.plotting' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"cgda_jax.plotting.{_MODULES[name]}"),
                    name)
    globals()[name] = value
    return value


if TYPE_CHECKING:  # the names as the API docs and type checkers see them
    from cgda_jax.plotting._base import (
        FIRST_POINT as FIRST_POINT,
        POINT_AXIS as POINT_AXIS,
        knot_curve as knot_curve,
    )
    from cgda_jax.plotting.convergence import (
        plot_fitness as plot_fitness,
        plot_point_errors as plot_point_errors,
        plot_time_per_point as plot_time_per_point,
    )
    from cgda_jax.plotting.filmstrip import plot_frames as plot_frames
    from cgda_jax.plotting.motion import plot_motion as plot_motion
    from cgda_jax.plotting.segments import plot_segmentation as plot_segmentation
    from cgda_jax.plotting.selection import plot_zscores as plot_zscores
    from cgda_jax.plotting.tables import plot_cost_matrix as plot_cost_matrix
    from cgda_jax.plotting.trajectories import (
        plot_demonstrations as plot_demonstrations,
        plot_goal_vs_executed as plot_goal_vs_executed,
    )

__all__ = [
    "FIRST_POINT",
    "knot_curve",
    "plot_cost_matrix",
    "plot_demonstrations",
    "plot_fitness",
    "plot_frames",
    "plot_motion",
    "plot_goal_vs_executed",
    "plot_point_errors",
    "plot_segmentation",
    "plot_time_per_point",
    "plot_zscores",
    "units",
]
