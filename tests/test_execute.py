"""Simulator: rollouts vs MuJoCo C, painting along paths, batching, no recompiles."""

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path

TEO_PAPER = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]


@pytest.fixture(scope="module")
def tiny():
    return Robot.from_mjcf(
        model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"], "marker"
    )


@pytest.fixture(scope="module")
def teo():
    return Robot.from_mjcf(
        model_path("teo.xml"),
        TEO_PAPER,
        "marker",
        fixed={"r_forearm_rotation": math.radians(45)},
    )


def _c_marker(robot, genes):
    data = mujoco.MjData(robot.mj_model)
    data.qpos[:] = np.asarray(robot.qpos(jnp.asarray(genes, jnp.float32)), np.float64)
    mujoco.mj_kinematics(robot.mj_model, data)
    return data.site_xpos[robot.site_id].copy()


def _random_waypoints(robot, shape, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    return rng.uniform(lo, hi, size=(*shape, robot.n_dof)).astype(np.float32)


@pytest.mark.parametrize("robot_name", ["tiny", "teo"])
def test_marker_rollout_matches_mujoco_c(robot_name, request):
    robot = request.getfixturevalue(robot_name)
    sim = Simulator(robot, MarkerScene(), substeps=3)
    wps = _random_waypoints(robot, (6,))
    feats, state = jax.jit(sim.rollout)(wps)
    want = np.stack([_c_marker(robot, w) for w in wps])
    np.testing.assert_allclose(np.asarray(feats), want, atol=1e-5)
    np.testing.assert_allclose(np.asarray(state.genes), wps[-1])
    assert sim.feature_names == ("X", "Y", "Z") and sim.n_features == 3


def test_waypoints_are_clipped_into_the_limits(tiny):
    sim = Simulator(tiny, MarkerScene(), substeps=1)
    wp = np.array([[3.0, -3.0, 0.0]], np.float32)
    feats = sim.execute(wp)
    clipped = np.clip(wp[0], tiny.lower, tiny.upper)
    np.testing.assert_allclose(
        np.asarray(feats[0]), _c_marker(tiny, clipped), atol=1e-5
    )


def _teo_marker(teo, deg):
    return np.asarray(teo.marker_position(jnp.asarray(np.radians(deg), jnp.float32)))


def test_substeps_paint_along_the_path(teo):
    """A square passed through between two waypoints is painted with sub-steps, and
    not when the arm jumps (one straight segment: the chord misses the arc's
    middle)."""
    a, b = [70, 0, 0], [70, -70, 0]  # arm forward, swept outwards to the right
    mid = _teo_marker(teo, [70, -35, 0])
    wall = PaintWall(np.array([mid]), radius=0.05, path_tolerance=None)
    assert np.linalg.norm(_teo_marker(teo, a) - mid) > 0.2
    assert np.linalg.norm(_teo_marker(teo, b) - mid) > 0.2
    wps = np.radians([a, b]).astype(np.float32)
    swept = Simulator(teo, wall, substeps=16).execute(wps)
    jumped = Simulator(teo, wall, substeps=1).execute(wps)
    np.testing.assert_allclose(np.asarray(swept[:, 0]), [0.0, 100.0])
    np.testing.assert_allclose(np.asarray(jumped[:, 0]), [0.0, 0.0])


def test_teo_paint_features_match_a_host_reference(teo):
    """Painted percentage after each waypoint = a NumPy replay of the same sub-steps
    through MuJoCo C forward kinematics, the wall painted along the straight
    segments between them (the closest point of each segment by projection)."""
    wall = PaintWall.grid()
    sim = Simulator(teo, wall, substeps=4)
    k_sub = sim.substeps
    assert k_sub > 4  # raised for the wall's path tolerance
    wps = _random_waypoints(teo, (8,), seed=3)
    got = np.asarray(sim.execute(wps))[:, 0]

    def seg_near(p, q):
        d = q - p
        t = np.clip((wall.centres - p) @ d / max(d @ d, 1e-30), 0, 1)
        closest = p + t[:, None] * d
        return np.linalg.norm(wall.centres - closest, axis=1) <= 0.12

    painted = np.zeros(16, bool)
    prev = np.zeros(3, np.float32)
    last = _c_marker(teo, prev)
    painted |= np.linalg.norm(wall.centres - last, axis=1) <= 0.12
    want = []
    for w in wps:
        for k in range(1, k_sub + 1):
            m = _c_marker(teo, prev + k / k_sub * (w - prev))
            painted |= seg_near(last, m)
            last = m
        want.append(100 * painted.mean())
        prev = w
    np.testing.assert_allclose(got, want)
    assert got[-1] > 0


def test_rollout_continues_from_a_carried_state(tiny):
    wall = PaintWall(
        np.array([[0.3, 0.0, 0.3], [0.0, 0.3, 0.3], [-0.3, 0.0, 0.3]]), radius=0.1
    )
    sim = Simulator(tiny, wall, substeps=4)
    wps = _random_waypoints(tiny, (10,), seed=4)
    whole, _ = sim.rollout(wps)
    first, state = sim.rollout(wps[:4])
    second, _ = sim.rollout(wps[4:], state)
    np.testing.assert_allclose(np.concatenate([first, second]), whole)
    start = sim.init_state(jnp.asarray(wps[3]))
    np.testing.assert_allclose(np.asarray(start.genes), wps[3])


def test_population_equals_each_alone_and_does_not_recompile(teo):
    sim = Simulator(teo, PaintWall.grid(), substeps=4)
    pop = _random_waypoints(teo, (5, 17), seed=5)
    batched = np.asarray(sim.execute_population(pop))
    assert batched.shape == (5, 17, 1)
    alone = np.stack([np.asarray(sim.execute(p)) for p in pop])
    np.testing.assert_allclose(batched, alone)
    assert len(np.unique(batched[:, -1])) > 1  # the candidates really differ
    before = sim._execute_population._cache_size()
    sim.execute_population(_random_waypoints(teo, (5, 17), seed=6))
    assert sim.n_traces == 1
    assert sim._execute_population._cache_size() == before == 1


@pytest.mark.slow  # 40 s in CI (three MJX compiles); test_strategies checks the slicing path
def test_dynamic_population_in_slices_equals_each_candidate(tiny):
    # 5 candidates in slices of 2 (lax.map over vmapped slices, a ragged last one)
    sim = Simulator(tiny, MarkerScene(), mode="dynamic", physics_steps=5, batch_size=2,
                    physics="mjx")
    pop = _random_waypoints(tiny, (5, 3), seed=11)
    out = np.asarray(sim.execute_population(pop))
    one = jax.jit(sim.execute)
    want = np.stack([np.asarray(one(w)) for w in pop])
    np.testing.assert_allclose(out, want, atol=1e-5)
    assert len({tuple(np.round(o.ravel(), 4)) for o in out}) == 5  # really distinct
    # the generic helper the strategies can use gives the same as a plain vmap
    mapped = jax.jit(lambda q: sim.map_population(sim.execute, q))(pop)
    np.testing.assert_allclose(np.asarray(mapped), want, atol=1e-5)
    with pytest.raises(ValueError, match="batch_size"):
        Simulator(tiny, MarkerScene(), mode="dynamic", batch_size=0)


@pytest.mark.slow  # compiling mjx.step for TEO under vmap takes ~1 min on 2 CPU cores
def test_dynamic_teo_population(teo):
    sim = Simulator(teo, PaintWall.grid(), mode="dynamic", physics_steps=20,
                    physics="mjx")
    pop = _random_waypoints(teo, (2, 3), seed=7)
    out = np.asarray(sim.execute_population(pop))
    assert out.shape == (2, 3, 1) and np.all(np.isfinite(out))


def test_bad_inputs_name_the_problem(tiny, tmp_path):
    sim = Simulator(tiny, MarkerScene())
    with pytest.raises(ValueError, match=r"expected \(N, DoF\) with DoF = 3"):
        sim.execute(np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"expected \(N, DoF\)"):
        sim.execute(np.zeros(3))
    with pytest.raises(ValueError, match=r"expected \(P, N, DoF\)"):
        sim.execute_population(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="waypoint"):
        sim.step(sim.init_state(), jnp.zeros(4))
    with pytest.raises(ValueError, match="genes0"):
        sim.init_state(jnp.zeros(2))
    with pytest.raises(ValueError, match="mode"):
        Simulator(tiny, MarkerScene(), mode="fast")
    with pytest.raises(ValueError, match="substeps"):
        Simulator(tiny, MarkerScene(), substeps=0)
    xml = model_path("tiny_arm.xml").read_text()
    no_act = tmp_path / "no_actuator.xml"
    no_act.write_text(xml.replace('<position name="elbow" joint="elbow"/>', ""))
    robot = Robot.from_mjcf(no_act, ["yaw", "elbow"], "marker")
    with pytest.raises(ValueError, match="elbow"):
        Simulator(robot, MarkerScene(), mode="dynamic")
