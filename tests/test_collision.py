"""Collider (cgda_jax.sim.collision) against MuJoCo C's mj_geomDistance."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax import Robot, model_path
from cgda_jax.sim import primitive_distances
from cgda_jax.sim.collision import Collider, Obstacle

ARM3 = ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
ARM6 = ["r_shoulder_flexion", "r_shoulder_abduction", "r_upper_arm_rotation",
        "r_elbow", "r_forearm_rotation", "r_wrist"]
#: obstacles around TEO's right arm's workspace, one per type
OBSTACLES = (
    Obstacle("board", "box", (0.45, -0.5, 0.3), (0.02, 0.3, 0.3),
             (0.966, 0.0, 0.259, 0.0)),
    Obstacle("ball", "sphere", (0.3, -0.6, 0.1), (0.08,)),
    Obstacle("rod", "capsule", (0.25, -0.3, 0.0), (0.03, 0.2), (0.7, 0.7, 0.0, 0.1)),
    Obstacle("post", "cylinder", (0.2, -0.7, 0.2), (0.04, 0.15), (0.9, 0.2, 0.3, 0.0)),
    Obstacle("floor", "plane", (0.0, 0.0, -0.25), (), (0.99, 0.05, 0.1, 0.0)),
)


def teo(joints=ARM6, **kw):
    return Robot.from_mjcf(model_path("teo.xml"), joints, "marker", **kw)


def _qpos(robot, genes):
    q = np.asarray(robot.qpos0, dtype=np.float64).copy()
    q[robot.qpos_adr] = genes
    return q


def _with_obstacles(robot, obstacles):
    """The robot's model with the obstacles as real geoms of its world body."""
    spec = mujoco.MjSpec.from_file(str(model_path("teo.xml")))
    types = {"box": mujoco.mjtGeom.mjGEOM_BOX, "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
             "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
             "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
             "plane": mujoco.mjtGeom.mjGEOM_PLANE}
    for o in obstacles:
        size = np.zeros(3)
        size[: len(o.size)] = o.size
        if o.type == "plane":
            size = [1.0, 1.0, 0.1]
        spec.worldbody.add_geom(name=o.name, type=types[o.type], size=size,
                                pos=o.pos, quat=o.quat)
    return spec.compile()


def _compare(robot, col, model=None, n=100, seed=0):
    """Ours vs mj_geomDistance over random postures: per pair type,
    (max error on separated pairs / their bound, sign disagreements, depth gaps)."""
    m = model if model is not None else robot.mj_model
    d = mujoco.MjData(m)
    rng = np.random.default_rng(seed)
    genes = rng.uniform(np.asarray(robot.lower), np.asarray(robot.upper),
                        size=(n, robot.n_dof)).astype(np.float32)
    ours = np.asarray(jax.jit(jax.vmap(col.distances))(jnp.asarray(genes)))
    ids = [(m.geom(a).id, m.geom(b).id) for a, b in col.pair_names]
    worst, bad_sign, depth = {}, [], {}
    for g, row in zip(genes, ours):
        d.qpos[:] = _qpos(robot, g)
        mujoco.mj_kinematics(m, d)
        for k, (g1, g2) in enumerate(ids):
            ref = mujoco.mj_geomDistance(m, d, g1, g2, 10.0, None)
            key = col.pair_types[k]
            if key == ("capsule", "box") and ref > 1e-4 and row[k] < -1e-4:
                # mjc_CapsuleBox misses a thin capsule piercing right through a
                # box (it reports a separation): check ours by brute force instead
                assert row[k] == pytest.approx(_brute(m, d, g1, g2), abs=1e-4)
                continue
            if ref > 1e-4:
                ratio = abs(row[k] - ref) / col.error_bounds[k]
                worst[key] = max(worst.get(key, 0.0), ratio)
            elif ref < -1e-4:
                depth[key] = max(depth.get(key, 0.0), abs(row[k] - ref))
            if abs(ref) > 1e-4 and np.sign(ref) != np.sign(row[k]):
                bad_sign.append((col.pair_names[k], float(row[k]), ref))
    return worst, bad_sign, depth


def _brute(m, d, capsule, box):
    """Smallest box sdf over 20001 points of the capsule's segment, minus its radius."""
    R, p = d.geom_xmat[capsule].reshape(3, 3), d.geom_xpos[capsule]
    r, h = m.geom_size[capsule][:2]
    pts = p + np.linspace(-h, h, 20001)[:, None] * R[:, 2]
    local = (pts - d.geom_xpos[box]) @ d.geom_xmat[box].reshape(3, 3)
    q = np.abs(local) - m.geom_size[box]
    sdf = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
    return sdf.min() - r


def test_mj_geom_distance_is_negative_in_penetration():
    xml = """<mujoco><worldbody><geom name="a" type="sphere" size="0.1"/>
      <geom name="b" type="box" size="0.1 0.1 0.1" pos="0.15 0 0"/></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    ref = mujoco.mj_geomDistance(m, d, 0, 1, 1.0, None)
    ours = primitive_distances.pair_distance(
        "sphere", "box", jnp.array([0.1, 0, 0]), jnp.eye(3), jnp.zeros(3),
        jnp.array([0.1, 0.1, 0.1]), jnp.eye(3), jnp.array([0.15, 0, 0]))
    assert ref == pytest.approx(-0.05) and float(ours) == pytest.approx(-0.05, abs=1e-6)


@pytest.mark.parametrize("joints", [ARM3, ARM6, ["trunk_axial", *ARM6]])
def test_teo_matches_mujoco(joints):
    robot = teo(joints)
    col = Collider(robot)
    worst, bad_sign, _ = _compare(robot, col)
    assert worst and max(worst.values()) <= 1.0, worst
    assert not bad_sign


def test_tiny_arm_matches_mujoco():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    col = Collider(robot)
    assert col.pair_names == (("link1", "base"), ("link2", "base"))
    worst, bad_sign, depth = _compare(robot, col)
    assert max(worst.values()) <= 1.0 and not bad_sign
    assert max(depth.values()) < 1e-4  # link1's cap in the base: a shallow contact


def test_obstacles_match_mujoco_with_them_as_geoms():
    robot = teo(ARM6)
    col = Collider(robot, OBSTACLES)
    names = {b for _, b in col.pair_names}
    assert {o.name for o in OBSTACLES} <= names
    worst, bad_sign, _ = _compare(robot, col, _with_obstacles(robot, OBSTACLES))
    kinds = {k for k in worst}
    assert {("r_hand", "box"), ("r_tool", "cylinder")} <= {
        (a, kb) for (a, b), (_, kb) in zip(col.pair_names, col.pair_types)}
    assert max(worst.values()) <= 1.0, worst
    assert ("box", "cylinder") in kinds and ("capsule", "plane") in kinds
    assert not bad_sign


def test_geom_frames_match_mj_kinematics():
    robot = teo(["trunk_axial", *ARM6])
    col = Collider(robot, self_collision=True)
    m, d = robot.mj_model, mujoco.MjData(robot.mj_model)
    genes = np.deg2rad([20, 30, -20, 40, 60, -45, 70]).astype(np.float32)
    d.qpos[:] = _qpos(robot, genes)
    mujoco.mj_kinematics(m, d)
    R, p = (np.asarray(x) for x in col.geom_frames(jnp.asarray(genes)))
    for name in ("chest", "r_upper_arm", "r_forearm", "r_hand", "r_tool", "pelvis"):
        row, g = col.geom_names.index(name), m.geom(name).id
        np.testing.assert_allclose(p[row], d.geom_xpos[g], atol=2e-6)
        np.testing.assert_allclose(R[row].ravel(), d.geom_xmat[g], atol=2e-6)


def test_penetration_is_negative_and_names_the_pair():
    board = Obstacle("board", "box", (0.0, -0.34692, 0.07), (0.1, 0.1, 0.02))
    robot = teo(ARM6)
    col = Collider(robot, [board])
    d, k = col.min_distance(jnp.zeros(6))  # arm hanging: the forearm crosses it
    assert float(d) < -0.03 and col.pair_names[int(k)] == ("r_forearm", "board")
    d, _ = col.min_distance(jnp.deg2rad(jnp.array([60.0, -40, 0, 0, 0, 0])))
    assert float(d) > 0.0
    # self: the tool swung back into the pelvis (MuJoCo agrees it penetrates)
    genes = np.deg2rad([-38, 10, -5, 73, -85, 64]).astype(np.float32)
    d, k = Collider(robot).min_distance(jnp.asarray(genes))
    assert float(d) < -0.03 and Collider(robot).pair_names[int(k)] == ("r_tool",
                                                                      "pelvis")
    m, data = robot.mj_model, mujoco.MjData(robot.mj_model)
    data.qpos[:] = _qpos(robot, genes)
    mujoco.mj_kinematics(m, data)
    assert mujoco.mj_geomDistance(m, data, m.geom("r_tool").id, m.geom("pelvis").id,
                                  1.0, None) < -0.03


def test_pairs_respect_the_filters():
    robot = teo(ARM3)
    m = robot.mj_model
    col = Collider(robot)
    assert col.n_pairs == len(col.pair_names) == 31
    moving = {"r_upper_arm", "r_forearm", "r_hand", "r_tool"}
    for a, b in col.pair_names:
        assert a in moving  # robot (moving) geom first; no static-static pair
        ba, bb = m.geom(a).bodyid[0], m.geom(b).bodyid[0]
        assert ba != bb
        assert m.body_parentid[ba] != bb and m.body_parentid[bb] != ba
    assert ("r_hand", "r_tool") not in col.pair_names  # one body
    assert ("r_forearm", "r_hand") not in col.pair_names  # parent / child
    assert ("r_upper_arm", "chest") not in col.pair_names  # trunk is its parent
    assert ("r_upper_arm", "r_hand") in col.pair_names
    ex = Collider(robot, OBSTACLES, exclude=("pelvis", "ball"))
    assert all("pelvis" not in p and "ball" not in p for p in ex.pair_names)
    assert ex.n_pairs == 31 - 4 + 4 * (len(OBSTACLES) - 1)
    no_self = Collider(robot, self_collision=False)
    assert all(b not in moving for _, b in no_self.pair_names)
    assert no_self.n_pairs == 31 - 2
    with pytest.raises(KeyError, match="nope"):
        Collider(robot, exclude=["nope"])
    with pytest.raises(ValueError, match="type"):
        Obstacle("x", "mesh", (0, 0, 0), (1,))


def test_jit_vmap_batch_equals_per_posture():
    robot = teo(ARM6)
    col = Collider(robot, OBSTACLES[:2])
    rng = np.random.default_rng(3)
    paths = rng.uniform(np.asarray(robot.lower), np.asarray(robot.upper),
                        size=(3, 4, 6)).astype(np.float32)
    batch = jax.jit(jax.vmap(jax.vmap(col.distances)))(jnp.asarray(paths))
    worst, idx = jax.jit(jax.vmap(col.path_min_distance))(jnp.asarray(paths))
    assert batch.shape == (3, 4, col.n_pairs) and batch.dtype == jnp.float32
    for p in range(3):
        rows = np.stack([np.asarray(col.distances(jnp.asarray(g))) for g in paths[p]])
        np.testing.assert_allclose(np.asarray(batch[p]), rows, atol=1e-6)
        assert float(worst[p]) == pytest.approx(rows.min(), abs=1e-6)
        assert rows.min(axis=0)[int(idx[p])] == pytest.approx(rows.min(), abs=1e-6)
    with pytest.raises(ValueError, match="shape"):
        col.distances(jnp.zeros(5))


def test_world_table_geoms_are_included():
    table = {"piece": "table", "pos": [0.35, -0.35, -0.05]}
    robot = Robot.from_world(model_path("teo.xml"), [table], ARM6, "marker")
    col = Collider(robot)
    others = {b for _, b in col.pair_names}
    assert {"table", "table/leg1", "table/leg4"} <= others
    worst, bad_sign, _ = _compare(robot, col, n=60, seed=5)
    assert max(worst.values()) <= 1.0 and not bad_sign
    assert ("box", "cylinder") in worst
