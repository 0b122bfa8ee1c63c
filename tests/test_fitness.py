"""The fitness in one place (`cgda_jax.strategies.fitness`): the ranked judging of a
population against judging every candidate, and the plans' fitness against the
formulas it replaces."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax.strategies.fitness import (
    distances,
    judge_best,
    judged_round,
    least_motion,
    ordered_point_errors,
    penalized,
    point_errors,
    point_fitness,
)


def _rank(x, k):
    return np.argsort(np.where(np.isfinite(x), x, np.inf), kind="stable")[:k]


@pytest.mark.parametrize("n,ranks", [(32, 16), (9, 4), (5, 5)])
def test_judge_best_keeps_the_best_ranks_exact(n, ranks):
    """Random populations (invalid candidates, feasible and infeasible ones, every
    share of them): the best ``ranks`` of `judge_best` are those of judging every
    candidate (same candidates, order and values); an unjudged candidate is told
    no better than any judged feasible one; it judges fewer than all when the
    best are feasible."""
    rng = np.random.default_rng(n)
    ranked = jax.jit(lambda f, v: judge_best(f, lambda idx, need: v[idx], 1e3, ranks,
                                             judged_round(ranks)))
    saved = 0
    for _ in range(60):
        f = (rng.random(n) * rng.choice([0.01, 1.0, 100.0])).astype(np.float32)
        f[rng.random(n) < 0.1] = np.inf
        v = np.where(rng.random(n) < rng.random(), rng.random(n) * 3, 0.0)
        v = v.astype(np.float32)
        full = np.asarray(penalized(jnp.asarray(f), jnp.asarray(v), 1e3))
        got, viol = (np.asarray(x) for x in ranked(f, v))
        a, b = _rank(full, ranks), _rank(got, ranks)
        ok = np.isfinite(full[a])
        np.testing.assert_array_equal(a[ok], b[ok])
        # (jitted: XLA may fuse the penalty into one multiply-add, 1 ulp)
        np.testing.assert_allclose(full[a][ok], got[b][ok], rtol=1e-6)
        judged = ~np.isnan(viol)
        np.testing.assert_array_equal(viol[judged], v[judged])
        feasible = judged & (v == 0) & np.isfinite(f)
        if (~judged).any() and feasible.any():
            assert got[~judged].min() >= got[feasible].max()
        saved += int((~judged).sum())
    assert saved > 0 or ranks == n


def test_judge_best_judges_a_round_when_the_best_are_feasible():
    f = jnp.arange(32, dtype=jnp.float32)
    calls = []

    def judge(idx, need):
        calls.append(idx.shape)
        return jnp.zeros(idx.shape, jnp.float32)

    got, viol = judge_best(f, judge, 1e3, 16, judged_round(16))
    assert judged_round(16) == 20
    assert int(np.sum(~np.isnan(np.asarray(viol)))) == 20
    np.testing.assert_array_equal(np.asarray(got)[:20], np.arange(20))
    np.testing.assert_array_equal(np.asarray(got)[20:], np.arange(20, 32) + 1e3)


@pytest.mark.parametrize("n,ranks", [(32, 16), (9, 4)])
def test_judge_best_with_a_lead_judges_it_first_and_the_rest_as_without(n, ranks):
    """``lead``: a move judged whatever its fitness (IE's best in context) joins
    the first round; the other candidates' values, violations and rounds are
    those of `judge_best` without it (the reference), bit for bit."""
    rng = np.random.default_rng(n)
    size = judged_round(ranks)

    runs = {lead: jax.jit(lambda f, v, lead=lead: judge_best(
        f, lambda idx, need: v[idx], 1e3, ranks, size, lead=lead)) for lead in (0, 1)}

    def run(f, v, lead):
        return [np.asarray(x) for x in runs[lead](f, v)]

    for _ in range(40):
        f = (rng.random(n) * rng.choice([0.01, 1.0, 100.0])).astype(np.float32)
        f[rng.random(n) < 0.1] = np.inf
        v = np.where(rng.random(n) < rng.random(), rng.random(n) * 3, 0.0)
        v = v.astype(np.float32)
        lead_v = np.float32(rng.random() * (rng.random() < 0.5))
        got, viol = run(jnp.asarray(f), jnp.asarray(v), 0)
        got1, viol1 = run(jnp.concatenate([jnp.zeros(1), jnp.asarray(f)]),
                          jnp.concatenate([jnp.asarray([lead_v]), jnp.asarray(v)]), 1)
        np.testing.assert_array_equal(got1[1:], got)
        np.testing.assert_array_equal(viol1[1:], viol)
        assert viol1[0] == lead_v  # judged whatever its (zero) fitness


def test_formulas():
    feats = np.array([[0.0, 3.0], [1.0, 1.0]], np.float32)
    goal = np.array([[4.0, 0.0], [1.0, 1.0]], np.float32)
    d = distances(feats, goal)
    assert isinstance(d, np.ndarray) and d.dtype == np.float32
    np.testing.assert_array_equal(d, [5.0, 0.0])
    np.testing.assert_allclose(np.asarray(distances(jnp.asarray(feats), goal)), d)
    # least motion below the aim, the penalty on top, the prefix in between
    err = jnp.asarray([0.01, 0.5])
    np.testing.assert_allclose(np.asarray(least_motion(err, jnp.asarray([1.0, 1.0]),
                                                       0.02)), [0.01, 0.5])
    f = point_fitness(err, jnp.asarray([0.0, 2.0]), 1e3, motion=jnp.asarray([3.0, 0.0]),
                      aim=0.02, prefix_sq=jnp.float32(0.0))
    np.testing.assert_allclose(np.asarray(f), [0.015, 0.5 + 3e3], rtol=1e-6)
    # the result's errors: OET in order, the others per point
    np.testing.assert_array_equal(point_errors("ie", feats, goal, 0.1), [5.0, 0.0])
    np.testing.assert_array_equal(
        point_errors("oet", feats, goal, 0.1),
        ordered_point_errors(np.linalg.norm(goal[:, None].astype(float)
                                            - feats[None].astype(float), axis=-1), 0.1))
