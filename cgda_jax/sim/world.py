"""The world: a robot MJCF plus object pieces, composed with ``mujoco.MjSpec``.

`compose_world` loads the robot's MJCF as a spec and attaches each object piece (an
MJCF file of its own) at a frame in the robot's world body with MuJoCo's model-editing
API (``MjSpec.attach``); no XML text is edited.  The robot part keeps its kinematics
exactly; the pieces only add bodies, joints, geoms and sites.  `compile_world` returns
the compiled ``mujoco.MjModel``.

Object dicts (as in a config's ``[[world.objects]]``):

``piece`` (required)
    a built-in piece, ``"box"``, ``"table"``, ``"valve"`` or ``"iron"`` (`list_pieces`; the files
    in ``models/objects/``), or the path of an MJCF file of your own.
``name``
    the object's name (default: the piece name, or the file's stem).  The piece's
    elements called ``object`` (its main body, joint, geom) take this name; the others
    are prefixed ``"<name>/"`` (e.g. the box's centre site ``"box/centre"``, the valve's
    rim site ``"valve/rim"``).  Features then read ``{"body": "box", ...}`` and
    ``{"joint": "valve", "quantity": "angle"}``.
``pos`` (required)
    ``[x, y, z]`` of the piece's frame in the world [m]: a box's centre, a table's top
    surface centre, a valve's hinge centre.
``body`` (optional)
    the name of a robot body to attach the piece to (a tool in the hand: the piece
    is welded to that body and moves with it; ``pos`` and the orientation are then
    in that body's frame); default: the world.
``euler`` / ``quat`` (optional, not both)
    the piece frame's orientation: ``[rx, ry, rz]`` in DEGREES, intrinsic x-y-z
    (MuJoCo's default ``eulerseq``), or ``[w, x, y, z]``.
piece parameters (optional; none for MJCF files of your own)
    - box: ``size`` half-sizes ``[hx, hy, hz]`` [m] (default 0.04 each), ``mass`` [kg]
      (0.3), ``friction`` sliding coefficient (0.5), ``rgba``.
    - table: ``size`` half-sizes of the top [m] (0.3, 0.4, 0.02), ``height`` from the
      surface to the feet [m] (0.6), ``friction`` (0.5), ``rgba``.
    - valve: ``radius`` of the wheel [m] (0.1), ``damping`` of the hinge [N m s/rad]
      (0.05), ``rgba``.
    - iron: a tool for a hand (``body``): ``mass`` [kg] (1.0), ``friction`` of the
      sole (0.3), ``rgba``; its force/torque sensor site ``"<name>/ft"`` sits at
      its mount, its tool point ``"<name>/tcp"`` at the centre of the sole's face.

Contacts: the pieces collide with each other through bit 1 (``contype`` and
``conaffinity`` 1: a box rests on and slides over a table); the valve's spoke and
handle have ``contype`` 0, ``conaffinity`` 2 (only the robot turns them).  The robot's
own collisions stay as its MJCF sets them (off for ``teo.xml``).  ``contact_geoms``
names the robot geoms that should touch the objects (e.g. ``("r_hand", "r_tool")``):
they get ``contype`` 2 and ``conaffinity`` 1, so they push boxes, tables and valves but
never collide with each other.  A piece whose MJCF sets the friction cone or
``impratio`` in its ``<option>`` (``CONTACT_OPTIONS``; the iron: elliptic cones,
impratio 10, so that a pressed sole holds still at any time step) sets them for the
whole world; a robot MJCF that sets them otherwise is an error naming both.

Example:
    >>> from cgda_jax.sim.robot import model_path
    >>> m = compile_world(model_path("tiny_arm.xml"), [
    ...     {"piece": "table", "pos": [0.4, 0, 0]},
    ...     {"piece": "box", "pos": [0.4, 0, 0.04], "size": [0.03, 0.03, 0.04]}])
    >>> m.body("box").name, m.site("box/centre").name, m.nq
    ('box', 'box/centre', 10)
"""

from __future__ import annotations

import os
import pathlib
from collections.abc import Callable, Mapping, Sequence

import mujoco
import numpy as np

from cgda_jax.builtin import models_dir

__all__ = ["OBJECTS_DIR", "compile_world", "compose_world", "list_pieces"]

#: Folder of the built-in object pieces.
OBJECTS_DIR = models_dir() / "objects"
#: Name of the elements of a piece file that take the object's own name.
MAIN = "object"
#: contype / conaffinity of the robot geoms named in ``contact_geoms``.
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 1
_COMMON_KEYS = ("piece", "name", "pos", "body", "euler", "quat")


def list_pieces() -> tuple[str, ...]:
    """Names of the built-in pieces (the ``*.xml`` files in `OBJECTS_DIR`)."""
    return tuple(sorted(p.stem for p in OBJECTS_DIR.glob("*.xml")))


# --- piece parameters: each sets a value on the piece's spec before attaching ------


def _vector(key: str, n: int, positive: bool = False) -> Callable:
    def check(value) -> np.ndarray:
        v = np.asarray(value, dtype=float)
        if v.shape != (n,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{key!r} must be {n} finite numbers, got {value!r}")
        if positive and np.any(v <= 0):
            raise ValueError(f"{key!r} must be positive, got {value!r}")
        return v

    return check


def _positive(key: str) -> Callable:
    def check(value) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{key!r} must be a number, got {value!r}")
        if not value > 0:
            raise ValueError(f"{key!r} must be positive, got {value!r}")
        return float(value)

    return check


def _set_rgba(spec: mujoco.MjSpec, v: np.ndarray) -> None:
    spec.geom(MAIN).rgba = v


def _set_friction(spec: mujoco.MjSpec, v: float) -> None:
    g = spec.geom(MAIN)
    g.friction = [v, *g.friction[1:]]


def _set_box_size(spec: mujoco.MjSpec, v: np.ndarray) -> None:
    spec.geom(MAIN).size = v


def _set_box_mass(spec: mujoco.MjSpec, v: float) -> None:
    spec.geom(MAIN).mass = v


def _table_layout(spec: mujoco.MjSpec, size=None, height=None) -> None:
    """Size the top (surface at z = 0) and put the legs under its corners."""
    top = spec.geom(MAIN)
    legs = [spec.geom(f"leg{k}") for k in range(1, 5)]
    if size is not None:
        top.size = size
        top.pos = [0.0, 0.0, -size[2]]
    hx, hy, hz = top.size
    if height is None:
        height = -(legs[0].pos[2] - legs[0].size[1])
    half = (height - 2 * hz) / 2
    if half <= 0:
        raise ValueError(f"'height' {height} must exceed the top's thickness {2 * hz}")
    inset = legs[0].size[0] + 0.01
    for leg, (sx, sy) in zip(legs, ((1, 1), (1, -1), (-1, 1), (-1, -1))):
        leg.size = [leg.size[0], half, 0.0]
        leg.pos = [sx * (hx - inset), sy * (hy - inset), -2 * hz - half]


def _set_iron_mass(spec: mujoco.MjSpec, v: float) -> None:
    """The sole carries the iron's mass (the handle is massless)."""
    spec.geom(MAIN).mass = v


def _set_valve_radius(spec: mujoco.MjSpec, r: float) -> None:
    spoke, handle, wheel = spec.geom(MAIN), spec.geom("handle"), spec.geom("wheel")
    spoke.size = [r / 2, *spoke.size[1:]]
    spoke.pos = [r / 2, *spoke.pos[1:]]
    handle.pos = [r, *handle.pos[1:]]
    wheel.size = [r, *wheel.size[1:]]
    rim = spec.site("rim")
    rim.pos = [r, *rim.pos[1:]]


def _set_valve_damping(spec: mujoco.MjSpec, v: float) -> None:
    joint = spec.joint(MAIN)  # MuJoCo 4: damping = [linear, polynomial terms...]
    joint.damping = [v, *joint.damping[1:]]


#: piece -> parameter -> (check, setter(spec, checked value)).
PIECE_PARAMS: dict[str, dict[str, tuple[Callable, Callable]]] = {
    "box": {
        "size": (_vector("size", 3, positive=True), _set_box_size),
        "mass": (_positive("mass"), _set_box_mass),
        "friction": (_positive("friction"), _set_friction),
        "rgba": (_vector("rgba", 4), _set_rgba),
    },
    "table": {
        "size": (_vector("size", 3, positive=True),
                 lambda s, v: _table_layout(s, size=v)),
        "height": (_positive("height"), lambda s, v: _table_layout(s, height=v)),
        "friction": (_positive("friction"), _set_friction),
        "rgba": (_vector("rgba", 4), _set_rgba),
    },
    "iron": {
        "mass": (_positive("mass"), _set_iron_mass),
        "friction": (_positive("friction"), _set_friction),
        "rgba": (_vector("rgba", 4), _set_rgba),
    },
    "valve": {
        "radius": (_positive("radius"), _set_valve_radius),
        "damping": (_positive("damping"), _set_valve_damping),
        "rgba": (_vector("rgba", 4), _set_rgba),
    },
}


# --- composing ----------------------------------------------------------------------


def _piece_file(piece) -> tuple[pathlib.Path, str | None]:
    """(MJCF path, built-in name or None) of an object's ``piece`` value."""
    if not isinstance(piece, (str, os.PathLike)):
        raise ValueError(f"'piece' must be a piece name or an MJCF path, got {piece!r}")
    text = os.fspath(piece)
    if text in list_pieces():
        return OBJECTS_DIR / f"{text}.xml", text
    path = pathlib.Path(text).expanduser()
    if path.suffix.lower() == ".xml" or os.sep in text or "/" in text:
        if not path.is_file():
            raise FileNotFoundError(f"object piece file {text!r} not found")
        return path, None
    raise ValueError(f"unknown object piece {text!r}; the built-in pieces are "
                     f"{list(list_pieces())} (in {OBJECTS_DIR}), or give an MJCF path")


def _orientation(obj: Mapping, label: str) -> np.ndarray | None:
    """The frame quaternion ``[w, x, y, z]`` from ``euler`` (degrees) or ``quat``."""
    if "euler" in obj and "quat" in obj:
        raise ValueError(f"{label}: give 'euler' or 'quat', not both")
    if "euler" in obj:
        e = _vector("euler", 3)(obj["euler"])
        q = np.zeros(4)
        mujoco.mju_euler2Quat(q, np.deg2rad(e), "xyz")
        return q
    if "quat" in obj:
        q = _vector("quat", 4)(obj["quat"])
        n = np.linalg.norm(q)
        if n == 0:
            raise ValueError(f"{label}: 'quat' must not be zero")
        return q / n
    return None


def _element_names(spec: mujoco.MjSpec) -> set[str]:
    return {e.name for coll in (spec.bodies, spec.joints, spec.geoms, spec.sites)
            for e in coll if e.name}


def _attach(world: mujoco.MjSpec, obj: Mapping, index: int, taken: set[str]) -> str:
    """Attach one object dict to ``world``; returns the object's name."""
    if not isinstance(obj, Mapping):
        raise ValueError(f"object {index}: must be a dict with 'piece' and 'pos', "
                         f"got {obj!r}")
    if "piece" not in obj:
        raise ValueError(f"object {index}: missing key 'piece' (one of "
                         f"{list(list_pieces())} or an MJCF path)")
    path, builtin = _piece_file(obj["piece"])
    params = PIECE_PARAMS.get(builtin, {})
    name = obj.get("name", builtin or path.stem)
    label = f"object {index} ({name!r}, piece {os.fspath(obj['piece'])!r})"
    bad = sorted(set(obj) - {*_COMMON_KEYS, *params})
    if bad:
        raise ValueError(f"{label}: unknown key(s) {bad}; allowed: "
                         f"{[*_COMMON_KEYS, *params]}")
    if not isinstance(name, str) or not name:
        raise ValueError(f"{label}: 'name' must be a non-empty string")
    if name in taken or any(n.startswith(f"{name}/") for n in taken):
        raise ValueError(f"{label}: the name {name!r} is already used in the world")
    if "pos" not in obj:
        raise ValueError(f"{label}: missing key 'pos' ([x, y, z] in metres)")
    pos = _vector("pos", 3)(obj["pos"])
    quat = _orientation(obj, label)

    piece = mujoco.MjSpec.from_file(str(path))  # a fresh spec: attach takes it over
    for key, (check, setter) in params.items():
        if key in obj:
            try:
                setter(piece, check(obj[key]))
            except ValueError as err:
                raise ValueError(f"{label}: {err}") from None
    _carry_contact_options(world, piece, label)
    parent = world.worldbody
    if "body" in obj:
        parent = world.body(obj["body"]) if isinstance(obj["body"], str) else None
        if parent is None:
            raise ValueError(f"{label}: 'body' {obj['body']!r} not found; the robot "
                             f"has bodies {[b.name for b in world.bodies if b.name]}")
    frame = parent.add_frame(pos=pos)
    if quat is not None:
        frame.quat = quat
    world.attach(piece, prefix=f"{name}/", frame=frame)
    for coll in (world.bodies, world.joints, world.geoms, world.sites):
        for element in coll:
            if element.name == f"{name}/{MAIN}":
                element.name = name
    taken |= _element_names(world)
    return name


#: The ``<option>`` attributes of the contact model a piece may set for the world
#: (its contacts were tuned with them): the friction cone and ``impratio``.
CONTACT_OPTIONS = ("cone", "impratio")


def _carry_contact_options(world: mujoco.MjSpec, piece: mujoco.MjSpec,
                           label: str) -> None:
    """The piece's friction cone and ``impratio``, where its MJCF changes them from
    MuJoCo's defaults (pyramidal, 1), set on ``world``; a world whose own
    differ from the defaults and from the piece's is an error."""
    default = mujoco.MjSpec().option
    for key in CONTACT_OPTIONS:
        want, have = getattr(piece.option, key), getattr(world.option, key)
        if want == getattr(default, key) or want == have:
            continue
        if have != getattr(default, key):
            raise ValueError(f"{label}: its option {key}={want!r} disagrees with the "
                             f"world's {key}={have!r}")
        setattr(world.option, key, want)


def _enable_robot_contacts(world: mujoco.MjSpec, contact_geoms: Sequence[str]) -> None:
    have = [g.name for g in world.geoms]
    for geom_name in contact_geoms:
        geom = world.geom(geom_name)
        if geom is None:
            raise KeyError(f"contact geom {geom_name!r} not found; the robot has geoms "
                           f"{[n for n in have if n]}")
        geom.contype, geom.conaffinity = ROBOT_CONTYPE, ROBOT_CONAFFINITY


def compose_world(
    robot_mjcf: str | os.PathLike,
    objects: Sequence[Mapping] = (),
    contact_geoms: Sequence[str] = (),
) -> mujoco.MjSpec:
    """The robot's MJCF with object pieces attached, as an (uncompiled) spec.

    Args:
        robot_mjcf: path of the robot's MJCF file (e.g. ``model_path("teo.xml")``).
        objects: object dicts (schema in the module docstring), attached in order.
        contact_geoms: robot geoms that touch the objects (``contype`` 2,
            ``conaffinity`` 1); empty keeps the robot's own collision settings.

    Returns:
        The composed ``mujoco.MjSpec``; add sensors or edit it further, then
        ``.compile()`` (or use `compile_world`).

    Raises:
        ValueError: an unknown piece (the message lists the built-in pieces), an
            unknown key (the message lists the allowed ones), a bad value, or a name
            used twice.
        FileNotFoundError: the robot file or a piece file does not exist.
        KeyError: an unknown contact geom (the message lists the robot's geoms).
    """
    robot_path = pathlib.Path(robot_mjcf).expanduser()
    if not robot_path.is_file():
        raise FileNotFoundError(f"robot MJCF {os.fspath(robot_mjcf)!r} not found")
    if isinstance(contact_geoms, str):
        contact_geoms = [contact_geoms]
    world = mujoco.MjSpec.from_file(str(robot_path))
    _enable_robot_contacts(world, contact_geoms)
    taken = _element_names(world)
    for index, obj in enumerate(objects):
        _attach(world, obj, index, taken)
    return world


def compile_world(
    robot_mjcf: str | os.PathLike,
    objects: Sequence[Mapping] = (),
    contact_geoms: Sequence[str] = (),
) -> mujoco.MjModel:
    """`compose_world` then compile: the world's ``mujoco.MjModel``.

    Args:
        robot_mjcf: path of the robot's MJCF file.
        objects: object dicts (schema in the module docstring).
        contact_geoms: robot geoms that touch the objects.

    Returns:
        The compiled model; ``qpos0`` holds each free object's pose (its ``pos`` and
        orientation).
    """
    return compose_world(robot_mjcf, objects, contact_geoms).compile()
