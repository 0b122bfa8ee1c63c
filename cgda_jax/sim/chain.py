"""Closed-form forward kinematics of one site along one kinematic chain.

`build_chain_fk` walks the MuJoCo kinematic tree once, at build time, from a site's
body up to the world, and returns a pure JAX function ``genes (DoF,) -> (3,)`` that
reproduces ``mujoco.mj_kinematics``'s ``site_xpos`` for that site.  Everything that
does not depend on the evolved joints (body offsets and orientations, joint anchors,
fixed joints, joints held at their ``qpos0`` value, free or ball joints elsewhere in
the chain) is folded into a few constant rigid transforms, so the traced function is
only a handful of Rodrigues rotations and 3x3 affine maps: much cheaper than a full
``mjx.kinematics`` pass over every body of the model, which is what the population
evaluation needs when only the marker position matters.

The composition follows MuJoCo's ``mj_kinematics`` exactly (engine_core_smooth.c):
for each body ``x = x_parent * (body_pos, body_quat)``; then for each joint of the
body, in order, a hinge rotates by ``qpos - model.qpos0`` about ``jnt_axis`` through
the anchor ``jnt_pos``, a slide translates by ``(qpos - model.qpos0) * jnt_axis``, a
ball rotates by the (normalized) ``qpos`` quaternion about the anchor, and a free
joint replaces the body's pose by ``qpos``.  The site is then at
``x * site_pos``.

Example:
    >>> import mujoco
    >>> xml = '''<mujoco><worldbody><body pos="0 0 1">
    ...   <joint name="j" type="hinge" axis="0 0 1"/><geom size="0.1"/>
    ...   <site name="tip" pos="1 0 0"/></body></worldbody></mujoco>'''
    >>> m = mujoco.MjModel.from_xml_string(xml)
    >>> fk = build_chain_fk(m, m.qpos0, [0], 0)
    >>> [round(float(v), 4) + 0.0 for v in fk(jnp.array([jnp.pi / 2]))]
    [0.0, 1.0, 1.0]
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax import Array

__all__ = [
    "ChainOp",
    "body_chain_ops",
    "build_chain_fk",
    "chain_ops",
    "gene_map",
    "hinge_reach",
    "path_substeps",
]

_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
_BALL = int(mujoco.mjtJoint.mjJNT_BALL)
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)


class ChainOp(NamedTuple):
    """One step of the folded chain, applied to a point in the child frame.

    kind: "const" (``p -> rot @ p + vec``), "hinge" (rotate ``p`` about the unit
    ``vec`` by ``gene - offset``) or "slide" (``p -> p + (gene - offset) * vec``).
    gene: index into the genes vector (-1 for "const").
    """

    kind: str
    rot: np.ndarray  # (3, 3), identity unless kind == "const"
    vec: np.ndarray  # (3,)
    gene: int
    offset: float


def _quat_to_mat(q: np.ndarray, what: str = "the model") -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    norm = np.linalg.norm(q)
    if not np.isfinite(norm) or norm == 0.0:
        raise ValueError(
            f"{what}: quaternion {q.tolist()} is not a rotation (zero or not finite)"
        )
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _axis_angle_mat(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * (kx @ kx)


def _const(rot: np.ndarray, vec: np.ndarray) -> ChainOp:
    return ChainOp("const", np.asarray(rot, float), np.asarray(vec, float), -1, 0.0)


def _name(mj_model: mujoco.MjModel, jid: int) -> str:
    name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_JOINT, jid)
    return repr(name) if name else f"#{jid}"


def _resolve(mj_model: mujoco.MjModel, kind: mujoco.mjtObj, ref: int | str, what: str):
    if isinstance(ref, str):
        idx = mujoco.mj_name2id(mj_model, kind, ref)
        if idx < 0:
            raise ValueError(f"{what} {ref!r} not found in the model")
        return idx
    idx = int(ref)
    n = {"joint": mj_model.njnt, "site": mj_model.nsite}[what]
    if not 0 <= idx < n:
        raise ValueError(f"{what} id {idx} out of range [0, {n})")
    return idx


def gene_map(
    mj_model: mujoco.MjModel, qpos0: np.ndarray, joint_ids: Sequence[int | str]
) -> tuple[np.ndarray, dict[int, int]]:
    """Check ``qpos0`` and the evolved joints; ``(qpos0 as float64, joint id -> gene)``.

    Args:
        mj_model: the compiled model.
        qpos0: (nq,) posture that every joint not in ``joint_ids`` keeps.
        joint_ids: (DoF,) evolved joints (ids or names); hinge or slide only.

    Raises:
        ValueError: unknown or repeated joint, a joint that is not a hinge or slide,
            or a ``qpos0`` of the wrong size.
    """
    qpos0 = np.asarray(qpos0, dtype=np.float64)
    if qpos0.shape != (mj_model.nq,):
        raise ValueError(f"qpos0 has shape {qpos0.shape}, expected ({mj_model.nq},)")
    jids = [
        _resolve(mj_model, mujoco.mjtObj.mjOBJ_JOINT, j, "joint") for j in joint_ids
    ]
    if len(set(jids)) != len(jids):
        raise ValueError(f"joint_ids {list(joint_ids)} contain a joint twice")
    gene_of = {}
    for gene, jid in enumerate(jids):
        jtype = int(mj_model.jnt_type[jid])
        if jtype not in (_HINGE, _SLIDE):
            name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_JOINT, jid)
            raise ValueError(
                f"joint {name!r} (id {jid}) is a {mujoco.mjtJoint(jtype).name}; only "
                "hinge and slide joints can be evolved"
            )
        gene_of[jid] = gene
    return qpos0, gene_of


def _merge(ops: Sequence[ChainOp]) -> list[ChainOp]:
    merged: list[ChainOp] = []
    for op in ops:
        if op.kind == "const" and merged and merged[-1].kind == "const":
            last = merged[-1]
            merged[-1] = _const(last.rot @ op.rot, last.rot @ op.vec + last.vec)
        else:
            merged.append(op)
    return merged


def body_chain_ops(
    mj_model: mujoco.MjModel,
    qpos0: np.ndarray,
    joint_ids: Sequence[int | str],
    body_id: int,
    root: int = 0,
) -> list[ChainOp]:
    """The folded chain from the frame of body ``root`` down to body ``body_id``'s.

    Composed in order (``T = op_0 o op_1 o ... o op_k``) onto ``root``'s frame, the
    ops give the body's frame as ``mj_kinematics`` computes it (``xpos``, ``xmat``).

    Args:
        mj_model: the compiled model.
        qpos0: (nq,) posture that every joint not in ``joint_ids`` keeps.
        joint_ids: (DoF,) evolved joints (ids or names); hinge or slide only.
        body_id: the body whose frame is computed.
        root: an ancestor of ``body_id`` (0, the world, by default) whose frame the
            ops start from.

    Returns:
        The ops, consecutive constant transforms merged (empty when
        ``body_id == root``).

    Raises:
        ValueError: as `gene_map`; ``root`` not an ancestor of the body; a free
            joint between ``root`` (not the world) and the body; a zero or
            non-finite quaternion of a ball/free joint in ``qpos0`` (named).
    """
    qpos0, gene_of = gene_map(mj_model, qpos0, joint_ids)
    bodies = []  # the body up to (excluding) root
    b = int(body_id)
    while b != root:
        if b == 0:
            raise ValueError(f"body {root} is not an ancestor of body {body_id}")
        bodies.append(b)
        b = int(mj_model.body_parentid[b])

    ops: list[ChainOp] = []
    for b in reversed(bodies):  # root-most body first
        adr, num = int(mj_model.body_jntadr[b]), int(mj_model.body_jntnum[b])
        jnts = range(adr, adr + num) if num > 0 else range(0)
        if num == 1 and int(mj_model.jnt_type[adr]) == _FREE:
            if root != 0:
                raise ValueError(f"body {b} has a free joint below body {root}")
            # A free joint replaces the body's pose by qpos (world-frame, top level).
            q = qpos0[mj_model.jnt_qposadr[adr] :][:7]
            what = f"free joint {_name(mj_model, adr)} in qpos0"
            ops = [_const(_quat_to_mat(q[3:7], what), q[:3])]
            continue
        ops.append(_const(_quat_to_mat(mj_model.body_quat[b]), mj_model.body_pos[b]))
        for j in jnts:
            jtype, qadr = int(mj_model.jnt_type[j]), int(mj_model.jnt_qposadr[j])
            anchor = np.asarray(mj_model.jnt_pos[j], dtype=np.float64)
            axis = np.asarray(mj_model.jnt_axis[j], dtype=np.float64)
            ref = float(mj_model.qpos0[qadr])  # mj_kinematics measures from this
            if jtype == _FREE:
                raise ValueError(f"body {b} has a free joint beside other joints")
            if j in gene_of:
                if jtype == _HINGE:
                    ops.append(_const(np.eye(3), anchor))
                    unit = axis / np.linalg.norm(axis)
                    ops.append(ChainOp("hinge", np.eye(3), unit, gene_of[j], ref))
                    ops.append(_const(np.eye(3), -anchor))
                else:
                    ops.append(ChainOp("slide", np.eye(3), axis, gene_of[j], ref))
            elif jtype == _SLIDE:
                ops.append(_const(np.eye(3), axis * (qpos0[qadr] - ref)))
            else:
                if jtype == _HINGE:
                    rot = _axis_angle_mat(axis, qpos0[qadr] - ref)
                else:  # ball: held at its qpos0 quaternion, a constant rotation
                    rot = _quat_to_mat(
                        qpos0[qadr : qadr + 4],
                        f"ball joint {_name(mj_model, j)} in qpos0",
                    )
                ops.append(_const(np.eye(3), anchor))
                ops.append(_const(rot, np.zeros(3)))
                ops.append(_const(np.eye(3), -anchor))
    return _merge(ops)


def chain_ops(
    mj_model: mujoco.MjModel,
    qpos0: np.ndarray,
    joint_ids: Sequence[int | str],
    site_id: int | str,
) -> list[ChainOp]:
    """The folded chain from the world (first op) down to the site's point (last op).

    Args:
        mj_model: the compiled model.
        qpos0: (nq,) posture that every joint not in ``joint_ids`` keeps.
        joint_ids: (DoF,) evolved joints (ids or names); hinge or slide only.
        site_id: the site (id or name) whose world position is computed.

    Returns:
        Ops such that ``site_xpos = op_0(op_1(...op_k(0)))``; consecutive constant
        transforms are merged.

    Raises:
        ValueError: unknown joint/site, repeated joint, an evolved joint that is not a
            hinge or slide, a ``qpos0`` of the wrong size, or a zero or non-finite
            quaternion of a ball/free joint on the chain in ``qpos0`` (named).
    """
    qpos0, _ = gene_map(mj_model, qpos0, joint_ids)
    sid = _resolve(mj_model, mujoco.mjtObj.mjOBJ_SITE, site_id, "site")
    ops = body_chain_ops(mj_model, qpos0, joint_ids, int(mj_model.site_bodyid[sid]))
    return _merge([*ops, _const(np.eye(3), mj_model.site_pos[sid])])


def build_chain_fk(
    mj_model: mujoco.MjModel,
    qpos0: np.ndarray,
    joint_ids: Sequence[int | str],
    site_id: int | str,
) -> Callable[[Array], Array]:
    """A pure function from evolved joint values to the site's world position.

    Args:
        mj_model: the compiled model (read once, here; not captured).
        qpos0: (nq,) posture held by every joint not in ``joint_ids``.
        joint_ids: (DoF,) evolved hinge/slide joints, ids or names, in gene order.
            Genes are raw ``qpos`` values (radians / metres), as in ``Robot.qpos``.
        site_id: the marker site, id or name.

    Returns:
        ``fk(genes (DoF,)) -> (3,)``, float32, jit/vmap/grad-able; equal to
        ``mj_kinematics``'s ``site_xpos`` for ``qpos = qpos0`` with the genes written
        at the joints' qpos addresses. Genes of joints that are not ancestors of the
        site do not affect the result.

    Raises:
        ValueError: see `chain_ops`.
    """
    n_dof = len(joint_ids)
    ops = chain_ops(mj_model, qpos0, joint_ids, site_id)
    # Constants as float32 numpy: they become literals of the traced function.
    steps = [
        (
            op.kind,
            op.rot.astype(np.float32),
            op.vec.astype(np.float32),
            op.gene,
            np.float32(op.offset),
        )
        for op in reversed(ops)
    ]

    def fk(genes: Array) -> Array:
        if genes.shape[-1:] != (n_dof,) or genes.ndim != 1:
            raise ValueError(f"genes has shape {genes.shape}, expected ({n_dof},)")
        p = jnp.zeros(3, dtype=jnp.float32)
        for kind, rot, vec, gene, offset in steps:
            if kind == "const":
                p = jnp.asarray(rot) @ p + vec
            elif kind == "slide":
                p = p + (genes[gene] - offset) * vec
            else:  # Rodrigues rotation about the unit axis `vec`
                angle = genes[gene] - offset
                c, s = jnp.cos(angle), jnp.sin(angle)
                k = jnp.asarray(vec)
                p = p * c + jnp.cross(k, p) * s + k * (jnp.dot(k, p) * (1 - c))
        return p

    # one program where it is called eagerly (not one per operation); inlined in
    # traces
    return jax.jit(fk)


def hinge_reach(ops: Sequence[ChainOp], travel: Sequence[float]) -> float:
    """An upper bound on the distance from the site to any evolved hinge's axis,
    over every posture: for each hinge op, the lengths of the translations between
    it and the site (rotations keep lengths; slide genes add ``travel[gene]``, their
    largest displacement); the largest over the hinges (0 without hinges).

    Args:
        ops: `chain_ops` of the site.
        travel: (DoF,) the largest ``|gene - offset|`` of each gene (slides only).
    """
    bound, reach = 0.0, 0.0
    for op in reversed(ops):  # from the site up to the world
        if op.kind == "const":
            bound += float(np.linalg.norm(op.vec))
        elif op.kind == "slide":
            bound += float(np.linalg.norm(op.vec)) * float(travel[op.gene])
        else:
            reach = max(reach, bound)
    return reach


def path_substeps(robot, tolerance: float) -> int:
    """Kinematic sub-steps per move that keep the straight segments between them
    within ``tolerance`` (m) of the marker's true path, for any move between the
    joint limits (hinge chains).

    On a move that is linear in joint space, ``q(t) = q0 + t dq`` (t in [0, 1]),
    the marker's acceleration is at most ``1.5 R |dq|_1^2``, R a bound on its
    distance from every evolved hinge's axis (`hinge_reach`):
    differentiating ``sum_i dq_i a_i x (p - o_i)`` gives, per hinge i, the turn of
    its axis and anchor by the hinges before it (``|dq_i| sum_{j<i} |dq_j| R``) and
    the marker's own motion (``|dq_i| sum_j |dq_j| R``); summed, at most
    ``(|dq|_1^2 + |dq|_1^2 / 2) R``.  A chord over a parameter interval h strays
    at most ``h^2 / 8`` times the largest acceleration from the curve, so with K
    sub-steps the polyline strays at most ``sag = (3 / 16) R (|dq|_1 / K)^2``,
    where ``|dq|_1`` is at most the sum of the joint ranges:
    ``K = ceil(sum(range) sqrt(3 R / (16 tolerance)))``.  A square's distance to
    the polyline then differs from its distance to the true path by at most
    ``tolerance``.  Evolved slide joints are not covered by the bound (their
    ranges are left out of the sum).

    Args:
        robot: the `cgda_jax.sim.robot.Robot`.
        tolerance: metres (`PaintWall.path_tolerance`).
    """
    if not tolerance > 0:
        raise ValueError(f"path tolerance must be > 0 metres, got {tolerance}")
    lower, upper = np.asarray(robot.lower, float), np.asarray(robot.upper, float)
    ops = chain_ops(robot.mj_model, np.asarray(robot.qpos0, float),
                    list(robot.joint_names), robot.marker_site)
    offsets = np.zeros(robot.n_dof)
    hinge = np.zeros(robot.n_dof, bool)
    for op in ops:
        if op.kind != "const":
            offsets[op.gene] = op.offset
            hinge[op.gene] = op.kind == "hinge"
    travel = np.maximum(np.abs(lower - offsets), np.abs(upper - offsets))
    reach = hinge_reach(ops, travel)
    span = float(np.sum((upper - lower)[hinge]))
    return max(1, int(np.ceil(span * np.sqrt(3.0 * reach / (16.0 * tolerance)))))
