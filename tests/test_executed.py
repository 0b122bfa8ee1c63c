"""Dynamic mode judges what the physics executed (issue 39, "Honest in physics
too"): the simulated postures against collisions, the tracking error and the time
at the force limit, in the search (`Feasibility.executed` through the simulator's
violation) and in the independent replay (`motion_report`'s ``executed``)."""

import mujoco
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator
from cgda_jax.experiment.report import motion_lines
from cgda_jax.sim.feasibility import Feasibility
from cgda_jax.sim.host_replay import reference_ctrl
from cgda_jax.sim.motion_check import motion_report

# A two-link arm pitching about y, horizontal at zero (gravity pulls the forearm
# down); "weak": an elbow motor of 0.3 N m, less than the forearm's 0.55 N m.
ARM = """
<mujoco model="arm">
  <compiler angle="radian"/>
  <option timestep="0.002" gravity="0 0 -9.81" integrator="Euler"/>
  <default><joint damping="0.05" armature="0.01"/>
    <geom contype="0" conaffinity="0" density="800"/></default>
  <worldbody>
    <body name="l1" pos="0 0 0.1">
      <joint name="shoulder" axis="0 1 0" range="-2 2"/>
      <geom name="upper" type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
      <body name="l2" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0" range="-2.5 2.5"/>
        <geom name="fore" type="capsule" fromto="0 0 0 0.25 0 0" size="0.025"/>
        <site name="tip" pos="0.25 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="m1" joint="shoulder" gear="2" ctrlrange="-10 10"/>
    <motor name="m2" joint="elbow" ctrlrange="-{elbow} {elbow}"/>
  </actuator>
</mujoco>
"""
JOINTS = ["shoulder", "elbow"]
# a plate 9 cm under the held forearm: clear of every commanded posture
PLATE = {"name": "plate", "type": "box", "pos": [0.45, 0.0, 0.0],
         "size": [0.12, 0.1, 0.01]}
HOLD = np.zeros((2, 2), np.float32)  # hold the start posture (horizontal) twice
LIMITS = {"velocity": 5.0, "acceleration": 50.0, "effort": 20.0}


@pytest.fixture(scope="module")
def arms(tmp_path_factory):
    folder = tmp_path_factory.mktemp("executed")
    out = {}
    for name, elbow in (("strong", "8"), ("weak", "0.3")):
        (folder / f"{name}.xml").write_text(ARM.replace("{elbow}", elbow))
        out[name] = Robot.from_mjcf(folder / f"{name}.xml", JOINTS, "tip")
    return out


def simulator(robot, physics="mujoco"):
    feas = Feasibility(robot, LIMITS, [PLATE], physics_contacts=True)
    return Simulator(robot, MarkerScene(), mode="dynamic", physics=physics,
                     waypoint_s=0.5, feasibility=feas)


def test_a_sagging_arm_is_infeasible_though_its_commands_are_clear(arms):
    """The weak elbow cannot hold the forearm: it sags through the plate, far from
    its commanded posture, at its force limit all the time.  The commanded path
    is clear (`Feasibility.move` 0); the executed one is judged infeasible, by the
    search and by the replay, with the numbers in the report."""
    sim = simulator(arms["weak"])
    feas = sim.feasibility
    assert feas.collider is not None and ("fore", "plate") in feas.collider.pair_names
    q0 = np.zeros(2, np.float32)
    assert float(feas.move(q0, q0, 0.3)) == 0.0  # commanded: held, clear
    violation = float(sim.violation(HOLD))
    assert violation > 1.0, violation
    motion = motion_report(sim, HOLD)
    ex = motion["executed"]
    assert ex["pair"] == ["fore", "plate"] and ex["penetration_m"] > 0.02
    assert ex["tracking_deg"]["elbow"] > 45.0 and ex["tracking_deg"]["shoulder"] < 5.0
    assert ex["saturation"] > 0.9 and ex["saturation_limit"] == feas.saturation
    assert not motion["feasible"]
    said = " ".join(motion["problems"])
    assert "executed path: fore" in said and "elbow: tracking error" in said
    assert "at the force limit" in said
    text = "\n".join(motion_lines(motion, False))
    assert "Executed path" in text and "limit 30 deg" in text
    # the strong elbow holds it: feasible in the search and in the replay
    strong = simulator(arms["strong"])
    assert float(strong.violation(HOLD)) == 0.0
    motion = motion_report(strong, HOLD)
    assert motion["feasible"], motion["problems"]
    assert motion["executed"]["penetration_m"] == 0.0


def test_each_executed_limit_alone_makes_a_move_infeasible(arms):
    """The violation is the max of the normalized excesses of the simulated
    postures' penetration, the tracking error and the time at the force limit."""
    feas = Feasibility(arms["weak"], LIMITS, [PLATE], physics_contacts=True,
                       tracking_deg=5.0, saturation=0.1)
    clear = np.zeros((3, 2), np.float32)  # held horizontal, 9 cm above the plate
    low = np.array([[0.0, 0.0], [0.0, 0.6], [0.0, 0.0]], np.float32)  # sagged
    ok = np.full(2, np.radians(4.0), np.float32)
    keep = 0.95  # the search keeps 5 % of each limit in hand (EXECUTED_MARGIN)
    assert float(feas.executed(clear, ok, 0.09)) == 0.0
    assert float(feas.executed(low, ok, 0.0)) > 1.0  # into the plate
    bad = ok.copy()
    bad[1] = np.radians(7.5)
    assert float(feas.executed(clear, bad, 0.0)) == pytest.approx(7.5 / (keep * 5) - 1,
                                                                  rel=1e-5)
    assert float(feas.executed(clear, ok, 0.25)) == pytest.approx(
        (0.25 - keep * 0.1) / (keep * 0.1), rel=1e-4)
    feas.tracking_deg, feas.saturation = 10.0, 1.0  # as the constructor sets them
    assert float(feas.executed(clear, bad, 0.9)) == 0.0
    with pytest.raises(ValueError, match="tracking_deg must be > 0"):
        Feasibility(arms["weak"], LIMITS, tracking_deg=0.0)
    with pytest.raises(ValueError, match=r"saturation must be in \[0, 1\]"):
        Feasibility(arms["weak"], LIMITS, saturation=1.5)


def test_tracking_error_equals_a_numpy_reference(arms):
    """`Physics.executed` on a segment of the strong arm's move: the tracking error
    and the saturation equal a plain ``mj_step`` loop's (float64) reading of the
    same commanded reference."""
    sim = Simulator(arms["strong"], MarkerScene(), mode="dynamic", physics="mujoco",
                    waypoint_s=0.5)
    phys = sim.physics
    start, target = np.zeros(2), np.array([0.9, -1.2])
    profile = sim.reference_profiles()[1]
    ctrl = reference_ctrl(phys, start, target, profile)
    state = sim.init_state()
    _, sens = sim.backend.segment(state.data, np.asarray(ctrl, np.float32))
    commanded = start + profile[:, None] * (target - start)
    _, track, sat = phys.executed(np.asarray(sens), commanded)
    m = phys.model
    d = mujoco.MjData(m)
    d.qpos[:] = phys.qpos0
    q, f = [], []
    for c in ctrl:
        d.ctrl[:] = c
        mujoco.mj_step(m, d)
        q.append(d.qpos[phys.gene_qadr].copy())
        mujoco.mj_forward(m, d)  # the force the next step applies
        f.append(d.qfrc_actuator[phys.gene_qadr].copy())
    want = np.abs(np.array(q) - commanded).max(axis=0)
    assert want.max() > np.radians(1.0)  # a real lag, not zeros
    np.testing.assert_allclose(np.asarray(track), want, atol=1e-5)
    lo, hi = phys.force_range.T
    at = np.any((np.array(f) >= 0.999 * hi) | (np.array(f) <= 0.999 * lo), axis=1)
    assert float(sat) == pytest.approx(at.mean(), abs=0.01)


def test_dynamic_plans_judge_every_move_with_the_executed_motion(arms):
    """Ranked judging (`Settings.judge`) judges moves after stepping, which in
    dynamic mode would lose what the physics executed: a dynamic plan judges every
    move in the step, and `Simulator.judge` refuses dynamic mode."""
    from cgda_jax.strategies.ie import IEPlan

    sim = simulator(arms["weak"])
    goal = np.asarray([[0.3, 0.0, 0.0], [0.35, 0.0, 0.05]], np.float32)
    assert IEPlan(sim, goal, population_size=8, judge="ranked").judge_ranks is None
    state = sim.init_state()
    with pytest.raises(ValueError, match="kinematic mode"):
        sim.judge(state, state)
