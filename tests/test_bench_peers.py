"""The benchmark peers (benchmarks/peers.py) compute the same numbers as cgda_jax,
so the timings in benchmarks/ compare equal work."""

import pathlib
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax.distance import dtw

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
import peers  # noqa: E402


def _numpy_dtw(x, y):
    """The paper's score with a plain double loop (float64)."""
    x, y = np.atleast_2d(x.T).T, np.atleast_2d(y.T).T
    n, m = len(x), len(y)
    total = 0.0
    for d in range(x.shape[1]):
        acc = np.full((n + 1, m + 1), np.inf)
        acc[0, 0] = 0.0
        for i in range(1, n + 1):
            for j in range(1, m + 1):
                acc[i, j] = abs(x[i - 1, d] - y[j - 1, d]) + min(
                    acc[i - 1, j], acc[i, j - 1], acc[i - 1, j - 1]
                )
        total += acc[n, m]
    return total / (n + m)


@pytest.fixture(scope="module")
def series():
    rng = np.random.default_rng(0)
    cands = rng.normal(size=(5, 12, 3)).astype(np.float32)
    ref = rng.normal(size=(15, 3)).astype(np.float32)
    return cands, ref


def _ours_to_ref(cands, ref):
    return np.asarray(jax.vmap(dtw, in_axes=(0, None))(cands, ref))


@pytest.mark.parametrize(
    "pair_fn",
    [
        peers.dtai_pair,
        peers.dtwpython_pair,
        # tslearn's numba kernels compile for ~15 s in every new process.
        pytest.param(peers.tslearn_pair, marks=pytest.mark.slow),
    ],
)
def test_dtw_pair_peers_match_ours(series, pair_fn):
    if pair_fn is peers.tslearn_pair:
        pytest.importorskip("tslearn")
    cands, ref = series
    want = np.array([_numpy_dtw(c, ref) for c in cands])
    got_peer = peers.pairs_to_ref(pair_fn, cands, ref)
    np.testing.assert_allclose(got_peer, want, rtol=1e-7)
    np.testing.assert_allclose(_ours_to_ref(cands, ref), want, rtol=1e-5)


def test_dtaidistance_block_matches_ours(series):
    cands, _ = series
    refs = cands[:2] + 0.5
    want = np.array([[_numpy_dtw(q, r) for r in refs] for q in cands])
    for parallel in (True, False):
        got = peers.dtai_block(cands, refs, parallel=parallel)
        np.testing.assert_allclose(got, want, rtol=1e-7)
    ours = jax.vmap(jax.vmap(dtw, in_axes=(None, 0)), in_axes=(0, None))(cands, refs)
    np.testing.assert_allclose(np.asarray(ours), want, rtol=1e-5)


@pytest.mark.parametrize("scene_kind", ["marker", "paint"])
def test_mujoco_c_execution_matches_simulator(scene_kind):
    from cgda_jax.sim import MarkerScene, PaintWall, Robot, Simulator, model_path

    robot = Robot.from_mjcf(
        model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"], "marker"
    )
    if scene_kind == "marker":
        scene = MarkerScene()
    else:
        rng = np.random.default_rng(1)
        scene = PaintWall(rng.uniform(-0.4, 0.4, size=(12, 3)), radius=0.15)
    sim = Simulator(robot, scene, substeps=3)
    c_sim = peers.MujocoMarker.from_simulator(sim)
    rng = np.random.default_rng(2)
    pop = rng.uniform(-2.5, 2.5, size=(4, 6, 3)).astype(np.float32)  # some clipped
    ours = np.asarray(sim.execute_population(jnp.asarray(pop)))
    theirs = np.stack([c_sim.execute(w) for w in pop])
    assert ours.shape == theirs.shape
    np.testing.assert_allclose(ours, theirs, atol=1e-4)
    if scene_kind == "paint":
        assert theirs.max() > 0  # the check is not vacuous


def test_pycma_peers_use_our_gene_map_and_solve_a_tiny_goal():
    from cgda_jax.sim import MarkerScene, Robot, Simulator, model_path
    from cgda_jax.strategies.base import to_joints

    robot = Robot.from_mjcf(
        model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"], "marker"
    )
    sim = Simulator(robot, MarkerScene(), substeps=2)
    c_sim = peers.MujocoMarker.from_simulator(sim)
    u = np.random.default_rng(3).normal(size=(5, 3))
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    np.testing.assert_allclose(
        peers.to_joints(u, lo, hi),
        np.asarray(to_joints(jnp.asarray(u, jnp.float32), robot.lower, robot.upper)),
        atol=1e-6,
    )
    # Reachable goals: the marker at two known postures.
    goal = c_sim.execute(np.array([[0.3, 0.4, -0.5], [-0.2, 0.6, 0.3]]))
    ie = peers.pycma_ie(c_sim, goal, popsize=8, tolerance=0.02, max_gens=150)
    assert ie["success"] and ie["point_errors"].max() < 0.02
    iet = peers.pycma_iet(c_sim, goal, popsize=8, tolerance=0.02, max_gens=150)
    assert iet["success"] and len(iet["point_times_s"]) == 2
