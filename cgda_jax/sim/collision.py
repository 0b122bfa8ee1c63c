"""Signed distances between a robot's geoms and themselves / the world, from genes.

`Collider` picks, once, every pair of geoms whose relative pose depends on the
evolved joints, and builds pure, jittable, vmappable functions of the genes (DoF,)
that return each pair's signed distance (metres; negative = penetration), cheap
enough to run at every kinematic sub-step of every candidate of a population.

Every geom counts whatever its ``contype``/``conaffinity`` (the built-in models set
collisions off).  The robot's body frames follow `cgda_jax.sim.chain.body_chain_ops`
(the same folding as the marker's forward kinematics, exact to float32): each needed
body's frame is computed once per posture, from its nearest moving ancestor's.
Geoms that do not move with the genes (the world's, objects', the robot's held
joints') are constants at ``robot.qpos0``'s pose (``mj_kinematics``).

Pairs (`Collider.pairs`): a geom on a moving body (one whose pose depends on a gene)
against every other geom and every `Obstacle`, if their relative pose depends on the
genes (some evolved joint lies on the tree path between their bodies), with MuJoCo's
filters: not two geoms of one weld body, not a parent/child pair of weld bodies
(``filterparent``; the world is never the parent here) unless the model disables
that filter.  Left out: ``exclude``d geom/obstacle names, invisible geoms
(``rgba`` alpha 0), and plane-plane pairs.  A mesh or an ellipsoid is checked as
its bounding box (MuJoCo's ``geom_aabb``, in the geom's own frame; `geoms.BOXED`):
the box holds the geom, so a distance is never larger than the geom's own and a move
the check accepts keeps at least that clearance (a concave or rounded part may be
refused where it would pass; an exact box mesh is checked exactly).  Height fields
and SDF geoms are not supported: they are skipped (listed in `Collider.skipped`, with
a warning), so exclude them or replace them by primitives.

Accuracy (`cgda_jax.sim.primitive_distances` has the methods): separated pairs are exact to
float32 (< 1e-5 m) for every type pair except those of a cylinder against a box or
cylinder, which sample the cylinder's side at 32 angles (overestimate by at most
0.098 x its radius, ~0.005 x in the usual face-to-side case; `Collider.error_bounds`).
Penetration values are minus the depth of the deepest point of one shape's core
(segment / point, or box edges, cylinder generators) inside the other, plus radii,
and for two boxes minus the shortest separating translation, as MuJoCo measures it:
negative exactly when the shapes overlap (MuJoCo's pair functions measure depth
their own way: signs agree in the tests, magnitudes may differ by centimetres for deep
overlaps; MuJoCo's capsule-box even reports a separation for a thin capsule that
pierces right through a box, where this module is negative).

Round geometry (``rounded=True``, the feasibility check's, `cgda_jax.sim.feasibility`):
every moving geom that is not a sphere or capsule is checked as capsules whose union
holds it (`cgda_jax.sim.geoms.round_cover`: a box, a mesh's or ellipsoid's box, as 1-4
capsules along its longest axis, side by side across its middle one; a cylinder as
its own capsule or its box's), every still geom as shapes that each hold it
(`geoms.closed_form_bounds`: a cylinder as its bounding box and that box turned 45
degrees, the larger distance counting).  So every pair is a capsule against a
capsule, a box or a plane, all closed form (no golden-section search, no separating
axes), and a distance is never larger than the geoms' own and at most
`Collider.excess` smaller (TEO's hand box: 2 capsules of radius 37.5 mm, at most
37.5 mm stricter; `tests/test_round_collision.py` checks both against MuJoCo C).
Its pairs are computed by component (`cgda_jax.sim.box_distances.dot3`): the moving
pieces' core ends from their bodies' frames, then every row of a kind at once, a
few tens of nanoseconds a pair on one CPU core
(``benchmarks/bench_check_budget.py``).

Example:
    >>> import jax.numpy as jnp
    >>> from cgda_jax import Robot, model_path
    >>> robot = Robot.from_mjcf(model_path("tiny_arm.xml"),
    ...                         ["yaw", "shoulder", "elbow"], "marker")
    >>> col = Collider(robot)
    >>> col.pair_names
    (('link1', 'base'), ('link2', 'base'))
    >>> d, k = col.min_distance(jnp.zeros(3))  # link1's end cap sits in the base
    >>> round(float(d), 3), col.pair_names[int(k)]
    (-0.015, ('link1', 'base'))
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax import Array

from cgda_jax.sim.box_distances import (
    dot3,
    mat_mul3,
    mat_vec3,
    segment_box_min,
    to_local,
)
from cgda_jax.sim.chain import body_chain_ops
from cgda_jax.sim.geoms import (
    GEOM_KINDS,
    Obstacle,
    closed_form_bounds,
    cover_excess,
    geom_name,
    geom_radius,
    geom_reach,
    geom_shape,
    quat_mat,
    round_cover,
)
from cgda_jax.sim.primitive_distances import (
    BASE_ERROR,
    KINDS,
    error_bound,
    pair_distance,
    segment_segment,
    swap_needed,
)

__all__ = ["GEOM_KINDS", "Collider", "Obstacle", "geom_radius", "geom_reach"]

_FREE = int(mujoco.mjtJoint.mjJNT_FREE)


def _pieces(kind: str, size, moving: bool, rounded: bool) -> list:
    """The shapes a table entry is checked as (`geoms.Piece`s, in its frame):
    itself; with ``rounded`` a moving geom's `round_cover` (a plane stays one)
    and a still geom's `closed_form_bounds`."""
    if rounded and moving and kind != "plane":
        return round_cover(kind, size)
    if rounded and not moving:
        return closed_form_bounds(kind, size)
    return [(kind, size, np.eye(3), np.zeros(3))]


def _frame_apply(ops, genes: Array, R: Array, p: Array) -> tuple[Array, Array]:
    """Compose folded chain ops (`cgda_jax.sim.chain.ChainOp`) onto a frame."""
    for op in ops:  # by component (box_distances.mat_mul3: fused, vectorized)
        if op.kind == "const":
            p = p + mat_vec3(R, op.vec)
            R = mat_mul3(R, op.rot)
        elif op.kind == "slide":
            p = p + mat_vec3(R, op.vec * (genes[op.gene] - op.offset))
        else:  # hinge: Rodrigues rotation about the unit axis through the origin
            angle = genes[op.gene] - op.offset
            k = op.vec
            K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]],
                         np.float32)
            R = mat_mul3(R, np.eye(3, dtype=np.float32) + jnp.sin(angle) * K
                         + (1 - jnp.cos(angle)) * (K @ K))
    return R, p


class Collider:
    """Signed distances between the robot's moving geoms and the rest, from genes.

    Args:
        robot: a `cgda_jax.sim.robot.Robot` (its model, evolved joints, ``qpos0``).
        obstacles: extra world primitives (`Obstacle`), checked against every moving
            geom.
        self_collision: include pairs of two robot geoms that both move.
        exclude: geom or obstacle names left out of every pair (e.g. a pushed box).
        only: keep just these ``(robot geom, other)`` pairs (names as in
            `pair_names`; None: every pair).
        rounded: check the round geometry (module doc): the moving geoms as
            capsules that hold them, the still ones as closed-form shapes that
            hold them; never more lenient, at most `excess` stricter.

    Attributes:
        pairs: (n_pairs, 2) geom-table indices (internal; see `pair_names`).
        pair_names: (n_pairs,) ``(robot geom, other geom or obstacle)`` names.
        pair_types: (n_pairs,) their geom types.
        error_bounds: (n_pairs,) numpy worst-case error (m) on separated geoms
            (of the shapes checked: with ``rounded`` float32 round-off).
        excess: (n_pairs,) numpy: how much smaller (m) a pair's distance may be
            than its geoms' (``rounded``; 0 otherwise): their shapes' reach
            beyond them (`cgda_jax.sim.geoms.cover_excess`; meshes beyond their
            bounding boxes not counted).
        rounded: whether the round geometry is checked.
        n_pairs: number of pairs.
        skipped: names of geoms left out for an unsupported type.
        geom_names: (G,) names of the rows of `geom_frames` (with ``rounded``
            its pieces: ``"r_hand[0]"``, ...).
        pair_reach: (n_pairs, DoF) numpy: how far (m) any point of either geom of
            a pair can move per unit change of each gene (radian / metre), an upper
            bound over every posture (the chain's lengths from the joint to the
            geom's farthest point; 0 for a geom that does not move): a change
            ``dq`` moves the pair's geoms relative to each other by at most
            ``pair_reach @ |dq|``, so their signed distance changes by at most that.

    Raises:
        KeyError: an ``exclude`` name that is neither a geom nor an obstacle.
        ValueError: two obstacles with one name, or a name clash with a geom.
    """

    def __init__(self, robot, obstacles: Sequence[Obstacle] = (), *,
                 self_collision: bool = True, exclude: Sequence[str] = (),
                 only: Sequence[tuple[str, str]] | None = None,
                 rounded: bool = False):
        m = robot.mj_model
        self.n_dof = int(robot.n_dof)
        joint_ids = [int(j) for j in robot.joint_ids]
        qpos0 = np.asarray(robot.qpos0, dtype=np.float64)
        obstacles = tuple(obstacles)
        names = [geom_name(m, g) for g in range(m.ngeom)]
        obs_names = [o.name for o in obstacles]
        if len(set(obs_names)) != len(obs_names) or set(obs_names) & set(names):
            raise ValueError(f"obstacle names {obs_names} repeat or clash with geoms")
        exclude = set([exclude] if isinstance(exclude, str) else exclude)
        unknown = exclude - set(names) - set(obs_names)
        if unknown:
            raise KeyError(f"exclude names {sorted(unknown)} are neither geoms nor "
                           f"obstacles; geoms: {names}")

        # which bodies move, and which evolved joints lie above each (free resets)
        evolved = {int(m.jnt_bodyid[j]): set() for j in joint_ids}
        for j in joint_ids:
            evolved[int(m.jnt_bodyid[j])].add(j)
        above: list[frozenset] = [frozenset()] * m.nbody
        for b in range(1, m.nbody):  # parents have smaller ids
            free = m.body_jntnum[b] == 1 and m.jnt_type[m.body_jntadr[b]] == _FREE
            base = frozenset() if free else above[int(m.body_parentid[b])]
            above[b] = base | frozenset(evolved.get(b, ()))
        moving = [bool(s) for s in above]

        data = mujoco.MjData(m)
        data.qpos[:] = qpos0
        mujoco.mj_kinematics(m, data)
        usable, self.skipped, shape = [], [], {}
        for g in range(m.ngeom):
            if names[g] in exclude or m.geom_rgba[g, 3] == 0:
                continue
            shape[g] = geom_shape(m, g)
            if shape[g] is None:
                self.skipped.append(names[g])
                continue
            usable.append(g)
        if self.skipped:
            warnings.warn(f"Collider: geoms {self.skipped} have unsupported types "
                          f"(supported: {KINDS}, and meshes and ellipsoids as their "
                          "bounding boxes); they are left out", stacklevel=2)

        # the geom table: moving geoms (frames from genes), then constant ones
        mov = [g for g in usable if moving[int(m.geom_bodyid[g])]]
        const = [g for g in usable if not moving[int(m.geom_bodyid[g])]]
        kept_obs = [o for o in obstacles if o.name not in exclude]
        table_names = [names[g] for g in mov + const] + [o.name for o in kept_obs]
        table_types = ([shape[g][0] for g in mov + const]
                       + [o.type for o in kept_obs])
        sizes = [shape[g][1] for g in mov + const]
        c_R = [data.geom_xmat[g].reshape(3, 3).copy() for g in const]
        c_p = [data.geom_xpos[g] + R @ shape[g][2] for g, R in zip(const, c_R,
                                                                   strict=True)]
        for o in kept_obs:
            R, p, size = o.frame()
            c_R.append(R)
            c_p.append(p)
            sizes.append(size)

        weld = [int(w) for w in m.body_weldid]
        parent_weld = [weld[int(m.body_parentid[w])] for w in weld]
        filter_parent = not (m.opt.disableflags
                             & int(mujoco.mjtDisableBit.mjDSBL_FILTERPARENT))

        def filtered(b1: int, b2: int) -> bool:
            w1, w2 = weld[b1], weld[b2]
            if w1 == w2:
                return True
            return (filter_parent and w1 != 0 and w2 != 0
                    and (w1 == parent_weld[w2] or w2 == parent_weld[w1]))

        pairs = []
        n_mov = len(mov)
        for i, g1 in enumerate(mov):
            b1 = int(m.geom_bodyid[g1])
            for j, g2 in enumerate(mov + const):
                b2 = int(m.geom_bodyid[g2])
                if j < n_mov and (j <= i or not self_collision):
                    continue
                if above[b1] == above[b2] or filtered(b1, b2):
                    continue
                if table_types[i] == table_types[j] == "plane":
                    continue
                pairs.append((i, j))
            for k, o in enumerate(kept_obs):
                if not table_types[i] == o.type == "plane":
                    pairs.append((i, len(mov) + len(const) + k))
        if only is not None:
            wanted = {tuple(x) for x in only}
            pairs = [(a, b) for a, b in pairs
                     if (table_names[a], table_names[b]) in wanted]
        reach = np.zeros((len(table_names), self.n_dof))
        for i, g in enumerate(mov):
            reach[i] = geom_reach(m, qpos0, joint_ids, g)
        self.pair_reach = np.asarray([reach[a] + reach[b] for a, b in pairs],
                                     np.float64).reshape(-1, self.n_dof)
        self.pairs = np.asarray(pairs, dtype=np.int32).reshape(-1, 2)
        self.n_pairs = len(pairs)
        self.pair_names = tuple((table_names[a], table_names[b]) for a, b in pairs)
        self.pair_types = tuple((table_types[a], table_types[b]) for a, b in pairs)
        self.error_bounds = np.array(
            [BASE_ERROR if rounded else
             error_bound(table_types[a], sizes[a], table_types[b], sizes[b])
             for a, b in pairs])

        # body frames: each needed body from its nearest moving ancestor
        def root_of(b: int) -> int:
            x = int(m.body_parentid[b])
            while x != 0 and not moving[x]:
                free = m.body_jntnum[x] == 1 and m.jnt_type[m.body_jntadr[x]] == _FREE
                if free:
                    return 0
                x = int(m.body_parentid[x])
            return x

        needed = set()
        todo = {int(m.geom_bodyid[mov[g]]) for pair in pairs for g in pair
                if g < n_mov}  # both sides of a self pair move
        while todo:
            b = todo.pop()
            needed.add(b)
            r = root_of(b)
            if r != 0 and r not in needed:
                todo.add(r)
        self._bodies = sorted(needed)  # parents first
        self._body_plan = []
        for b in self._bodies:
            r = root_of(b)
            ops = [op._replace(rot=op.rot.astype(np.float32),
                               vec=op.vec.astype(np.float32),
                               offset=np.float32(op.offset))
                   for op in body_chain_ops(m, qpos0, joint_ids, b, root=r)]
            self._body_plan.append((b, r, ops))
        slot = {b: k for k, b in enumerate(self._bodies)}
        used = sorted({a for a, _ in pairs} | {b for _, b in pairs if b < n_mov})
        # the table: used moving geoms, then the constants (and obstacles); each
        # entry checked as one or more pieces (`_pieces`)
        tab = [(table_types[a], sizes[a]) for a in used] + [
            (table_types[n_mov + c], sizes[n_mov + c]) for c in range(len(c_R))]
        pieces = [_pieces(k, sz, t < len(used), rounded) for t, (k, sz) in enumerate(tab)]
        self.rounded = bool(rounded)
        excess = np.asarray([
            cover_excess(k, sz, t < len(used)) if rounded else 0.0
            for t, (k, sz) in enumerate(tab)])
        piece_names = [
            [table_names[n] if len(ps) == 1 else f"{table_names[n]}[{i}]"
             for i in range(len(ps))]
            for n, ps in zip(used + list(range(n_mov, len(table_names))), pieces,
                             strict=True)]
        self.geom_names = tuple(x for names_t in piece_names for x in names_t)
        mov_body, mov_pos, mov_rot, p_R, p_p, kinds, psize = [], [], [], [], [], [], []
        for t, ps in enumerate(pieces):
            if t < len(used):
                g = mov[used[t]]
                gR = quat_mat(m.geom_quat[g])
                gp = m.geom_pos[g] + gR @ shape[g][2]
            else:
                gR, gp = c_R[t - len(used)], c_p[t - len(used)]
            for kind, size, R, pos in ps:
                kinds.append(kind)
                psize.append(size)
                if t < len(used):
                    mov_body.append(slot[int(m.geom_bodyid[mov[used[t]]])])
                    mov_rot.append(gR @ R)
                    mov_pos.append(gp + gR @ pos)
                else:
                    p_R.append(gR @ R)
                    p_p.append(gp + gR @ pos)
        self._mov_body = np.asarray(mov_body, np.int32)
        self._mov_pos = np.asarray(mov_pos, np.float32).reshape(-1, 3)
        self._mov_rot = np.asarray(mov_rot, np.float32).reshape(-1, 3, 3)
        self._const_R = np.asarray(p_R, np.float32).reshape(-1, 3, 3)
        self._const_p = np.asarray(p_p, np.float32).reshape(-1, 3)
        first = np.cumsum([0] + [len(ps) for ps in pieces])

        # rows: every piece of a pair's first entry against every piece of its
        # second, grouped by (kind a, kind b) in pair_distance's order
        remap = {a: k for k, a in enumerate(used)}
        remap.update({n_mov + c: len(used) + c for c in range(len(c_R))})
        groups: dict[tuple[str, str], list] = {}
        grid = []  # per pair: (its rows' numbers (pieces a, pieces b), join by max)
        n_rows = 0
        for n, (a, b) in enumerate(pairs):
            ta, tb = remap[a], remap[b]
            cells = np.empty((first[ta + 1] - first[ta], first[tb + 1] - first[tb]),
                             np.int64)
            for i, ia in enumerate(range(first[ta], first[ta + 1])):
                for j, ib in enumerate(range(first[tb], first[tb + 1])):
                    ka, kb, x, y = kinds[ia], kinds[ib], ia, ib
                    if swap_needed(ka, kb):
                        x, y, ka, kb = y, x, kb, ka
                    groups.setdefault((ka, kb), []).append((n_rows, x, y, psize[x],
                                                            psize[y]))
                    cells[i, j] = n_rows
                    n_rows += 1
            # a still geom's bounds hold it together: the largest distance counts
            grid.append((cells, rounded and tb >= len(used) and cells.shape[1] > 1))
        self._groups = [
            (ta, tb, np.asarray([e[1] for e in g], np.int32),
             np.asarray([e[2] for e in g], np.int32),
             np.asarray([e[3] for e in g], np.float32),
             np.asarray([e[4] for e in g], np.float32))
            for (ta, tb), g in groups.items()]
        order = np.concatenate([[e[0] for e in g] for g in groups.values()] or [[]])
        self._inverse = np.argsort(order).astype(np.int32)  # rows, in row order
        self._reduce = None
        if n_rows > len(pairs):  # some pair has several rows: (pairs, Pa, Pb)
            pa = max(c.shape[0] for c, _ in grid)
            pb = max(c.shape[1] for c, _ in grid)
            idx = np.zeros((len(pairs), pa, pb), np.int32)
            valid = np.zeros((len(pairs), pa, pb), bool)
            for n, (cells, _) in enumerate(grid):
                idx[n, :cells.shape[0], :cells.shape[1]] = self._inverse[cells]
                valid[n, :cells.shape[0], :cells.shape[1]] = True
            self._reduce = (idx, valid, np.asarray([j for _, j in grid], bool))
        self._round = self._round_plan(groups, grid, kinds, psize, mov_body,
                                       mov_pos, mov_rot, p_R, p_p) if rounded else None
        self.excess = np.asarray([excess[remap[a]] + excess[remap[b]]
                                  for a, b in pairs], np.float64)
        self.pair_reach = self.pair_reach + np.asarray(
            [excess[remap[a]] * (reach[a] > 0) + excess[remap[b]] * (reach[b] > 0)
             for a, b in pairs], np.float64).reshape(-1, self.n_dof)

    def __repr__(self) -> str:
        return f"Collider(n_pairs={self.n_pairs}, bodies={len(self._bodies)})"

    def _round_plan(self, groups, grid, kinds, psize, mov_body, mov_pos, mov_rot,
                    p_R, p_p) -> dict:
        """Constants of the rounded check (`_round_distances`): each round
        piece's core ends (a moving one's in its body's frame, a still one's in
        the world's), each row's pieces, the still boxes' and planes' world
        frames, and which rows each pair reduces."""
        n_mov = len(mov_body)
        ends = []
        for i, (kind, size) in enumerate(zip(kinds, psize, strict=True)):
            if kind != "capsule":
                ends.append(None)
                continue
            R, p = (mov_rot[i], mov_pos[i]) if i < n_mov else (p_R[i - n_mov],
                                                               p_p[i - n_mov])
            ends.append((p - R[:, 2] * size[1], p + R[:, 2] * size[1], size[0]))
        plan = {"rows": [], "n_mov": n_mov,
                "bodies": np.asarray(mov_body, np.int32),
                "c0": np.asarray([e[0] if e else np.zeros(3) for e in ends[:n_mov]],
                                 np.float32).reshape(-1, 3),
                "c1": np.asarray([e[1] if e else np.zeros(3) for e in ends[:n_mov]],
                                 np.float32).reshape(-1, 3)}
        for (ka, kb), rows in groups.items():
            if ka != "capsule" or kb not in ("capsule", "box", "plane"):
                raise ValueError(
                    f"the round check has no closed form for a {ka} against a {kb} "
                    f"(a plane on a moving body?): use the exact geometry "
                    f"(feasibility.geometry = \"exact\")")
            xs = np.asarray([e[1] for e in rows], np.int32)
            ys = np.asarray([e[2] for e in rows], np.int32)
            row = {"kind": kb, "a": xs, "ra": np.asarray([ends[x][2] for x in xs],
                                                          np.float32)}
            if kb == "capsule":
                row["b"] = ys
                row["rb"] = np.asarray([ends[y][2] for y in ys], np.float32)
            else:  # a still box or plane: its world frame, constant
                row["R"] = np.asarray([p_R[y - n_mov] for y in ys], np.float32)
                row["p"] = np.asarray([p_p[y - n_mov] for y in ys], np.float32)
                row["size"] = np.asarray([psize[y] for y in ys], np.float32)
            plan["rows"].append(row)
        # the still round pieces' ends, after the moving ones'
        plan["s0"] = np.asarray([e[0] if e else np.zeros(3) for e in ends[n_mov:]],
                                np.float32).reshape(-1, 3)
        plan["s1"] = np.asarray([e[1] if e else np.zeros(3) for e in ends[n_mov:]],
                                np.float32).reshape(-1, 3)
        return plan

    def _round_distances(self, genes: Array) -> Array:
        """The rounded check's distances (module doc), by component: the moving
        pieces' core ends from their bodies' frames, then each row's closed-form
        distance vectorized over the rows, then each pair's reduction."""
        plan = self._round
        genes = jnp.asarray(genes, jnp.float32)
        frames = {0: (jnp.eye(3, dtype=jnp.float32), jnp.zeros(3, jnp.float32))}
        for b, r, ops in self._body_plan:
            frames[b] = _frame_apply(ops, genes, *frames[r])
        if plan["n_mov"]:
            bR = jnp.stack([frames[b][0] for b in self._bodies])[plan["bodies"]]
            bp = jnp.stack([frames[b][1] for b in self._bodies])[plan["bodies"]]
            e0 = jnp.concatenate([bp + mat_vec3(bR, plan["c0"]), plan["s0"]])
            e1 = jnp.concatenate([bp + mat_vec3(bR, plan["c1"]), plan["s1"]])
        else:
            e0, e1 = jnp.asarray(plan["s0"]), jnp.asarray(plan["s1"])
        out = []
        for row in plan["rows"]:
            a0, a1 = e0[row["a"]].T, e1[row["a"]].T  # (3, rows)
            if row["kind"] == "capsule":
                d = segment_segment(a0, a1, e0[row["b"]].T, e1[row["b"]].T) - row["rb"]
            elif row["kind"] == "box":
                R, p = row["R"], row["p"]
                d = segment_box_min(row["size"].T, to_local(R.transpose(1, 2, 0), p.T, a0),
                                    to_local(R.transpose(1, 2, 0), p.T, a1))
            else:  # plane: the lower end along its normal
                n, pp = row["R"][:, :, 2].T, row["p"].T
                d = jnp.minimum(dot3(n, a0 - pp), dot3(n, a1 - pp))
            out.append(d - row["ra"])
        return self._pairs_of(jnp.concatenate(out))

    def geom_frames(self, genes: Array) -> tuple[Array, Array]:
        """World frames of the geom table (used moving geoms, then constants).

        Args:
            genes: (DoF,) evolved joint values.

        Returns:
            (rotations (G, 3, 3), centres (G, 3)), float32.
        """
        genes = jnp.asarray(genes, jnp.float32)
        if genes.shape != (self.n_dof,):
            raise ValueError(f"genes has shape {genes.shape}, expected ({self.n_dof},)")
        frames = {0: (jnp.eye(3, dtype=jnp.float32), jnp.zeros(3, jnp.float32))}
        for b, r, ops in self._body_plan:
            frames[b] = _frame_apply(ops, genes, *frames[r])
        if not len(self._bodies):
            return jnp.asarray(self._const_R), jnp.asarray(self._const_p)
        bR = jnp.stack([frames[b][0] for b in self._bodies])[self._mov_body]
        bp = jnp.stack([frames[b][1] for b in self._bodies])[self._mov_body]
        R = mat_mul3(bR, self._mov_rot)
        p = bp + mat_vec3(bR, self._mov_pos)
        return (jnp.concatenate([R, self._const_R]),
                jnp.concatenate([p, self._const_p]))

    def distances(self, genes: Array, *, exact: bool = True) -> Array:
        """Signed distance of every pair (m; negative = penetration depth).

        Args:
            genes: (DoF,) evolved joint values (radians / metres).
            exact: False gives separated box-box pairs a lower bound of their
                distance (`cgda_jax.sim.box_distances.box_box_sat`, about 8 times
                cheaper; their depth is the same) and box-cylinder pairs a lower
                bound of their signed distance (`box_cylinder_sat`, about 4 times
                cheaper, within a millimetre of the depth); every other pair is
                the same.  For checks that need the depth, not the clearance
                (`cgda_jax.sim.feasibility`).

        Returns:
            (n_pairs,) float32, in `pair_names` order.
        """
        if self._round is not None:
            return self._round_distances(genes) if self.n_pairs else jnp.zeros(
                (0,), jnp.float32)
        R, p = self.geom_frames(genes)
        out = []
        for ta, tb, ia, ib, sa, sb in self._groups:
            def one(ia, ib, sa, sb, ta=ta, tb=tb):
                return pair_distance(ta, tb, sa, R[ia], p[ia], sb, R[ib], p[ib],
                                     exact=exact)

            out.append(jax.vmap(one)(ia, ib, sa, sb))
        if not out:
            return jnp.zeros((0,), jnp.float32)
        return self._pairs_of(jnp.concatenate(out))

    def _pairs_of(self, rows: Array) -> Array:
        """Each pair's distance from its rows' (in group order): a union of pieces
        the nearest, a still geom's bounds the farthest."""
        if self._reduce is None:
            return rows[self._inverse]
        idx, valid, join_max = self._reduce
        d = rows[idx]  # (pairs, pieces a, pieces b)
        inner = jnp.where(join_max[:, None],
                          jnp.max(jnp.where(valid, d, -jnp.inf), axis=-1),
                          jnp.min(jnp.where(valid, d, jnp.inf), axis=-1))
        return jnp.min(jnp.where(valid.any(-1), inner, jnp.inf), axis=-1)

    def min_distance(self, genes: Array) -> tuple[Array, Array]:
        """The worst (smallest) signed distance and its pair's index.

        Args:
            genes: (DoF,) evolved joint values.

        Returns:
            (scalar float32, scalar int32); ``(inf, -1)`` without pairs.
        """
        return _worst(self.distances(genes)[None])

    def path_min_distance(self, path: Array) -> tuple[Array, Array]:
        """The worst signed distance over K postures and its pair's index.

        Args:
            path: (K, DoF) postures (e.g. a move's kinematic sub-steps).

        Returns:
            (scalar float32, scalar int32); ``(inf, -1)`` without pairs.
        """
        path = jnp.asarray(path, jnp.float32)
        if path.ndim != 2 or path.shape[1] != self.n_dof:
            raise ValueError(f"path has shape {path.shape}, expected (K, {self.n_dof})")
        return _worst(jax.vmap(self.distances)(path))


def _worst(d: Array) -> tuple[Array, Array]:
    """(K, n) distances -> (min over all, its pair index)."""
    if d.shape[-1] == 0:
        return jnp.float32(jnp.inf), jnp.int32(-1)
    per_pair = jnp.min(d, axis=0)
    i = jnp.argmin(per_pair).astype(jnp.int32)
    return per_pair[i], i
