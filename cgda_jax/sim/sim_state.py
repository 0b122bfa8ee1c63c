"""What the `cgda_jax.sim.simulator.Simulator` carries between waypoints, and the
checks of what it is given (settings, waypoint arrays), each naming the problem."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jax import Array

__all__ = ["MODES", "SimState", "check_settings", "check_waypoints", "scene_along"]

MODES = ("kinematic", "dynamic")


@struct.dataclass
class SimState:
    """What the simulator carries between waypoints.

    Attributes:
        genes: (DoF,) the last waypoint (kinematic mode: the posture; dynamic mode:
            the last commanded target, which the next move starts from).
        scene: the scene's state (e.g. painted (S,) bool).
        data: dynamic mode: the physics state ``concat(qpos, qvel)`` of the simulated
            model (see `cgda_jax.sim.physics.Physics`); ``None`` in kinematic mode.
        marker: (3,) the marker's last position, where the next move's swept path
            starts (None: recomputed from ``genes``).
        violation: with feasibility: the summed violation of every move so far
            (scalar, 0 = feasible); None without.
        move_violation: with feasibility: the last move's violation; None without.
        first: with feasibility: True until the first move (the approach) is made.
    """

    genes: Array
    scene: Any
    data: Any = None
    marker: Any = None
    violation: Any = None
    move_violation: Any = None
    first: Any = None


def check_settings(*, mode: str, substeps: int, waypoint_s: float,
                   physics_steps: int | None, move_fraction: float,
                   batch_size: int | None) -> None:
    """Raise ValueError naming the first `Simulator` setting out of its range."""
    if mode not in MODES:
        raise ValueError(f"mode={mode!r}; expected one of {MODES}")
    if int(substeps) < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    if not (np.isfinite(waypoint_s) and waypoint_s > 0):
        raise ValueError(f"waypoint_s must be > 0 seconds, got {waypoint_s}")
    if physics_steps is not None and int(physics_steps) < 1:
        raise ValueError(f"physics_steps must be >= 1, got {physics_steps}")
    if not 0 < move_fraction <= 1:
        raise ValueError(f"move_fraction must be in (0, 1], got {move_fraction}")
    if batch_size is not None and int(batch_size) < 1:
        raise ValueError(f"batch_size must be >= 1 or None, got {batch_size}")


def check_waypoints(waypoints: Array, robot: Any, batched: bool = False) -> None:
    """Raise ValueError unless ``waypoints`` is (N, DoF) (``batched``: (P, N, DoF)),
    non-empty, with DoF = the robot's evolved joints."""
    shape = tuple(jnp.shape(waypoints))
    want = "(P, N, DoF)" if batched else "(N, DoF)"
    ndim = 3 if batched else 2
    if len(shape) != ndim or shape[-1] != robot.n_dof or 0 in shape:
        raise ValueError(
            f"waypoints has shape {shape}, expected {want} with DoF = {robot.n_dof} "
            f"(joints {robot.joint_names})"
        )


def scene_along(scene: Any, scene_state: Any, start: Array, markers: Array) -> Any:
    """The scene's state after the marker moved from ``start`` (3,) through
    ``markers`` (K, 3): the scene's ``sweep`` along that polyline where it has one
    (the paint wall), else its ``update`` at each position in turn."""
    sweep = getattr(scene, "sweep", None)
    if sweep is not None:
        start = jnp.asarray(start, markers.dtype)
        return sweep(scene_state, jnp.concatenate([start[None], markers]))

    def update(state, marker):
        return scene.update(state, marker), None

    return jax.lax.scan(update, scene_state, markers)[0]
