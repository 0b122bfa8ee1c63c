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


# --- pycma + MuJoCo C strategies ---------------------------------------------------
# The same searches as cgda_jax.strategies (CMA-ES in the same normalized gene space,
# same start mean 0 and step size, same population size, fitness and stopping rules),
# written the way a user of pycma would: ask/tell, each candidate executed on its own.


def to_joints(u, lower, upper) -> np.ndarray:
    """Normalized genes -> joint angles (cgda_jax.strategies.base.to_joints)."""
    mid, half = 0.5 * (upper + lower), 0.5 * (upper - lower)
    return mid + half * np.sin(0.5 * np.pi * np.asarray(u))


def _cma(n_genes: int, popsize: int, sigma0: float, seed: int, max_gens: int):
    import cma

    opts = {
        "popsize": popsize,
        "seed": seed + 1,  # pycma: seed 0 means "random"
        "verbose": -9,
        "maxiter": max_gens,
        "CMA_diagonal": False,
        # stop by the caller's rule only, as cgda_jax does: none of pycma's own
        # flat-fitness / small-change stops (a paint score is flat over large regions)
        "tolflatfitness": max_gens + 1,
        "tolfun": 0,
        "tolfunhist": 0,
        "tolx": 0,
        "tolstagnation": max_gens + 1,
        "tolxstagnation": False,
    }
    return cma.CMAEvolutionStrategy(np.zeros(n_genes), sigma0, opts)


def _evolve(fitness, n_genes, popsize, sigma0, seed, max_gens, stop):
    """ask/tell until ``stop(best, stall, generation)`` or pycma stops.

    Returns (best_u, best_f, generations, evaluations)."""
    es = _cma(n_genes, popsize, sigma0, seed, max_gens)
    best_u, best_f, stall, gen = np.zeros(n_genes), np.inf, 0, 0
    while not es.stop():
        pop = es.ask()
        fit = [fitness(u) for u in pop]  # one candidate at a time
        es.tell(pop, fit)
        gen += 1
        i = int(np.argmin(fit))
        if fit[i] < best_f:
            best_u, best_f, stall = np.asarray(pop[i]), fit[i], 0
        else:
            stall += 1
        if stop(best_f, stall, gen):
            break
    return best_u, best_f, gen, gen * popsize


def _evolve_point(fitness, n_genes, popsize, sigma0, seed, max_gens, tolerance):
    """One point's evolution: stop below ``tolerance`` or after ``max_gens``."""
    return _evolve(
        fitness,
        n_genes,
        popsize,
        sigma0,
        seed,
        max_gens,
        lambda f, stall, gen: f < tolerance or gen >= max_gens,
    )


def pycma_ie(c_sim, goal, popsize, tolerance, max_gens, seed=0, sigma0=1.0) -> dict:
    """IE: each point evolved on its own (one after the other), fitness = distance of
    the features after one step from the start to the candidate posture."""
    lo, hi = c_sim.lower, c_sim.upper
    start = c_sim.init_state()
    postures, evals, gens = [], 0, []
    for i, g in enumerate(np.asarray(goal, np.float64)):

        def fitness(u, g=g):
            return float(np.linalg.norm(c_sim.step(start, to_joints(u, lo, hi))[1] - g))

        u, _, n_gen, n_eval = _evolve_point(
            fitness, len(lo), popsize, sigma0, seed + 1000 * i, max_gens, tolerance
        )
        postures.append(to_joints(u, lo, hi))
        evals += n_eval
        gens.append(n_gen)
    errors = np.linalg.norm(c_sim.execute(np.array(postures)) - goal, axis=-1)
    return {
        "success": bool(np.all(errors < tolerance)),
        "evaluations": evals,
        "generations": int(max(gens)),
        "point_errors": errors,
    }


def pycma_fte(
    c_sim, goal, popsize, tolerance, max_gens, stagnation=10, seed=0, sigma0=1.0
) -> dict:
    """FTE: one evolution over all N x DoF genes, fitness = the paper's DTW score
    (dtaidistance C) of the whole executed trajectory."""
    lo, hi = c_sim.lower, c_sim.upper
    n, dof = goal.shape[0], len(lo)
    goal = np.asarray(goal, np.float64)

    def fitness(u):
        feats = c_sim.execute(to_joints(np.reshape(u, (n, dof)), lo, hi))
        return dtai_pair(feats, goal)

    u, best, gens, evals = _evolve(
        fitness,
        n * dof,
        popsize,
        sigma0,
        seed,
        max_gens,
        lambda f, stall, gen: stall >= stagnation or gen >= max_gens,
    )
    feats = c_sim.execute(to_joints(np.reshape(u, (n, dof)), lo, hi))
    errors = np.linalg.norm(feats - goal, axis=-1)
    return {
        "success": bool(np.all(errors < tolerance)),
        "evaluations": evals,
        "generations": gens,
        "point_errors": errors,
        "final_fitness": best,
    }


def pycma_iet(c_sim, goal, popsize, tolerance, max_gens, seed=0, sigma0=1.0) -> dict:
    """IET: point i evolved with points 0..i-1 frozen, fitness = the distance of
    executed features 0..i to goal 0..i; the state reached by the frozen prefix is
    carried (one step per candidate), as cgda_jax does."""
    import time

    lo, hi = c_sim.lower, c_sim.upper
    state, prefix_sq = c_sim.init_state(), 0.0
    point_times, point_fitness, evals = [], [], 0
    for i, g in enumerate(np.asarray(goal, np.float64)):
        t0 = time.perf_counter()

        def fitness(u, g=g, state=state, prefix_sq=prefix_sq):
            feats = c_sim.step(state, to_joints(u, lo, hi))[1]
            return float(np.sqrt(prefix_sq + np.sum((feats - g) ** 2)))

        u, best, _, n_eval = _evolve_point(
            fitness, len(lo), popsize, sigma0, seed + 1000 * i, max_gens, tolerance
        )
        state, feats = c_sim.step(state, to_joints(u, lo, hi))
        prefix_sq += float(np.sum((feats - g) ** 2))
        evals += n_eval
        point_fitness.append(best)
        point_times.append(time.perf_counter() - t0)
    point_fitness = np.array(point_fitness)
    return {
        "success": bool(np.all(point_fitness < tolerance)),
        "evaluations": evals,
        "point_times_s": point_times,
        "point_fitness": point_fitness,
    }
