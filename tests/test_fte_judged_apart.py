"""FTE with feasibility (issue 39): a generation's moves judged apart from their
execution, together (`Simulator.judge_moves`), ranked or all; the reach start's
descents penalized after, only the iterates that can be the best judged
(`fitness.polish_penalty`); `fitness.judge_best` batched.

References: the judged rollout (`FTEPlan.execution`: every move judged in
order, summed), the descent that judges every iterate's move
(`refine.descend` on `polish_loss`), and `judge_best` row by row."""

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


def _plan(sim, judge):
    return FTEPlan(sim, jnp.asarray(GOAL), algorithm="CMA_ES", population_size=16,
                   tolerance=0.03, max_generations=20, restarts=0, judge=judge,
                   init="middle")


def _rank(x, k):
    return np.argsort(np.where(np.isfinite(x), x, np.inf), kind="stable")[:k]


def test_a_generations_fitness_judged_apart_equals_the_judged_rollouts(sim):
    """Random populations (wide: infeasible trajectories among them): with
    ``judge="all"`` the fitness is the judged rollout's penalized DTW bit for
    bit; with ``"ranked"`` the best `judge_ranks` are the same trajectories in
    the same order with the same values, and fewer trajectories are judged."""
    plans = {j: _plan(sim, j) for j in ("all", "ranked")}
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
        a, b = _rank(ref, 8), _rank(got, 8)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(ref[a], got[b])
        infeasible += int(np.sum(ref >= 1e3))
    assert infeasible > 0  # the penalty was exercised


def test_a_generation_of_fte_traces_one_collision_check(sim, monkeypatch):
    """The generation's fitness calls the check at one place (the judged
    trajectories' moves together), whichever ``judge``."""
    from cgda_jax.sim.feasibility import Feasibility as F

    for judge in ("all", "ranked"):
        plan = _plan(sim, judge)
        calls = []
        for name in ("move", "moves"):
            def counted(self, *a, _f=getattr(F, name), **k):
                calls.append(1)
                return _f(self, *a, **k)

            monkeypatch.setattr(F, name, counted)
        jax.jit(plan._fitness).lower(jnp.zeros((16, 9), jnp.float32))
        assert len(calls) == 1, judge
        monkeypatch.undo()


def test_the_descents_penalized_apart_equal_the_judged_descents(sim):
    """The reach start's candidates: descents on the squared error whose
    iterates are penalized after, together, only where they can be the best
    (`polish_penalty`), against descents that judge every iterate's move in
    the loss (`polish_loss`): the same candidates and errors, bit for bit."""
    state = sim.init_state()
    lower, upper = jnp.asarray(sim.lower), jnp.asarray(sim.upper)
    goal = jnp.asarray(GOAL)
    plan = _plan(sim, "all")
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
