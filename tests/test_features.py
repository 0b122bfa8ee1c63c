"""Object features by name (cgda_jax.sim.features) against MuJoCo C."""

import types

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax.sim._mujoco_env import mjx_module
from cgda_jax.sim.features import FeatureSet, FeatureSpec, add_sensors

# A hinge arm with a tilted tool site, a free box with a site off its centre, a hinge
# valve, a slide joint and a ball joint: every kind of feature and every joint type.
MJCF = """
<mujoco>
  <default><geom contype="0" conaffinity="0"/></default>
  <worldbody>
    <body name="arm" pos="0 0 0.1">
      <joint name="shoulder" type="hinge" axis="0 1 0"/>
      <joint name="yaw" type="hinge" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/>
      <site name="tool" pos="0.3 0 0" euler="0.3 -0.2 0.7"/>
    </body>
    <body name="box" pos="0.5 0.2 0.05">
      <freejoint name="box_free"/>
      <geom type="box" size="0.04 0.05 0.03" pos="0.01 0 0"/>
      <site name="box_corner" pos="0.04 -0.05 0.03"/>
    </body>
    <body name="valve" pos="0 0.5 0.2" euler="0.4 0 0">
      <joint name="valve" type="hinge" axis="0 0 1" damping="0.1"/>
      <geom type="cylinder" size="0.1 0.01"/>
      <site name="rim" pos="0.1 0 0"/>
    </body>
    <body name="slider" pos="-0.3 0 0">
      <joint name="slide" type="slide" axis="1 0 0"/>
      <joint name="ball" type="ball"/>
      <geom type="sphere" size="0.03"/>
    </body>
  </worldbody>
</mujoco>
"""

ALL = [
    {"body": "box", "quantity": "xyz"},
    {"body": "box", "quantity": "yaw"},
    {"body": "arm", "quantity": "xy"},
    {"body": "valve", "quantity": "z"},
    {"body": "valve", "quantity": "yaw"},
    {"site": "tool", "quantity": "x"},
    {"site": "tool", "quantity": "y"},
    {"site": "tool", "quantity": "yaw"},
    {"site": "box_corner", "quantity": "xyz"},
    {"site": "rim", "quantity": "yaw"},
    {"joint": "valve", "quantity": "angle"},
    {"joint": "shoulder", "quantity": "angle"},
    {"joint": "slide", "quantity": "position"},
]


def _reference(m, d) -> np.ndarray:
    """The ALL features computed by NumPy from MjData after mj_forward."""

    def body(name):
        return m.body(name).id

    def site(name):
        return m.site(name).id

    def yaw(xmat):
        r = np.reshape(xmat, (3, 3))
        return np.arctan2(r[1, 0], r[0, 0])

    def qpos(name):
        return d.qpos[m.jnt_qposadr[m.joint(name).id]]

    return np.array([
        *d.xpos[body("box")],
        yaw(d.xmat[body("box")]),
        *d.xpos[body("arm")][:2],
        d.xpos[body("valve")][2],
        yaw(d.xmat[body("valve")]),
        d.site_xpos[site("tool")][0],
        d.site_xpos[site("tool")][1],
        yaw(d.site_xmat[site("tool")]),
        *d.site_xpos[site("box_corner")],
        yaw(d.site_xmat[site("rim")]),
        qpos("valve"),
        qpos("shoulder"),
        qpos("slide"),
    ])


def _random_qpos(m, rng) -> np.ndarray:
    qpos = rng.uniform(-np.pi, np.pi, m.nq)
    for j in range(m.njnt):
        adr = m.jnt_qposadr[j]
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            qpos[adr:adr + 3] = rng.uniform(-1, 1, 3)
            q = rng.normal(size=4)
            qpos[adr + 3:adr + 7] = q / np.linalg.norm(q)
        elif m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            q = rng.normal(size=4)
            qpos[adr:adr + 4] = q / np.linalg.norm(q)
    return qpos


@pytest.fixture(scope="module")
def world():
    """(model, model with sensors, FeatureSet on the latter, 4 random MjData)."""
    m = mujoco.MjModel.from_xml_string(MJCF)
    spec = mujoco.MjSpec.from_string(MJCF)
    added = add_sensors(spec, ALL)
    assert len(added) == 12  # 13 features; tool x and y share one sensor
    ms = spec.compile()
    fs = FeatureSet(ms, ALL)
    rng = np.random.default_rng(0)
    datas = []
    for _ in range(4):
        d = mujoco.MjData(ms)
        d.qpos[:] = _random_qpos(ms, rng)
        mujoco.mj_forward(ms, d)
        datas.append(d)
    return m, ms, fs, datas


def test_names_units_and_count(world):
    _, _, fs, _ = world
    assert fs.n_features == 18 == len(fs.feature_names) == len(fs.units)
    assert fs.feature_names[:4] == ("box.x [m]", "box.y [m]", "box.z [m]",
                                    "box.yaw [rad]")
    assert fs.feature_names[-3:] == ("valve.angle [rad]", "shoulder.angle [rad]",
                                     "slide.position [m]")
    assert fs.has_sensors


def test_from_data_on_mjdata_equals_numpy(world):
    _, _, fs, datas = world
    for d in datas:
        ns = types.SimpleNamespace(**{
            k: jnp.asarray(getattr(d, k))
            for k in ("xpos", "xmat", "xquat", "site_xpos", "site_xmat", "qpos")
        })
        np.testing.assert_allclose(fs.from_data(ns), _reference(d.model, d), atol=2e-6)
        # xquat instead of xmat for body yaw
        ns.xmat = None
        np.testing.assert_allclose(fs.from_data(ns), _reference(d.model, d), atol=2e-6)


def test_from_sensordata_equals_numpy(world):
    _, _, fs, datas = world
    for d in datas:
        np.testing.assert_allclose(
            fs.from_sensordata(d.sensordata), _reference(d.model, d), atol=2e-6
        )


def test_from_data_on_mjx_kinematics_and_mjx_sensors(world):
    _, ms, fs, datas = world
    mjx = mjx_module()
    mx = mjx.put_model(ms, impl="jax")
    qpos = jnp.asarray(np.stack([d.qpos for d in datas]), dtype=jnp.float32)

    @jax.jit
    @jax.vmap
    def run(q):
        d0 = mjx.make_data(mx).replace(qpos=q)
        dx = mjx.forward(mx, d0)
        kin = fs.from_data(mjx.kinematics(mx, d0))
        return kin, fs.from_data(dx), fs.from_sensordata(dx.sensordata)

    by_kinematics, by_data, by_sensors = run(qpos)
    ref = np.stack([_reference(ms, d) for d in datas])
    np.testing.assert_allclose(by_kinematics, ref, atol=1e-4)
    np.testing.assert_allclose(by_data, ref, atol=1e-4)
    np.testing.assert_allclose(by_sensors, ref, atol=1e-4)


def test_jit_vmap_on_stacked_kinematics(world):
    _, _, fs, datas = world
    fields = ("xpos", "xmat", "site_xpos", "site_xmat", "qpos")
    batch = {k: jnp.asarray(np.stack([getattr(d, k) for d in datas])) for k in fields}
    out = jax.jit(jax.vmap(lambda b: fs.from_data(types.SimpleNamespace(**b))))(batch)
    sens = jax.jit(jax.vmap(fs.from_sensordata))(
        jnp.asarray(np.stack([d.sensordata for d in datas]))
    )
    ref = np.stack([_reference(d.model, d) for d in datas])
    assert out.shape == sens.shape == (4, fs.n_features)
    np.testing.assert_allclose(out, ref, atol=2e-6)
    np.testing.assert_allclose(sens, ref, atol=2e-6)


def test_spec_forms():
    assert FeatureSpec.from_dict({"joint": "valve", "quantity": "angle"}) == \
        FeatureSpec("joint", "valve", "angle")
    spec = FeatureSpec("site", "rim", "yaw")
    assert FeatureSpec.from_dict(spec) is spec
    assert spec.columns() == ("rim.yaw",) and spec.unit == "rad"


@pytest.mark.parametrize("entry, match", [
    ({"body": "box", "quantity": "xy", "colour": 1}, r"unknown key\(s\) \['colour'\]"),
    ({"bodies": "box", "quantity": "xy"}, r"unknown key\(s\) \['bodies'\]"),
    ({"body": "box", "joint": "valve", "quantity": "xy"}, "exactly one of"),
    ({"quantity": "xy"}, "exactly one of"),
    ({"body": "box"}, "missing key 'quantity'"),
    ({"body": "box", "quantity": "angle"}, "quantity 'angle' unknown; a body has"),
    ({"joint": "valve", "quantity": "xy"}, "quantity 'xy' unknown; a joint has"),
    ({"site": "", "quantity": "x"}, "non-empty string"),
])
def test_bad_dicts_name_the_key(entry, match):
    with pytest.raises(ValueError, match=match):
        FeatureSpec.from_dict(entry)


def test_bad_kind():
    with pytest.raises(ValueError, match="feature kind 'geom' unknown"):
        FeatureSpec("geom", "box", "xyz")


@pytest.mark.parametrize("kind, name, quantity, listed", [
    ("body", "boxx", "xy", "bodies ['world', 'arm', 'box', 'valve', 'slider']"),
    ("site", "tip", "xyz", "sites ['tool', 'box_corner', 'rim']"),
    ("joint", "valv", "angle", "joints ['shoulder', 'yaw', 'box_free', 'valve',"),
])
def test_unknown_names_list_the_model(world, kind, name, quantity, listed):
    m = world[0]
    with pytest.raises(KeyError) as err:
        FeatureSet(m, [FeatureSpec(kind, name, quantity)])
    msg = err.value.args[0]
    assert f"{kind} {name!r} not found; the model has" in msg and listed in msg


@pytest.mark.parametrize("joint, quantity, match", [
    ("box_free", "angle", "'box_free' is a free joint; quantity 'angle' needs a hinge"),
    ("ball", "angle", "'ball' is a ball joint"),
    ("valve", "position", "'valve' is a hinge joint; quantity 'position' needs a sl"),
    ("slide", "angle", "'slide' is a slide joint"),
])
def test_wrong_joint_type(world, joint, quantity, match):
    with pytest.raises(ValueError, match=match):
        FeatureSet(world[0], [{"joint": joint, "quantity": quantity}])


def test_sensordata_without_sensors_is_a_clear_error(world):
    fs = FeatureSet(world[0], [{"body": "box", "quantity": "xy"}])
    assert not fs.has_sensors
    with pytest.raises(ValueError, match="call add_sensors"):
        fs.from_sensordata(jnp.zeros(3))
