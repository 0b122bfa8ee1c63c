"""A move judged once per program (issue 21's compile cost): `Simulator.step`
with ``judge=False``, IE's sequential context judged in the candidates' batched
evaluation, IET's commit and FTE's point errors without a second judgement;
FTE's generation judged apart and together (ranked or all), its reach start's
descents penalized after (`fitness.polish_penalty`), `fitness.judge_best`
batched (issue 39; references: the judged rollouts and descents, row by row).

The values are checked against the judged rollout (`Simulator.rollout`, the
reference: every move judged in order), and the traces of `Feasibility.move`
count the copies of the collision check a program carries."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax import MarkerScene, Robot, Simulator, model_path
from cgda_jax.sim.feasibility import Feasibility
from cgda_jax.strategies.fitness import (
    judge_best,
    judged_round,
    penalized,
    polish_loss,
    polish_penalty,
)
from cgda_jax.strategies.fte import FTEPlan
from cgda_jax.strategies.ie import IEPlan
from cgda_jax.strategies.iet import IETPlan
from cgda_jax.strategies.refine import descended_candidates, sample_pool

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


# ---- FTE (issue 39): its generation's moves judged apart, together; its reach
# start's descents penalized after; `judge_best` batched
def _fte_plan(sim, judge):
    return FTEPlan(sim, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=16,
                   tolerance=0.03, max_generations=20, restarts=0, judge=judge,
                   init="middle")


def _ranked(x, k):
    return np.argsort(np.where(np.isfinite(x), x, np.inf), kind="stable")[:k]


def test_a_generations_fitness_judged_apart_equals_the_judged_rollouts(sim):
    """Random populations (wide: infeasible trajectories among them): with
    ``judge="all"`` the fitness is the judged rollout's penalized DTW bit for
    bit; with ``"ranked"`` the best `judge_ranks` are the same trajectories in
    the same order with the same values, and fewer trajectories are judged."""
    plans = {j: _fte_plan(sim, j) for j in ("all", "ranked")}
    assert plans["all"].moves_apart and plans["ranked"].judge_ranks == 8
    ref_plan = plans["all"]

    @jax.jit
    def reference(pop):  # every candidate's rollout judged move by move
        out = jax.vmap(lambda u: ref_plan.execution(ref_plan._trajectory(u)))(pop)
        f = jax.vmap(lambda f: ref_plan.distance(f, ref_plan.goal))(out["features"])
        return ref_plan.penalize(f, out["violation"])

    fits = {j: jax.jit(p._fitness) for j, p in plans.items()}
    rng = np.random.default_rng(0)
    infeasible = 0
    for scale in (0.2, 0.6, 1.0, 1.0):
        pop = jnp.asarray(rng.uniform(-scale, scale, (16, 9)), jnp.float32)
        ref = np.asarray(reference(pop))
        np.testing.assert_array_equal(np.asarray(fits["all"](pop)), ref)
        got = np.asarray(fits["ranked"](pop))
        a, b = _ranked(ref, 8), _ranked(got, 8)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(ref[a], got[b])
        infeasible += int(np.sum(ref >= 1e3))
    assert infeasible > 0  # the penalty was exercised


@pytest.mark.parametrize("judge", ["all", "ranked"])
def test_a_generation_of_fte_traces_one_collision_check(sim, judge, monkeypatch):
    """FTE's generation fitness calls the check at one place (the judged
    trajectories' moves together), whichever ``judge``."""
    plan = _fte_plan(sim, judge)
    calls = _move_traces(monkeypatch)
    jax.jit(plan._fitness).lower(jnp.zeros((16, 9), jnp.float32))
    assert len(calls) == 1


def test_the_descents_penalized_apart_equal_the_judged_descents(sim):
    """The reach start's candidates: descents on the squared error whose
    iterates are penalized after, together, only where they can be the best
    (`polish_penalty`), against descents that judge every iterate's move in
    the loss (`polish_loss`): the same candidates and errors, bit for bit."""
    state = sim.init_state()
    lower, upper = jnp.asarray(sim.lower), jnp.asarray(sim.upper)
    goal = jnp.asarray(GOAL)
    plan = _fte_plan(sim, "all")
    u, f, _ = sample_pool(jax.random.key(0), lambda x: plan.point_features(state, x),
                          3, 64, batch=64)
    penalty = polish_penalty(sim, state, lower, upper)
    assert penalty is not None

    def run(apart):
        return descended_candidates(
            u, f, goal,
            lambda g: polish_loss(sim, state, g, lower, upper, judge=not apart),
            n_starts=2, steps=12, penalty=penalty if apart else None)

    ref = jax.jit(lambda: run(False))()
    got = jax.jit(lambda: run(True))()
    for r, g in zip(ref, got, strict=True):
        np.testing.assert_array_equal(np.asarray(r), np.asarray(g))
    # some of the moves the descents try are infeasible (the penalty matters)
    q = plan.joints(u)
    news = jax.vmap(lambda w: sim.step(state, w, judge=False)[0])(q)
    assert float(jnp.max(sim.judge_moves(state, news))) > 0.0


def test_judge_best_batched_equals_row_by_row():
    """``fitness`` (B, P): each row's values and violations those of
    `judge_best` on that row alone, bit for bit; ``judge`` called with the
    rows' picks at once, its ``need`` False for rows that are done."""
    rng = np.random.default_rng(3)
    b, n, ranks = 6, 12, 3
    size = judged_round(ranks)
    one = jax.jit(lambda f, v: judge_best(f, lambda idx, need: v[idx], 1e3, ranks,
                                          size))

    def judge_rows(v):
        def judge(idx, need):
            assert idx.shape == (b, size) and need.shape == (b, size)
            return jnp.where(need, jnp.take_along_axis(v, idx, axis=-1), jnp.nan)

        return judge

    both = jax.jit(lambda f, v: judge_best(f, judge_rows(v), 1e3, ranks, size))
    for _ in range(20):
        f = (rng.random((b, n)) * rng.choice([0.01, 1.0, 100.0])).astype(np.float32)
        f[rng.random((b, n)) < 0.1] = np.inf
        v = np.where(rng.random((b, n)) < rng.random((b, 1)),
                     rng.random((b, n)) * 3, 0.0).astype(np.float32)
        got, viol = (np.asarray(x) for x in both(f, v))
        for r in range(b):
            want, want_v = (np.asarray(x) for x in one(f[r], v[r]))
            np.testing.assert_array_equal(got[r], want)
            np.testing.assert_array_equal(viol[r], want_v)
        assert np.all(got[np.isfinite(f)] >= f[np.isfinite(f)])
        full = np.asarray(penalized(jnp.asarray(f), jnp.asarray(v), 1e3))
        # (jitted: XLA may fuse the penalty into one multiply-add, 1 ulp)
        np.testing.assert_allclose(np.min(got, axis=1), np.min(full, axis=1),
                                   rtol=1e-6)


@pytest.mark.slow
def test_a_restarts_mean_judged_with_the_next_generation_keeps_the_run(sim):
    """A restart's start mean evaluated with its try's first generation
    (`FTEPlan.mean_later`, one copy of the check) against evaluated at the
    restart by its judged rollout (the reference): the same best fitness and
    try every generation over restarts (ranked judging), the same evaluations
    in the end (the mean's counted one generation later)."""
    runs = {}
    for later in (False, True):
        cls = type("Plan", (FTEPlan,), {"mean_later": later})
        plan = cls(sim, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=8,
                   tolerance=0.002, max_generations=30, restarts=2, stagnation=4,
                   init="sampled", init_samples=64)
        c, step, seen = jax.jit(plan.init)(jax.random.key(3)), jax.jit(plan.step), []
        for _ in range(24):
            c, m = step(c)
            seen.append((float(m["best_fitness"]), int(m["try"])))
        runs[later] = (seen, int(c.evaluations + c.evo.evaluations))
    assert runs[True] == runs[False]
    assert runs[True][0][-1][1] == 2  # both restarts ran
