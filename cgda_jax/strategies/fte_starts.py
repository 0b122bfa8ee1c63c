"""FTE's start means: the sampled pool, the descended candidates, restart means.

The plan (`cgda_jax.strategies.fte.FTEPlan`) calls these inside its compiled
``init`` and ``step``; see its module docstring for what each init mode does.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from cgda_jax.strategies.base import from_joints
from cgda_jax.strategies.refine import point_loss
from cgda_jax.strategies.seeding import (
    descended_candidates,
    nearest_in_pool,
    pick_candidate,
    sample_pool,
)

__all__ = ["REACH_STARTS", "first_mean", "restart_mean", "start_pool"]

#: Sampled postures descended per goal point (init "reach").
REACH_STARTS = 8
#: Adam steps of that descent (redundant 6-7 joint arms need more than 60).
REACH_STEPS = 200
_SAMPLE_SALT = 0x5EED  # key of the pool: fold_in(key, salt)


def start_pool(plan: Any, key: jax.Array) -> tuple:
    """The sampled postures of a run and, for init "reach", the descended
    candidates of every point (empty arrays where unused), and the
    evaluations spent (count, invalid)."""
    zero = jnp.zeros((), jnp.int32)
    f_dim = plan.goal.shape[1]
    empty = (jnp.zeros((0, plan.n_dof)), jnp.zeros((0, f_dim)),
             jnp.zeros((plan.n_points, 0, plan.n_dof)),
             jnp.zeros((plan.n_points, 0)))
    if plan.init_mode not in ("sampled", "reach"):
        return (*empty, zero, zero)
    state = plan.sim.init_state()
    u, f, bad = sample_pool(
        jax.random.fold_in(key, _SAMPLE_SALT),
        lambda x: plan.point_features(state, x), plan.n_dof, plan.init_samples,
        batch=plan.algo.population_size)
    evals = jnp.asarray(u.shape[0], jnp.int32)
    if plan.init_mode == "sampled":
        return (u, f, *empty[2:], evals, bad)
    cand_u, cand_err = descended_candidates(
        u, f, plan.goal,
        lambda g: point_loss(plan.sim, state, g, plan.lower, plan.upper),
        n_starts=REACH_STARTS, steps=REACH_STEPS)
    return (*empty[:2], cand_u, cand_err, evals, bad)


def first_mean(plan: Any, s: Any) -> jax.Array | None:
    """The first try's mean (N * D,) of the plan's init mode (None: the middle)."""
    if plan.init_mode == "middle":
        return None
    if plan.init_mode == "start":
        q0 = plan.sim.init_state().genes
        u0 = from_joints(jnp.asarray(q0, jnp.float32), plan.lower, plan.upper)
        return jnp.tile(u0, plan.n_points)
    if plan.init_mode == "reach":
        i = jnp.argmin(s.cand_err, axis=1)
        return jnp.take_along_axis(s.cand_u, i[:, None, None], axis=1).reshape(-1)
    genes, _ = nearest_in_pool(s.pool_u, s.pool_f, plan.goal)
    return genes.reshape(-1)


def restart_mean(plan: Any, s: Any) -> tuple[jax.Array, jax.Array]:
    """The mean (N * D,) and key of try ``s.tries``.

    Odd tries repair the best trajectory (its points that miss the tolerance get
    fresh postures), even ones start wholly fresh. Fresh postures: init "reach", a
    random descended candidate within tolerance, away from the posture the point
    stuck at (`pick_candidate`); "sampled", the nearest of a random half of the
    pool, away from it (`nearest_in_pool`); otherwise uniform random.
    """
    t = s.tries
    k_mean, k_evo = jax.random.split(jax.random.fold_in(s.key, t))
    best = s.best_u.reshape(plan.n_points, plan.n_dof)
    miss = ~(s.best_errors < plan.aim_tolerance)
    avoid = jnp.where((miss & jnp.isfinite(s.best_fitness))[:, None], best,
                      jnp.nan)
    if plan.init_mode == "reach":
        fresh = pick_candidate(k_mean, s.cand_u, s.cand_err, plan.aim_tolerance,
                               avoid)
    elif plan.init_mode == "sampled":
        fresh, _ = nearest_in_pool(s.pool_u, s.pool_f, plan.goal, key=k_mean,
                                   avoid=avoid)
    else:
        fresh = jax.random.uniform(k_mean, (plan.n_points, plan.n_dof),
                                   minval=-1.0, maxval=1.0)
    repair = jnp.where(miss[:, None], fresh, best)
    use = (t % 2 == 1) & jnp.isfinite(s.best_fitness)
    mean = jnp.where(use, repair, fresh).reshape(-1)
    return mean, k_evo
