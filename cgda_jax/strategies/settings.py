"""What every strategy checks before it runs: the goal against the simulator,
the common settings, and whether its points are independent."""

from __future__ import annotations

import numbers
from typing import Any

import jax
import numpy as np

__all__ = ["check_config", "check_stagnation", "points_independent"]


def points_independent(sim: Any) -> bool:
    """Whether a step's features depend only on its waypoint, not on where it starts:
    kinematic mode (``sim.mode``, default kinematic) and a scene state with no arrays
    (the marker; a paint wall remembers what was painted)."""
    if getattr(sim, "mode", "kinematic") != "kinematic":
        return False
    scene = getattr(sim, "scene", None)
    return scene is None or not jax.tree.leaves(scene.init_state())


def check_config(
    sim: Any,
    goal: Any,
    *,
    tolerance: float | None = None,
    max_generations: int | None = None,
    min_points: int = 1,
) -> jax.Array:
    """Checks a goal (N, F) against a simulator and common settings; returns it f32.

    The checks run in NumPy on the host (eager JAX ops would each compile once).
    """
    from cgda_jax.checks import check_float32

    g64 = np.asarray(goal, dtype=np.float64)
    if np.all(np.isfinite(g64)):  # NaN/inf: the per-point message below
        check_float32(g64, "goal")
    g = g64.astype(np.float32)
    if g.ndim == 1 and sim.n_features == 1:
        g = g[:, None]
    if g.ndim != 2:
        raise ValueError(f"goal must have shape (N, F); got shape {tuple(g.shape)}")
    if g.shape[1] != sim.n_features:
        names = getattr(sim, "feature_names", None)
        raise ValueError(
            f"goal has {g.shape[1]} features per point but the simulator's scene has "
            f"{sim.n_features}" + (f" ({', '.join(names)})" if names else "")
        )
    if g.shape[0] < min_points:
        raise ValueError(f"goal needs at least {min_points} point(s); got {g.shape[0]}")

    if not np.all(np.isfinite(g)):
        bad = int(np.argmax(~np.all(np.isfinite(g), axis=1)))
        raise ValueError(f"goal has a non-finite value at point {bad}")
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance must be a finite number > 0; got {tolerance}")
    if max_generations is not None and int(max_generations) < 1:
        raise ValueError(f"max_generations must be >= 1; got {max_generations}")
    return jax.device_put(g)  # a transfer (jnp.asarray compiles a copy program)


def check_stagnation(stagnation: Any) -> int | None:
    """A strategy's ``stagnation``: None (off) or a whole number >= 1, as an int.

    Raises ValueError naming the value otherwise (a bool, 0, 2.5, "10").
    """
    if stagnation is None:
        return None
    ok = (not isinstance(stagnation, (bool, str)) and isinstance(stagnation, numbers.Real)
          and float(stagnation) == int(stagnation) and int(stagnation) >= 1)
    if not ok:
        raise ValueError(f"stagnation must be a whole number >= 1 or None; got "
                         f"{stagnation!r}")
    return int(stagnation)
