"""Checks of a compiled MuJoCo model before anything runs on it.

- `check_model_numbers`: every number of the model (positions, orientations,
  masses, inertias, sizes, joint ranges, gains, options) is finite and within
  float32, the precision the simulations run in. MuJoCo itself accepts ``nan`` and
  ``inf`` in an MJCF file (it only warns about NaN); a simulation of such a model
  gives NaN features or a diverged evolution much later.
- `check_kinematic`: what kinematic mode cannot honour. Kinematic mode sets the
  evolved joints and places the bodies by forward kinematics, nothing else; so it
  refuses (naming the element and pointing to dynamic mode, where the physics
  honours them) an active equality constraint (joint coupling, connect, weld,
  tendon) that involves an evolved joint or a body one moves; a limited tendon over
  one; a feature that no evolved joint moves: a free object, a valve's joint
  (only contact could move them), so it would never change; and a force or torque
  (only the physics gives one).

Tendons without a range only act through forces (springs, dampers, actuators),
which kinematic mode has none of: they are allowed.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

__all__ = ["check_kinematic", "check_model_numbers", "moved_bodies"]

_FLOAT32_MAX = float(np.finfo(np.float32).max)

#: Field prefix -> (object type for its name, count attribute).
_OBJECTS = {
    "body": (mujoco.mjtObj.mjOBJ_BODY, "nbody"),
    "jnt": (mujoco.mjtObj.mjOBJ_JOINT, "njnt"),
    "geom": (mujoco.mjtObj.mjOBJ_GEOM, "ngeom"),
    "site": (mujoco.mjtObj.mjOBJ_SITE, "nsite"),
    "actuator": (mujoco.mjtObj.mjOBJ_ACTUATOR, "nu"),
    "tendon": (mujoco.mjtObj.mjOBJ_TENDON, "ntendon"),
    "eq": (mujoco.mjtObj.mjOBJ_EQUALITY, "neq"),
    "cam": (mujoco.mjtObj.mjOBJ_CAMERA, "ncam"),
    "light": (mujoco.mjtObj.mjOBJ_LIGHT, "nlight"),
    "mesh": (mujoco.mjtObj.mjOBJ_MESH, "nmesh"),
    "sensor": (mujoco.mjtObj.mjOBJ_SENSOR, "nsensor"),
    "key": (mujoco.mjtObj.mjOBJ_KEY, "nkey"),
    "mat": (mujoco.mjtObj.mjOBJ_MATERIAL, "nmat"),
    "pair": (mujoco.mjtObj.mjOBJ_PAIR, "npair"),
}
#: Fields an MJCF file sets directly, reported before the fields derived from them
#: (geoms before the masses and inertias MuJoCo derives from their sizes).
_GIVEN = (
    "geom_size", "geom_pos", "geom_quat", "geom_friction", "body_pos", "body_quat",
    "jnt_pos", "jnt_axis", "jnt_range", "jnt_stiffness", "jnt_margin", "site_pos",
    "site_quat", "site_size", "dof_damping", "dof_armature", "dof_frictionloss",
    "actuator_gainprm", "actuator_ctrlrange", "actuator_forcerange", "actuator_gear",
    "tendon_range", "tendon_stiffness", "qpos0", "qpos_spring", "key_qpos",
    "key_ctrl", "eq_data", "body_mass", "body_inertia", "body_ipos", "body_iquat",
)
_WORDS = {"jnt": "joint", "eq": "equality", "cam": "camera", "mat": "material",
          "dof": "joint", "key": "keyframe"}


def _name(m: mujoco.MjModel, prefix: str, row: int) -> str:
    if prefix == "dof":  # degrees of freedom are named by their joint
        prefix, row = "jnt", int(m.dof_jntid[row])
    obj, _ = _OBJECTS[prefix]
    name = mujoco.mj_id2name(m, obj, row)
    return f"{_WORDS.get(prefix, prefix)} {name!r}" if name else \
        f"{_WORDS.get(prefix, prefix)} {row} (unnamed)"


def _first_bad(values: np.ndarray) -> tuple[int, ...] | None:
    bad = ~np.isfinite(values) | (np.abs(values) > _FLOAT32_MAX)
    if not bad.any():
        return None
    return tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), values.shape))


def check_model_numbers(m: mujoco.MjModel, source: str = "the model") -> None:
    """Every float of `m` (and of ``m.opt``) is finite and within float32.

    Raises:
        ValueError: ``"model <source>: body 'link1' has body_pos = [0, 0, nan] ..."``
            naming the element, the field and the value.
    """
    for field in ("timestep", "gravity", "wind", "magnetic", "density", "viscosity",
                  "impratio", "tolerance", "o_margin", "o_solref", "o_solimp"):
        value = np.atleast_1d(np.asarray(getattr(m.opt, field, 0.0), float))
        if _first_bad(value) is not None:
            raise ValueError(f"model {source}: option {field} = {value.tolist()} is "
                             "not a finite float32 number")
    # the numbers an MJCF file gives first, then what MuJoCo derives from them
    rank = {f: i for i, f in enumerate(_GIVEN)}
    fields = sorted(dir(m), key=lambda f: (rank.get(f, len(rank)), f))
    for field in fields:
        if field.startswith("_"):
            continue
        values = getattr(m, field, None)
        if not isinstance(values, np.ndarray) or values.dtype.kind != "f" \
                or values.size == 0:
            continue
        where = _first_bad(values)
        if where is None:
            continue
        prefix = field.split("_", 1)[0]
        count = {"dof": "nv"}.get(prefix) or _OBJECTS.get(prefix, (None, ""))[1]
        row = values[where[0]]
        if count and values.shape[0] == getattr(m, count, -1):
            what = _name(m, prefix, where[0])
        else:
            what = f"entry {list(where)}"
        shown = np.asarray(row).tolist()
        raise ValueError(f"model {source}: {what} has {field} = {shown}, not a finite "
                         "float32 number (nan, inf or beyond 3.4e38)")


def moved_bodies(m: mujoco.MjModel, joint_ids: Sequence[int]) -> np.ndarray:
    """(nbody,) whether each body moves when the joints `joint_ids` move (it or an
    ancestor carries one of them)."""
    moved = np.zeros(m.nbody, bool)
    moved[[int(m.jnt_bodyid[j]) for j in joint_ids]] = True
    for b in range(1, m.nbody):  # parents come before their children
        moved[b] |= moved[int(m.body_parentid[b])]
    return moved


def _eq_bodies(m: mujoco.MjModel, k: int) -> list[int]:
    objtype = int(m.eq_objtype[k])
    ids = [int(m.eq_obj1id[k]), int(m.eq_obj2id[k])]
    if objtype == int(mujoco.mjtObj.mjOBJ_SITE):
        return [int(m.site_bodyid[i]) for i in ids if i >= 0]
    return [i for i in ids if i >= 0]  # bodies; world (0) when obj2 is unset


def _tendon_joints_bodies(m: mujoco.MjModel, t: int) -> tuple[set[int], set[int]]:
    joints, bodies = set(), set()
    adr, num = int(m.tendon_adr[t]), int(m.tendon_num[t])
    for w in range(adr, adr + num):
        kind, obj = int(m.wrap_type[w]), int(m.wrap_objid[w])
        if kind == int(mujoco.mjtWrap.mjWRAP_JOINT):
            joints.add(obj)
        elif kind == int(mujoco.mjtWrap.mjWRAP_SITE):
            bodies.add(int(m.site_bodyid[obj]))
        elif kind in (int(mujoco.mjtWrap.mjWRAP_SPHERE),
                      int(mujoco.mjtWrap.mjWRAP_CYLINDER)):
            bodies.add(int(m.geom_bodyid[obj]))
    return joints, bodies


_DYNAMIC = ("use mode='dynamic' (robot.mode = \"dynamic\"), where the physics "
            "honours it")


def check_kinematic(m: mujoco.MjModel, joint_ids: Sequence[int],
                    features: Sequence | None = None, marker_site: int | None = None
                    ) -> None:
    """What kinematic mode with the evolved joints `joint_ids` cannot honour.

    Args:
        m: the compiled model (robot + objects).
        joint_ids: the evolved joints.
        features: the scene's declared features (`cgda_jax.sim.features.FeatureSpec`)
            read from the world, if any.
        marker_site: the site a marker scene reads (None: not read).

    Raises:
        ValueError: starting "kinematic mode", naming the constraint, tendon or
            feature and suggesting dynamic mode.
    """
    joint_ids = [int(j) for j in joint_ids]
    moved = moved_bodies(m, joint_ids)
    evolved = set(joint_ids)
    def jname(j: int) -> str:
        return mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)

    def bname(b: int) -> str:
        return mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"#{b}"
    for k in range(m.neq):
        if not m.eq_active0[k]:
            continue
        kind = mujoco.mjtEq(int(m.eq_type[k])).name.removeprefix("mjEQ_").lower()
        if kind == "joint":
            ties = [int(j) for j in (m.eq_obj1id[k], m.eq_obj2id[k]) if j >= 0]
            hit = [jname(j) for j in ties if j in evolved]
            involved = f"ties joints {[jname(j) for j in ties]}"
        elif kind == "tendon":
            ties = [int(t) for t in (m.eq_obj1id[k], m.eq_obj2id[k]) if t >= 0]
            hit = [jname(j) for t in ties for j in _tendon_joints_bodies(m, t)[0]
                   if j in evolved]
            hit += [bname(b) for t in ties for b in _tendon_joints_bodies(m, t)[1]
                    if moved[b]]
            involved = "ties tendons"
        elif kind in ("connect", "weld"):
            names = [bname(b) for b in _eq_bodies(m, k)]
            hit = [bname(b) for b in _eq_bodies(m, k) if moved[b]]
            involved = f"holds bodies {names}"
        else:  # flex and other kinds: nothing kinematic mode could place
            hit, involved = ["(all)"], "a deformable or other constraint"
        if hit:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_EQUALITY, k) or f"#{k}"
            raise ValueError(
                f"kinematic mode cannot honour the {kind} equality constraint "
                f"{name!r} ({involved}; evolved or moved by an evolved joint: {hit}): "
                f"the "
                f"postures it evaluates would break it; {_DYNAMIC}, or remove it")
    for t in range(m.ntendon):
        if not m.tendon_limited[t]:
            continue
        joints, bodies = _tendon_joints_bodies(m, t)
        hit = [jname(j) for j in joints if j in evolved] + [
            bname(b) for b in bodies if moved[b]]
        if hit:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_TENDON, t) or f"#{t}"
            lo, hi = (float(v) for v in m.tendon_range[t])
            raise ValueError(
                f"kinematic mode cannot honour tendon {name!r} limited to [{lo:g}, "
                f"{hi:g}] over {hit}: the postures it evaluates could break the "
                f"limit; {_DYNAMIC}")
    for spec in features or ():
        _check_feature_moves(m, spec, evolved, moved, jname)
    if marker_site is not None and not moved[int(m.site_bodyid[marker_site])]:
        site = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, marker_site)
        raise ValueError(f"kinematic mode: the marker site {site!r} is on a body that "
                         "none of the evolved joints moves, so the scene's features "
                         "never change; evolve a joint of its chain")


def _check_feature_moves(m, spec, evolved, moved, jname) -> None:
    obj = {"body": mujoco.mjtObj.mjOBJ_BODY, "site": mujoco.mjtObj.mjOBJ_SITE,
           "joint": mujoco.mjtObj.mjOBJ_JOINT}[spec.kind]
    i = mujoco.mj_name2id(m, obj, spec.name)
    if i < 0:
        return  # named by the feature set's own check
    if getattr(spec, "is_wrench", False):
        raise ValueError(
            f"kinematic mode: feature site {spec.name!r} ({spec.quantity}) is a force "
            "or torque: only the physics gives one. Use mode='dynamic' (robot.mode "
            "= \"dynamic\")")
    if spec.kind == "joint":
        if i in evolved:
            return
        why = f"joint {spec.name!r} is not evolved"
    else:
        body = i if spec.kind == "body" else int(m.site_bodyid[i])
        if moved[body]:
            return
        joints = [jname(j) for j in sorted(evolved)]
        why = (f"none of the evolved joints {joints} moves body "
               f"{mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body)!r}")
    raise ValueError(
        f"kinematic mode: feature {spec.kind} {spec.name!r} ({spec.quantity}) never "
        f"changes: {why}; only contact or the physics could move it. Use "
        "mode='dynamic' (robot.mode = \"dynamic\")")
