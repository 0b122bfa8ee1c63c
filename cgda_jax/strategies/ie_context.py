"""IE's sequential context: every point evolved from where the bests before it
leave the arm (`cgda_jax.strategies.ie`, ``info["sequential_context"]``).

Each generation first executes the current best postures of all points in order
from the start (`contexts`: one rollout of N waypoints), so that point i's
candidates are evaluated from the state after points 0..i-1, and re-scores each
point's best where its predecessors now leave it (`rescore`) before the stop
test.

With feasibility the rollout does not judge its moves: `judged_generation`
evaluates every point's candidates and, first in each row, its current best in
one batched call, so that the move's judgement (the collision check, the most
expensive code to compile) appears once in the generation's program, not once
more in the rollout (clean_ie's chunk: 287 XLA fusions instead of 368).  The
values are those of judging the rollout's moves: the same move from the same
state.  The violations of the bests' moves are kept (``IEState.judged_u``,
``judged_violation``), and the run is done only when the kept ones are the
current bests' (`fresh`): the result's execution then takes them
(`judged_execution`) and the finish program carries no collision check either.
A run its generation budget cuts before they are fresh is judged again on the
host (`cgda_jax.strategies.base.PlanBase.rejudge`).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from cgda_jax.strategies.evolution import evolution_ask

__all__ = ["contexts", "fresh", "judged_execution", "judged_generation", "rescore"]


def contexts(plan, best_u: jax.Array) -> tuple[Any, jax.Array | None]:
    """Start states of every point (stacked, N) and each point's error (N,) when
    ``plan.joints(best_u)`` (N, DoF) are executed in order; independent points:
    the start state each and inf.  With feasibility the error is None: the moves
    are judged by `judged_generation`."""
    start = plan.sim.init_state()
    if not plan.sequential:
        states = jax.tree.map(
            lambda x: jnp.broadcast_to(x, (plan.n_points, *jnp.shape(x))), start)
        return states, jnp.full((plan.n_points,), jnp.inf)
    if plan.feasibility is not None:
        return jax.lax.scan(lambda st, w: (plan.advance(st, w)[0], st), start,
                            plan.joints(best_u))[1], None

    def body(state, w):
        new, feats = plan.sim.step(state, w)
        return new, (state, feats, new.move_violation)

    _, (states, feats, violation) = jax.lax.scan(body, start, plan.joints(best_u))
    errors = plan.penalize(jnp.linalg.norm(feats - plan.goal, axis=-1), violation)
    return states, jnp.where(jnp.isfinite(errors), errors, jnp.inf)


def judged_generation(plan, evo, best_u: jax.Array, states):
    """One batched evaluation of every point's candidates (asked of ``evo``, N
    evolutions) with, first in each row, its best ``best_u`` (N, D) from its
    context ``states``.  Returns the bests' errors (N; inf where not finite),
    their moves' violations (N) and ``(populations (N, P, D), algorithm states,
    fitness (N, P))`` for `cgda_jax.strategies.evolution.evolution_tell`."""
    pops, algo_states = jax.vmap(lambda e: evolution_ask(plan.algo, plan.params, e))(evo)
    cands = jnp.concatenate([best_u[:, None], pops], axis=1)  # (N, P + 1, D)
    feats, violation = jax.vmap(
        lambda st, c: plan.sharded(lambda u: plan.point_outcome(st, u))(c)
    )(states, cands)
    errors = plan.penalize(jnp.linalg.norm(feats[:, 0] - plan.goal, axis=-1),
                           violation[:, 0])
    fitness = jax.vmap(plan.outcome_fitness)(states, pops, feats[:, 1:],
                                             violation[:, 1:], plan.goal)
    return (jnp.where(jnp.isfinite(errors), errors, jnp.inf), violation[:, 0],
            (pops, algo_states, fitness))


def fresh(s) -> jax.Array:
    """Whether the last judged bests (``s.judged_u``) are the current ones: their
    stored violations are then those of executing the result."""
    return jnp.all(s.judged_u == s.best_u)


def judged_execution(plan, s, joints: jax.Array) -> dict:
    """`PlanBase.execution` of the result ``joints`` (N, DoF; NaN where nothing
    was found) without a judgement of its own: the features of the unjudged
    rollout and the sum of the moves' violations the last generation stored
    (NaN where a point has no posture, as the judged rollout gives), and
    ``judged``: whether those are the current bests' (`fresh`; else
    `PlanBase.rejudge` on the host)."""
    found = jnp.all(jnp.isfinite(joints))
    return {"joints": joints, "features": plan.executed_features(joints),
            "violation": jnp.where(found, jnp.sum(s.judged_violation), jnp.nan),
            "judged": fresh(s)}


def rescore(plan, s, errors: jax.Array):
    """The IE state ``s`` and its evolutions with each point's best re-scored to
    ``errors`` (N) (its error in the current context), the stop test redone."""
    evo = s.evo
    now = jnp.where(jnp.isfinite(s.best_fitness), errors, s.best_fitness)
    same = jnp.all(evo.best_u == s.best_u, axis=-1)
    evo = evo.replace(best_fitness=jnp.where(
        same & jnp.isfinite(evo.best_fitness), now, evo.best_fitness))
    evo = evo.replace(done=jax.vmap(plan.point_stop)(evo))
    s = s.replace(best_fitness=now, done=(now < plan.aim_tolerance)
                  | (evo.done & (s.tries > plan.restarts)))
    return s, evo
