"""The default PD gain of a motor-driven joint fits the time step (`stable_kp`)."""

import logging

import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator
from cgda_jax.sim.pd_gains import STABLE_SHARE, stable_kp

# A 0.3 m rod on a pitch joint, driven by a torque motor (Euler integrator).
ROD = """
<mujoco model="rod">
  <compiler angle="radian"/>
  <option timestep="0.002" integrator="Euler"/>
  <default><joint damping="0.01" armature="0.002"/>
    <geom contype="0" conaffinity="0" density="800"/></default>
  <worldbody>
    <body name="l1" pos="0 0 0.5">
      <joint name="shoulder" axis="0 1 0" range="-2 2"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/>
      <site name="tip" pos="0.3 0 0"/>
    </body>
  </worldbody>
  <actuator><motor name="m" joint="shoulder" ctrlrange="-{limit} {limit}"/></actuator>
</mujoco>"""
TARGETS = [0.8, -0.5, 0.3]


def _rod(tmp_path, limit: float) -> Robot:
    path = tmp_path / f"rod_{limit:g}.xml"
    path.write_text(ROD.format(limit=limit))
    return Robot.from_mjcf(path, ["shoulder"], "tip")


def _ends(sim) -> np.ndarray:
    """The joint angle at the end of each waypoint of `TARGETS`."""
    state, out = sim.init_state(), []
    for w in TARGETS:
        state, _ = sim.step(state, np.array([w], np.float32))
        out.append(float(state.data[0]))
    return np.array(out)


@pytest.mark.parametrize("implicit", [False, True])
def test_stable_kp_meets_the_bound_it_is_named_for(implicit):
    rng = np.random.default_rng(0)
    for inertia, dt, zeta in zip(rng.uniform(1e-3, 2.0, 20), rng.uniform(1e-3, 0.02, 20),
                                 rng.uniform(0.3, 2.0, 20), strict=True):
        kp = stable_kp(inertia, dt, zeta, implicit)
        kd = 2.0 * zeta * np.sqrt(kp * inertia)
        stiff = kp * dt * dt / inertia + (0.0 if implicit else kd * dt / inertia)
        assert stiff == pytest.approx(STABLE_SHARE, rel=1e-9)


def test_a_stiff_default_gain_is_lowered_for_the_step_and_then_tracks(tmp_path, caplog):
    robot = _rod(tmp_path, 500.0)  # default kp = 500 / 0.1 = 5,000 N m/rad
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=1.0, timestep=0.005)
    drive = sim.physics.control.drives[0]
    assert drive.kp < 100.0 and "lowered for the 0.005 s step" in drive.sources["kp"]
    np.testing.assert_allclose(_ends(sim), TARGETS, atol=1e-3)
    # the gain it replaced, given explicitly, is kept (and warned about): the rod
    # then swings between its force limits and ends far from its targets
    with caplog.at_level(logging.WARNING, logger="cgda_jax"):
        stiff = Simulator(robot, MarkerScene(), mode="dynamic", physics="mujoco",
                          waypoint_s=1.0, timestep=0.005, control={"kp": 5000.0})
    assert stiff.physics.control.drives[0].kp == 5000.0
    assert "is stiff for the 0.005 s time step" in caplog.text
    assert np.abs(_ends(stiff) - TARGETS).max() > 0.05


def test_a_default_gain_the_step_allows_is_kept(tmp_path):
    sim = Simulator(_rod(tmp_path, 5.0), MarkerScene(), mode="dynamic",
                    physics="mujoco", waypoint_s=1.0)  # the model's 0.002 s
    drive = sim.physics.control.drives[0]
    assert drive.kp == pytest.approx(5.0 / 0.1)
    assert drive.sources["kp"] == "force limit / 0.1"
    np.testing.assert_allclose(_ends(sim), TARGETS, atol=1e-3)
