"""Force and torque features (MuJoCo force/torque sensors) against MuJoCo C."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax.sim._mujoco_env import mjx_module
from cgda_jax.sim.features import FeatureSet, FeatureSpec, add_sensors

# A two-joint arm whose tool (a body of its own, behind the sensor site "ft", tilted)
# presses a capsule tip on a plate; position servos push it into the plate.
MJCF = """
<mujoco>
  <option timestep="0.002" iterations="200" tolerance="1e-12"/>
  <worldbody>
    <geom name="plate" type="box" size="0.3 0.3 0.02" pos="0.35 0 0.08"/>
    <body name="upper" pos="0 0 0.4">
      <joint name="shoulder" axis="0 1 0" damping="2"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" contype="0"
            conaffinity="0"/>
      <body name="fore" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0" damping="2"/>
        <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.02" contype="0"
              conaffinity="0"/>
        <body name="tool" pos="0.1 0 0" euler="0 -1.3 0.3">
          <site name="ft" euler="0.1 0.4 -0.2"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.15" size="0.015" mass="0.4"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position joint="shoulder" kp="80"/>
    <position joint="elbow" kp="40"/>
  </actuator>
</mujoco>
"""

WRENCH = [
    {"site": "ft", "quantity": "force"},
    {"site": "ft", "quantity": "fz", "frame": "world"},
    {"site": "ft", "quantity": "torque", "frame": "world"},
    {"site": "ft", "quantity": "ty"},
    {"site": "ft", "quantity": "xyz"},
]


def _reference(m, d) -> np.ndarray:
    """The WRENCH features from MuJoCo C's own sensors and site frame (NumPy)."""
    force = d.sensor("cgda_site:ft:force").data
    torque = d.sensor("cgda_site:ft:torque").data
    rot = d.site("ft").xmat.reshape(3, 3)  # site frame -> world
    return np.array([*force, (rot @ force)[2], *(rot @ torque), torque[1],
                     *d.site("ft").xpos])


@pytest.fixture(scope="module")
def pressing():
    """(model, FeatureSet, 4 MjData of a C rollout pressing on the plate)."""
    spec = mujoco.MjSpec.from_string(MJCF)
    add_sensors(spec, WRENCH)
    m = spec.compile()
    fs = FeatureSet(m, WRENCH)
    d = mujoco.MjData(m)
    datas = []
    # the tool tip settles on the plate, then the servos push it down ever harder
    for ctrl in ([0.6, 0.9], [0.7, 1.0], [0.8, 1.1], [0.9, 1.2]):
        d.ctrl[:] = ctrl
        for _ in range(800):
            mujoco.mj_step(m, d)
        mujoco.mj_forward(m, d)
        copy = mujoco.MjData(m)
        copy.qpos[:], copy.qvel[:], copy.ctrl[:] = d.qpos, d.qvel, d.ctrl
        mujoco.mj_forward(m, copy)
        datas.append(copy)
    return m, fs, datas


def test_names_units_and_spec_forms():
    assert FeatureSpec.from_dict({"site": "ft", "quantity": "fz", "frame": "world"}) \
        == FeatureSpec("site", "ft", "fz", "world")
    m = mujoco.MjModel.from_xml_string(MJCF)
    fs = FeatureSet(m, WRENCH)
    assert fs.feature_names[:4] == ("ft.fx [N]", "ft.fy [N]", "ft.fz [N]",
                                    "ft.fz_world [N]")
    assert fs.feature_names[4:8] == ("ft.tx_world [N m]", "ft.ty_world [N m]",
                                     "ft.tz_world [N m]", "ft.ty [N m]")
    assert fs.n_features == 11 and not fs.has_sensors  # no sensors added yet


@pytest.mark.parametrize("entry,match", [
    ({"site": "ft", "quantity": "fz", "frame": "base"}, "frame 'base' unknown"),
    ({"site": "ft", "quantity": "xyz", "frame": "world"}, "only for forces"),
    ({"body": "tool", "quantity": "fz"}, "quantity 'fz' unknown"),
])
def test_bad_wrench_specs_name_the_problem(entry, match):
    with pytest.raises(ValueError, match=match):
        FeatureSpec.from_dict(entry)


def test_contact_forces_are_pressing(pressing):
    """The states really press: the plate pushes up on the tool harder each time."""
    m, _, datas = pressing
    up = [(_reference(m, d)[3]) for d in datas]
    # world fz = weight of the tool (0.4 kg) minus the plate's push
    assert up[0] < 0.4 * 9.81 - 1.0
    assert all(b < a - 0.5 for a, b in zip(up, up[1:]))


def test_from_sensordata_equals_mujoco_c(pressing):
    m, fs, datas = pressing
    for d in datas:
        np.testing.assert_allclose(fs.from_sensordata(d.sensordata), _reference(m, d),
                                   rtol=1e-6, atol=1e-6)


def test_mjx_batched_equals_mujoco_c(pressing):
    """MJX's sensors on the same states (jit + vmap) give MuJoCo C's forces."""
    m, fs, datas = pressing
    mjx = mjx_module()
    mx = mjx.put_model(m, impl="jax")
    qpos = jnp.asarray(np.stack([d.qpos for d in datas]), jnp.float32)
    qvel = jnp.asarray(np.stack([d.qvel for d in datas]), jnp.float32)
    ctrl = jnp.asarray(np.stack([d.ctrl for d in datas]), jnp.float32)

    @jax.jit
    @jax.vmap
    def run(q, v, c):
        dx = mjx.forward(mx, mjx.make_data(mx).replace(qpos=q, qvel=v, ctrl=c))
        return fs.from_sensordata(dx.sensordata)

    got = np.asarray(run(qpos, qvel, ctrl))
    ref = np.stack([_reference(m, d) for d in datas])
    assert got.shape == (4, fs.n_features)
    np.testing.assert_allclose(got, ref, atol=0.02 * np.abs(ref).max(), rtol=0)
    np.testing.assert_allclose(got[:, 8:], ref[:, 8:], atol=1e-4)  # the site


def test_kinematics_refuse_forces(pressing):
    m, fs, datas = pressing
    with pytest.raises(ValueError, match="use dynamic mode"):
        fs.from_data(datas[0])


def test_scale_weights_a_feature(pressing):
    """``scale`` multiplies the values (sensordata and kinematics) and names it."""
    m, fs, datas = pressing
    scaled = FeatureSet(m, [{"site": "ft", "quantity": "fz", "scale": 1 / 300},
                            {"site": "ft", "quantity": "x", "scale": 2.5}])
    assert scaled.feature_names == ("ft.fz [300 N]", "ft.x [0.4 m]")
    got = np.asarray(scaled.from_sensordata(datas[1].sensordata))
    ref = _reference(m, datas[1])
    np.testing.assert_allclose(got, [ref[2] / 300, 2.5 * ref[8]], rtol=1e-6)
    pos = FeatureSet(m, [{"site": "ft", "quantity": "z", "scale": 0.5}])
    np.testing.assert_allclose(pos.from_data(datas[1]), [0.5 * ref[10]], rtol=1e-6)
    with pytest.raises(ValueError, match="scale must be a positive number"):
        FeatureSpec.from_dict({"site": "ft", "quantity": "fz", "scale": 0})
