"""The MJX step against MuJoCo C when an actuator's force saturates (implicitfast)."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from cgda_jax.sim._mujoco_env import mjx_module
from cgda_jax.sim.mjx_step import needs_clamped_step, step_fn

# a 1 kg rod on a hinge, driven by a servo (kp 100, kv 20) towards 1 rad
ARM = """<mujoco><option timestep="0.01" integrator="{integrator}"/>
<worldbody><body><joint name="j" type="hinge" axis="0 1 0" {joint}/>
<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/></body></worldbody>
<actuator><general joint="j" gainprm="100" biastype="affine" biasprm="0 -100 -20"
 {actuator}/></actuator></mujoco>"""
JOINT_LIMIT = 'actuatorfrclimited="true" actuatorfrcrange="-5 5"'
OWN_LIMIT = 'forcelimited="true" forcerange="-5 5"'


def _model(integrator="implicitfast", joint="", actuator=""):
    return mujoco.MjModel.from_xml_string(
        ARM.format(integrator=integrator, joint=joint, actuator=actuator))


def _c_rollout(m, steps):
    d = mujoco.MjData(m)
    d.ctrl[0] = 1.0
    out = []
    for _ in range(steps):
        mujoco.mj_step(m, d)
        out.append(d.qpos[0])
    return np.array(out)


def _mjx_rollout(m, steps, step):
    mjx = mjx_module()
    mx = mjx.put_model(m, impl="jax")
    d0 = mjx.make_data(mx, impl="jax").replace(ctrl=jnp.ones(1))

    def body(d, _):
        d = step(mx, d)
        return d, d.qpos[0]

    return np.asarray(jax.jit(lambda d: jax.lax.scan(body, d, None, length=steps))(d0)[1])


@pytest.mark.parametrize("where", ["joint", "actuator"])
def test_a_saturated_servo_steps_as_in_mujoco_c(where):
    kw = {"joint": JOINT_LIMIT} if where == "joint" else {"actuator": OWN_LIMIT}
    m = _model(**kw)
    assert needs_clamped_step(m)
    ref = _c_rollout(m, 30)
    ours = _mjx_rollout(m, 30, step_fn(m))
    plain = _mjx_rollout(m, 30, mjx_module().step)
    np.testing.assert_allclose(ours, ref, atol=2e-5)
    # plain mjx.step keeps the clamped servo's implicit damping: far slower here
    assert np.abs(plain - ref).max() > 0.05
    # the arm saturates (5 N m against up to 100 N m asked), so the test means something
    d = mujoco.MjData(m)
    d.ctrl[0] = 1.0
    mujoco.mj_step(m, d)
    assert abs(d.qfrc_actuator[0]) == pytest.approx(5.0)


def test_an_unsaturated_servo_is_unchanged():
    m = _model(joint='actuatorfrclimited="true" actuatorfrcrange="-1000 1000"')
    np.testing.assert_allclose(_mjx_rollout(m, 30, step_fn(m)), _c_rollout(m, 30),
                               atol=2e-5)


def test_plain_mjx_step_where_nothing_can_saturate():
    mjx = mjx_module()
    assert step_fn(_model()) is mjx.step
    assert step_fn(_model(integrator="Euler", joint=JOINT_LIMIT)) is mjx.step
    assert not needs_clamped_step(_model(integrator="Euler", actuator=OWN_LIMIT))
