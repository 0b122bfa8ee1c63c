"""Scenes: object features computed from the marker position, with carried state.

A scene is static configuration (shapes and constants, closed over by the simulator)
plus a small pytree state that the simulator carries through its scans:

- ``init_state() -> state``
- ``update(state, marker_pos (3,)) -> state``  (the marker is at ``marker_pos``)
- ``features(state, marker_pos (3,)) -> (F,)``  (called at each waypoint)
- ``feature_names`` (F,), ``n_features``
- optional ``sweep(state, path (K + 1, 3)) -> state``: the marker moved along the
  polyline ``path`` (straight segments between consecutive positions).  For each
  move the simulator passes the previous position followed by every sub-step
  (kinematic mode) or physics step (dynamic mode) when the scene has it, else it
  calls ``update`` at each position; a scene that depends on the whole path
  (`PaintWall`) defines it so that nothing between two sampled positions is missed.

`MarkerScene`: the marker position itself (X, Y, Z in the robot's root frame).
`PaintWall`: a wall of squares painted when the marker's path comes near their
centres (`segment_distance2`: the swept segment between consecutive positions, not
only the positions); the feature is the painted percentage.  The authors' TEO wall
(Morante et al. 2015) is `PaintWall.grid()`'s default.
`ObjectScene`: features of anything in the simulated world, declared by name (an
object's position or yaw, a valve's angle; `cgda_jax.sim.features`); the simulator
reads them from the world state (MuJoCo sensors in dynamic mode, forward kinematics
of the whole model in kinematic mode).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

__all__ = [
    "TEO_WALL_Y",
    "TEO_WALL_Z",
    "MarkerScene",
    "ObjectScene",
    "PaintWall",
    "segment_distance2",
]

#: The authors' paint wall (world frame, robot waist at z = 0.3).
TEO_WALL_Y = (-0.8, -0.6, -0.4, -0.2)
TEO_WALL_Z = (0.32, 0.52, 0.72, 0.92)


def segment_distance2(points: Array, start: Array, end: Array) -> Array:
    """Squared distance from each of ``points`` (S, 3) to the segment
    ``start -> end`` ((..., 3) each), in closed form: the segment's closest point to
    p is ``start + t d`` with ``d = end - start`` and
    ``t = clip((p - start) . d / (d . d), 0, 1)`` (a zero-length segment is its
    start point).  Returns (..., S).

    Written per coordinate, without (..., S, 3) temporaries or small matrix
    products (slow on XLA's CPU back-end under ``vmap``):
    ``|p - start - t d|^2 = |p - start|^2 - 2 t (p - start) . d + t^2 d . d``.
    """
    points = jnp.asarray(points)
    start = jnp.asarray(start, points.dtype)
    d = jnp.asarray(end, points.dtype) - start
    rel = [points[:, c] - start[..., c, None] for c in range(3)]  # (..., S) each
    rel_d = sum(r * d[..., c, None] for c, r in enumerate(rel))
    rel2 = sum(r * r for r in rel)
    dd = jnp.sum(d * d, axis=-1)[..., None]
    t = jnp.clip(rel_d / jnp.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return jnp.maximum(rel2 - 2.0 * t * rel_d + t * t * dd, 0.0)


@dataclass(frozen=True, eq=False)
class MarkerScene:
    """Features = the marker position (X, Y, Z) in the robot's root frame; F = 3.

    The state is an empty tuple.
    """

    feature_names: tuple[str, ...] = ("X", "Y", "Z")

    @property
    def n_features(self) -> int:
        return 3

    def init_state(self) -> tuple:
        return ()

    def update(self, state: tuple, marker_pos: Array) -> tuple:
        del marker_pos
        return state

    def features(self, state: tuple, marker_pos: Array) -> Array:
        del state
        return jnp.asarray(marker_pos, jnp.float32)

    def decorations(self, state) -> list:
        """Nothing extra to draw (the marker site is part of the model)."""
        del state
        return []


@dataclass(frozen=True, eq=False)
class PaintWall:
    """A wall of S squares; a square is painted, for good, once the marker's path
    comes within ``radius`` of its centre.  Feature: painted percentage (F = 1), in
    multiples of 100 / S.  State: ``painted`` (S,) bool.

    `update` paints at one position; `sweep` paints along the straight segments
    between consecutive positions (closed-form point-to-segment distance), which is
    what the simulator calls for each move: the marker may travel further between
    two sub-steps than a square's painting diameter.

    Args:
        centres: (S, 3) square centres in the robot's root frame (metres).
        radius: painting distance (metres); the authors used 0.12.
        size: square side (metres), for drawing only.
        normal: (3,) wall normal, for drawing only.
        path_tolerance: metres: a kinematic `Simulator` takes enough sub-steps per
            move that the straight segments between them stay this close to the
            marker's curved path (`cgda_jax.sim.chain.path_substeps`; 1 mm gives
            67 on TEO's arm); None: the simulator's sub-steps as given.
    """

    centres: np.ndarray
    radius: float = 0.12
    size: float = 0.20
    normal: tuple[float, float, float] = (1.0, 0.0, 0.0)
    path_tolerance: float | None = 0.001
    feature_names: tuple[str, ...] = field(default=("painted",))

    def __post_init__(self):
        centres = np.asarray(self.centres, dtype=np.float32)
        if centres.ndim != 2 or centres.shape[1] != 3 or len(centres) == 0:
            raise ValueError(
                f"PaintWall centres has shape {centres.shape}, expected (S, 3)"
            )
        if not np.all(np.isfinite(centres)):
            raise ValueError("PaintWall centres contain NaN or inf")
        if not self.radius > 0:
            raise ValueError(f"PaintWall radius must be > 0, got {self.radius}")
        if self.path_tolerance is not None and not self.path_tolerance > 0:
            raise ValueError(
                f"PaintWall path_tolerance must be > 0, got {self.path_tolerance}")
        object.__setattr__(self, "centres", centres)

    @classmethod
    def grid(
        cls,
        x: float = 0.6,
        ys: Sequence[float] = TEO_WALL_Y,
        zs: Sequence[float] = TEO_WALL_Z,
        root_height: float = 0.3,
        radius: float = 0.12,
        size: float = 0.20,
        path_tolerance: float | None = 0.001,
    ) -> PaintWall:
        """A vertical wall (normal +x) of len(ys) x len(zs) squares at ``x``.

        Defaults are the authors' TEO scene: centres at x 0.6, y in {-0.8, ..., -0.2},
        z in {0.32, ..., 0.92} in a world where the robot's root (TEO's waist) stands
        at z = ``root_height`` = 0.3; the centres are returned in the root frame
        (z - 0.3).  Order: z-major (bottom row first), then y.
        """
        centres = [(x, y, z - root_height) for z in zs for y in ys]
        return cls(np.array(centres), radius=radius, size=size,
                   path_tolerance=path_tolerance)

    @property
    def n_squares(self) -> int:
        return len(self.centres)

    @property
    def n_features(self) -> int:
        return 1

    def init_state(self) -> Array:
        return jax.device_put(np.zeros(self.n_squares, dtype=bool))

    def near(self, marker_pos: Array) -> Array:
        """(S,) bool: squares within ``radius`` of the marker."""
        return _near(self.centres, marker_pos, self.radius)

    def near_segment(self, start: Array, end: Array) -> Array:
        """(..., S) bool: squares within ``radius`` of the segment ``start -> end``
        (``(3,)`` each, or batched ``(..., 3)``)."""
        return _near_segment(self.centres, start, end, self.radius)

    def update(self, state: Array, marker_pos: Array) -> Array:
        return _paint(state, self.centres, marker_pos, self.radius)

    def sweep(self, state: Array, path: Array) -> Array:
        """Paint along the polyline ``path`` (K + 1, 3): the K straight segments
        between consecutive positions (all at once; one position paints at it)."""
        return _sweep(state, self.centres, path, self.radius)

    def features(self, state: Array, marker_pos: Array) -> Array:
        del marker_pos
        return (100.0 * jnp.mean(state.astype(jnp.float32)))[None]

    def decorations(self, state) -> list:
        """Boxes to draw: (type "box", half sizes (3,), centre (3,), rgba (4,)) each;
        painted squares red, the others light grey."""
        painted = np.asarray(state, dtype=bool)
        n = np.asarray(self.normal, dtype=np.float64)
        half = np.where(np.abs(n) > 0.5, 0.004, self.size / 2 * 0.96)
        out = []
        for c, p in zip(self.centres, painted):
            rgba = (0.85, 0.1, 0.1, 1.0) if p else (0.85, 0.85, 0.85, 1.0)
            out.append(("box", half, np.asarray(c, np.float64), rgba))
        return out


# PaintWall's geometry as jitted functions of its centres (the radius static): one
# program per shape where they are called eagerly (set-up, renders), not one per
# operation; inlined in the simulator's traces.
@partial(jax.jit, static_argnums=2)
def _near(centres: Array, marker_pos: Array, radius: float) -> Array:
    d2 = jnp.sum((jnp.asarray(centres) - marker_pos) ** 2, axis=-1)
    return d2 <= radius**2


@partial(jax.jit, static_argnums=3)
def _near_segment(centres: Array, start: Array, end: Array, radius: float) -> Array:
    start = jnp.asarray(start, jnp.float32)
    end = jnp.asarray(end, jnp.float32)
    return segment_distance2(jnp.asarray(centres), start, end) <= radius**2


@partial(jax.jit, static_argnums=3)
def _paint(state: Array, centres: Array, marker_pos: Array, radius: float) -> Array:
    return state | _near(centres, marker_pos, radius)


@partial(jax.jit, static_argnums=3)
def _sweep(state: Array, centres: Array, path: Array, radius: float) -> Array:
    path = jnp.asarray(path, jnp.float32)
    if path.shape[0] == 1:
        return _paint(state, centres, path[0], radius)
    return state | jnp.any(_near_segment(centres, path[:-1], path[1:], radius), axis=0)


@dataclass(frozen=True, eq=False)
class ObjectScene:
    """Features of bodies, sites and joints of the simulated world, by name.

    Args:
        specs: `cgda_jax.sim.features.FeatureSpec` entries or their dict form,
            e.g. ``[{"body": "box", "quantity": "xy"}, {"joint": "valve",
            "quantity": "angle"}]``; names are resolved against the model when the
            `Simulator` is built (an unknown name raises KeyError listing the
            model's names).
        goal_path: optional (K, 3) points drawn in renders (e.g. the goal path of a
            pushed box), world frame.

    The simulator computes the features (``world_features`` tells it which); this
    scene carries no state.  Units are in `feature_names` (m, rad).
    """

    specs: tuple = ()
    goal_path: np.ndarray | None = None

    def __post_init__(self):
        from cgda_jax.sim.features import FeatureSpec

        specs = tuple(f if isinstance(f, FeatureSpec) else FeatureSpec.from_dict(f)
                      for f in self.specs)
        if not specs:
            raise ValueError("ObjectScene needs at least one feature")
        object.__setattr__(self, "specs", specs)
        if self.goal_path is not None:
            path = np.asarray(self.goal_path, np.float64)
            if path.ndim != 2 or path.shape[1] != 3 or not np.all(np.isfinite(path)):
                raise ValueError(f"goal_path must be finite (K, 3); got {path.shape}")
            object.__setattr__(self, "goal_path", path)

    @property
    def world_features(self) -> tuple:
        return self.specs

    @property
    def feature_names(self) -> tuple[str, ...]:
        return tuple(f"{c} [{f.unit}]" for f in self.specs for c in f.columns())

    @property
    def n_features(self) -> int:
        return len(self.feature_names)

    def init_state(self) -> tuple:
        return ()

    def update(self, state: tuple, marker_pos: Array) -> tuple:
        del marker_pos
        return state

    def decorations(self, state) -> list:
        """The goal path as small green spheres (renders)."""
        del state
        if self.goal_path is None:
            return []
        half = np.full(3, 0.012)
        return [("sphere", half, p, (0.1, 0.8, 0.2, 0.8)) for p in self.goal_path]
