"""Feasible motions (issue 21): moves judged for collisions and joint limits, every
strategy kept out of an obstacle, the motion report as an independent check."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import cgda_jax as cg
from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path
from cgda_jax.sim.feasibility import Feasibility
from cgda_jax.strategies.fitness import penalized
from cgda_jax.sim.limits import read_limits
from cgda_jax.sim.motion_check import motion_profile, motion_report

WALL = {"name": "wall", "type": "box", "pos": (0.3, 0.0, 0.125),
        "size": (0.12, 0.01, 0.125)}


@pytest.fixture(scope="module")
def tiny():
    return Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                           "marker")


@pytest.fixture(scope="module")
def teo_paint():
    robot = Robot.from_mjcf(model_path("teo.xml"),
                            ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"],
                            "marker", fixed={"r_forearm_rotation": np.deg2rad(45)})
    return Simulator(robot, PaintWall.grid(), feasibility=True)


def test_penalty_only_where_infeasible():
    f = jnp.asarray([0.5, 0.5, 2.0])
    v = jnp.asarray([0.0, 0.3, 0.0])
    np.testing.assert_allclose(np.asarray(penalized(f, v, 1e3)), [0.5, 1300.5, 2.0])


def test_teo_paint_pairs_and_limits(teo_paint):
    feas = teo_paint.feasibility
    names = feas.collider.pair_names
    assert ("r_tool", "paint_board") in names and ("r_hand", "paint_board") in names
    # the upper arm cannot reach the board (0.6 m away, 0.37 m long): culled
    assert ("r_upper_arm", "paint_board") not in names
    np.testing.assert_allclose(feas.limits.velocity, 3.0)
    # the approach: long enough for any posture in the limits at 3 rad/s
    lo, hi = np.asarray(teo_paint.lower), np.asarray(teo_paint.upper)
    start = np.asarray(teo_paint.robot.start_genes)
    worst = np.maximum(hi - start, start - lo).max()
    assert teo_paint.approach_s == pytest.approx(1.875 * worst / 3.0, rel=1e-4)


def test_a_posture_through_the_board_is_infeasible(teo_paint):
    sim = teo_paint
    state = sim.init_state()
    # arm forward and level: the tool tip reaches x ~ 0.8 m, through the board
    through = jnp.deg2rad(jnp.asarray([70.0, 0.0, 20.0]))
    new, _ = jax.jit(sim.step)(state, through)
    assert float(new.move_violation) > 0
    assert float(sim.feasibility.depth(jnp.zeros(3), through)) > 0.02
    # a small, slow move near the start: feasible
    new, _ = jax.jit(sim.step)(state, jnp.deg2rad(jnp.asarray([10.0, -5.0, 10.0])))
    assert float(new.move_violation) == 0.0


def _random_moves(sim, n, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(sim.lower), np.asarray(sim.upper)
    q0 = rng.uniform(lo, hi, (n, 3)).astype(np.float32)
    q1 = rng.uniform(lo, hi, (n, 3)).astype(np.float32)
    alphas = np.linspace(0, 1, 301, dtype=np.float32)
    path = q0[:, None] + alphas[None, :, None] * (q1 - q0)[:, None]
    col = sim.feasibility.collider
    dense = np.asarray(jax.jit(jax.vmap(jax.vmap(col.distances)))(path))
    return q0, q1 - q0, np.maximum(-dense.min(axis=(1, 2)), 0)


def test_path_bound_is_below_the_dense_distance(teo_paint):
    """With ``certify`` the sampled distance less the reach slack lower-bounds the
    distance on the whole move: no penetration slips between the samples."""
    feas = Feasibility(teo_paint.robot, obstacles=[teo_paint.scene.board],
                       certify=True)
    assert feas.collider.pair_names == teo_paint.feasibility.collider.pair_names
    q0, dq, true_depth = _random_moves(teo_paint, 40)
    bound = np.asarray(jax.jit(jax.vmap(feas.depth))(q0, dq))
    assert np.all(bound >= true_depth - 1e-4)
    assert np.any(true_depth > 0.01)  # some of these moves do pass through


def test_the_sampled_check_with_its_margin_lets_no_deep_move_through(teo_paint):
    """The default check: sampled distances 2 mm inside the limit.  A sample is a
    posture of the move, so on the exact geometry it never overstates the depth
    (on the round one by at most its excess); of 600 random moves (some through
    the board), none it accepts goes deeper than the limit on a 30 x denser path,
    and it accepts moves that the bound rejects."""
    feas = teo_paint.feasibility
    assert not feas.certify and feas.allowed == pytest.approx(0.003)
    assert feas.geometry == "round" and feas.check is not feas.collider
    q0, dq, true_depth = _random_moves(teo_paint, 600, seed=1)
    sampled = np.asarray(jax.jit(jax.vmap(feas.depth))(q0, dq))
    exact = Feasibility(teo_paint.robot, obstacles=[teo_paint.scene.board],
                        geometry="exact")
    on_geoms = np.asarray(jax.jit(jax.vmap(exact.depth))(q0, dq))
    assert np.all(on_geoms <= true_depth + 1e-6)
    # the round check is never more lenient: as deep, or past the tolerance too
    assert np.all(np.minimum(on_geoms, feas.penetration) <= sampled + 1e-6)
    assert np.all(sampled <= true_depth + feas.check.excess.max() + 1e-6)
    accepted = sampled <= feas.allowed
    assert np.all(true_depth[accepted] <= feas.penetration)
    assert np.sum(true_depth > 0.02) > 50 and np.sum(~accepted) > 50
    certify = Feasibility(teo_paint.robot, obstacles=[teo_paint.scene.board],
                          certify=True)
    bound = np.asarray(jax.jit(jax.vmap(certify.depth))(q0, dq))
    assert np.sum(accepted & (bound > certify.penetration)) > 0
    with pytest.raises(ValueError, match="margin"):
        Feasibility(teo_paint.robot, margin=0.005)


def test_speed_limit_makes_a_fast_move_infeasible(tiny):
    limits = read_limits(tiny.mj_model, tiny.joint_names, {"velocity": 1.0})
    sim = Simulator(tiny, MarkerScene(), feasibility=Feasibility(tiny, limits),
                    waypoint_s=1.0, move_fraction=0.5)
    # the approach has its own duration: 1.875 * 120 deg / (1 rad/s)
    assert sim.approach_s == pytest.approx(1.875 * np.deg2rad(120), rel=1e-5)
    state = sim.init_state()
    first, _ = sim.step(state, jnp.asarray([0.0, 0.0, np.deg2rad(100)]))
    assert float(first.move_violation) == 0.0  # slow enough over approach_s
    # then a 0.5 s move of 0.4 rad: 1.875 * 0.4 / 0.5 = 1.5 rad/s > 1 rad/s
    second, _ = sim.step(first, jnp.asarray([0.4, 0.0, np.deg2rad(100)]))
    assert float(second.move_violation) == pytest.approx(0.5, rel=1e-4)
    # 0.25 rad: 0.9375 rad/s, within
    third, _ = sim.step(first, jnp.asarray([0.25, 0.0, np.deg2rad(100)]))
    assert float(third.move_violation) == 0.0
    # the profile's speeds against finite differences of its positions
    prof = motion_profile(sim, np.array([[0.0, 0.0, 1.7], [0.4, 0.0, 1.7]]), 2001)
    seg = slice(2002, 4003)  # after the approach (2001 samples) and its hold (1)
    fd = np.gradient(prof.q[seg, 0], prof.t[seg])
    np.testing.assert_allclose(fd[5:-5], prof.qd[seg, 0][5:-5], atol=2e-3)
    assert np.abs(prof.qd[seg, 0]).max() == pytest.approx(1.5, rel=1e-3)


def test_a_joint_swinging_over_max_step_is_flailing(tiny):
    """A move that changes a joint by more than max_step (90 deg) between two
    waypoints is infeasible however slow; the approach is not capped."""
    sim = Simulator(tiny, MarkerScene(), waypoint_s=10.0,
                    feasibility=Feasibility(tiny, collisions=False))
    state = sim.init_state()
    far = jnp.asarray([0.0, 0.0, np.deg2rad(100)])
    first, _ = sim.step(state, far)
    assert float(first.move_violation) == 0.0  # the approach: 100 deg allowed
    back, _ = sim.step(first, jnp.asarray([0.0, 0.0, np.deg2rad(-5)]))  # 105 deg
    assert float(back.move_violation) == pytest.approx(105 / 90 - 1, rel=1e-4)
    fine, _ = sim.step(first, jnp.asarray([0.0, 0.0, np.deg2rad(15)]))  # 85 deg
    assert float(fine.move_violation) == 0.0


# The obstacle test: three goal points on either side of and above a wall; the
# straight joint-space moves between them must go around it.
GOAL = np.array([[0.30, -0.22, 0.25], [0.25, 0.0, 0.50], [0.30, 0.22, 0.25]],
                np.float32)


@pytest.mark.parametrize("strategy", ["ie", "iet", "oet", "fte"])
def test_every_strategy_keeps_out_of_the_wall(tiny, strategy):
    feas = Feasibility(tiny, obstacles=[WALL])
    assert any(p[1] == "wall" for p in feas.collider.pair_names)
    sim = Simulator(tiny, MarkerScene(), substeps=4, feasibility=feas)
    run = getattr(cg, f"run_{strategy}")
    kwargs = {"population_size": 24, "max_generations": 150, "seed": 0}
    res = run(sim, GOAL, tolerance=0.03, **kwargs)
    assert res.success, (strategy, res.point_errors, res.info.get("violation"))
    assert res.info["feasible"] and res.info["violation"] == 0.0
    report = motion_report(sim, np.asarray(res.joints))
    assert report["collisions"]["penetration_m"] <= 0.005, report["collisions"]
    assert report["feasible"], report["problems"]


def test_the_unconstrained_run_passes_through_the_wall(tiny):
    """The obstacle test has teeth: without feasibility IE's motion goes through
    the wall (the independent check on a simulator that has it says so)."""
    free = Simulator(tiny, MarkerScene(), substeps=4)
    res = cg.run_ie(free, GOAL, population_size=24, max_generations=150, seed=0,
                    tolerance=0.03)
    assert res.success
    walled = Simulator(tiny, MarkerScene(), substeps=4,
                       feasibility=Feasibility(tiny, obstacles=[WALL]))
    report = motion_report(walled, np.asarray(res.joints))
    assert report["collisions"]["penetration_m"] > 0.005
    assert report["collisions"]["pair"][1] == "wall"


def test_without_feasibility_the_run_is_unchanged(tiny):
    """`feasibility=None` is today's unconstrained simulator: same features, same
    result as a simulator built without the argument."""
    a = Simulator(tiny, MarkerScene(), substeps=4)
    b = Simulator(tiny, MarkerScene(), substeps=4, feasibility=None)
    ra = cg.run_ie(a, GOAL, population_size=16, max_generations=60, seed=1)
    rb = cg.run_ie(b, GOAL, population_size=16, max_generations=60, seed=1)
    np.testing.assert_array_equal(np.asarray(ra.joints), np.asarray(rb.joints))
    assert "feasible" not in ra.info
    assert a.init_state().violation is None


def test_motion_report_names_what_is_wrong(teo_paint):
    bad = np.deg2rad([[70.0, 0.0, 20.0], [-40.0, -60.0, 90.0]])
    rep = motion_report(teo_paint, bad)
    assert not rep["feasible"]
    assert rep["collisions"]["pair"][1] == "paint_board"
    assert any("paint_board" in p for p in rep["problems"])
    assert any("rad/s" in p for p in rep["problems"])  # 110 deg in 0.6 s
    assert rep["moves_over_max_step"] == 1
    with pytest.raises(ValueError, match="NaN"):
        motion_report(teo_paint, np.full((2, 3), np.nan))
