"""The geoms the collision checks work with: the supported kinds, extra obstacles
that are not in the model (`Obstacle`), and bounds on where a geom can be
(`geom_radius`, `geom_reach`: how far it moves per unit of each gene)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from cgda_jax.sim.chain import body_chain_ops
from cgda_jax.sim.primitive_distances import KINDS

__all__ = ["BOXED", "GEOM_KINDS", "Obstacle", "geom_bound", "geom_ids", "geom_name",
           "geom_radius", "geom_reach", "geom_shape", "quat_mat"]

#: MuJoCo geom type id -> the supported kind name (`primitive_distances.KINDS`).
GEOM_KINDS = {int(getattr(mujoco.mjtGeom, f"mjGEOM_{k.upper()}")): k for k in KINDS}
_SIZE_LEN = {"sphere": 1, "capsule": 2, "box": 3, "cylinder": 2, "plane": 0}
#: Geom types the collision check replaces by their bounding box (MuJoCo's
#: ``geom_aabb``, in the geom's own frame): it holds the geom, so a distance to it is
#: never larger than to the geom itself and the check stays on the safe side.
BOXED = {int(mujoco.mjtGeom.mjGEOM_MESH): "mesh",
         int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): "ellipsoid"}


def geom_name(m: mujoco.MjModel, g: int) -> str:
    """Geom ``g``'s name, or ``"geom#<id>"`` for an unnamed one (as the collision
    check and the reports name it)."""
    return mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom#{g}"


def geom_ids(m: mujoco.MjModel) -> dict[str, int]:
    """`geom_name` -> geom id, for every geom of ``m``."""
    return {geom_name(m, g): g for g in range(m.ngeom)}


def geom_shape(m: mujoco.MjModel, g: int) -> tuple[str, np.ndarray, np.ndarray] | None:
    """Geom ``g`` as the collision check sees it: ``(kind, size (3,), centre)``,
    ``centre`` the shape's offset in the geom's frame; a primitive as it is, a mesh
    or an ellipsoid as its bounding box (`BOXED`); None for the others (height
    fields, SDFs)."""
    t = int(m.geom_type[g])
    if t in GEOM_KINDS:
        return GEOM_KINDS[t], np.asarray(m.geom_size[g], float), np.zeros(3)
    if t in BOXED:
        aabb = np.asarray(m.geom_aabb[g], float)
        return "box", aabb[3:].copy(), aabb[:3].copy()
    return None


@dataclass(frozen=True)
class Obstacle:
    """An extra world primitive that is not in the model (e.g. a paint board).

    Attributes:
        name: its name in `Collider.pair_names` (and for ``exclude``).
        type: "box", "sphere", "capsule", "cylinder" or "plane".
        pos: (3,) centre in the robot's world frame (m).
        size: MuJoCo's size for the type: box half sizes (3,), sphere (r,), capsule
            and cylinder (r, half length) along the local z axis; plane: ignored
            (the half-space below its local z = 0).
        quat: (4,) orientation [w, x, y, z] (normalized here).
    """

    name: str
    type: str
    pos: tuple
    size: tuple = ()
    quat: tuple = (1.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        if self.type not in KINDS:
            raise ValueError(f"obstacle {self.name!r}: type {self.type!r} is not one "
                             f"of {KINDS}")
        n = _SIZE_LEN[self.type]
        size = np.asarray(self.size, float).ravel()
        if size.size < n or not np.all(np.isfinite(size)) or np.any(size[:n] <= 0):
            raise ValueError(f"obstacle {self.name!r}: a {self.type} needs {n} "
                             f"positive size value(s), got {self.size!r}")
        if np.shape(self.pos) != (3,) or not np.all(np.isfinite(self.pos)):
            raise ValueError(f"obstacle {self.name!r}: pos must be 3 finite numbers")
        q = np.asarray(self.quat, float)
        if q.shape != (4,) or not np.linalg.norm(q) > 0:
            raise ValueError(f"obstacle {self.name!r}: quat must be 4 numbers, not 0")

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rotation (3, 3), centre (3,), size (3,)) as float64."""
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, np.asarray(self.quat, float) / np.linalg.norm(self.quat))
        size = np.zeros(3)
        n = np.asarray(self.size, float).ravel()[:3]
        size[: n.size] = n
        return R.reshape(3, 3), np.asarray(self.pos, float), size


def geom_radius(kind: int, size: np.ndarray) -> float:
    """Radius (m) of a ball about a geom's centre that holds the geom."""
    kind = GEOM_KINDS.get(int(kind), "")
    size = np.asarray(size, float)
    if kind == "sphere":
        return float(size[0])
    if kind == "capsule":
        return float(size[0] + size[1])
    if kind in ("box", "cylinder"):
        return float(np.linalg.norm(size[:3] if kind == "box" else size[:2]))
    return 0.0


def geom_bound(m: mujoco.MjModel, g: int) -> float:
    """Radius (m) of a ball about geom ``g``'s frame origin that holds it: MuJoCo's
    ``geom_rbound`` for a mesh or ellipsoid, else `geom_radius`."""
    if int(m.geom_type[g]) in BOXED:
        return float(m.geom_rbound[g])
    return geom_radius(m.geom_type[g], m.geom_size[g])


def geom_reach(m: mujoco.MjModel, qpos0: np.ndarray, joint_ids: Sequence[int],
               geom: int) -> np.ndarray:
    """(DoF,) how far (m) any point of ``geom`` moves per unit change of each gene,
    bounded over every posture: for a hinge, the sum of the chain's translation
    lengths from the joint to the geom's centre plus the geom's radius (a bound on
    the point's distance from the axis); for a slide, 1 (and its travel adds to
    the hinges above it)."""
    ops = body_chain_ops(m, qpos0, joint_ids, int(m.geom_bodyid[geom]))
    bound = float(np.linalg.norm(m.geom_pos[geom])) + geom_bound(m, geom)
    lo = m.jnt_range[np.asarray(joint_ids)]
    travel = np.maximum(np.abs(lo[:, 0]), np.abs(lo[:, 1]))
    out = np.zeros(len(joint_ids))
    for op in reversed(ops):
        if op.kind == "const":
            bound += float(np.linalg.norm(op.vec))
        elif op.kind == "hinge":
            out[op.gene] = max(out[op.gene], bound)
        else:  # slide: unit motion per metre; its travel lengthens what is above
            out[op.gene] = max(out[op.gene], 1.0)
            bound += float(travel[op.gene] + abs(op.offset))
    return out


def quat_mat(q) -> np.ndarray:
    """(3, 3) rotation matrix of a quaternion [w, x, y, z] (MuJoCo's ``mju_quat2Mat``)."""
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, np.asarray(q, float))
    return R.reshape(3, 3)
