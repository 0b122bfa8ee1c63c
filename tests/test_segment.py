"""segment(): action sequences in one recording; the DP against a brute force; the
costs against single `dtw` calls; execute_sequence on the tiny arm."""

import functools
import itertools

import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, PaintWall, Robot, Simulator, model_path
from cgda_jax.data import Demonstration
from cgda_jax.datasets import synthetic_actions, synthetic_sequence
from cgda_jax.distance import dtw
from cgda_jax.recognition import ActionLibrary
from cgda_jax.segmentation import (
    REST,
    Segment,
    best_segmentation,
    execute_sequence,
    refine_boundaries,
    segment,
    segment_costs,
)
from cgda_jax.strategies import ExecutionResult, run_ie, run_iet

# the grid and duration range of the accuracy tests (actions last 3-12 s)
SETTINGS = {"step_s": 0.2, "durations_s": (1.0, 15.0)}


@pytest.fixture(scope="module")
def library():
    return ActionLibrary.from_demonstrations(synthetic_actions(6, seed=0))


def _brute_force(costs, lengths):
    """Least total over every segmentation (NumPy, no DP): all compositions of the
    grid into the allowed lengths, every labelling, no rest after a rest."""
    g, _, n_lab = costs.shape
    index = {int(v): k for k, v in enumerate(lengths)}
    best, best_path = np.inf, None

    def cuts(start):
        if start == g:
            yield []
            return
        for length in lengths:
            if start + length <= g:
                for rest in cuts(start + int(length)):
                    yield [(start, start + int(length))] + rest

    for parts in cuts(0):
        for labels in itertools.product(range(n_lab), repeat=len(parts)):
            if any(a == b == n_lab - 1 for a, b in zip(labels, labels[1:])):
                continue
            total = sum(costs[s, index[e - s], a] * (e - s)
                        for (s, e), a in zip(parts, labels))
            if total < best:
                best, best_path = total, [(s, e, a) for (s, e), a in zip(parts, labels)]
    return best_path, best


@pytest.mark.parametrize("seed", range(4))
def test_dynamic_programme_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    g, lengths, n_lab = 7, np.arange(1, 5), 3
    costs = rng.uniform(0.0, 1.0, (g, len(lengths), n_lab)).astype(np.float32)
    costs[:, 0, :-1] = np.inf  # actions of one step are not allowed
    for s in range(g):  # nor segments past the end
        costs[s, lengths + s > g] = np.inf
    path, total = best_segmentation(costs, lengths)
    ref_path, ref_total = _brute_force(costs, lengths)
    np.testing.assert_allclose(total, ref_total, rtol=1e-6)
    assert path == ref_path
    labels = [a for _, _, a in path]
    assert all(not (a == b == n_lab - 1) for a, b in zip(labels, labels[1:]))


def test_costs_are_dtw_of_each_segment_relative_to_its_start():
    # piecewise-linear features: no noise, so each is scaled by 1e-3 of its range
    t = np.linspace(0.0, 6.0, 121)
    x = np.stack([np.minimum(t, 3.0), np.abs(t - 3.0) * 0.5], 1)
    rec = Demonstration(t, x, ("a", "b"), "rec")
    demo = Demonstration(t[:61], x[:61] + [1.0, 0.0], ("a", "b"), "d")
    lib = ActionLibrary.from_demonstrations({"up": [demo]}, interval_s=0.5)
    grid_t, lengths, costs = segment_costs(rec, lib, n_samples=12, step_s=0.5,
                                           durations_s=(1.0, 4.0))
    costs = np.asarray(costs)
    np.testing.assert_allclose(grid_t, np.arange(13) * 0.5)
    np.testing.assert_array_equal(lengths, np.arange(1, 9))
    act = lib["up"]
    tt = np.clip(np.linspace(0, 1, 12), act.knot_times[0], act.knot_times[-1])
    scale = 1e-3 * np.ptp(x, axis=0)
    ref = np.asarray(act(tt)) / scale
    ref = ref - ref[0]
    for s, k in [(0, 5), (2, 3), (4, 7)]:
        # a grid point: the mean of the samples within half a step of it
        pts = np.array([x[np.abs(t - gt) <= 0.25 + 1e-9].mean(0)
                        for gt in grid_t[s:s + lengths[k] + 1]])
        pos = np.linspace(0, lengths[k], 12)
        seg = np.stack([np.interp(pos, np.arange(len(pts)), pts[:, f])
                        for f in range(2)], 1)
        seg = (seg - seg[0]) / scale
        np.testing.assert_allclose(costs[s, k, 0], float(dtw(seg, ref)), rtol=1e-4,
                                   atol=1e-5)
        np.testing.assert_allclose(costs[s, k, 1], float(dtw(seg, 0 * ref)),
                                   rtol=1e-4, atol=1e-5)
    assert np.all(np.isinf(costs[:, 0, 0]))  # an action of 0.5 s < 1 s
    assert np.isinf(costs[10, 4, 0]) and np.isfinite(costs[10, 1, 0])  # past the end


def _errors(segments, truth):
    """(labels right, boundary errors as fractions of each true duration)."""
    assert len(segments) == len(truth), (segments, truth)
    right = sum(s.action == a for s, (a, _, _) in zip(segments, truth))
    errs = [max(abs(s.start - t0), abs(s.end - t1)) / (t1 - t0)
            for s, (_, t0, t1) in zip(segments, truth)]
    return right, errs


@pytest.mark.parametrize("pause_s", [(0.0, 0.0), (0.5, 2.0)],
                         ids=["back-to-back", "pauses"])
def test_synthetic_sequences_are_segmented(library, pause_s):
    right = total = 0
    errs, raw_errs = [], []
    for seed in (101, 102, 103):  # 3 to 4 actions each, random order
        seq = synthetic_sequence(seed=seed, pause_s=pause_s)
        raw = segment(seq.recording, library, refine=False, **SETTINGS)
        segs = refine_boundaries(seq.recording, raw)
        assert [s.action for s in segs] == [s.action for s in raw]
        r, e = _errors(segs, seq.truth)
        right, total, errs = right + r, total + len(seq.truth), errs + e
        raw_errs += _errors(raw, seq.truth)[1]
        assert all(s.start < s.end for s in segs)
        assert all(a.end <= b.start for a, b in zip(segs, segs[1:]))
    assert right >= 0.95 * total
    # the refinement is what brings the boundaries near the 10 % target: the
    # search alone is ~10 % off at the median (README, bench_sequence.py)
    assert np.median(errs) <= 0.05 < np.median(raw_errs), (errs, raw_errs)
    # the target: every boundary within 10 % of its action's duration (the
    # benchmark's 2 x 80 actions: all but one, worst 11.2 %)
    assert max(errs) <= 0.1, errs


def test_refinement_finds_minimum_jerk_ends_exactly():
    # noise-free: rest, a 4 s minimum-jerk move, 1 s rest, a 3 s move straight on
    # (back to back with the next), a 5 s move, rest; the model is exact there
    rate = 30.0
    t = np.arange(int(16 * rate)) / rate

    def ramp(t0, d):
        u = np.clip((t - t0) / d, 0.0, 1.0)
        return u**3 * (10 - 15 * u + 6 * u**2)

    truth = [(1.0, 5.0), (6.0, 9.0), (9.0, 14.0)]
    x = np.stack([100 * ramp(1.0, 4.0) - 60 * ramp(9.0, 5.0),
                  40 * ramp(6.0, 3.0) + 5 * ramp(1.0, 4.0)], 1)
    x = x + 1e-3 * np.random.default_rng(0).standard_normal(x.shape)
    rec = Demonstration(t, x, ("a", "b"), "ramps")
    rough = [Segment("up", 1.4, 4.6, 0.0), Segment("side", 5.6, 9.5, 0.0),
             Segment("back", 9.5, 13.2, 0.0)]  # each boundary 8-16 % off
    refined = refine_boundaries(rec, rough)
    for s, (t0, t1) in zip(refined, truth):
        assert abs(s.start - t0) <= 1 / rate + 1e-9, (s, t0)
        assert abs(s.end - t1) <= 1 / rate + 1e-9, (s, t1)
    assert [s.action for s in refined] == ["up", "side", "back"]
    assert refine_boundaries(rec, []) == []


def test_refinement_measures_clean_features_in_the_library_s_noise():
    # a clean recording (a tracked video): two minimum-jerk moves and a feature
    # constant up to rounding; in units of its own noise (1e-16) that rounding
    # decides the fit, in the library's noise (its knots') it is nothing
    rate = 30.0
    t = np.arange(int(12 * rate)) / rate
    rng = np.random.default_rng(0)

    def ramp(t0, d):
        u = np.clip((t - t0) / d, 0.0, 1.0)
        return u**3 * (10 - 15 * u + 6 * u**2)

    x = np.stack([100 * ramp(1.0, 4.0) - 60 * ramp(6.0, 5.0),
                  60.0 + 1e-13 * rng.standard_normal(t.size)], 1)
    rec = Demonstration(t, x, ("a", "hue"), "clean")
    demo = Demonstration(t, x + rng.normal(0.0, [3.0, 1.5], x.shape), ("a", "hue"), "d")
    lib = ActionLibrary.from_demonstrations({"up": [demo]})
    rough = [Segment("up", 1.4, 4.6, 0.0), Segment("up", 5.6, 10.5, 0.0)]
    truth = [(1.0, 5.0), (6.0, 11.0)]

    def worst(segments):
        return max(max(abs(s.start - t0), abs(s.end - t1))
                   for s, (t0, t1) in zip(segments, truth))

    assert worst(refine_boundaries(rec, rough, lib)) <= 1 / rate + 1e-9
    assert worst(refine_boundaries(rec, rough)) > 0.2  # the recording's noise only


def _min_jerk_ramp(t, t0, d):
    u = np.clip((t - t0) / d, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def test_refinement_places_ends_between_samples_at_8_fps():
    # noise-free minimum-jerk moves whose ends fall between the frames of an 8 fps
    # recording: each boundary is the last frame at rest before the motion and the
    # first at rest after it (as the truth of bench_sequence counts them); back to
    # back, the frames either side of the junction
    rate = 8.0
    t = np.arange(int(14 * rate)) / rate
    truth = [(1.05, 4.33), (5.71, 9.02), (9.02, 12.4)]  # the last two back to back
    x = np.stack([100 * _min_jerk_ramp(t, 1.05, 3.28) - 70 * _min_jerk_ramp(t, 9.02, 3.38),
                  50 * _min_jerk_ramp(t, 5.71, 3.31)], 1)
    rec = Demonstration(t, x + 1e-6 * np.random.default_rng(1).standard_normal(x.shape),
                        ("a", "b"), "ramps")
    rough = [Segment("up", 1.4, 4.0, 0.0), Segment("side", 5.4, 9.4, 0.0),
             Segment("back", 9.4, 12.0, 0.0)]
    refined = refine_boundaries(rec, rough)
    step = 1 / rate
    assert [(s.start, s.end) for s in refined] == [
        (np.floor(1.05 / step) * step, np.ceil(4.33 / step) * step),
        (np.floor(5.71 / step) * step, np.floor(9.02 / step) * step),
        (np.ceil(9.02 / step) * step, np.ceil(12.4 / step) * step)]


def test_refinement_ignores_drift_where_no_action_moves_a_feature():
    # light that dims: "value" falls linearly all through the recording; "up" moves
    # "a" only, "dim" moves "value" (as PAINT darkens the marker); the library says
    # which action moves what, so the drift between and inside the actions neither
    # pulls a start into a pause nor stretches an end
    rate = 30.0
    t = np.arange(int(16 * rate)) / rate
    rng = np.random.default_rng(2)
    truth = [(1.0, 5.0), (7.0, 11.0), (12.5, 14.5)]
    a = 100 * _min_jerk_ramp(t, 1.0, 4.0) - 100 * _min_jerk_ramp(t, 12.5, 2.0)
    value = 190 - 3.0 * t - 80 * _min_jerk_ramp(t, 7.0, 4.0)
    x = np.stack([a, value], 1)
    rec = Demonstration(t, x + rng.normal(0.0, 0.3, x.shape), ("a", "value"), "dim")

    def demo(feats, n=61):
        return Demonstration(np.linspace(0, 4, n), feats + rng.normal(0, 0.3, (n, 2)),
                             ("a", "value"), "d")

    u = _min_jerk_ramp(np.linspace(0, 4, 61), 0.0, 4.0)
    lib = ActionLibrary.from_demonstrations({
        "up": [demo(np.stack([100 * u, 0 * u], 1))],
        "dim": [demo(np.stack([0 * u, -80 * u], 1))],
        "down": [demo(np.stack([-100 * u, 0 * u], 1))]}, interval_s=0.25)
    rough = [Segment("up", 1.5, 4.5, 0.0), Segment("dim", 6.4, 11.6, 0.0),
             Segment("down", 12.2, 14.8, 0.0)]
    refined = refine_boundaries(rec, rough, lib)  # without the drift: dim at 5.1 s
    for s, (t0, t1) in zip(refined, truth):
        assert abs(s.start - t0) <= 0.03 * (t1 - t0), (s, t0)
        assert abs(s.end - t1) <= 0.03 * (t1 - t0), (s, t1)


def test_refinement_with_a_coarse_library_still_moves_its_action_s_feature():
    # a library of few knots: the second differences of its knots (its noise
    # estimate) are the motion's own curvature, 1/5 of the range; the action's most
    # moved feature is moved all the same (held still, nothing would place the ends)
    rate = 30.0
    t = np.arange(int(10 * rate)) / rate
    x = (100 * _min_jerk_ramp(t, 1.0, 3.0) + 100 * _min_jerk_ramp(t, 5.0, 4.0))[:, None]
    rec = Demonstration(t, x + 1e-3 * np.random.default_rng(3).standard_normal(x.shape),
                        ("a",), "ramps")
    tt = np.linspace(0.0, 4.0, 41)
    lib = ActionLibrary.from_demonstrations(
        {"up": [Demonstration(tt, 100 * _min_jerk_ramp(tt, 0.0, 3.0)[:, None], ("a",),
                              "d")]})
    assert len(lib["up"].knots) <= 5
    rough = [Segment("up", 1.3, 3.6, 0.0), Segment("up", 4.6, 8.6, 0.0)]
    refined = refine_boundaries(rec, rough, lib)
    assert refined == refine_boundaries(rec, rough)
    for s, (t0, t1) in zip(refined, [(1.0, 4.0), (5.0, 9.0)]):
        assert abs(s.start - t0) <= 1 / rate + 1e-9 and abs(s.end - t1) <= 1 / rate + 1e-9


def test_synthetic_sequence_generator():
    seq = synthetic_sequence(["MOVE", "CLEAN", "PAINT"], seed=3, pause_s=(1.0, 1.0))
    rec, truth = seq
    assert [a for a, _, _ in truth] == ["MOVE", "CLEAN", "PAINT"]
    x = rec.features
    for (_, t0, t1), (_, t2, _) in zip(truth, truth[1:]):
        assert t2 - t1 == pytest.approx(1.0 + 1 / 30, abs=0.04)  # the pause
        # the next action starts where this one left the marker
        at_end = x[(rec.times > t1) & (rec.times < t2)].mean(0)
        i = int(np.searchsorted(rec.times, t2))
        np.testing.assert_allclose(x[i:i + 3].mean(0)[:3], at_end[:3], atol=8.0)
    # MOVE moves the marker 300 mm; PAINT turns it blue (hue 60 -> ~115)
    before = x[rec.times < truth[0][1]].mean(0)
    after = x[(rec.times > truth[0][2]) & (rec.times < truth[1][1])].mean(0)
    assert np.linalg.norm(after[:2] - before[:2]) == pytest.approx(300, abs=40)
    assert x[-10:, 4].mean() - x[:10, 4].mean() > 45
    with pytest.raises(ValueError, match="actions must name"):
        synthetic_sequence(["SWIM"])
    with pytest.raises(ValueError, match="pause_s"):
        synthetic_sequence(pause_s=(2.0, 1.0))


def test_bad_input_is_refused_by_name(library):
    rec = synthetic_sequence(["MOVE", "ROTATE"], seed=0).recording
    with pytest.raises(ValueError, match="library has no actions"):
        segment(rec, ActionLibrary())
    with pytest.raises(ValueError, match="not an ActionLibrary"):
        segment(rec, {"MOVE": library["MOVE"]})
    with pytest.raises(ValueError, match="not a Demonstration"):
        segment(np.zeros((0, 8)), library)
    other = Demonstration(rec.times, rec.features[:, :3], ("X", "Y", "Z"), "xyz")
    with pytest.raises(ValueError, match=r"recording 'xyz' has features \('X', 'Y', "
                       r"'Z'\) but the library has"):
        segment(other, library)
    with pytest.raises(ValueError, match="durations_s must be"):
        segment(rec, library, durations_s=(3.0, 1.0))
    with pytest.raises(ValueError, match="no room for an action"):
        segment(rec, library, durations_s=(60.0, 90.0))
    with pytest.raises(ValueError, match="unknown metric"):
        segment(rec, library, metric="cosine")
    renamed = ActionLibrary({REST: library["MOVE"]})
    with pytest.raises(ValueError, match="names the pauses"):
        segment(rec, renamed)


def test_execute_sequence_starts_each_goal_where_the_last_ended():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    sim = Simulator(robot, MarkerScene(), substeps=4)

    def reach(postures):
        return np.stack([np.asarray(robot.marker_position(jnp.asarray(q)))
                         for q in postures])

    first = reach([[0.2, 0.5, 0.6], [0.4, 0.6, 0.7], [0.6, 0.7, 0.7]])
    # the second goal as demonstrated elsewhere: its shape, not its place, counts
    second = reach([[0.6, 0.7, 0.7], [0.7, 0.6, 0.6], [0.8, 0.5, 0.5]]) + 0.05
    results = execute_sequence(sim, [first, second], run_ie, population_size=12,
                               tolerance=0.01, max_generations=80)
    assert [r.strategy for r in results] == ["ie", "ie"]
    assert all(r.success for r in results), [r.point_errors for r in results]
    np.testing.assert_allclose(results[0].goal, first)
    np.testing.assert_allclose(results[1].goal[0], results[0].features[-1], atol=1e-6)
    np.testing.assert_allclose(results[1].goal - results[1].goal[0],
                               second - second[0], atol=1e-6)
    with pytest.raises(ValueError, match="no goals"):
        execute_sequence(sim, [], run_ie)
    with pytest.raises(ValueError, match=r"goal 1 has shape \(3, 2\)"):
        execute_sequence(sim, [first, first[:, :2]], run_ie)
    with pytest.raises(ValueError, match="2 strategies for 1 goals"):
        execute_sequence(sim, [first], [run_ie, run_ie])


def _tiny_wall_sim():
    robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                            "marker")
    wall = PaintWall(np.array([[0.3, 0.0, 0.3], [0.0, 0.3, 0.3], [-0.3, 0.0, 0.3],
                               [0.0, -0.3, 0.3]]), radius=0.1, thickness=0.0)
    return Simulator(robot, wall, substeps=2)


def test_execute_sequence_carries_the_scene_state_and_the_posture():
    # a stand-in strategy that executes fixed joints from the simulator's
    # init_state(), as the incremental strategies start: with the state carried,
    # the executions are one rollout of all their joints from the start state
    sim = _tiny_wall_sim()
    joints = np.random.default_rng(0).uniform(sim.lower, sim.upper, (9, 3))
    parts = [joints[:4], joints[4:]]

    def replay(s, goal, *, part):
        features, final = s.rollout(parts[part].astype(np.float32), s.init_state())
        return ExecutionResult(
            strategy="replay", joints=parts[part], features=np.asarray(features),
            goal=goal, point_errors=np.zeros(len(goal)), fitness_history=np.zeros(1),
            evaluations=0, generations=0, wall_time_s=0.0, compile_time_s=0.0,
            success=True, tolerance=1.0, final_fitness=0.0,
            info={"start": np.asarray(s.init_state().genes)})

    runs = [functools.partial(replay, part=0), functools.partial(replay, part=1)]
    goals = [np.zeros((4, 1)), np.zeros((5, 1))]
    whole = np.asarray(sim.rollout(joints.astype(np.float32))[0])
    assert 0 < whole[3, 0] < whole[-1, 0]  # the first part paints, the second more
    carried = execute_sequence(sim, goals, runs)
    np.testing.assert_allclose(np.vstack([r.features for r in carried]), whole)
    np.testing.assert_allclose(carried[1].info["start"], joints[3], atol=1e-6)
    fresh = execute_sequence(sim, goals, runs, carry_state=False)
    alone = np.asarray(sim.rollout(parts[1].astype(np.float32))[0])
    np.testing.assert_allclose(fresh[1].features, alone)
    assert not np.allclose(alone, whole[4:])


@pytest.mark.slow
def test_paint_then_paint_by_iet_goes_on_painting_the_same_wall():
    # PAINT then PAINT (IET, tiny arm): the second run starts on the wall the
    # first left; the bench's TEO run: benchmarks/bench_sequence.py --paint
    sim = _tiny_wall_sim()
    half = np.array([[0.0], [25.0], [50.0]])  # 2 of the 4 squares each
    results = execute_sequence(sim, [half, half], run_iet, population_size=8,
                               tolerance=3.0, max_generations=40)
    assert all(r.success for r in results), [r.features for r in results]
    np.testing.assert_allclose(results[1].features[:, 0], [50.0, 75.0, 100.0])
    joints = np.vstack([r.joints for r in results]).astype(np.float32)
    whole = np.asarray(sim.rollout(joints)[0])
    np.testing.assert_allclose(whole, np.vstack([r.features for r in results]))


def test_cli_segment_writes_the_table_and_the_figure(tmp_path, capsys):
    from cgda_jax.cli.app import main
    from cgda_jax.data import save_csv

    lib_dir = tmp_path / "lib"
    demos = synthetic_actions(6, seed=0)
    for action, reps in demos.items():
        (lib_dir / action).mkdir(parents=True)
        for d in reps:
            save_csv(d, lib_dir / action / f"{d.name}.csv")
    seq = synthetic_sequence(["MOVE", "CLEAN", "PAINT"], seed=7, pause_s=(0.5, 2.0))
    save_csv(seq.recording, tmp_path / "task.csv")
    out = tmp_path / "out"
    argv = ["segment", str(tmp_path / "task.csv"), "--library", str(lib_dir),
            "--durations", "1,15", "--step", "0.2", "--out", str(out)]
    assert main(argv) == 0
    rows = (out / "segments.csv").read_text().splitlines()
    assert rows[0] == "action,start_s,end_s,cost"
    assert [r.split(",")[0] for r in rows[1:]] == ["MOVE", "CLEAN", "PAINT"]
    for row, (_, t0, t1) in zip(rows[1:], seq.truth):
        start, end = (float(v) for v in row.split(",")[1:3])
        assert abs(start - t0) < 0.4 * (t1 - t0) and abs(end - t1) < 0.4 * (t1 - t0)
    assert (out / "segments.png").stat().st_size > 10_000
    assert "MOVE" in capsys.readouterr().out
    # bad input: exit status 2 and one line naming the problem
    (tmp_path / "empty").mkdir()
    assert main(argv[:3] + [str(tmp_path / "empty")] + argv[4:]) == 2
    assert "has no action folders" in capsys.readouterr().err
    save_csv(Demonstration(seq.recording.times, seq.recording.features[:, :2],
                           ("X", "Y"), "xy"), tmp_path / "xy.csv")
    assert main(["segment", str(tmp_path / "xy.csv")] + argv[2:]) == 2
    assert "has features ('X', 'Y') but the library has" in capsys.readouterr().err
    assert main(argv[:4] + ["--durations", "5"] + argv[6:]) == 2
    assert "--durations must be MIN,MAX" in capsys.readouterr().err
