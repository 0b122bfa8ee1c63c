"""Signed distances between convex primitives in JAX (float32), for `collision`.

Shapes use MuJoCo's conventions: a geom has a world frame (rotation ``R`` (3, 3),
whose columns are the geom's axes, and centre ``p`` (3,)) and ``size`` (3,): sphere
``[r, -, -]``, capsule ``[r, half length, -]`` along local z, box ``[hx, hy, hz]``
(half sizes), cylinder ``[r, half height, -]`` along local z, plane: the infinite
half-space local ``z <= 0`` (its size is only for rendering).  Distances are signed:
positive separation, negative penetration.

Methods, by pair (`pair_distance`; "round" = sphere or capsule, a point or segment
"core" inflated by a radius):

- round vs round: closed-form segment-segment distance minus both radii.  Exact.
- anything vs plane: the support point along the plane's normal, closed form.  Exact.
- round vs box / cylinder: the signed distance function (sdf) of a convex set is
  convex, so along the core segment it is unimodal: against a box, its minimum at
  one of 37 candidate points in closed form
  (`cgda_jax.sim.box_distances.segment_box_min`); against a
  cylinder, golden-section search (`GOLDEN_ITERS` iterations, bracket
  ``0.618**(GOLDEN_ITERS + 1)`` of the segment's length, the sdf is 1-Lipschitz);
  minus the radius.  Exact to < 1e-6 m.
- box / cylinder vs box / cylinder: the smallest sdf of each shape over the other's
  "feature" segments (a box's 12 edges; `N_GENERATORS` straight generator lines on a
  cylinder's side, ending on its rims), each by golden-section search of
  `FEATURE_ITERS` iterations (bracket 0.2 % of the segment's length, `error_bound`).
  For separated boxes this is exact up to that bracket (a closest pair always
  involves a vertex or two edges); a
  cylinder's side and rims are sampled at ``N_GENERATORS`` angles, so the value can
  exceed the true distance by at most ``2 r sin(pi / (2 N_GENERATORS))`` (0.098 r;
  about ``r (1 - cos(pi / N))`` = 0.005 r where a flat face meets the side).  In
  penetration the value is minus the depth of the deepest feature point inside the
  other shape (not MuJoCo's penetration depth, which is the shortest separating
  translation): negative whenever the shapes overlap.
- box vs box in penetration: the separating axis theorem
  (`cgda_jax.sim.box_distances.box_box_sat`, 15 axes,
  closed form) gives minus the shortest separating translation, MuJoCo's depth (to
  3e-8 m against ``mj_geomDistance`` in the tests, where the feature search was up
  to 10 cm off); separated, the feature search above, or with ``exact=False`` the
  separating-axis value, a lower bound of the distance at about 1/8 of the cost.
- box vs cylinder with ``exact=False``: projections on 67 axes with the exact
  support functions (`cgda_jax.sim.box_distances.box_cylinder_sat`): a lower bound
  of the signed distance, within 0.8 mm of MuJoCo's depth in penetration in the
  tests, at about 1/4 of the cost.

For round pairs and round vs box/cylinder in penetration the value is likewise
minus (the deepest core point's depth + the radius): never more negative than the
true penetration depth (the shortest separating translation).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from cgda_jax.sim.box_distances import (
    box_box_sat,
    box_cylinder_sat,
    box_sdf,
    dot3,
    norm3,
    segment_box_min,
    to_local,
)

__all__ = [
    "GOLDEN_ITERS",
    "KINDS",
    "N_GENERATORS",
    "BASE_ERROR",
    "ROUND",
    "error_bound",
    "feature_scale",
    "features",
    "pair_distance",
    "plane_distance",
    "sdf_local",
    "segment_min",
    "segment_segment",
    "swap_needed",
]

#: Golden-section iterations per segment.
GOLDEN_ITERS = 28
#: Golden-section iterations per feature segment of a box/cylinder pair (24 or more
#: searches per pair: the costliest pairs; bracket 0.618**13 = 0.2 % of the edge).
FEATURE_ITERS = 12
#: Generator lines sampled on a cylinder's side (box/cylinder pairs).
N_GENERATORS = 32
#: Supported geom types.
KINDS = ("sphere", "capsule", "box", "cylinder", "plane")
#: Types that are a point/segment core inflated by a radius.
ROUND = ("sphere", "capsule")
_INV_PHI = (math.sqrt(5.0) - 1.0) / 2.0
#: float32 round-off and golden-section slack on any pair (m).
BASE_ERROR = 1e-5


def sdf_local(kind: str, size: Array, x: Array) -> Array:
    """Signed distance from a point ``x`` (3,) in the geom's frame to the geom."""
    if kind == "sphere":
        return jnp.linalg.norm(x) - size[0]
    if kind == "capsule":
        z = jnp.clip(x[2], -size[1], size[1])
        return jnp.linalg.norm(x - jnp.array([0.0, 0.0, 1.0]) * z) - size[0]
    if kind == "box":
        return box_sdf(size, x)
    if kind == "cylinder":
        q = jnp.stack([jnp.linalg.norm(x[:2]) - size[0], jnp.abs(x[2]) - size[1]])
        return jnp.linalg.norm(jnp.maximum(q, 0.0)) + jnp.minimum(jnp.max(q), 0.0)
    if kind == "plane":
        return x[2]
    raise ValueError(f"unsupported geom type {kind!r}; supported: {KINDS}")


def segment_min(f, a: Array, b: Array, iters: int = GOLDEN_ITERS) -> Array:
    """Minimum of a convex ``f`` ((3,) -> scalar) on the segment ``a``-``b`` (3,):
    golden-section search, the smallest value met (endpoints included)."""
    d = b - a

    def g(t):
        return f(a + t * d)

    x1, x2 = 1.0 - _INV_PHI, _INV_PHI
    state = (jnp.float32(0.0), jnp.float32(1.0), jnp.float32(x1), jnp.float32(x2),
             g(x1), g(x2))

    def step(_, s):
        lo, hi, x1, x2, f1, f2 = s
        left = f1 < f2  # a minimizer lies in [lo, x2]
        lo, hi = jnp.where(left, lo, x1), jnp.where(left, x2, hi)
        t = jnp.where(left, hi - _INV_PHI * (hi - lo), lo + _INV_PHI * (hi - lo))
        ft = g(t)
        nx1, nx2 = jnp.where(left, t, x2), jnp.where(left, x1, t)
        nf1, nf2 = jnp.where(left, ft, f2), jnp.where(left, f1, ft)
        return lo, hi, nx1, nx2, nf1, nf2

    *_, f1, f2 = jax.lax.fori_loop(0, iters, step, state)
    return jnp.minimum(jnp.minimum(f1, f2), jnp.minimum(g(0.0), g(1.0)))


def segment_segment(p1: Array, q1: Array, p2: Array, q2: Array) -> Array:
    """Distance between the segments ``p1``-``q1`` and ``p2``-``q2`` (each (3,)),
    closed form (Ericson, Real-Time Collision Detection 5.1.9); degenerate
    (zero-length) segments are points.  Written out by component
    (`cgda_jax.sim.box_distances.dot3`)."""
    eps = 1e-12
    d1 = [q1[k] - p1[k] for k in range(3)]
    d2 = [q2[k] - p2[k] for k in range(3)]
    r = [p1[k] - p2[k] for k in range(3)]
    a, e, f = dot3(d1, d1), dot3(d2, d2), dot3(d2, r)
    c, b = dot3(d1, r), dot3(d1, d2)
    denom = a * e - b * b
    safe_a, safe_e = jnp.maximum(a, eps), jnp.maximum(e, eps)
    s = jnp.where(denom > eps * jnp.maximum(a * e, eps),
                  jnp.clip((b * f - c * e) / jnp.maximum(denom, eps), 0.0, 1.0), 0.0)
    s = jnp.where(a > eps, s, 0.0)
    t = jnp.where(e > eps, (b * s + f) / safe_e, 0.0)
    s = jnp.where(t < 0.0, jnp.clip(-c / safe_a, 0.0, 1.0),
                  jnp.where(t > 1.0, jnp.clip((b - c) / safe_a, 0.0, 1.0), s))
    s = jnp.where(e > eps, s, jnp.clip(-c / safe_a, 0.0, 1.0))  # b is a point
    s = jnp.where(a > eps, s, 0.0)
    t = jnp.clip(t, 0.0, 1.0)
    return norm3([p1[k] + s * d1[k] - p2[k] - t * d2[k] for k in range(3)])


def _core(kind: str, size: Array, R: Array, p: Array) -> tuple[Array, Array, Array]:
    """A round geom's core segment ends (3,) each, and its radius."""
    half = size[1] if kind == "capsule" else 0.0
    return p - R[:, 2] * half, p + R[:, 2] * half, size[0]


def features(kind: str) -> np.ndarray:
    """(E, 2, 3) unit feature segments, to be scaled by `feature_scale`: a box's 12
    edges, a cylinder's `N_GENERATORS` side generators (their ends on the rims)."""
    segs = []
    if kind == "box":
        for axis in range(3):
            o1, o2 = [k for k in range(3) if k != axis]
            for s1 in (-1, 1):
                for s2 in (-1, 1):
                    a = np.zeros(3)
                    a[o1], a[o2], a[axis] = s1, s2, -1.0
                    b = a.copy()
                    b[axis] = 1.0
                    segs.append((a, b))
    elif kind == "cylinder":
        for k in range(N_GENERATORS):
            th = 2 * math.pi * k / N_GENERATORS
            xy = [math.cos(th), math.sin(th)]
            segs.append(([*xy, -1.0], [*xy, 1.0]))
    else:
        raise ValueError(f"no feature segments for a {kind}")
    return np.asarray(segs, dtype=np.float32)


def feature_scale(kind: str, size: Array) -> Array:
    """(3,) per-axis scale of `features` for a geom of that size."""
    if kind == "cylinder":
        return jnp.stack([size[0], size[0], size[1]])
    return size


def plane_distance(kind: str, size: Array, R: Array, p: Array, Rp: Array, pp: Array):
    """Signed distance from a geom (frame ``R``, ``p``) to the plane (``Rp``, ``pp``):
    its lowest point along the plane's normal, closed form."""
    n = Rp[:, 2]
    h = dot3(n, p - pp)
    if kind in ROUND:
        a, b, r = _core(kind, size, R, p)
        return jnp.minimum(dot3(n, a - pp), dot3(n, b - pp)) - r
    if kind == "box":
        return h - sum(size[i] * jnp.abs(dot3(n, R[:, i])) for i in range(3))
    if kind == "cylinder":
        c = jnp.dot(n, R[:, 2])
        return h - size[1] * jnp.abs(c) - size[0] * jnp.sqrt(jnp.maximum(1 - c * c, 0))
    raise ValueError(f"no distance between a {kind} and a plane")


def _min_over_features(kind_a, size_a, kind_b, size_b, Ra, pa, Rb, pb):
    """Smallest sdf of geom b over geom a's feature segments (world frames)."""
    local = features(kind_a) * feature_scale(kind_a, size_a)
    world = jnp.einsum("ij,esj->esi", Ra, local) + pa

    def sdf_b(x):
        return sdf_local(kind_b, size_b, Rb.T @ (x - pb))

    per = jax.vmap(lambda s: segment_min(sdf_b, s[0], s[1], FEATURE_ITERS))(world)
    return jnp.min(per)


def pair_distance(kind_a: str, kind_b: str, size_a, Ra, pa, size_b, Rb, pb, *,
                  exact: bool = True) -> Array:
    """Signed distance between geom a and geom b (types static; canonical order,
    see `swap_needed`).

    Box-box pairs in penetration are minus the penetration depth
    (`cgda_jax.sim.box_distances.box_box_sat`: the shortest separating
    translation); separated, with ``exact`` their distance by the feature search
    (module doc), without it the separating-axis value, a lower bound of the
    distance that costs about 1/8 as much (a feasibility check needs the depth,
    not the clearance).  Without ``exact`` a box and a cylinder get
    `cgda_jax.sim.box_distances.box_cylinder_sat`: never above the signed
    distance, the depth within 0.8 mm of MuJoCo's in the tests, at about 1/4 of
    the cost.  ``exact`` changes nothing else.

    Args:
        kind_a, kind_b: geom types (`KINDS`).
        size_a, size_b: (3,) MuJoCo sizes.
        Ra, Rb: (3, 3) world rotations; pa, pb: (3,) world centres.
        exact: separated box-box pairs get their distance and box-cylinder
            pairs the feature search (True), or lower bounds of the signed
            distance (False).
    """
    if kind_a == "plane" and kind_b == "plane":
        raise ValueError("no distance between two planes")
    if kind_b == "plane":
        return plane_distance(kind_a, size_a, Ra, pa, Rb, pb)
    if kind_a in ROUND:
        a0, a1, ra = _core(kind_a, size_a, Ra, pa)
        if kind_b in ROUND:
            b0, b1, rb = _core(kind_b, size_b, Rb, pb)
            return segment_segment(a0, a1, b0, b1) - ra - rb

        def sdf_b(x):
            return sdf_local(kind_b, size_b, Rb.T @ (x - pb))

        if kind_a == "sphere":
            return sdf_b(pa) - ra
        if kind_b == "box":
            return (segment_box_min(size_b, to_local(Rb, pb, a0), to_local(Rb, pb, a1))
                    - ra)
        return segment_min(sdf_b, a0, a1) - ra
    sat = None
    if kind_a == kind_b == "box":
        sat = box_box_sat(size_a, Ra, pa, size_b, Rb, pb)
        if not exact:
            return sat
    if not exact and {kind_a, kind_b} == {"box", "cylinder"}:
        if kind_a == "box":
            return box_cylinder_sat(size_a, Ra, pa, size_b, Rb, pb)
        return box_cylinder_sat(size_b, Rb, pb, size_a, Ra, pa)
    search = jnp.minimum(
        _min_over_features(kind_a, size_a, kind_b, size_b, Ra, pa, Rb, pb),
        _min_over_features(kind_b, size_b, kind_a, size_a, Rb, pb, Ra, pa),
    )
    return search if sat is None else jnp.where(sat <= 0.0, sat, search)


def swap_needed(kind_a: str, kind_b: str) -> bool:
    """Whether `pair_distance` wants the pair the other way round (a plane second,
    a sphere/capsule first)."""
    if kind_a == "plane":
        return True
    return kind_b in ROUND and kind_a not in ROUND and kind_a != "plane"


def error_bound(kind_a: str, size_a, kind_b: str, size_b) -> float:
    """Worst-case |error| (m) of `pair_distance` on separated geoms (see the module
    docstring): `BASE_ERROR`, plus ``2 r sin(pi / (2 N_GENERATORS))`` per cylinder
    of a box/cylinder pair, plus for those pairs the golden-section bracket of
    `FEATURE_ITERS` on the longest feature segment (the sdf is 1-Lipschitz)."""
    bound = BASE_ERROR
    if kind_a in ("box", "cylinder") and kind_b in ("box", "cylinder"):
        longest = 0.0
        for kind, size in ((kind_a, size_a), (kind_b, size_b)):
            size = np.asarray(size, float)
            if kind == "cylinder":
                bound += 2 * float(size[0]) * math.sin(math.pi / (2 * N_GENERATORS))
                longest = max(longest, 2 * float(size[1]))
            else:
                longest = max(longest, 2 * float(np.max(size[:3])))
        bound += _INV_PHI ** (FEATURE_ITERS + 1) * longest
    return bound
