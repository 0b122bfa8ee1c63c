"""A move judged once per program (issue 21's compile cost): `Simulator.step`
with ``judge=False``, IE's sequential context judged in the candidates' batched
evaluation, IET's commit and FTE's point errors without a second judgement.

The values are checked against the judged rollout (`Simulator.rollout`, the
reference: every move judged in order), and the traces of `Feasibility.move`
count the copies of the collision check a program carries."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.sim.feasibility import Feasibility
from cgda_jax.strategies.fte import FTEPlan
from cgda_jax.strategies.ie import IEPlan
from cgda_jax.strategies.iet import IETPlan

WALL = {"name": "wall", "type": "box", "pos": (0.3, 0.0, 0.125),
        "size": (0.12, 0.01, 0.125)}
GOAL = np.array([[0.30, -0.22, 0.25], [0.25, 0.0, 0.50], [0.30, 0.22, 0.25]],
                np.float32)


@pytest.fixture(scope="module")
def sim():
    tiny = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                           "marker")
    return Simulator(tiny, MarkerScene(), substeps=4,
                     feasibility=Feasibility(tiny, obstacles=[WALL]))


def _random_postures(sim, n, seed):
    lo, hi = np.asarray(sim.lower), np.asarray(sim.upper)
    return jnp.asarray(np.random.default_rng(seed).uniform(lo, hi, (n, sim.n_dof)),
                       jnp.float32)


def test_an_unjudged_step_moves_the_same_and_carries_the_violations(sim):
    start = sim.init_state()
    q = _random_postures(sim, 2, 0)
    judged, f1 = sim.step(start, q[0])
    free, f2 = sim.step(start, q[0], judge=False)
    np.testing.assert_array_equal(np.asarray(f1), np.asarray(f2))
    np.testing.assert_array_equal(np.asarray(judged.genes), np.asarray(free.genes))
    assert not bool(free.first) and bool(start.first)  # the approach is done
    assert float(free.violation) == float(start.violation)  # not judged: carried
    assert float(free.move_violation) == float(start.move_violation)
    # the next move of an unjudged state is judged as after a judged one
    a, _ = sim.step(judged, q[1])
    b, _ = sim.step(free, q[1])
    assert float(a.move_violation) == float(b.move_violation)


def _move_traces(monkeypatch):
    """Calls of the check: `Feasibility.move` (one move) and `Feasibility.moves`
    (the moves of a ranked round together)."""
    calls = []
    for name in ("move", "moves"):
        def counted(self, *args, _f=getattr(Feasibility, name), **kwargs):
            calls.append(1)
            return _f(self, *args, **kwargs)

        monkeypatch.setattr(Feasibility, name, counted)
    return calls


@pytest.mark.parametrize("plan_cls, judge, checks", [
    (IEPlan, "all", 1), (IETPlan, "all", 1), (IETPlan, "ranked", 1),
    # ranked IE: the bests in their contexts join the candidates' first round
    # (`fitness.judge_best`'s ``lead``): one call, one copy
    (IEPlan, "ranked", 1)])
def test_a_generation_program_carries_one_collision_check(sim, plan_cls, judge, checks,
                                                          monkeypatch):
    """Tracing one generation calls `Feasibility.move` at one place per set of
    moves it judges (before: IE's context rollout and IET's commit judged their
    moves again, each a copy of the check in the compiled program: 2 calls)."""
    plan = plan_cls(sim, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=8,
                    tolerance=0.03,
                    max_generations=20, restarts=0, judge=judge)
    carry = plan.init(jax.random.key(0))
    calls = _move_traces(monkeypatch)
    jax.jit(plan.step).lower(carry)
    assert len(calls) == checks


def test_unjudged_features_equal_the_judged_execution(sim):
    """FTE's point errors come from `executed_features` (moves not judged); the
    reference is the judged execution's features."""
    plan = FTEPlan(sim, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=8,
                   tolerance=0.03, max_generations=20, restarts=0)
    for seed in range(3):
        q = _random_postures(sim, 3, seed)
        ref = plan.execution(q)
        assert float(ref["violation"]) >= 0.0
        np.testing.assert_array_equal(np.asarray(jax.jit(plan.executed_features)(q)),
                                      np.asarray(ref["features"]))


def test_the_bests_judged_with_the_candidates_equal_the_judged_rollout(sim):
    """IE's re-scored errors come from the candidates' batched evaluation; the
    reference is the rollout that judges every move in order."""
    plan = IEPlan(sim, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=8,
                  tolerance=0.03,
                  max_generations=20, restarts=0, stagnation=None)
    s = plan.init(jax.random.key(1))
    seen = []
    for seed in range(6):  # some of these moves cross the wall, some are too fast
        best_u = jax.random.uniform(jax.random.key(seed), (3, 3), minval=-1.0,
                                    maxval=1.0)
        states, none = plan.contexts(best_u)
        assert none is None
        errors, viol, (pops, _, fitness) = jax.jit(
            lambda b, st: plan.judged_generation(s.evo, b, st))(best_u, states)
        assert pops.shape == (3, 8, 3) and fitness.shape == (3, 8)
        q = plan.joints(best_u)
        feats, _ = sim.rollout(q)
        ref_v = []
        state = sim.init_state()
        for w in q:
            state, _ = sim.step(state, w)
            ref_v.append(float(state.move_violation))
        ref = plan.penalize(jnp.linalg.norm(feats - jnp.asarray(GOAL), axis=-1),
                            jnp.asarray(ref_v))
        np.testing.assert_allclose(np.asarray(errors), np.asarray(ref), rtol=1e-5)
        np.testing.assert_allclose(np.asarray(viol), ref_v, rtol=1e-5)
        seen += ref_v
    assert min(seen) == 0.0 and max(seen) > 0.0  # feasible and infeasible moves


def _check_result_and_finish(sim, res, plan_cls, monkeypatch):
    """A feasible success whose reported violation is the judged rollout's of its
    joints, and a finish program of ``plan_cls`` that traces no judgement."""
    ref = float(sim.violation(jnp.asarray(res.joints)))
    assert res.info["violation"] == pytest.approx(ref, abs=1e-6)
    assert res.success and res.info["feasible"]
    plan = plan_cls(sim, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=8,
                    tolerance=0.03, max_generations=20, restarts=0, stagnation=None)
    carry = plan.init(jax.random.key(0))
    jax.clear_caches()
    calls = _move_traces(monkeypatch)
    jax.jit(plan.finish).lower(carry)
    assert len(calls) == 0


def test_ie_reports_the_judged_rollouts_violation_without_judging_in_finish(
        sim, monkeypatch):
    """The result's violation is the stored one of the last generation; the
    reference is the judged rollout of the reported joints.  The finish program
    then judges nothing (before: one copy of the check)."""
    import cgda_jax as cg

    res = cg.run_ie(sim, GOAL, population_size=24, max_generations=150, seed=0,
                    tolerance=0.03)
    _check_result_and_finish(sim, res, IEPlan, monkeypatch)


def test_ie_with_a_polish_judges_with_the_candidates_and_its_result_in_finish(sim):
    """A polish (``refine``) changes the postures after the generations, so the
    finish judges them itself; the generations still judge the bests with the
    candidates (their carry holds the kept judgements from init on)."""
    import cgda_jax as cg

    res = cg.run_ie(sim, GOAL, population_size=24, max_generations=150, seed=0,
                    tolerance=0.03, refine="adam", refine_steps=20)
    ref = float(sim.violation(jnp.asarray(res.joints)))
    assert res.info["violation"] == pytest.approx(ref, abs=1e-6)
    assert res.success and res.info["feasible"]


def test_a_result_whose_bests_were_not_judged_is_judged_again(sim):
    """A run cut by its budget before the last bests were judged in context: the
    result's violation is computed again (`PlanBase.rejudge`), equal to the judged
    rollout's, also where it is not 0."""
    plan = IEPlan(sim, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=8,
                  tolerance=0.03, max_generations=20, restarts=0, stagnation=None)
    s = plan.init(jax.random.key(0))
    assert not bool(plan.done(s))  # nothing judged yet: never done
    refs = []
    for seed in range(3):
        u = jax.random.uniform(jax.random.key(seed), (3, 3), minval=-1.0, maxval=1.0)
        stale = s.replace(best_u=u, best_fitness=jnp.zeros(3), done=jnp.ones(3, bool))
        assert not bool(plan.done(stale))  # every point done, but not judged
        final = jax.device_get(jax.jit(plan.finish)(stale))
        assert not bool(final["judged"])
        again = plan.rejudge(final)
        assert "judged" not in again
        ref = plan.execution(plan.joints(u))["violation"]
        assert float(again["violation"]) == pytest.approx(float(ref), rel=1e-5)
        refs.append(float(ref))
        judged = stale.replace(judged_u=u, judged_violation=jnp.zeros(3))
        assert bool(plan.done(judged))
    assert max(refs) > 0.0  # the stored (stale) violation would have been NaN


@pytest.mark.parametrize("algorithm", ["CMA_ES", "DifferentialEvolution"])
def test_iet_reports_the_judged_rollouts_violation_without_judging_in_finish(
        sim, algorithm, monkeypatch):
    """IET keeps each committed move's violation from the evaluation that found
    it; the reference is the judged rollout of the reported joints.  With a
    population-based algorithm a try's first best may come from its initial
    population, whose violation is not kept: the result is then judged again
    (`PlanBase.rejudge`), with the same answer."""
    import cgda_jax as cg

    res = cg.run_iet(sim, GOAL, algorithm=algorithm, population_size=24,
                     max_generations=150, seed=0, tolerance=0.03)
    _check_result_and_finish(sim, res, IETPlan, monkeypatch)


def test_iet_kept_violations_equal_the_judged_moves():
    """The violation IET keeps for its evolution's best after each generation, and
    for its committed postures, against the judged move (the reference: one
    judged `Simulator.step` from the point's state); a speed limit of 0.8 rad/s
    makes bests infeasible on the way."""
    from cgda_jax.sim.limits import read_limits
    from cgda_jax.strategies.iet import tree_at

    tiny = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
                           "marker")
    limits = read_limits(tiny.mj_model, tiny.joint_names, {"velocity": 0.8})
    slow = Simulator(tiny, MarkerScene(), substeps=4,
                     feasibility=Feasibility(tiny, limits, obstacles=[WALL]))
    plan = IETPlan(slow, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=16,
                   tolerance=0.03, max_generations=25, restarts=0, backtracks=0,
                   stagnation=None)
    s = plan.init(jax.random.key(3))
    step = jax.jit(plan.step)
    seen = []
    for _ in range(100):  # every point commits after at most 25 generations
        if bool(plan.done(s)):
            break
        s, _ = step(s)
        if bool(s.evo.found) and int(s.point) < len(GOAL):
            new, _ = slow.step(tree_at(s.sim_states, s.point),
                               plan.joints(s.evo.best_u))
            ref = float(new.move_violation)
            assert float(s.evo_violation) == pytest.approx(ref, rel=1e-5, abs=1e-6)
            seen.append(ref)
    assert min(seen) == 0.0 and max(seen) > 0.0  # infeasible bests on the way
    assert bool(plan.done(s)) and int(s.point) == len(GOAL)
    state, ref = slow.init_state(), []
    for w in np.asarray(s.joints):
        state, _ = slow.step(state, jnp.asarray(w))
        ref.append(float(state.move_violation))
    np.testing.assert_allclose(np.asarray(s.violations), ref, rtol=1e-5, atol=1e-6)


def test_moves_judged_together_equal_one_by_one(sim):
    """`Feasibility.moves` (coarse to fine, batch entries packed together) gives
    `Feasibility.move`'s violations bit for bit, flat and under nested vmaps;
    ``need`` False leaves only the penetration out.  Short moves (the coarse
    bound proves most clear) and long ones (through the wall, too fast)."""
    feas = sim.feasibility
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(sim.lower), np.asarray(sim.upper)
    for scale in (0.05, 1.0):
        q0 = rng.uniform(lo, hi, (128, 3)).astype(np.float32)
        dq = (np.clip(q0 + scale * rng.standard_normal(q0.shape), lo, hi)
              - q0).astype(np.float32)
        dur = np.full(128, 0.5, np.float32)
        ap = rng.random(128) < 0.2
        need = rng.random(128) < 0.7
        ref = np.asarray(jax.jit(jax.vmap(feas.move))(q0, dq, dur, ap))
        flat = np.asarray(jax.jit(feas.moves)(q0, dq, dur, ap))
        nested = np.asarray(jax.jit(jax.vmap(jax.vmap(feas.moves)))(
            *(x.reshape(4, 4, 8, *x.shape[1:]) for x in (q0, dq, dur, ap))))
        np.testing.assert_array_equal(flat, ref)
        np.testing.assert_array_equal(nested.reshape(-1), ref)
        some = np.asarray(jax.jit(feas.moves)(q0, dq, dur, ap, need))
        np.testing.assert_array_equal(some[need], ref[need])
        assert (ref > 0).any() or scale < 1.0
    no_walls = np.asarray(jax.jit(jax.vmap(
        lambda a, b, c, d: jnp.maximum(feas.limit_violation(b, c), 0.0)))(
            q0, dq, dur, ap))
    assert np.all(some[~need] <= np.maximum(no_walls[~need], ref[~need]))
