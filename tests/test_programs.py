"""Fixed costs of a run (issue 39): compiled programs reused within a process, never
a stale one for another config; the pair culling's kept pairs against a per-pair
NumPy reference; the replay check's features without the collision check."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import cgda_jax as cg
from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path
from cgda_jax.experiment.compute import replayed_features
from cgda_jax.programs import cache_stats, clear_programs, compile_lowered, jit_call
from cgda_jax.sim.collision import Collider, Obstacle
from cgda_jax.sim.feasibility import (
    GRID_POSTURES,
    Feasibility,
    relevant_pairs,
    scene_obstacles,
)

WALL = {"name": "wall", "type": "box", "pos": (0.3, 0.0, 0.125),
        "size": (0.12, 0.01, 0.125)}
GOAL = np.array([[0.30, -0.22, 0.25], [0.25, 0.0, 0.50], [0.30, 0.22, 0.25]],
                np.float32)


@pytest.fixture(scope="module")
def tiny():
    return Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                           "marker")


def test_the_same_program_is_compiled_once_another_is_not_shared():
    clear_programs()

    def made(c):  # a new closure each time, as a run builds its plan anew
        return lambda x: jnp.sin(x) * c

    x = jnp.arange(4.0)
    a = jit_call(made(2.0), x)
    b = jit_call(made(2.0), x)
    assert cache_stats()["hits"] == 1 and cache_stats()["misses"] == 1
    np.testing.assert_array_equal(a, b)
    # another constant, another shape: compiled anew, the right values
    np.testing.assert_allclose(jit_call(made(3.0), x), np.sin(np.arange(4.0)) * 3.0,
                               rtol=1e-6)
    np.testing.assert_allclose(jit_call(made(2.0), jnp.arange(5.0)),
                               np.sin(np.arange(5.0)) * 2.0, rtol=1e-6)
    assert cache_stats()["misses"] == 3
    # another result tree of the same computation: not the first one's program
    pair = jit_call(lambda x: (jnp.sin(x) * 2.0, jnp.sin(x) * 2.0), x)
    assert isinstance(pair, tuple) and len(pair) == 2


def test_an_unused_argument_of_another_shape_gets_its_own_program():
    """An argument the program does not read is pruned from its text; a call
    with another shape of it must not take the first program."""
    clear_programs()
    for n in (3, 5):
        out = jit_call(lambda state, path: state + 1.0, jnp.zeros(2), jnp.zeros(n))
        np.testing.assert_array_equal(out, np.ones(2))
    assert cache_stats()["misses"] == 2


def test_programs_with_host_callbacks_are_never_shared():
    clear_programs()

    def calling(c):
        def host(v):
            return np.asarray(v) * c

        return lambda x: jax.pure_callback(
            host, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

    x = jnp.arange(3.0)
    np.testing.assert_allclose(jit_call(calling(2.0), x), [0.0, 2.0, 4.0])
    np.testing.assert_allclose(jit_call(calling(5.0), x), [0.0, 5.0, 10.0])
    assert cache_stats()["uncached"] == 2 and cache_stats()["hits"] == 0


def test_a_run_again_reuses_its_programs_and_another_config_gets_its_own(tiny):
    """Two runs of one config in a process: the second compiles nothing and finds
    the same result; a run with another goal and population between them, and
    after the cache is emptied, finds what it finds when compiled afresh."""
    sim = Simulator(tiny, MarkerScene(), substeps=2)
    kw = {"population_size": 8, "max_generations": 20, "seed": 0, "tolerance": 0.03}
    clear_programs()
    first = cg.run_ie(sim, GOAL, **kw)
    misses = cache_stats()["misses"]
    assert misses >= 4  # init, chunk, done, finish at least
    other_goal = GOAL + np.float32(0.02)
    other = cg.run_ie(sim, other_goal, **(kw | {"population_size": 6}))
    assert cache_stats()["misses"] > misses  # nothing of the first taken
    again = cg.run_ie(sim, GOAL, **kw)
    assert cache_stats()["hits"] >= 4
    np.testing.assert_array_equal(np.asarray(first.joints), np.asarray(again.joints))
    assert again.compile_time_s < first.compile_time_s
    clear_programs()
    fresh = cg.run_ie(sim, other_goal, **(kw | {"population_size": 6}))
    np.testing.assert_array_equal(np.asarray(other.joints), np.asarray(fresh.joints))
    np.testing.assert_array_equal(np.asarray(other.fitness_history),
                                  np.asarray(fresh.fitness_history))


def test_compile_lowered_keys_on_the_program_not_the_function():
    clear_programs()
    x = jnp.ones(3)
    f1 = compile_lowered(jax.jit(lambda v: v + 1.0).lower(x))
    f2 = compile_lowered(jax.jit(lambda v: v + 1.0).lower(x))
    f3 = compile_lowered(jax.jit(lambda v: v - 1.0).lower(x))
    assert f1 is f2 and f3 is not f1
    np.testing.assert_array_equal(f3(x), np.zeros(3))


# -- relevant_pairs against a per-pair NumPy reference ----------------------------
def _sdf_np(kind, size, x):
    """Signed distance of points x (K, 3), in the geom's frame, to the geom."""
    if kind == "sphere":
        return np.linalg.norm(x, axis=-1) - size[0]
    if kind == "capsule":
        z = np.clip(x[:, 2], -size[1], size[1])
        return np.linalg.norm(x - np.outer(z, [0, 0, 1]), axis=-1) - size[0]
    if kind == "box":
        q = np.abs(x) - size[:3]
        return (np.linalg.norm(np.maximum(q, 0), axis=-1)
                + np.minimum(q.max(axis=-1), 0))
    if kind == "cylinder":
        q = np.stack([np.linalg.norm(x[:, :2], axis=-1) - size[0],
                      np.abs(x[:, 2]) - size[1]], -1)
        return (np.linalg.norm(np.maximum(q, 0), axis=-1)
                + np.minimum(q.max(axis=-1), 0))
    assert kind == "plane"
    return x[:, 2]


def _reference_pairs(collider, robot, obstacles):
    """The culling as the module doc states it, one pair at a time in float64."""
    import mujoco

    from cgda_jax.sim.geoms import geom_bound, geom_ids, geom_shape

    m = robot.mj_model
    # the start overlaps: the collider's own distances, optimized (relevant_pairs
    # compiles them unoptimized: the same signs); the grid's bounds are compared
    d0 = np.asarray(jit_call(collider.distances, jnp.asarray(robot.start_genes)))
    over = [p for p, d in zip(collider.pair_names, d0) if d < 0]
    gid, obs = geom_ids(m), {o.name: o for o in obstacles}
    lo, hi = np.asarray(robot.lower, float), np.asarray(robot.upper, float)
    n = max(2, round(GRID_POSTURES ** (1.0 / robot.n_dof)))
    grid = np.stack(np.meshgrid(*[np.linspace(a, b, n) for a, b in zip(lo, hi)],
                                indexing="ij"), -1).reshape(-1, robot.n_dof)
    data = mujoco.MjData(m)
    cen = []
    for q in grid:
        data.qpos[:] = robot.qpos0
        data.qpos[robot.qpos_adr] = q
        mujoco.mj_kinematics(m, data)
        cen.append(data.geom_xpos.copy())
    cen = np.asarray(cen)
    data.qpos[:] = robot.qpos0
    mujoco.mj_kinematics(m, data)
    keep = []
    for k, (a, b) in enumerate(collider.pair_names):
        if (a, b) in over:
            continue
        ra = geom_bound(m, gid[a])
        if b in gid and np.ptp(cen[:, gid[b]], axis=0).max() > 1e-9:
            lb = (np.linalg.norm(cen[:, gid[a]] - cen[:, gid[b]], axis=-1) - ra
                  - geom_bound(m, gid[b]))
        else:
            if b in gid:
                kind, size, c = geom_shape(m, gid[b])
                R = data.geom_xmat[gid[b]].reshape(3, 3)
                p = data.geom_xpos[gid[b]] + R @ c
            else:
                kind = obs[b].type
                R, p, size = obs[b].frame()
            lb = _sdf_np(kind, np.resize(np.asarray(size, float), 3),
                         (cen[:, gid[a]] - p) @ R) - ra
        slack = collider.pair_reach[k] @ ((hi - lo) / (n - 1)) / 2
        if lb.min() - slack <= 0:
            keep.append((a, b))
    return keep, over


def _teo(extra=()):
    return Robot.from_mjcf(model_path("teo.xml"),
                           ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow",
                            *extra], "marker",
                           fixed={"r_forearm_rotation": np.deg2rad(45)})


@pytest.mark.parametrize("case", ["tiny_wall", "teo_marker", "teo_paint"])
def test_relevant_pairs_are_those_of_the_per_pair_reference(tiny, case):
    if case == "tiny_wall":
        robot, obs = tiny, [Obstacle(**WALL)]
    else:
        robot = _teo()
        obs = [Obstacle(o["name"], o["type"], tuple(o["pos"]), tuple(o["size"]),
                        tuple(o.get("quat", (1.0, 0.0, 0.0, 0.0))))
               for o in scene_obstacles(PaintWall.grid() if case == "teo_paint"
                                        else MarkerScene())]
    full = Collider(robot, obs)
    keep, over = relevant_pairs(full, robot, obs)
    want_keep, want_over = _reference_pairs(full, robot, obs)
    assert over == want_over
    assert keep == want_keep
    assert 0 < len(keep) < full.n_pairs  # the culling drops some, keeps some


def test_the_replay_features_are_the_judged_rollouts(tiny):
    """`replayed_features` (moves not judged: no collision check compiled) gives the
    simulator's own features, bit for bit."""
    sim = Simulator(tiny, MarkerScene(), substeps=4,
                    feasibility=Feasibility(tiny, obstacles=[WALL])).finer(4)
    joints = np.deg2rad([[10.0, 20.0, -30.0], [-15.0, 40.0, 20.0]])
    np.testing.assert_array_equal(replayed_features(sim, joints),
                                  np.asarray(sim.execute(joints)))
    with pytest.raises(ValueError, match="expected"):
        replayed_features(sim, joints[:, :2])
