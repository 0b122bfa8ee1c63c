"""Models made ready for MJX: collisions the task does not need switched off.

``mjx.put_model`` refuses a model with a geom pair it cannot collide (a cylinder
against a mesh, a mesh with a ``margin``), whether or not the pair ever touches.
Public arm models have such pairs (meshes, a floor plane with a margin), so:

- **kinematics** (``kinematics="mjx"``, the object features of kinematic mode) never
  collide: `collision_free` is the model with every geom's ``contype`` and
  ``conaffinity`` 0 and its explicit ``<pair>``s removed (the same bodies, joints,
  sites and geoms, the same ids), which MJX always accepts;
- **physics** (``physics="mjx"``): `mjx_ready` turns off, with a ``<exclude>`` of
  their two bodies, the unsupported pairs that the task does not need, the robot's
  own pairs (against itself or a floor of its MJCF): the task's contacts are those of
  the world's objects (`cgda_jax.sim.world`), which stay; an unsupported pair that
  touches an object is an error naming it and suggesting ``physics="mujoco"``.  The
  pairs turned off are named once in a warning; MuJoCo C (``physics="mujoco"``)
  still collides them, so on such a model the two backends differ by those contacts.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable

import mujoco

from cgda_jax.logs import warn_once

__all__ = ["collision_free", "mjx_ready", "unsupported_pairs"]

_MESH = {int(mujoco.mjtGeom.mjGEOM_MESH), int(mujoco.mjtGeom.mjGEOM_HFIELD)}


def _geom(m: mujoco.MjModel, g: int) -> str:
    name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g)
    kind = mujoco.mjtGeom(int(m.geom_type[g])).name.removeprefix("mjGEOM_").lower()
    return f"{name or f'geom #{g}'} ({kind})"


def unsupported_pairs(m: mujoco.MjModel) -> list[tuple[int, int, str]]:
    """The geom pairs MJX would collide but cannot: ``(geom1, geom2, why)``, with
    why "collisions" (no MJX function for the two types) or "margin" (a mesh or
    height field with a margin / gap); [] when MJX accepts every pair."""
    from mujoco.mjx._src import collision_driver  # MJX's own pair enumeration

    out = []
    for g1, g2, ip in collision_driver.geom_pairs(m):
        t1, t2 = (int(t) for t in m.geom_type[[g1, g2]])
        if not collision_driver.has_collision_fn(t1, t2):
            out.append((int(g1), int(g2), "collisions"))
            continue
        margin = (m.pair_margin[ip] if ip != -1
                  else m.geom_margin[g1] + m.geom_margin[g2])
        if _MESH & {t1, t2} and margin:
            out.append((int(g1), int(g2), "margin"))
    return out


def collision_free(m: mujoco.MjModel,
                   spec_factory: Callable[[], mujoco.MjSpec] | None = None
                   ) -> mujoco.MjModel:
    """``m`` without collisions (for kinematics): a copy with every geom's
    ``contype`` / ``conaffinity`` 0; explicit pairs are removed through
    ``spec_factory`` (the model's spec), else ``m`` itself is returned."""
    if m.npair:
        if spec_factory is None:
            return m
        spec = spec_factory()
        for pair in list(spec.pairs):
            spec.delete(pair)
        out = spec.compile()
        if out.ngeom != m.ngeom or out.nbody != m.nbody or out.nsite != m.nsite:
            return m  # not the same model: keep the original
    else:
        out = copy.deepcopy(m)
    out.geom_contype[:] = 0
    out.geom_conaffinity[:] = 0
    return out


def mjx_ready(m: mujoco.MjModel, spec: mujoco.MjSpec, object_bodies: Iterable[str],
              source: str) -> mujoco.MjModel:
    """``m`` (compiled from ``spec``) with its unsupported pairs that touch no
    object body excluded (see the module doc); ``m`` itself when there are none.

    Raises:
        ValueError: an unsupported pair touches an object (the task needs it); the
            message names it and suggests ``physics="mujoco"``.
    """
    bad = unsupported_pairs(m)
    if not bad:
        return m
    objects = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n)
               for n in object_bodies} - {-1}
    needed = [(g1, g2, why) for g1, g2, why in bad
              if {int(m.geom_bodyid[g1]), int(m.geom_bodyid[g2])} & objects]
    if needed:
        g1, g2, why = needed[0]
        what = ("collisions between these types" if why == "collisions"
                else "a mesh's margin / gap")
        raise ValueError(
            f"physics=\"mjx\": MJX does not implement {what}, and the task needs "
            f"the pair {_geom(m, g1)} - {_geom(m, g2)} of {source} (it touches an "
            f"object; {len(needed)} such pair(s)); use physics=\"mujoco\" (MuJoCo C), "
            "or give those geoms primitive shapes (capsules, boxes) and no margin")
    bodies = list(spec.bodies)
    names, excluded = [], set()
    for g1, g2, _ in bad:
        b1, b2 = sorted((int(m.geom_bodyid[g1]), int(m.geom_bodyid[g2])))
        names.append(f"{_geom(m, g1)} - {_geom(m, g2)}")
        if (b1, b2) in excluded:
            continue
        excluded.add((b1, b2))
        for b in (b1, b2):
            if not bodies[b].name:
                bodies[b].name = f"cgda_body_{b}"
        spec.add_exclude(bodyname1=bodies[b1].name, bodyname2=bodies[b2].name)
    out = spec.compile()
    out.opt.disableflags = m.opt.disableflags
    out.opt.timestep = m.opt.timestep
    warn_once(f"physics=\"mjx\": {source}: MJX cannot collide {len(names)} geom "
              f"pair(s) the task does not need, turned off: {', '.join(names[:6])}"
              f"{', ...' if len(names) > 6 else ''} (MuJoCo C, physics=\"mujoco\", "
              "keeps them)")
    return out
