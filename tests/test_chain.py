"""build_chain_fk against MuJoCo's C mj_kinematics (site_xpos)."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax.sim.chain import build_chain_fk, chain_ops

# A free-floating box (free joint, other tree), a fixed intermediate body, quats and
# euler-rotated bodies, off-centre joint anchors, oblique axes, a joint `ref`, a slide,
# two joints in one body, a ball joint on the chain held at qpos0, and a
# non-evolved hinge on the chain.
ARM_XML = """
<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="float" pos="2 0 0.5">
      <freejoint/><geom size="0.1 0.1 0.1" type="box"/>
    </body>
    <body name="base" pos="0.1 -0.2 0.3" quat="0.9 0.1 -0.3 0.2">
      <geom size="0.05"/>
      <joint name="j0" type="hinge" axis="0 0 1" pos="0.01 0.02 0"/>
      <body name="fixed" pos="0 0.05 0.1" euler="0.3 -0.2 0.5">
        <geom size="0.05"/>
        <body name="upper" pos="0.2 0 0" quat="0.7 0 0.7 0">
          <geom size="0.05"/>
          <joint name="j1" type="hinge" axis="1 1 0" pos="0 0 -0.05" ref="0.4"/>
          <joint name="j2" type="hinge" axis="0 1 0.3"/>
          <body name="ballbody" pos="0.15 0.02 0">
            <geom size="0.05"/>
            <joint name="ball" type="ball" pos="0.01 0 0"/>
            <body name="slider" pos="0 0 0.1" euler="0.1 0.2 0.3">
              <geom size="0.05"/>
              <joint name="s0" type="slide" axis="0.2 0.9 0.1"/>
              <joint name="held" type="hinge" axis="1 0 0" pos="0 0.03 0"/>
              <body name="fore" pos="0.3 0 0">
                <geom size="0.05"/>
                <joint name="j3" axis="-0.3 0.5 0.8" pos="0.02 -0.01 0.03"/>
                <site name="tip" pos="0.12 -0.03 0.04" euler="0.4 0 0"/>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
EVOLVED = ["j0", "j1", "j2", "s0", "j3"]


def _qpos_for(model, qpos0, joint_ids, genes):
    qpos = np.array(qpos0, dtype=np.float64)
    for jid, g in zip(joint_ids, genes):
        qpos[model.jnt_qposadr[jid]] = g
    return qpos


def _random_qpos0(model, rng):
    """A posture with every joint moved (free and ball included)."""
    qpos0 = np.array(model.qpos0, dtype=np.float64)
    for j in range(model.njnt):
        adr = model.jnt_qposadr[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            qpos0[adr : adr + 3] = rng.normal(size=3)
            q = rng.normal(size=4)
            qpos0[adr + 3 : adr + 7] = q / np.linalg.norm(q)
        elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            q = rng.normal(size=4)
            qpos0[adr : adr + 4] = q / np.linalg.norm(q)
        else:
            qpos0[adr] = rng.uniform(-1, 1)
    return qpos0


def _check_against_c(model, joint_names, site, n_postures=50, seed=0, qpos0=None):
    rng = np.random.default_rng(seed)
    jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joint_names]
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
    qpos0 = _random_qpos0(model, rng) if qpos0 is None else qpos0
    fk = jax.jit(jax.vmap(build_chain_fk(model, qpos0, jids, sid)))
    genes = rng.uniform(-np.pi, np.pi, size=(n_postures, len(jids)))
    data = mujoco.MjData(model)
    expected = []
    for g in genes:
        data.qpos[:] = _qpos_for(model, qpos0, jids, g)
        mujoco.mj_kinematics(model, data)
        expected.append(data.site_xpos[sid].copy())
    got = fk(jnp.asarray(genes, dtype=jnp.float32))
    assert got.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(got), np.array(expected), atol=1e-5)


def test_matches_mj_kinematics_on_a_general_chain():
    model = mujoco.MjModel.from_xml_string(ARM_XML)
    assert model.qpos0[model.jnt_qposadr[2]] == pytest.approx(0.4)  # j1 ref
    _check_against_c(model, EVOLVED, "tip")


@pytest.mark.parametrize("seed", [1, 2])
def test_joint_subsets_and_order(seed):
    """Joints held at qpos0 fold into constants; gene order follows joint_ids."""
    model = mujoco.MjModel.from_xml_string(ARM_XML)
    rng = np.random.default_rng(seed)
    subset = list(rng.permutation(EVOLVED)[: 2 + seed])
    _check_against_c(model, subset, "tip", n_postures=20, seed=seed)


def test_default_qpos0_and_single_constant_chain():
    model = mujoco.MjModel.from_xml_string(ARM_XML)
    _check_against_c(model, EVOLVED, "tip", qpos0=model.qpos0, n_postures=10)
    # No evolved joint on the chain: one constant transform, genes ignored.
    ops = chain_ops(model, model.qpos0, [], "tip")
    assert [op.kind for op in ops] == ["const"]


def test_site_on_a_free_body_and_unrelated_genes():
    xml = ARM_XML.replace(
        '<geom size="0.1 0.1 0.1" type="box"/>',
        '<geom size="0.1 0.1 0.1" type="box"/><site name="boxsite" pos="0.1 0.2 0.3"/>',
    )
    model = mujoco.MjModel.from_xml_string(xml)
    _check_against_c(model, EVOLVED, "boxsite", n_postures=5)


def test_grad_and_hinge_count():
    model = mujoco.MjModel.from_xml_string(ARM_XML)
    ops = chain_ops(model, model.qpos0, EVOLVED, "tip")
    assert sum(op.kind == "hinge" for op in ops) == 4
    assert sum(op.kind == "slide" for op in ops) == 1
    # Consecutive constants are merged: no two "const" ops in a row.
    kinds = [op.kind for op in ops]
    assert all(not (a == b == "const") for a, b in zip(kinds, kinds[1:]))
    fk = build_chain_fk(model, model.qpos0, EVOLVED, "tip")
    g = jnp.linspace(-0.5, 0.5, 5, dtype=jnp.float32)
    jac = jax.jacfwd(fk)(g)
    eps = 1e-3
    num = (fk(g.at[1].add(eps)) - fk(g.at[1].add(-eps))) / (2 * eps)
    np.testing.assert_allclose(jac[:, 1], num, atol=2e-3)


@pytest.mark.parametrize(
    ("joints", "site", "match"),
    [
        (["ball"], "tip", "only hinge and slide"),
        (["nope"], "tip", "joint 'nope' not found"),
        (["j0"], "nosite", "site 'nosite' not found"),
        (["j0", "j0"], "tip", "twice"),
        ([99], "tip", "joint id 99 out of range"),
    ],
)
def test_bad_input_raises(joints, site, match):
    model = mujoco.MjModel.from_xml_string(ARM_XML)
    with pytest.raises(ValueError, match=match):
        build_chain_fk(model, model.qpos0, joints, site)


def test_bad_shapes_raise():
    model = mujoco.MjModel.from_xml_string(ARM_XML)
    with pytest.raises(ValueError, match="qpos0 has shape"):
        build_chain_fk(model, np.zeros(3), EVOLVED, "tip")
    fk = build_chain_fk(model, model.qpos0, EVOLVED, "tip")
    with pytest.raises(ValueError, match="genes has shape"):
        fk(jnp.zeros(4))


@pytest.mark.parametrize("file", ["teo.xml", "tiny_arm.xml"])
def test_builtin_models(models_dir, file):
    """Every site of the shipped models, with every hinge/slide joint evolved."""
    path = models_dir / file
    if not path.exists():
        pytest.skip(f"{path} not written yet")
    model = mujoco.MjModel.from_xml_path(str(path))
    hinges = [
        mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        for j in range(model.njnt)
        if model.jnt_type[j]
        in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE)
    ]
    for s in range(model.nsite):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s)
        _check_against_c(model, hinges, name, n_postures=10, seed=s)
