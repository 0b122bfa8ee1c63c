"""Closed-form distances of boxes, for `cgda_jax.sim.primitive_distances` (float32, JAX).

- `box_sdf`: a box's signed distance at points in its frame (also
  `primitive_distances.sdf_local`'s);
- `segment_box_min`: the smallest signed distance of a box along a segment (a
  capsule's core), exact at 37 candidate points, no iterations;
- `box_box_sat`: the separating axis theorem for two boxes: minus the penetration
  depth (the shortest separating translation, MuJoCo's depth) when they overlap, a
  lower bound of the distance when they are apart;
- `box_cylinder_sat`: a lower bound of a box's and a cylinder's signed distance from
  their projections on 67 axes (exact support functions), within a millimetre of the
  depth where they overlap.

A lower bound serves the feasibility check (`cgda_jax.sim.feasibility`), which
needs the depth, not the clearance: the check is never more lenient than the true
geometry.  Frames follow MuJoCo: a rotation's columns are the geom's axes, sizes are
half sizes (box) or radius and half height (cylinder).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import Array

__all__ = ["SAT_PARALLEL", "box_box_sat", "box_cylinder_sat", "box_sdf",
           "segment_box_min"]

#: `box_box_sat` skips an edge-edge axis whose edges are this close to parallel
#: (the sine of their angle): its direction is noise in float32, and the face
#: axes already stand for it (skipping can only make the value smaller).
SAT_PARALLEL = 1e-3


def box_sdf(size: Array, x: Array) -> Array:
    """Signed distance from points ``x`` (..., 3) in a box's frame to the box of
    half sizes ``size`` (3,): (...,)."""
    q = jnp.abs(x) - size
    return (jnp.linalg.norm(jnp.maximum(q, 0.0), axis=-1)
            + jnp.minimum(jnp.max(q, axis=-1), 0.0))


def _box_corners():
    """The 8 vertex signs of a box, and its 12 edges' start signs and directions
    (end minus start signs)."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                      for sz in (-1, 1)], np.float32)
    edges = [(i, j) for i in range(8) for j in range(i + 1, 8)
             if np.sum(signs[i] != signs[j]) == 1]
    start = np.asarray([signs[i] for i, _ in edges])
    return signs, start, np.asarray([signs[j] for _, j in edges]) - start


_BOX_SIGNS, _EDGE_START, _EDGE_DIR = _box_corners()


def _segment_box_tables():
    """Constant tables of `segment_box_min`'s candidate parameters: per edge of
    the 12 (along axis k at signs s1, s2 in the other two axes) its selection
    (2, 3) and signs (2,); per kink of the 15 ``t = -(u.h + w.a) / (w.d)`` its
    rows ``u``, ``w`` (3,)."""
    sel, sgn = [], []
    for k in range(3):
        o = [i for i in range(3) if i != k]
        for s1 in (-1, 1):
            for s2 in (-1, 1):
                sel.append(np.eye(3, dtype=np.float32)[o])
                sgn.append([s1, s2])
    u, w = [], []
    for i in range(3):  # a coordinate crosses 0
        u.append(np.zeros(3))
        w.append(np.eye(3)[i])
    for i, j in ((0, 1), (0, 2), (1, 2)):  # s_i x_i - h_i = s_j x_j - h_j
        for si in (-1.0, 1.0):
            for sj in (-1.0, 1.0):
                uk, wk = np.zeros(3), np.zeros(3)
                uk[i], uk[j], wk[i], wk[j] = 1.0, -1.0, -si, sj
                u.append(uk)
                w.append(wk)
    return (np.asarray(sel, np.float32), np.asarray(sgn, np.float32),
            np.asarray(u, np.float32), np.asarray(w, np.float32))


_SEGMENT_BOX = _segment_box_tables()


def segment_box_min(size: Array, a: Array, b: Array) -> Array:
    """Minimum of a box's signed distance on the segment ``a``-``b`` (3,), both in
    the box's frame; closed form.

    The box sdf is convex along the segment, so its minimum is at one of 37
    parameters, all evaluated: the ends; the segment's points nearest each of the
    8 vertices and the lines of the 12 edges (outside the box the nearest box point
    is a vertex, an edge or a face, and a face's distance is linear along the
    segment); and the kinks of ``max_i(|x_i| - h_i)``, the sdf inside the box (a
    coordinate crossing 0, two coordinates' terms equal).  Exact up to float32
    round-off, with no iterations.
    """
    sel, sgn, u, w = _SEGMENT_BOX
    d = b - a

    def ratio(num, den):
        ok = jnp.abs(den) > 1e-12
        return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)

    t_vert = ratio((_BOX_SIGNS * size - a) @ d, jnp.dot(d, d))  # (8,)
    do = sel @ d  # (12, 2): the segment's direction across each edge
    t_edge = ratio(jnp.sum((sgn * (sel @ size) - sel @ a) * do, -1),
                   jnp.sum(do * do, -1))  # (12,)
    t_kink = ratio(-(u @ size + w @ a), w @ d)  # (15,)
    t = jnp.clip(jnp.concatenate([jnp.array([0.0, 1.0], jnp.float32), t_vert,
                                  t_edge, t_kink]), 0.0, 1.0)
    return jnp.min(box_sdf(size, a + t[:, None] * d))


def box_box_sat(size_a, Ra, pa, size_b, Rb, pb) -> Array:
    """The separating-axis value of two boxes: the largest gap between their
    projections on the 15 axes of the separating axis theorem (3 face normals of
    each box, 9 cross products of their edges), closed form.

    Overlapping boxes: minus the penetration depth, the shortest translation that
    separates them (the depth MuJoCo's box-box collision reports; the shortest
    translation of two convex polyhedra is along one of these axes), up to float32
    round-off.  Separated boxes: a value in ``(0, distance]``, equal to the
    distance when the closest features are a face and anything, or the insides of
    two edges, smaller for vertex-vertex and vertex-edge closest points.  Edge
    pairs within `SAT_PARALLEL` of parallel are skipped (their face axes stand
    for them), which can only make the value smaller.
    """
    t = pb - pa
    cross = jnp.cross(Ra.T[:, None, :], Rb.T[None, :, :]).reshape(9, 3)
    norm = jnp.linalg.norm(cross, axis=-1)
    ok = norm > SAT_PARALLEL
    axes = jnp.concatenate([Ra.T, Rb.T,
                            cross / jnp.where(ok, norm, 1.0)[:, None]])  # (15, 3)
    gap = (jnp.abs(axes @ t) - jnp.abs(axes @ Ra) @ size_a
           - jnp.abs(axes @ Rb) @ size_b)
    valid = jnp.concatenate([jnp.ones(6, bool), ok])
    return jnp.max(jnp.where(valid, gap, -jnp.inf))


def _unit_rows(v: Array, fallback: Array) -> Array:
    """Rows of ``v`` (K, 3) normalized; rows of (near) zero length -> ``fallback``."""
    n = jnp.linalg.norm(v, axis=-1, keepdims=True)
    ok = n > 1e-9
    return jnp.where(ok, v / jnp.where(ok, n, 1.0), fallback)


def box_cylinder_sat(size_box, Rb, pb, size_cyl, Rc, pc) -> Array:
    """A lower bound of the signed distance of a box and a cylinder: the largest
    gap between their projections over 67 axes, with their exact support
    functions (box ``sum_i h_i |b_i . L|``, cylinder ``h |c . L| + r |L x c|``).

    Any axis gives a lower bound (separated: the projections' gap is at most the
    distance; overlapping: their overlap is at least the shortest separating
    translation), so the value is never above the signed distance.  The axes are
    those of each kind of closest or deepest contact: the box's face normals (a
    box face against anything), the cylinder's axis (its flat caps), the box's
    edges across the axis, the radial directions through the box's vertices and
    through each edge's point nearest the axis (a vertex or edge against the
    curved side), the directions from each vertex to the nearest point of each
    rim circle (a vertex against a rim), and for an edge against a rim the common
    normal of the edge and the rim's tangent where the edge crosses the rim's
    plane (exact when the edge crosses it at the contact).  On 3,000 random poses
    the depth was never shallower than MuJoCo's and at most 0.74 mm deeper (93 %
    within 0.1 mm; `tests/test_box_distances.py`).  Closed form, about 1/4 of the
    feature search's cost.
    """
    Rl = Rc.T @ Rb  # the box's axes (columns) in the cylinder's frame
    t = Rc.T @ (pb - pc)  # the box's centre in the cylinder's frame
    r, hz = size_cyl[0], size_cyl[1]
    z = jnp.array([0.0, 0.0, 1.0], jnp.float32)
    verts = t + (_BOX_SIGNS * size_box) @ Rl.T  # (8, 3)
    ea = t + (_EDGE_START * size_box) @ Rl.T  # (12, 3) edges' starts
    de = (_EDGE_DIR * size_box) @ Rl.T  # and directions
    dxy = jnp.sum(de[:, :2] ** 2, -1)
    s = jnp.clip(jnp.where(dxy > 1e-12, -jnp.sum(ea[:, :2] * de[:, :2], -1)
                           / jnp.where(dxy > 1e-12, dxy, 1.0), 0.0), 0.0, 1.0)
    near_axis = ea + s[:, None] * de  # (12, 3)
    flat = jnp.array([1.0, 1.0, 0.0], jnp.float32)
    xy = _unit_rows(verts * flat, jnp.array([1.0, 0.0, 0.0], jnp.float32))
    rims = jnp.concatenate([r * xy + hz * z, r * xy - hz * z])  # nearest rim points
    # an edge against a rim: the common normal of the edge and the rim's tangent
    # where the edge crosses the rim's plane
    ez = jnp.where(jnp.abs(de[:, 2]) > 1e-12, de[:, 2], 1e-12)
    cross_pts = jnp.concatenate([
        ea + jnp.clip((hz - ea[:, 2]) / ez, 0.0, 1.0)[:, None] * de,
        ea + jnp.clip((-hz - ea[:, 2]) / ez, 0.0, 1.0)[:, None] * de])  # (24, 3)
    radial = _unit_rows(cross_pts * flat, jnp.array([1.0, 0.0, 0.0], jnp.float32))
    tangent = jnp.stack([-radial[:, 1], radial[:, 0], jnp.zeros(24)], -1)
    axes = jnp.concatenate([
        Rl.T, z[None], jnp.cross(Rl.T, z),
        verts * flat, near_axis * flat,
        jnp.concatenate([verts, verts]) - rims,
        jnp.cross(jnp.concatenate([de, de]), tangent),
    ])
    axes = _unit_rows(axes, z)  # (67, 3)
    lz = axes[:, 2]
    gap = (jnp.abs(axes @ t) - jnp.abs(axes @ Rl) @ size_box
           - hz * jnp.abs(lz) - r * jnp.linalg.norm(axes[:, :2], axis=-1))
    return jnp.max(gap)
