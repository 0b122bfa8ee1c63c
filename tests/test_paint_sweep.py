"""Painting along the swept path: the point-to-segment distance, the sub-step bound
for the curved path, and results that keep their painted squares when replayed with
16 x the sub-steps (issue 11: the optimiser exploited gaps between sub-steps)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import PaintWall, Simulator
from cgda_jax.experiment.build import build_goal, build_simulator
from cgda_jax.experiment.config import load_config
from cgda_jax.sim.chain import path_substeps
from cgda_jax.sim.scenes import segment_distance2
from cgda_jax.strategies import run_trials


@pytest.fixture(scope="module")
def paint_sim():
    """TEO's paint scene as experiments/paint_iet.toml builds it."""
    return build_simulator(load_config("experiments/paint_iet.toml"))


def _dense_distance(points, a, b, n=4001):
    """NumPy reference: min distance from each point to n samples of a -> b."""
    ts = np.linspace(0.0, 1.0, n)[:, None]
    samples = a + ts * (b - a)  # (n, 3)
    d = np.linalg.norm(points[:, None, :] - samples[None], axis=-1)
    return d.min(axis=1)


def test_segment_distance_matches_dense_sampling():
    rng = np.random.default_rng(0)
    points = rng.normal(0, 0.5, (16, 3))
    for k in range(30):
        a = rng.normal(0, 0.5, 3)
        b = a if k == 0 else a + rng.normal(0, 0.3 if k % 2 else 0.01, 3)
        got = np.sqrt(np.asarray(segment_distance2(
            jnp.asarray(points, jnp.float32), jnp.asarray(a, jnp.float32),
            jnp.asarray(b, jnp.float32))))
        want = _dense_distance(points, a, b)
        step = np.linalg.norm(b - a) / 4000
        np.testing.assert_allclose(got, want, atol=2e-6 + step)
    # batched: (K, 3) segments -> (K, S), each row as alone
    a = rng.normal(0, 0.5, (5, 3)).astype(np.float32)
    b = rng.normal(0, 0.5, (5, 3)).astype(np.float32)
    batch = np.asarray(segment_distance2(jnp.asarray(points, jnp.float32), a, b))
    assert batch.shape == (5, 16)
    for k in range(5):
        np.testing.assert_allclose(
            np.sqrt(batch[k]), _dense_distance(points, a[k], b[k]), atol=1e-5)


def test_sweep_paints_what_the_segment_passes():
    wall = PaintWall.grid()
    c = wall.centres[5]
    # both ends 0.17 m from the centre (0.13 m from the neighbours' centres, outside
    # the 0.12 m radius), the middle 0.11 m
    a, b = c + [-0.11, -0.13, 0.0], c + [-0.11, 0.13, 0.0]
    assert not np.any(np.asarray(wall.near(jnp.asarray(a, jnp.float32)))[5])
    painted = np.asarray(wall.sweep(wall.init_state(), np.stack([a, b])))
    assert painted.tolist() == [i == 5 for i in range(16)]
    # a segment ending exactly at the radius paints (the boundary counts); beyond: no
    r = wall.radius
    for reach, want in ((r - 1e-4, True), (r + 1e-4, False)):
        seg = np.stack([c + [-reach, -0.05, 0.0], c + [-reach, 0.05, 0.0]])
        assert bool(np.asarray(wall.near_segment(seg[:1], seg[1:]))[0, 5]) is want
    # one position: `update` there
    one = np.asarray(wall.sweep(wall.init_state(), c[None]))
    assert one[5] and one.sum() == 1


def test_a_tracker_pads_its_paths_and_paints_the_same():
    """`SceneTracker` pads a paint wall's path to a power of two rows with its last
    position (a few programs, not one per path length): the same painted squares,
    bit for bit, as the unpadded sweep of each piece, pieces of every length."""
    from cgda_jax.programs import cache_stats
    from cgda_jax.reality.replay import SceneTracker

    wall = PaintWall.grid()
    rng = np.random.default_rng(3)
    lo, hi = wall.centres.min(axis=0), wall.centres.max(axis=0)
    start = wall.centres[0] + [-0.05, 0.0, 0.0]
    tracker = SceneTracker(wall, start)
    want = wall.update(wall.init_state(), jnp.asarray(start, jnp.float32))
    last, before, counts = start, cache_stats()["misses"], []
    for k in range(1, 12):  # 1..11 new positions: paths of 2..12 rows
        # near the wall's front (x within 0.15 m), some ends on a square's radius
        pts = rng.uniform(lo - 0.1, hi + 0.1, (k, 3))
        pts[:, 0] = wall.centres[0, 0] - rng.uniform(0.0, 0.15, k)
        pts[-1] = wall.centres[k] + [-wall.radius, 0.0, 0.0]
        tracker.advance(pts)
        want = wall.sweep(want, np.concatenate([last[None], pts]))
        last = pts[-1]
        np.testing.assert_array_equal(np.asarray(tracker.state), np.asarray(want))
        counts.append(int(np.asarray(want).sum()))
    assert len(set(counts)) >= 3  # the pieces paint squares as they go
    assert cache_stats()["misses"] - before <= 4  # rows 2, 4, 8, 16: four programs


def test_path_substeps_bound_holds_on_teo(paint_sim):
    """Random moves: the K-sub-step polyline strays less than the wall's
    path_tolerance from the densely sampled marker path (the bound is not loose
    by orders of magnitude either)."""
    robot, wall = paint_sim.robot, paint_sim.scene
    k_sub = path_substeps(robot, wall.path_tolerance)
    assert paint_sim.substeps == k_sub > 8
    rng = np.random.default_rng(1)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    q0 = rng.uniform(lo, hi, (64, 3))
    q1 = rng.uniform(lo, hi, (64, 3))
    q0[0], q1[0] = lo, hi  # the longest move
    dense = 32  # samples per sub-step
    ts = np.arange(k_sub * dense + 1) / (k_sub * dense)
    fk = jax.jit(jax.vmap(jax.vmap(robot.marker_position)))
    path = np.asarray(fk(jnp.asarray(
        q0[:, None] + ts[None, :, None] * (q1 - q0)[:, None], jnp.float32)), float)
    knots = path[:, ::dense]  # (M, K + 1, 3) the sub-step positions
    a, b = knots[:, :-1, None], knots[:, 1:, None]  # (M, K, 1, 3) each chord
    inner = path[:, :-1].reshape(len(path), k_sub, dense, 3)  # the curve in between
    d = b - a
    t = np.clip(np.sum((inner - a) * d, -1, keepdims=True)
                / np.sum(d * d, -1, keepdims=True), 0.0, 1.0)
    worst = float(np.linalg.norm(inner - a - t * d, axis=-1).max())
    print(f"{k_sub} sub-steps: worst stray {worst * 1e3:.3f} mm")
    assert worst <= wall.path_tolerance
    assert worst > wall.path_tolerance / 100


def _painted_after_moves(sim, q0, q1):
    def one(a, b):
        state, _ = sim.step(sim.init_state(a), b)
        return state.scene

    return np.asarray(jax.jit(jax.vmap(one))(q0, q1))


def _stays_in_front(robot, wall, q0, q1, n=257):
    """(M,) bool: the marker's densely sampled path never passes behind the wall's
    plane (a move through the board is infeasible; where it crosses the plane, the
    front-only rule adds a boundary that sub-steps can resolve differently)."""
    ts = jnp.linspace(0.0, 1.0, n)[None, :, None]
    fk = jax.jit(jax.vmap(jax.vmap(robot.marker_position)))
    path = np.asarray(fk(q0[:, None] + ts * (q1 - q0)[:, None]))
    plane = float(np.min(wall.centres @ wall.front))
    return np.all(path @ wall.front >= plane - 1e-3, axis=1)


def test_random_moves_paint_the_same_at_16x_substeps(paint_sim):
    robot, wall = paint_sim.robot, paint_sim.scene
    rng = np.random.default_rng(2)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    q0 = jnp.asarray(rng.uniform(lo, hi, (1500, 3)), jnp.float32)
    q1 = jnp.asarray(rng.uniform(lo, hi, (1500, 3)), jnp.float32)
    front = _stays_in_front(robot, wall, q0, q1)
    assert front.sum() > 1000, front.sum()
    q0, q1 = q0[front], q1[front]
    base = _painted_after_moves(paint_sim, q0, q1)
    fine = _painted_after_moves(paint_sim.finer(16), q0, q1)
    assert fine.sum() > 500  # the moves do paint
    np.testing.assert_array_equal(base, fine)
    # the check has teeth: 8 sub-steps without the bound miss the curved path
    coarse = Simulator(robot, PaintWall(wall.centres, path_tolerance=None), substeps=8)
    assert np.any(_painted_after_moves(coarse, q0, q1) != fine)


@pytest.mark.slow  # 97 s in CI: a replay check of a full IET paint run
def test_iet_paint_results_replay_with_16x_substeps(paint_sim):
    """IET paint results (small budget, 3 seeds): the 16 x sub-step replay paints
    the same percentages after every waypoint."""
    goal, _, _ = build_goal(load_config("experiments/paint_iet.toml"))
    results = run_trials("iet", paint_sim, goal, 3, seed=0, population_size=16,
                         tolerance=3.0, max_generations=60)
    fine = paint_sim.finer(16)
    assert fine.substeps == 16 * paint_sim.substeps
    for r in results:
        replay = np.asarray(fine.execute(np.asarray(r.joints, np.float32)))
        np.testing.assert_array_equal(replay, np.asarray(r.features, np.float32))


@pytest.mark.slow
def test_dynamic_iet_paint_replays_with_16x_finer_physics():
    """Dynamic mode (paint_iet_dynamic.toml, one seed): the result replayed at
    timestep / 16 on MuJoCo C paints the same percentages."""
    cfg = load_config("experiments/paint_iet_dynamic.toml")
    sim = build_simulator(cfg)
    goal, _, _ = build_goal(cfg)
    (r,) = run_trials("iet", sim, goal, 1, seed=0, population_size=32,
                      tolerance=3.0, max_generations=200)
    replay = np.asarray(sim.finer(16).execute(np.asarray(r.joints, np.float32)))
    np.testing.assert_array_equal(replay, np.asarray(r.features, np.float32))
