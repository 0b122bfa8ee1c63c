"""What a user would use instead of cgda_jax, set up to compute the same numbers.

DTW (the paper's per-dimension score: local cost ``|x_i - y_j|``, symmetric steps
``min(D(i-1, j), D(i, j-1), D(i-1, j-1))`` each adding the local cost once, then
``D(N, M) / (N + M)`` summed over features):

- dtaidistance (C, OpenMP): ``inner_dist="euclidean"`` makes its local cost ``|a - b|``
  on 1-D series and returns the accumulated cost unchanged (its default
  ``"squared euclidean"`` sums squares and takes a square root at the end, which is
  a different quantity).  One call per feature; ``distance_matrix_fast`` with a
  ``block`` computes only the candidate-vs-reference cells, in parallel.
- dtw-python (C core): ``step_pattern="symmetric1"`` (its default ``symmetric2``
  weighs the diagonal step twice), ``dist_method="cityblock"``, one pair at a time.
- tslearn (numba): ``dtw_path_from_metric(metric="cityblock")`` on each feature (its
  ``dtw``/``cdist_dtw`` use squared differences and a final square root).

Execution: `MujocoMarker` is the marker-only kinematic simulator a user would write
with MuJoCo's C bindings (``mj_kinematics`` per sub-step), mirroring
``cgda_jax.sim.Simulator`` in kinematic mode; tests/test_bench_peers.py checks that it
returns the same features.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

# --- DTW peers ---------------------------------------------------------------------


def _as_float64(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return x[:, None] if x.ndim == 1 else x


def dtai_pair(x, y) -> float:
    """The paper's score for one pair with dtaidistance's C ``distance_fast``."""
    from dtaidistance import dtw

    x, y = _as_float64(x), _as_float64(y)
    total = sum(
        dtw.distance_fast(
            np.ascontiguousarray(x[:, d]),
            np.ascontiguousarray(y[:, d]),
            inner_dist="euclidean",
        )
        for d in range(x.shape[1])
    )
    return total / (x.shape[0] + y.shape[0])


def dtai_block(queries, refs, parallel: bool = True) -> np.ndarray:
    """(Q, R) scores of equal-length queries (Q, T, F) vs refs (R, T, F) with
    dtaidistance's parallel C ``distance_matrix_fast`` (only the Q x R block)."""
    from dtaidistance import dtw

    queries = np.asarray(queries, dtype=np.float64)
    refs = np.asarray(refs, dtype=np.float64)
    q, r = len(queries), len(refs)
    total = np.zeros((q, r))
    for d in range(queries.shape[2]):
        series = np.ascontiguousarray(
            np.concatenate([queries[:, :, d], refs[:, :, d]], axis=0)
        )
        block = dtw.distance_matrix_fast(  # compact: only the block, row-major
            series,
            block=((0, q), (q, q + r)),
            parallel=parallel,
            inner_dist="euclidean",
            compact=True,
        )
        total += np.asarray(block).reshape(q, r)
    return total / (queries.shape[1] + refs.shape[1])


def dtwpython_pair(x, y) -> float:
    """The paper's score for one pair with dtw-python (symmetric1, cityblock)."""
    import dtw as dtwpy

    x, y = _as_float64(x), _as_float64(y)
    total = sum(
        dtwpy.dtw(
            x[:, d],
            y[:, d],
            dist_method="cityblock",
            step_pattern="symmetric1",
            distance_only=True,
        ).distance
        for d in range(x.shape[1])
    )
    return total / (x.shape[0] + y.shape[0])


def tslearn_pair(x, y) -> float:
    """The paper's score for one pair with tslearn (cityblock, per feature)."""
    from tslearn.metrics import dtw_path_from_metric

    x, y = _as_float64(x), _as_float64(y)
    total = sum(
        dtw_path_from_metric(x[:, d : d + 1], y[:, d : d + 1], metric="cityblock")[1]
        for d in range(x.shape[1])
    )
    return total / (x.shape[0] + y.shape[0])


def pairs_to_ref(pair_fn, candidates, ref) -> np.ndarray:
    """(P,) scores of each candidate vs one reference, one pair at a time."""
    return np.array([pair_fn(c, ref) for c in candidates])


def pairs_matrix(pair_fn, queries, refs) -> np.ndarray:
    """(Q, R) scores, one pair at a time."""
    return np.array([[pair_fn(q, r) for r in refs] for q in queries])


# --- MuJoCo C execution ------------------------------------------------------------


class MujocoMarker:
    """Kinematic execution of joint waypoints with MuJoCo's C ``mj_kinematics``.

    Mirrors ``Simulator(robot, MarkerScene() or PaintWall(...), mode="kinematic")``:
    waypoints are clipped into the joint limits; from the current posture (start: all
    evolved joints at 0, clipped), ``substeps`` postures equally spaced in joint space
    towards the waypoint (the last one at it); the scene is updated at the start
    posture and at each sub-step, and the features are read at the waypoint.

    Args:
        model: the compiled model.
        joints: evolved joint names (gene order).
        site: marker site name.
        lower, upper: (DoF,) joint limits.
        qpos0: (nq,) posture of the joints not evolved.
        substeps: sub-steps per waypoint.
        paint_centres: (S, 3) square centres for a paint scene (feature = painted
            percent); None for the marker scene (features = marker x, y, z).
        paint_radius: a square is painted when the marker is this close or closer.
        paint_front: (3,) unit normal of the wall's painted side: only the part of
            the path on that side paints (None: any side).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        joints: Sequence[str],
        site: str,
        lower: np.ndarray,
        upper: np.ndarray,
        qpos0: np.ndarray,
        substeps: int = 8,
        paint_centres: np.ndarray | None = None,
        paint_radius: float = 0.12,
        paint_front: np.ndarray | None = None,
    ):
        self.model = model
        self.data = mujoco.MjData(model)
        jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints]
        self.qadr = np.asarray(model.jnt_qposadr[jids])
        self.site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
        self.lower = np.asarray(lower, np.float64)
        self.upper = np.asarray(upper, np.float64)
        self.qpos0 = np.array(qpos0, np.float64)
        self.alphas = np.arange(1, substeps + 1) / substeps
        self.centres = None if paint_centres is None else np.asarray(paint_centres)
        self.radius = paint_radius
        self.front = None if paint_front is None else np.asarray(paint_front, float)

    @classmethod
    def from_simulator(cls, sim) -> MujocoMarker:
        """The C twin of a kinematic ``cgda_jax.sim.Simulator`` (same robot, scene)."""
        robot, scene = sim.robot, sim.scene
        centres = getattr(scene, "centres", None)
        return cls(
            robot.mj_model,
            robot.joint_names,
            robot.marker_site,
            np.asarray(robot.lower),
            np.asarray(robot.upper),
            np.asarray(robot.qpos0),
            substeps=sim.substeps,
            paint_centres=None if centres is None else np.asarray(centres),
            paint_radius=float(getattr(scene, "radius", 0.12)),
            paint_front=getattr(scene, "front", None),
        )

    def marker(self, genes: np.ndarray) -> np.ndarray:
        """(3,) marker position for joint values (DoF,)."""
        self.data.qpos[:] = self.qpos0
        self.data.qpos[self.qadr] = genes
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.site_xpos[self.site].copy()

    def init_state(self, start: np.ndarray | None = None) -> tuple:
        """(posture (DoF,), painted (S,) or None, marker (3,)): ``start`` (default
        zeros), clipped, with the scene updated there."""
        q = np.zeros(len(self.qadr)) if start is None else np.asarray(start, float)
        q = np.clip(q, self.lower, self.upper)
        painted = None if self.centres is None else np.zeros(len(self.centres), bool)
        pos = self.marker(q)
        self._paint(painted, pos, pos)
        return q, painted, pos

    def _paint(self, painted, start, end) -> None:
        """Paint along the segment start -> end (as ``PaintWall.sweep``)."""
        if painted is None:
            return
        c = self.centres  # (S, 3)
        a = np.broadcast_to(start, c.shape).astype(float)
        b = np.broadcast_to(end, c.shape).astype(float)
        keep = np.ones(len(c), bool)
        if self.front is not None:  # keep the part of a -> b in front of each c
            sa, sb = (a - c) @ self.front, (b - c) @ self.front
            keep = (sa >= 0) | (sb >= 0)
            cross = (sa < 0) != (sb < 0)
            w = np.where(cross, sa / np.where(cross, sa - sb, 1.0), 0.0)[:, None]
            cut = a + (b - a) * w
            a = np.where((cross & (sa < 0))[:, None], cut, a)
            b = np.where((cross & (sb < 0))[:, None], cut, b)
        d = b - a
        dd = np.sum(d * d, axis=1)
        t = np.clip(np.sum((c - a) * d, axis=1) / np.where(dd > 0, dd, 1.0), 0, 1)
        near = np.sum((c - a - t[:, None] * d) ** 2, axis=1) <= self.radius**2
        painted |= keep & near

    def step(self, state: tuple, waypoint: np.ndarray) -> tuple[tuple, np.ndarray]:
        """Move to one (DoF,) waypoint: (new state, features (F,))."""
        q, painted, last = state
        painted = None if painted is None else painted.copy()
        w = np.clip(np.asarray(waypoint, np.float64), self.lower, self.upper)
        for a in self.alphas:
            pos = self.marker(q + a * (w - q))
            self._paint(painted, last, pos)
            last = pos
        feats = pos if painted is None else np.array([100.0 * painted.mean()])
        return (w, painted, last), feats

    def execute(self, waypoints: np.ndarray, start: np.ndarray | None = None):
        """Features (N, F) of executing (N, DoF) waypoints from ``start``."""
        state = self.init_state(start)
        feats = []
        for w in np.asarray(waypoints, np.float64):
            state, f = self.step(state, w)
            feats.append(f)
        return np.asarray(feats)

