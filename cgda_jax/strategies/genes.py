"""Gene bounds of every strategy: normalized genes <-> joint angles.

Algorithms search an unbounded, normalized space ``u`` (D,); joint angles
are ``q = mid + half * sin(pi / 2 * u)`` with ``mid, half`` the centre and half-width of
the joint limits. ``u`` in [-1, 1] covers the whole range once; beyond it the sine folds
back, a smooth reflection at the limits (no flat, gradient-free regions as with
clipping, no infeasible postures). ``u = 0`` is the middle of every joint range, the
start mean of distribution-based algorithms, and a step size of about 0.3 moves a joint
by a few tenths of its range.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["from_joints", "to_joints"]


def to_joints(u: jax.Array, lower: jax.Array, upper: jax.Array) -> jax.Array:
    """Maps normalized genes (..., DoF) to joint angles inside [lower, upper]."""
    mid = 0.5 * (upper + lower)
    half = 0.5 * (upper - lower)
    return mid + half * jnp.sin(0.5 * jnp.pi * u)


def from_joints(q: jax.Array, lower: jax.Array, upper: jax.Array) -> jax.Array:
    """Inverse of `to_joints` on [-1, 1] (angles are clipped into the limits first)."""
    mid = 0.5 * (upper + lower)
    half = jnp.maximum(0.5 * (upper - lower), 1e-12)
    s = jnp.clip((q - mid) / half, -1.0, 1.0)
    return jnp.arcsin(s) * (2.0 / jnp.pi)
