"""The geoms the collision checks work with: the supported kinds, extra obstacles
that are not in the model (`Obstacle`), bounds on where a geom can be
(`geom_radius`, `geom_reach`: how far it moves per unit of each gene), and the
conservative shapes of the feasibility check's round geometry (`round_cover`: the
capsules whose union holds a moving geom; `closed_form_bounds`: shapes whose
intersection holds a still one, each of a kind with a closed-form distance to a
capsule)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from cgda_jax.sim.chain import body_chain_ops
from cgda_jax.sim.primitive_distances import KINDS

__all__ = ["BOXED", "COVER_SPREAD", "GEOM_KINDS", "MAX_COVER", "Obstacle",
           "closed_form_bounds", "cover_excess", "geom_bound", "geom_ids", "geom_name",
           "geom_radius", "geom_reach", "geom_shape", "quat_mat", "round_cover"]

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


#: The most capsules `round_cover` lays side by side over a flat box.
MAX_COVER = 4
#: `round_cover` splits a box's middle axis into pieces no wider than this many
#: times its thinnest half size, so each capsule's radius is at most
#: ``sqrt(1 + COVER_SPREAD**2)`` = 1.25 times the half thickness.
COVER_SPREAD = 0.75

#: A piece of a conservative shape: (kind, size (3,), rotation (3, 3) and centre
#: (3,) in the geom's frame).
Piece = tuple[str, np.ndarray, np.ndarray, np.ndarray]


def _axes_frame(long: int, mid: int) -> np.ndarray:
    """A right-handed rotation whose local z is axis ``long`` and x axis ``mid``."""
    R = np.zeros((3, 3))
    R[long, 2] = 1.0
    R[mid, 0] = 1.0
    R[:, 1] = np.cross(R[:, 2], R[:, 0])
    return R


def _box_capsules(half: np.ndarray, n: int | None = None) -> list[Piece]:
    """``n`` capsules (default: by `COVER_SPREAD`, at most `MAX_COVER`) along a
    box's longest axis, side by side across its middle one: each holds a slab of
    the box (its core runs the box's full length through the slab's centre, its
    radius reaches the slab's corners), so their union holds the box."""
    half = np.asarray(half, float)
    thin, mid, long = np.argsort(half, kind="stable")
    a, b, c = half[long], half[mid], half[thin]
    if n is None:
        n = int(min(MAX_COVER, max(1, math.ceil(b / (COVER_SPREAD * c) - 1e-9))))
    r = math.hypot(b / n, c)
    R = _axes_frame(int(long), int(mid))
    out = []
    for k in range(n):
        p = np.zeros(3)
        p[mid] = -b + (2 * k + 1) * b / n
        out.append(("capsule", np.array([r, a, 0.0]), R, p))
    return out


def cover_excess(kind: str, size, moving: bool = True) -> float:
    """How far (m) the check's shape of a geom reaches beyond it, at most: its
    `round_cover` (``moving``) or its `closed_form_bounds`.  Every point of the
    shape lies within this of the geom, so a pair's distance between the shapes
    is at most the two excesses smaller than between the geoms (0 for a sphere, a
    capsule, and a still box or plane)."""
    size = np.asarray(size, float)
    if kind in ("sphere", "capsule", "plane") or not moving and kind == "box":
        return 0.0
    if not moving:  # a cylinder: its bounding box's corners
        return float(size[0] * (math.sqrt(2) - 1.0))
    pieces = round_cover(kind, size)
    # each core lies inside the geom's box; a cylinder's box's corners lie
    # r (sqrt 2 - 1) beyond it (its own capsule's core lies inside it)
    radius = max(float(s[0]) for _, s, _, _ in pieces)
    boxed = kind == "cylinder" and pieces[0][1][0] != size[0]
    return radius + (float(size[0]) * (math.sqrt(2) - 1) if boxed else 0.0)


def round_cover(kind: str, size) -> list[Piece]:
    """Capsules (and spheres, as capsules of half length 0) whose union holds a
    geom of ``kind`` (a `GEOM_KINDS` name, meshes and ellipsoids as their boxes) and
    MuJoCo ``size``: a distance to them is never larger than to the geom.

    A sphere or capsule is itself.  A box becomes `_box_capsules` (a flat box
    several side by side, so each radius stays within 1.25 times the half
    thickness).  A cylinder becomes the capsule of its radius and half height or
    the capsules of its bounding box, whichever reaches out less
    (`cover_excess`).  A plane has no cover (ValueError)."""
    size = np.asarray(size, float)
    eye, zero = np.eye(3), np.zeros(3)
    if kind == "sphere":
        return [("capsule", np.array([size[0], 0.0, 0.0]), eye, zero)]
    if kind == "capsule":
        return [("capsule", np.array([size[0], size[1], 0.0]), eye, zero)]
    if kind == "box":
        return _box_capsules(size[:3])
    if kind == "cylinder":
        own = [("capsule", np.array([size[0], size[1], 0.0]), eye, zero)]
        boxed = _box_capsules(np.array([size[0], size[0], size[1]]))
        # the box's corners lie r (sqrt 2 - 1) beyond the cylinder
        if boxed[0][1][0] + size[0] * (math.sqrt(2) - 1) < size[0]:
            return boxed
        return own
    raise ValueError(f"no round cover of a {kind}")


def closed_form_bounds(kind: str, size) -> list[Piece]:
    """Shapes that each hold a geom that does not move, each a sphere, capsule,
    box or plane (closed-form distances to a capsule): a cylinder as two boxes,
    its bounding box and the same turned 45 degrees about its axis; a sphere as a
    capsule of half length 0; the others as they are.  The largest of the
    distances to them is a distance never larger than to the geom, and at most
    `cover_excess` smaller (a cylinder's: ``r (sqrt 2 - 1)``, its bounding box's
    corners; the turned box takes most of that back, about half where measured,
    `tests/test_round_collision.py`)."""
    size = np.asarray(size, float)
    eye, zero = np.eye(3), np.zeros(3)
    if kind == "sphere":
        return [("capsule", np.array([size[0], 0.0, 0.0]), eye, zero)]
    if kind == "cylinder":
        box = np.array([size[0], size[0], size[1]])
        c = s = math.sqrt(0.5)
        turned = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return [("box", box, eye, zero), ("box", box, turned, zero)]
    return [(kind, size.copy(), eye, zero)]
