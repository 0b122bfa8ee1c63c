"""Scenes: object features computed from the marker position, with carried state.

A scene is static configuration (shapes and constants, closed over by the simulator)
plus a small pytree state that the simulator carries through its scans:

- ``init_state() -> state``
- ``update(state, marker_pos (3,)) -> state``  (called at every sub-step)
- ``features(state, marker_pos (3,)) -> (F,)``  (called at each waypoint)
- ``feature_names`` (F,), ``n_features``

`MarkerScene`: the marker position itself (X, Y, Z in the robot's root frame).
`PaintWall`: a wall of squares painted when the marker comes near their centres; the
feature is the painted percentage.  The authors' TEO wall (Morante et al. 2015) is
`PaintWall.grid()`'s default.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import jax.numpy as jnp
import numpy as np
from jax import Array

__all__ = ["TEO_WALL_Y", "TEO_WALL_Z", "MarkerScene", "PaintWall"]

#: The authors' paint wall (world frame, robot waist at z = 0.3).
TEO_WALL_Y = (-0.8, -0.6, -0.4, -0.2)
TEO_WALL_Z = (0.32, 0.52, 0.72, 0.92)


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
    """A wall of S squares; a square is painted, for good, once the marker is within
    ``radius`` of its centre.  Feature: painted percentage (F = 1), in multiples of
    100 / S.  State: ``painted`` (S,) bool.

    Args:
        centres: (S, 3) square centres in the robot's root frame (metres).
        radius: painting distance (metres); the authors used 0.12.
        size: square side (metres), for drawing only.
        normal: (3,) wall normal, for drawing only.
    """

    centres: np.ndarray
    radius: float = 0.12
    size: float = 0.20
    normal: tuple[float, float, float] = (1.0, 0.0, 0.0)
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
    ) -> PaintWall:
        """A vertical wall (normal +x) of len(ys) x len(zs) squares at ``x``.

        Defaults are the authors' TEO scene: centres at x 0.6, y in {-0.8, ..., -0.2},
        z in {0.32, ..., 0.92} in a world where the robot's root (TEO's waist) stands
        at z = ``root_height`` = 0.3; the centres are returned in the root frame
        (z - 0.3).  Order: z-major (bottom row first), then y.
        """
        centres = [(x, y, z - root_height) for z in zs for y in ys]
        return cls(np.array(centres), radius=radius, size=size)

    @property
    def n_squares(self) -> int:
        return len(self.centres)

    @property
    def n_features(self) -> int:
        return 1

    def init_state(self) -> Array:
        return jnp.zeros(self.n_squares, dtype=bool)

    def near(self, marker_pos: Array) -> Array:
        """(S,) bool: squares within ``radius`` of the marker."""
        d2 = jnp.sum((jnp.asarray(self.centres) - marker_pos) ** 2, axis=-1)
        return d2 <= self.radius**2

    def update(self, state: Array, marker_pos: Array) -> Array:
        return state | self.near(marker_pos)

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
