"""Exported trajectories (issue 22): the time parameterization (the run's own
minimum-jerk ramp, or ruckig's jerk-limited profile) checked on the samples
themselves, the files (a ROS JointTrajectory in JSON, CSV, NPZ) round-trip, and the
exported file replayed on MuJoCo C gives each strategy's features."""

import json

import numpy as np
import pytest

from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path
from cgda_jax.experiment.compute import export_check
from cgda_jax.experiment.report import export_rows
from cgda_jax.reality.control_trajectory import time_parameterize, trajectory_of
from cgda_jax.reality.files import (
    from_json_dict,
    load_trajectory,
    save_trajectory,
    to_json_dict,
)
from cgda_jax.reality.replay import replay_trajectory
from cgda_jax.strategies import run_fte, run_ie, run_iet, run_oet

JOINTS = ["yaw", "shoulder", "elbow"]
RNG = np.random.default_rng(3)
WAYPOINTS = RNG.uniform(-1.2, 1.2, (6, 3))
START = np.array([0.1, -0.2, 0.3])
V, A = np.array([1.5, 2.0, 3.0]), np.array([6.0, 4.0, 10.0])
LOWER, UPPER = np.full(3, -1.0), np.full(3, 1.0)


@pytest.fixture(scope="module", params=["min_jerk", "ruckig"])
def limited(request):
    """Six moves within velocity / acceleration limits, 0.6 s each + 0.4 s hold
    (waypoints partly outside [-1, 1]: clipped as the simulator clips them)."""
    return time_parameterize(START, WAYPOINTS, [0.6] * 6, [0.4] * 6, rate=100.0,
                             velocity=V, acceleration=A, lower=LOWER, upper=UPPER,
                             joint_names=JOINTS, profile=request.param)


def test_samples_respect_every_limit_and_describe_one_motion(limited):
    tr = limited
    assert np.all(np.abs(tr.qd) <= V * (1 + 1e-9))
    assert np.all(np.abs(tr.qdd) <= A * (1 + 1e-9))
    assert np.all((tr.q >= LOWER - 1e-12) & (tr.q <= UPPER + 1e-12))
    # the velocities and accelerations are those of the positions: the trapezoid
    # rule integrates them into the next sample (errors O(jerk dt^3), O(jerk dt^2))
    dt = 1 / tr.rate
    np.testing.assert_allclose(np.diff(tr.q, axis=0),
                               (tr.qd[1:] + tr.qd[:-1]) / 2 * dt, rtol=0, atol=1e-4)
    np.testing.assert_allclose(np.diff(tr.qd, axis=0),
                               (tr.qdd[1:] + tr.qdd[:-1]) / 2 * dt, rtol=0, atol=0.02)
    np.testing.assert_allclose(np.diff(tr.t), dt, rtol=0, atol=1e-12)
    # the limits bind: the export uses the room it has (not a crawl)
    assert np.abs(tr.qd).max(axis=0).max() > 0.5 * V.min()


def test_starts_at_the_start_and_passes_every_waypoint_on_straight_moves(limited):
    tr = limited
    wps = np.clip(WAYPOINTS, LOWER, UPPER)
    np.testing.assert_array_equal(tr.q[0], START)
    np.testing.assert_array_equal(tr.qd[0], 0)
    np.testing.assert_allclose(tr.q[tr.reached_index], wps, atol=1e-12)
    prev, k0, need = START, 0, []
    for i, (kr, kf) in enumerate(zip(tr.reached_index, tr.feature_index)):
        seg = tr.q[k0:kr + 1]
        dq = wps[i] - prev
        s = (seg - prev) @ dq / (dq @ dq)  # along the line, 0 -> 1 monotone
        np.testing.assert_allclose(seg, prev + s[:, None] * dq, atol=1e-9)
        assert np.all(np.diff(s) >= -1e-12) and abs(s[0]) < 1e-12
        # each move takes the run's 0.6 s (60 periods) where the run's own
        # minimum-jerk move keeps the limits (closed-form peaks 1.875 |dq| / T,
        # 5.7735 |dq| / T^2); longer where even bang-bang within v and a could not
        # (|dq| / v + v / a, or 2 sqrt(|dq| / a) without a coast)
        a_dq = np.abs(dq)
        fits = np.all(1.875 * a_dq / 0.6 <= V) and np.all(
            10 / np.sqrt(3) * a_dq / 0.36 <= A)
        bang = np.max(np.where(a_dq > V**2 / A, a_dq / V + V / A,
                               2 * np.sqrt(a_dq / A)))
        if fits:
            assert kr - k0 == 60
        if tr.info["profile"] == "min_jerk":  # just long enough, to the period
            least = max(0.6, np.max(1.875 * a_dq / V),
                        np.sqrt(np.max(10 / np.sqrt(3) * a_dq / A)))
            assert kr - k0 == np.ceil(least * tr.rate - 1e-6)
        if bang > 0.6:
            assert (kr - k0) / tr.rate >= bang
        if kr - k0 > 60:
            need.append(i + 1)
        assert kr - k0 >= 60
        np.testing.assert_array_equal(tr.q[kr:kf + 1], np.repeat(wps[i][None],
                                                                 kf - kr + 1, 0))
        np.testing.assert_array_equal(tr.qd[kr:kf + 1], 0)
        assert (kf - kr) / tr.rate == pytest.approx(0.4)
        prev, k0 = wps[i], kf
    assert [m["move"] for m in tr.info["stretched"]] == need
    # ruckig's near time-optimal profile fits some moves the minimum-jerk ramp
    # (peak speed 1.875 x the mean) cannot
    assert 0 < len(need) < len(wps) if tr.info["profile"] == "ruckig" else need


@pytest.mark.parametrize("profile", ["min_jerk", "ruckig"])
def test_a_move_the_limits_cannot_fit_is_stretched_and_said(profile):
    tr = time_parameterize([0.0], [[2.0]], [0.5], [0.0], velocity=1.0,
                           acceleration=5.0, profile=profile)
    # 2 rad at <= 1 rad/s takes > 2 s, not the run's 0.5 s
    assert tr.duration > 2.0 and np.abs(tr.qd).max() <= 1 + 1e-9
    assert tr.info["stretched"][0]["move"] == 1
    if profile == "min_jerk":  # just long enough: 1.875 * 2 rad / 1 rad/s = 3.75 s
        assert tr.duration == pytest.approx(3.75)
        assert np.abs(tr.qd).max() == pytest.approx(1.0, abs=1e-3)
    with pytest.raises(ValueError, match="waypoints \\[2\\] are NaN"):
        time_parameterize([0.0], [[1.0], [np.nan]], [0.5, 0.5], [0.1, 0.1])


def test_min_jerk_sends_the_simulator_s_own_reference():
    """The default profile's samples are the minimum-jerk reference the dynamic
    simulator commands (`cgda_jax.sim.timing.min_jerk`, the paper's ramp) at the
    same times, and its velocities and accelerations are that ramp's derivatives
    (against an independent high-order finite difference)."""
    move, hold = 0.553, 0.447  # a move time that is not a whole number of periods
    tr = time_parameterize(START, WAYPOINTS[:3], [move] * 3, [hold] * 3, rate=200.0)
    assert tr.info["profile"] == "min_jerk" and not tr.info["stretched"]
    prev, k0 = START, 0
    for i in range(3):
        kr = tr.reached_index[i]
        t = tr.t[k0:kr + 1] - tr.t[k0]
        tau = np.minimum(t / move, 1.0)
        s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5  # written out, not imported
        np.testing.assert_allclose(tr.q[k0:kr + 1], prev + s[:, None] * (
            WAYPOINTS[i] - prev), rtol=0, atol=1e-12)
        prev, k0 = WAYPOINTS[i], tr.feature_index[i]
    # five-point central differences of the positions (inside the moves)
    h = 1 / tr.rate
    fd = (-tr.q[4:] + 8 * tr.q[3:-1] - 8 * tr.q[1:-3] + tr.q[:-4]) / (12 * h)
    np.testing.assert_allclose(fd, tr.qd[2:-2], rtol=0, atol=2e-3)
    fd2 = (-tr.q[4:] + 16 * tr.q[3:-1] - 30 * tr.q[2:-2] + 16 * tr.q[1:-3]
           - tr.q[:-4]) / (12 * h * h)
    inside = np.ones(len(fd2), bool)  # the five-point stencil straddles no corner
    for k in (*tr.reached_index, *tr.feature_index):
        inside[max(0, k - 4):k + 1] = False
    np.testing.assert_allclose(fd2[inside], tr.qdd[2:-2][inside], rtol=0, atol=0.05)
    with pytest.raises(ValueError, match="profile must be one of"):
        time_parameterize(START, WAYPOINTS[:1], [move], [hold], profile="linear")


def test_quintic_between_samples_is_the_simulator_s_reference():
    """``position_at(..., quintic=True)`` (the dynamic replay's controller) gives the
    minimum-jerk ramp between the 100 Hz samples exactly; linear interpolation
    misses it by up to dq x 5.8 / (8 T^2 rate^2)."""
    move, hold = 0.9, 0.6  # whole periods: each move one quintic
    tr = time_parameterize(START, WAYPOINTS[:2], [move] * 2, [hold] * 2, rate=100.0)
    t = np.linspace(0.0, move, 2001)
    tau = t / move
    want = START + (10 * tau**3 - 15 * tau**4 + 6 * tau**5)[:, None] * (
        WAYPOINTS[0] - START)
    np.testing.assert_allclose(tr.position_at(t, quintic=True), want, rtol=0,
                               atol=1e-12)
    assert np.abs(tr.position_at(t) - want).max() > 1e-6
    np.testing.assert_array_equal(tr.position_at(tr.t, quintic=True), tr.q)
    after = tr.position_at(np.array([tr.duration + 1.0]), quintic=True)
    np.testing.assert_allclose(after[0], tr.q[-1], atol=1e-12)  # held after the end


@pytest.mark.parametrize("fmt", ["json", "csv", "npz"])
def test_files_round_trip(limited, tmp_path, fmt):
    path = save_trajectory(limited, tmp_path / f"t.{fmt}")
    back = load_trajectory(path)
    for k in ("t", "q", "qd", "qdd", "start", "waypoints", "reached_index",
              "feature_index"):
        np.testing.assert_allclose(getattr(back, k), getattr(limited, k), rtol=0,
                                   atol=1e-12, err_msg=k)
    assert back.joint_names == limited.joint_names and back.units == ("rad",) * 3
    assert back.rate == 100.0
    np.testing.assert_array_equal(back.limits["velocity"], V)
    assert np.all(np.isnan(back.limits["jerk"]))


def test_json_is_a_ros_joint_trajectory(limited):
    doc = json.loads(json.dumps(to_json_dict(limited)))
    jt = doc["joint_trajectory"]
    assert set(jt) == {"header", "joint_names", "points"}
    assert jt["joint_names"] == JOINTS and len(jt["points"]) == limited.n_samples
    p = jt["points"][37]
    assert set(p) == {"positions", "velocities", "accelerations", "effort",
                      "time_from_start"}
    assert p["time_from_start"] == {"sec": 0, "nanosec": 370_000_000}
    last = jt["points"][-1]["time_from_start"]
    assert last["sec"] + last["nanosec"] * 1e-9 == pytest.approx(limited.duration)
    assert doc["units"] == {j: "rad" for j in JOINTS}
    np.testing.assert_array_equal(from_json_dict(doc).q, limited.q)


# -- the exported file replayed on MuJoCo C, one strategy each ------------------------
GOAL = np.array([[0.25, 0.05, 0.45], [0.3, 0.1, 0.35], [0.25, 0.15, 0.3]], np.float32)


def _robot():
    return Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")


#: Waypoints moving two joints at once, and a wall of two small squares centred on
#: the marker's path halfway along the 2nd and 3rd straight joint-space moves.
BENT = np.array([[0.0, 0.9, 0.6], [0.9, 1.3, 0.0], [-0.9, 0.9, 0.6]], np.float32)


def _wall():
    robot = _robot()
    centres = [np.asarray(robot.marker_position((BENT[i] + BENT[i + 1]) / 2))
               for i in range(2)]
    return PaintWall(np.array(centres), radius=0.02, size=0.03, path_tolerance=0.005)


CASES = {  # strategy: (runner, mode, scene, goal, options)
    "fte": (run_fte, "kinematic", "paint", None, {"max_generations": 3}),
    "ie": (run_ie, "kinematic", "marker", GOAL, {"max_generations": 4}),
    "iet": (run_iet, "dynamic", "marker", GOAL, {"max_generations": 3}),
    "oet": (run_oet, "dynamic", "marker", GOAL, {"max_generations": 3,
                                                 "max_steps": 4}),
}


# FTE (paint) and IET (dynamic) compile for 15-20 s each on 2 cores: slow (`-m slow`);
# the swept paint path is also checked by test_a_bent_path_would_be_caught
@pytest.mark.parametrize("strategy", [
    pytest.param("fte", marks=pytest.mark.slow), "ie",
    pytest.param("iet", marks=pytest.mark.slow), "oet"])
def test_the_exported_file_replayed_on_mujoco_gives_the_run_s_features(strategy,
                                                                       tmp_path):
    runner, mode, scene, goal, opts = CASES[strategy]
    kw = {"waypoint_s": 0.5} if mode == "dynamic" else {"substeps": 4}
    scene = _wall() if scene == "paint" else MarkerScene()
    if goal is None:
        goal = np.array([[0.0], [50.0], [100.0]], np.float32)
    sim = Simulator(_robot(), scene, mode=mode, **kw)
    res = runner(sim, goal, population_size=4, tolerance=0.02, seed=1, **opts)
    traj = trajectory_of(sim, res.joints)
    back = load_trajectory(save_trajectory(traj, tmp_path / "t.json"))
    feats = replay_trajectory(sim, back)
    assert feats.shape == res.features.shape
    # kinematic: the same straight path, 4x finer; dynamic: the same minimum-jerk
    # reference at 100 Hz (linear between samples), 4x finer physics
    atol = 1e-4 if mode == "kinematic" else 2e-3
    np.testing.assert_allclose(feats, res.features, rtol=0, atol=atol)
    if strategy == "fte":  # paint: the path swept, not only the waypoints, counts
        assert res.features.max() > 0
    check = export_check(sim, res)
    assert check["exported"] and check["samples"] == traj.n_samples
    assert check["max_feature_difference"] < atol
    assert check["success"] == res.success
    np.testing.assert_allclose(check["max_point_error"], res.max_point_error,
                               atol=atol)
    row = export_rows(check, "m")[0]
    assert row.startswith("| exported trajectory (minimum jerk") and "MuJoCo C" in row


def test_a_bent_path_would_be_caught():
    """The replay sees the path between samples: samples off the straight
    joint-space line (one joint lagging 0.3 s) miss a square the run painted."""
    sim = Simulator(_robot(), _wall(), substeps=4)
    want = np.asarray(sim.execute(BENT), np.float64)
    np.testing.assert_array_equal(want[:, 0], [0.0, 50.0, 100.0])
    traj = trajectory_of(sim, BENT)
    np.testing.assert_array_equal(replay_trajectory(sim, traj), want)
    bent = traj.q.copy()
    bent[:, 0] = np.interp(traj.t - 0.3, traj.t, traj.q[:, 0])
    lagged = type(traj)(**{**traj.__dict__, "q": bent})
    assert replay_trajectory(sim, lagged)[-1, 0] < 100.0


# ------------------------------------------------- bad input and full disks (issue 43)
@pytest.mark.parametrize("fmt", ["json", "csv", "npz"])
def test_a_full_disk_keeps_the_earlier_file_whole(limited, tmp_path, fmt, full_disk):
    """A truncated JSON or a 0-byte .npz was left, over a good earlier file."""
    old, new = tmp_path / f"old.{fmt}", tmp_path / f"new.{fmt}"
    save_trajectory(limited, old)
    before = old.read_bytes()
    assert len(before) > 4096
    with full_disk(4096):
        for path in (old, new):
            with pytest.raises(OSError, match="File too large"):
                save_trajectory(limited, path)
    assert sorted(p.name for p in tmp_path.iterdir()) == [old.name]  # no .tmp
    assert old.read_bytes() == before
    assert load_trajectory(old).n_samples == limited.n_samples


@pytest.mark.parametrize("profile", ["min_jerk", "ruckig"])
@pytest.mark.parametrize("change, words", [
    ({"hold_s": [1e308] * 6}, ["move 1 of the export", "inf control periods",
                               "hold 1e+308 s"]),
    ({"velocity": 1e-30}, ["move 1 of the export", "velocity 1e-30"]),
    ({"rate": 1e-300}, ["rate must be in [1, 100000] Hz, got 1e-300"]),
    ({"rate": 1e9}, ["rate must be in [1, 100000] Hz, got 1e+09"]),
])
def test_sizes_past_a_million_samples_are_refused_by_their_cause(profile, change,
                                                                 words):
    """An OverflowError, a RuckigError or "Maximum allowed size exceeded" (or 6 GB
    at 1e9 Hz) before."""
    kwargs = dict(rate=100.0, velocity=V, acceleration=A, hold_s=[0.4] * 6) | change
    hold = kwargs.pop("hold_s")
    with pytest.raises(ValueError) as err:
        time_parameterize(START, WAYPOINTS, [0.6] * 6, hold, profile=profile,
                          **kwargs)
    for w in words:
        assert w in str(err.value)
