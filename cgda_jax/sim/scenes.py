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
    "feature_labels",
    "front_segment_distance2",
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
    rel, d, rel_d, rel2, dd = _segment_terms(points, start, end)
    t = jnp.clip(rel_d / jnp.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return jnp.maximum(rel2 - 2.0 * t * rel_d + t * t * dd, 0.0)


def _segment_terms(points: Array, start: Array, end: Array):
    """Per-coordinate terms of the distances from ``points`` (S, 3) to the segments
    ``start -> end`` ((..., 3) each): ``rel`` (3 x (..., S), p - start), ``d``
    (..., 3), ``rel . d``, ``|rel|^2`` (..., S) and ``d . d`` (..., 1)."""
    points = jnp.asarray(points)
    start = jnp.asarray(start, points.dtype)
    d = jnp.asarray(end, points.dtype) - start
    rel = [points[:, c] - start[..., c, None] for c in range(3)]  # (..., S) each
    rel_d = sum(r * d[..., c, None] for c, r in enumerate(rel))
    rel2 = sum(r * r for r in rel)
    dd = jnp.sum(d * d, axis=-1)[..., None]
    return rel, d, rel_d, rel2, dd


def front_segment_distance2(
    points: Array, start: Array, end: Array, front: Array
) -> Array:
    """Squared distance from each of ``points`` (S, 3) to the part of the segment
    ``start -> end`` ((..., 3) each) that lies on the front side of the plane through
    that point with unit normal ``front`` (3,): ``(x - p) . front >= 0``.  ``inf``
    where no part of the segment is in front.  Returns (..., S).

    On ``x(t) = start + t d`` the side ``s(t) = (start - p) . front + t d . front``
    is linear in t, so the front part is one interval ``[lo, hi]`` of [0, 1]; the
    closest point of that interval is the unconstrained closest ``t`` clipped into
    it (the squared distance is a convex quadratic in t).
    """
    rel, d, rel_d, rel2, dd = _segment_terms(points, start, end)
    f = jnp.asarray(front, d.dtype)
    s0 = -sum(r * f[c] for c, r in enumerate(rel))  # side of the start, (..., S)
    sd = jnp.sum(d * f, axis=-1)[..., None]  # its rate along the segment
    safe = jnp.where(sd != 0, sd, 1.0)
    cross = -s0 / safe  # where the segment meets the plane
    lo = jnp.where(sd > 0, jnp.maximum(cross, 0.0), 0.0)
    hi = jnp.where(sd < 0, jnp.minimum(cross, 1.0), 1.0)
    empty = jnp.where(sd == 0, s0 < 0, lo > hi)
    t = jnp.clip(rel_d / jnp.where(dd > 0, dd, 1.0), 0.0, 1.0)
    t = jnp.clip(t, lo, jnp.maximum(lo, hi))
    d2 = jnp.maximum(rel2 - 2.0 * t * rel_d + t * t * dd, 0.0)
    return jnp.where(empty, jnp.inf, d2)


def feature_labels(scene) -> tuple[str, ...]:
    """A scene's feature names with their units, for axis labels (``"X [m]"``,
    ``"painted [%]"``): its ``feature_units`` where it has them; a name that
    already carries its unit in brackets (the object scenes') is kept."""
    units = getattr(scene, "feature_units", None) or (None,) * len(
        scene.feature_names)
    return tuple(n if (u is None or str(n).rstrip().endswith("]")) else f"{n} [{u}]"
                 for n, u in zip(scene.feature_names, units))


@dataclass(frozen=True, eq=False)
class MarkerScene:
    """Features = the marker position (X, Y, Z) in the robot's root frame; F = 3.

    The state is an empty tuple.
    """

    feature_names: tuple[str, ...] = ("X", "Y", "Z")
    #: the features' units (`feature_labels`): metres in the robot's root frame.
    feature_units: tuple[str, ...] = ("m", "m", "m")

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
    """A wall of S squares on a solid board; a square is painted, for good, once the
    marker's path comes within ``radius`` of its centre on the FRONT side of the
    wall (the side ``front`` points to; a tool reaching a centre from behind the
    board paints nothing).  Feature: painted percentage (F = 1), in multiples of
    100 / S.  State: ``painted`` (S,) bool.

    `update` paints at one position; `sweep` paints along the straight segments
    between consecutive positions (closed-form point-to-segment distance, the part
    of each segment in front of the wall: `front_segment_distance2`), which is what
    the simulator calls for each move: the marker may travel further between two
    sub-steps than a square's painting diameter.

    The board (`board`) is a box of ``thickness`` behind the squares' plane,
    ``margin`` beyond the outer squares' edges: an obstacle the feasibility check
    (`cgda_jax.sim.collision`) keeps the robot out of, drawn in renders.

    Args:
        centres: (S, 3) square centres in the robot's root frame (metres).
        radius: painting distance (metres); the authors used 0.12.
        size: square side (metres).
        normal: (3,) unit vector from the wall towards its front, the side that
            is painted (the robot's side; `grid`: -x).  Must be a coordinate axis
            for the board.
        path_tolerance: metres: a kinematic `Simulator` takes enough sub-steps per
            move that the straight segments between them stay this close to the
            marker's curved path (`cgda_jax.sim.chain.path_substeps`; 1 mm gives
            67 on TEO's arm); None: the simulator's sub-steps as given.
        thickness: board thickness behind the squares (metres); 0: no board.
        margin: board border beyond the outer squares (metres).
    """

    centres: np.ndarray
    radius: float = 0.12
    size: float = 0.20
    normal: tuple[float, float, float] = (-1.0, 0.0, 0.0)
    path_tolerance: float | None = 0.001
    thickness: float = 0.03
    margin: float = 0.05
    feature_names: tuple[str, ...] = field(default=("painted",))
    feature_units: tuple[str, ...] = field(default=("%",))

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
        n = np.asarray(self.normal, dtype=np.float64)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise ValueError(f"PaintWall normal must be a (3,) non-zero vector, got "
                             f"{self.normal}")
        n = n / np.linalg.norm(n)
        for key in ("thickness", "margin"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"PaintWall {key} must be >= 0 metres, got {v}")
        if self.thickness > 0 and np.max(np.abs(n)) < 1 - 1e-6:
            raise ValueError(f"PaintWall normal {self.normal}: a board needs a "
                             "coordinate axis (or thickness = 0: no board)")
        object.__setattr__(self, "centres", centres)
        object.__setattr__(self, "normal", tuple(float(v) for v in n))

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
        thickness: float = 0.03,
        margin: float = 0.05,
    ) -> PaintWall:
        """A vertical wall of len(ys) x len(zs) squares at ``x``, painted from the
        robot's side (front -x), on a board ``thickness`` deep behind them.

        Defaults are the authors' TEO scene: centres at x 0.6, y in {-0.8, ..., -0.2},
        z in {0.32, ..., 0.92} in a world where the robot's root (TEO's waist) stands
        at z = ``root_height`` = 0.3; the centres are returned in the root frame
        (z - 0.3).  Order: z-major (bottom row first), then y.
        """
        centres = [(x, y, z - root_height) for z in zs for y in ys]
        return cls(np.array(centres), radius=radius, size=size,
                   path_tolerance=path_tolerance, thickness=thickness, margin=margin)

    @property
    def n_squares(self) -> int:
        return len(self.centres)

    @property
    def n_features(self) -> int:
        return 1

    def init_state(self) -> Array:
        return jax.device_put(np.zeros(self.n_squares, dtype=bool))

    @property
    def front(self) -> np.ndarray:
        """(3,) float32 unit normal towards the painted side."""
        return np.asarray(self.normal, np.float32)

    @property
    def board(self) -> dict | None:
        """The board as a box: ``{"name", "type": "box", "pos" (3,), "size" (3,)
        half sizes}`` in the root frame (None when ``thickness`` is 0).  Its front
        face is the squares' plane (the farthest centre along ``-front``)."""
        if self.thickness <= 0:
            return None
        c = np.asarray(self.centres, np.float64)
        n = np.asarray(self.normal, np.float64)
        axis = int(np.argmax(np.abs(n)))
        plane = float(np.min(c @ n))  # the squares' plane, along the normal
        lo = c.min(axis=0) - self.size / 2 - self.margin
        hi = c.max(axis=0) + self.size / 2 + self.margin
        pos, half = (lo + hi) / 2, (hi - lo) / 2
        pos[axis] = (plane - self.thickness / 2) * np.sign(n[axis])
        half[axis] = self.thickness / 2
        return {"name": "paint_board", "type": "box", "pos": pos, "size": half}

    def near(self, marker_pos: Array) -> Array:
        """(S,) bool: squares within ``radius`` of the marker, on the front side."""
        return _near(self.centres, marker_pos, self.front, self.radius)

    def near_segment(self, start: Array, end: Array) -> Array:
        """(..., S) bool: squares within ``radius`` of the front part of the
        segment ``start -> end`` (``(3,)`` each, or batched ``(..., 3)``)."""
        return _near_segment(self.centres, start, end, self.front, self.radius)

    def update(self, state: Array, marker_pos: Array) -> Array:
        return _paint(state, self.centres, marker_pos, self.front, self.radius)

    def sweep(self, state: Array, path: Array) -> Array:
        """Paint along the polyline ``path`` (K + 1, 3): the K straight segments
        between consecutive positions (all at once; one position paints at it)."""
        return _sweep(state, self.centres, path, self.front, self.radius)

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
        board = self.board
        if board is not None:  # behind the squares (they stand 4 mm in front)
            out.append(("box", board["size"], board["pos"], (0.45, 0.33, 0.22, 1.0)))
        return out


# PaintWall's geometry as jitted functions of its centres (the radius static): one
# program per shape where they are called eagerly (set-up, renders), not one per
# operation; inlined in the simulator's traces.
@partial(jax.jit, static_argnums=3)
def _near(centres: Array, marker_pos: Array, front: Array, radius: float) -> Array:
    rel = marker_pos - jnp.asarray(centres)
    d2 = jnp.sum(rel**2, axis=-1)
    return (d2 <= radius**2) & (rel @ jnp.asarray(front) >= 0)


@partial(jax.jit, static_argnums=4)
def _near_segment(centres: Array, start: Array, end: Array, front: Array,
                  radius: float) -> Array:
    start = jnp.asarray(start, jnp.float32)
    end = jnp.asarray(end, jnp.float32)
    d2 = front_segment_distance2(jnp.asarray(centres), start, end, front)
    return d2 <= radius**2


@partial(jax.jit, static_argnums=4)
def _paint(state: Array, centres: Array, marker_pos: Array, front: Array,
           radius: float) -> Array:
    return state | _near(centres, marker_pos, front, radius)


@partial(jax.jit, static_argnums=4)
def _sweep(state: Array, centres: Array, path: Array, front: Array,
           radius: float) -> Array:
    path = jnp.asarray(path, jnp.float32)
    if path.shape[0] == 1:
        return _paint(state, centres, path[0], front, radius)
    near = _near_segment(centres, path[:-1], path[1:], front, radius)
    return state | jnp.any(near, axis=0)


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
        return tuple(name for f in self.specs for name in f.labels())

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
