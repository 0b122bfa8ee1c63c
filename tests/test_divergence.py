"""Diverged simulations (non-finite features): counted, penalized, reported, never best.

A fake simulator wraps the kinematic tiny-arm `Simulator` and "blows up" (NaN features,
NaN state from then on) in a region of joint space, the way a physics simulation with
absurd gains does. The strategies must rank those candidates last, count them, report
only evaluated postures and warn once; when nothing at all is valid they raise
`SimulationDiverged`.
"""

import logging

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import cgda_jax
from cgda_jax import MarkerScene, Robot, SimulationDiverged, Simulator, model_path
from cgda_jax.strategies import (
    INVALID_PENALTY,
    ExecutionResult,
    run_fte,
    run_ie,
    run_iet,
    run_oet,
)
from cgda_jax.strategies.evolution import (
    Evolution,
    default_kwargs,
    evolution_init,
    evolution_step,
    make_algorithm,
    screen,
)

JOINTS = ["yaw", "shoulder", "elbow"]


class DivergingSim:
    """The tiny-arm simulator, diverging where ``diverges(state, waypoint)`` holds.

    Same duck type as `Simulator` for the strategies (n_dof, n_features,
    feature_names, lower, upper, init_state, step, rollout). Once a step diverged its
    state is NaN, so every later step of a rollout diverges too (as physics does).
    """

    def __init__(self, sim, diverges):
        self.sim, self.diverges = sim, diverges
        self.n_dof, self.n_features = sim.n_dof, sim.n_features
        self.feature_names = sim.feature_names
        self.lower, self.upper = sim.lower, sim.upper

    def init_state(self):
        return self.sim.init_state()

    def step(self, state, waypoint):
        new, feats = self.sim.step(state, waypoint)
        bad = self.diverges(state, waypoint) | ~jnp.all(jnp.isfinite(state.genes))
        new = new.replace(genes=jnp.where(bad, jnp.nan, new.genes))
        return new, jnp.where(bad, jnp.nan, feats)

    def rollout(self, waypoints, state=None):
        state = self.init_state() if state is None else state
        waypoints = jnp.asarray(waypoints, jnp.float32)
        state, feats = jax.lax.scan(self.step, state, waypoints)
        return feats, state


@pytest.fixture(scope="module")
def robot():
    return Robot.from_mjcf(model_path("tiny_arm.xml"), JOINTS, "marker")


@pytest.fixture(scope="module")
def sim(robot):
    return Simulator(robot, MarkerScene(), substeps=4)


@pytest.fixture(scope="module")
def half_sim(sim):
    """Diverges wherever the first joint (yaw) is > 0: half of joint space."""
    return DivergingSim(sim, lambda state, q: q[0] > 0)


@pytest.fixture(scope="module")
def nan_sim(sim):
    """Diverges everywhere."""
    return DivergingSim(sim, lambda state, q: jnp.asarray(True))


@pytest.fixture(scope="module")
def trap_sim(sim):
    """Valid from the start posture, but every step from a posture with yaw < -0.3
    diverges: point 0 of the goal below is reachable, then nothing is."""
    return DivergingSim(sim, lambda state, q: state.genes[0] < -0.3)


@pytest.fixture(scope="module")
def goal(robot):
    # marker positions of postures in the valid half (yaw < 0): reachable there
    postures = [[-0.2, 0.5, 0.6], [-0.4, 0.6, 0.8], [-0.6, 0.7, 0.6], [-0.8, 0.5, 0.4]]
    return np.stack([np.asarray(robot.marker_position(jnp.asarray(q)))
                     for q in postures])


@pytest.fixture
def warnings_log():
    """Messages of the ``cgda_jax`` logger (a handler on it: the CLI may have turned
    its propagation off in this process)."""
    messages = []

    class Collect(logging.Handler):
        def emit(self, record):
            messages.append(record.getMessage())

    handler = Collect(level=logging.WARNING)
    logger = logging.getLogger("cgda_jax")
    logger.addHandler(handler)
    yield messages
    logger.removeHandler(handler)


# --------------------------------------------------------------------------- strategies
RUNS = {
    "ie": lambda s, g, **k: run_ie(s, g, population_size=12, tolerance=0.01,
                                   max_generations=80, **k),
    "iet": lambda s, g, **k: run_iet(s, g, population_size=12, tolerance=0.01,
                                     max_generations=60, **k),
    "oet": lambda s, g, **k: run_oet(s, g, population_size=12, tolerance=0.01,
                                     max_generations=60, **k),
    "fte": lambda s, g, **k: run_fte(s, g[:2], population_size=16, stagnation=10,
                                     max_generations=60, distance="dtw_multi", **k),
}


@pytest.mark.parametrize("name", sorted(RUNS))
def test_invalid_candidates_are_counted_and_never_reported(
    name, half_sim, sim, goal, warnings_log, tmp_path
):
    res = RUNS[name](half_sim, goal)
    goal_used = res.goal
    assert 0 < res.invalid_evaluations < res.evaluations
    assert res.summary()["invalid_evaluations"] == res.invalid_evaluations
    per_point = res.info.get("step_invalid" if name == "oet" else "point_invalid")
    if name != "fte":
        assert sum(per_point) == res.invalid_evaluations
    assert res.info["points_without_valid"] == []
    # the reported postures were evaluated: valid, and the plain simulator re-executes
    # them to the reported features and errors
    assert np.all(np.isfinite(res.joints)) and np.all(res.joints[:, 0] <= 0)
    feats, _ = sim.rollout(jnp.asarray(res.joints), sim.init_state())
    np.testing.assert_allclose(res.features, feats, atol=1e-5)
    if name == "oet":
        dist = np.linalg.norm(goal_used[:, None] - np.asarray(feats)[None], axis=-1)
        np.testing.assert_allclose(res.point_errors, dist.min(axis=1), atol=1e-5)
    else:
        np.testing.assert_allclose(
            res.point_errors, np.linalg.norm(np.asarray(feats) - goal_used, axis=-1),
            atol=1e-5)
    if name != "fte":  # the goal lies in the valid half: reached despite divergence
        assert res.success, res.point_errors
    assert np.all(np.isfinite(res.fitness_history[~np.isnan(res.fitness_history)]))
    # one warning line, with the figures
    assert len(warnings_log) == 1, warnings_log
    assert (f"{res.invalid_evaluations} of {res.evaluations} candidate evaluations "
            "diverged (non-finite features)") in warnings_log[0]
    assert name.upper() in warnings_log[0] and "\n" not in warnings_log[0]
    # result.json carries the total; it survives the round trip
    back = ExecutionResult.load(res.save(tmp_path / name))
    assert back.invalid_evaluations == res.invalid_evaluations


@pytest.mark.parametrize("name", sorted(RUNS))
def test_every_candidate_diverged_raises(name, nan_sim, goal, warnings_log):
    small = {"ie": dict(max_generations=3), "iet": dict(max_generations=3, restarts=1,
                                                        backtracks=0),
             "oet": dict(max_generations=3), "fte": dict(max_generations=3)}[name]
    run = {"ie": run_ie, "iet": run_iet, "oet": run_oet, "fte": run_fte}[name]
    with pytest.raises(SimulationDiverged, match=rf"{name.upper()} run") as err:
        run(nan_sim, goal[:2], population_size=6, **small)
    msg = str(err.value)
    assert "every one of the" in msg and "non-finite" in msg
    assert "gains" in msg and "timestep" in msg
    assert warnings_log == []  # the error says it; no warning besides
    assert isinstance(err.value, RuntimeError)
    assert cgda_jax.SimulationDiverged is SimulationDiverged


def test_a_point_without_any_valid_candidate_stops_the_run(
    trap_sim, goal, warnings_log
):
    # (OET's counterpart, a step that finds nothing valid, runs in the all-NaN test)
    goal = goal[[2, 0, 1]]  # point 0 at yaw -0.6: reachable, and after it nothing is
    res = run_iet(trap_sim, goal, population_size=12, tolerance=0.01,
                  max_generations=30, restarts=1, backtracks=0)
    assert not res.success
    assert res.info["points_without_valid"] == [1]
    assert 0 < res.invalid_evaluations < res.evaluations
    assert res.info["point_invalid"][0] == 0 and res.info["point_invalid"][1] > 0
    # point 0 committed; no posture for point 1 (and none after the stop)
    assert np.all(np.isfinite(res.joints[0])) and np.all(np.isnan(res.joints[1:]))
    assert res.point_errors[0] < 0.01 and np.isinf(res.point_errors[1:]).all()
    assert len(warnings_log) == 1 and "points [1]" in warnings_log[0]


# --------------------------------------------------------------------------- algorithms
def _half_invalid(pop):
    """Sphere fitness, NaN for every other candidate (exactly half)."""
    odd = jnp.arange(pop.shape[0]) % 2 == 1
    return jnp.where(odd, jnp.nan, jnp.sum(pop**2, axis=-1))


def _all_invalid(pop):
    return jnp.full(pop.shape[:1], jnp.nan)


def _nonfinite_leaves(tree):
    return [
        jax.tree_util.keystr(path)
        for path, x in jax.tree_util.tree_leaves_with_path(tree)
        if jnp.issubdtype(jnp.asarray(x).dtype, jnp.floating)
        and not bool(jnp.all(jnp.isfinite(x)))
    ]


@pytest.mark.parametrize(
    "name",
    ["CMA_ES", "SimpleGA", "DifferentialEvolution", "PSO", "SNES", "Open_ES"],
)
def test_algorithm_state_stays_finite_with_invalid_generations(name):
    # (every other evosax algorithm was checked the same way once, by hand: all keep
    # a finite state; GuidedES holds a NaN `grad` by design: "no surrogate gradient")
    algo, params = make_algorithm(name, 8, 3, algorithm_kwargs=default_kwargs(name))

    def stop(evo):
        return jnp.asarray(False)

    @jax.jit
    def run(key):
        # all invalid from the start (population-based: the initial population too),
        # then half, then all invalid again
        evo = evolution_init(algo, params, key, _all_invalid, 3)
        outs = []
        for f in (_all_invalid, _half_invalid, _all_invalid):
            evo, metrics = evolution_step(algo, params, evo, f, stop)
            outs.append((evo, metrics))
        return outs

    (e1, m1), (e2, m2), (e3, m3) = run(jax.random.key(0))
    for evo in (e1, e2, e3):
        assert _nonfinite_leaves(evo.algo) == [], name
    # nothing valid yet: no best at all (the start was never evaluated)
    assert int(m1["invalid"]) == 8 and float(m1["generation_best"]) == np.inf
    assert not bool(e1.found) and float(e1.best_fitness) == np.inf
    assert int(e1.invalid) == int(e1.evaluations) in (8, 16)  # (+ initial population)
    # half invalid: counted; the best is a valid, evaluated candidate
    assert int(m2["invalid"]) == 4 and int(e2.invalid) == int(e1.invalid) + 4
    assert bool(e2.found) and float(e2.best_fitness) == float(m2["generation_best"])
    sphere = float(jnp.sum(e2.best_u**2))
    assert float(e2.best_fitness) == pytest.approx(sphere, rel=1e-5)
    # an all-invalid generation changes neither the best nor lets a penalty in
    assert int(m3["invalid"]) == 8 and float(m3["generation_best"]) == np.inf
    assert float(e3.best_fitness) == float(e2.best_fitness)
    np.testing.assert_array_equal(e3.best_u, e2.best_u)
    assert int(e3.invalid) == int(e3.evaluations) - 4


def test_screen_penalizes_and_counts():
    fit = jnp.array([0.5, jnp.nan, jnp.inf, -jnp.inf, 2e10, 1.0])
    told, ranked, n = screen(fit)
    np.testing.assert_array_equal(
        told, [0.5, INVALID_PENALTY, INVALID_PENALTY, INVALID_PENALTY, INVALID_PENALTY,
               1.0])
    np.testing.assert_array_equal(ranked, [0.5, np.inf, np.inf, np.inf, 2e10, 1.0])
    assert int(n) == 3 and n.dtype == jnp.int32
    assert "invalid" in Evolution.__dataclass_fields__


# --------------------------------------------------------------------------- real physics
def _absurd_arm(tmp_path):
    """The tiny arm with position gains no Euler step can hold (kp = 5e7)."""
    from cgda_jax import model_path

    xml = model_path("tiny_arm.xml").read_text().replace('<position kp="50"/>',
                                                         '<position kp="5e7"/>')
    path = tmp_path / "absurd_gains.xml"
    path.write_text(xml)
    return path


@pytest.mark.parametrize("backend", ["mujoco", "mjx"])
def test_absurd_gains_diverge_and_are_reported(tmp_path, backend):
    from cgda_jax import MarkerScene, Robot, Simulator, SimulationDiverged, run_ie

    robot = Robot.from_mjcf(_absurd_arm(tmp_path), ["yaw", "shoulder", "elbow"],
                            "marker")
    sim = Simulator(robot, MarkerScene(), mode="dynamic", physics=backend,
                    waypoint_s=0.05)
    # every candidate diverges: non-finite features (MuJoCo C's stopped rollouts too)
    feats = np.asarray(sim.execute_population(
        np.random.default_rng(0).uniform(-1, 1, (4, 2, 3)).astype(np.float32)))
    assert np.all(np.isnan(feats))
    if backend == "mjx":  # the strategy layer is the same; spare CI an MJX plan compile
        return
    with pytest.raises(SimulationDiverged, match="IE run diverged.*gains"):
        run_ie(sim, np.array([[0.2, 0.1, 0.4]]), population_size=4, max_generations=2)


def test_absurd_gains_from_the_cli_exit_3_with_one_line(tmp_path, capsys, monkeypatch):
    from cgda_jax.cli import main

    monkeypatch.setenv("CGDA_JAX_CACHE", str(tmp_path / "cache"))
    cfg = tmp_path / "absurd.toml"
    cfg.write_text(
        'kind = "execution"\n[data]\nsource = "clean_circle"\ncentre = [0.3, 0.0, 0.4]\n'
        'diameter = 0.1\nn_demos = 2\n'
        f'[robot]\nmodel = "{_absurd_arm(tmp_path)}"\njoints = ["yaw", "shoulder", '
        '"elbow"]\nfixed = {}\nmode = "dynamic"\nphysics = "mujoco"\nwaypoint_s = 0.05\n'
        '[strategy]\npopulation_size = 4\nmax_generations = 2\n'
        '[output]\nplots = false\nrender = false\n')
    code = main(["run", str(cfg), "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3
    # the model has no speed or effort limits: one warning says so before the run
    assert [w for w in err if w.startswith("cgda: warning:")] == [
        w for w in err if "no speed limit" in w] and len(err) == 2
    err = [e for e in err if not e.startswith("cgda: warning:")]
    assert len(err) == 1 and err[0].startswith("cgda: error:") and "diverge" in err[0]
