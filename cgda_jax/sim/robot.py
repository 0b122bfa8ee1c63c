"""A robot model: MJCF -> MjModel -> MJX model once, and the evolved joint subset.

`Robot.from_mjcf` parses the model, resolves joint and site names to ids, reads the
joint limits and puts the MJX model on the device, all once.  Nothing here is specific
to one robot: any MJCF arm with hinge/slide joints works by naming its joints and its
marker, a site or a point fixed on a body (`cgda_jax.sim.marker`).  The start posture
is `cgda_jax.sim.posture.start_posture`.

Genes are raw ``qpos`` values of the evolved joints (radians for hinges, metres for
slides), in the order the joints are listed.

Example:
    >>> import jax.numpy as jnp
    >>> from cgda_jax import Robot, model_path
    >>> robot = Robot.from_mjcf(model_path("tiny_arm.xml"), ["yaw", "shoulder", "elbow"],
    ...                         "marker")
    >>> [round(float(v), 3) for v in robot.marker_position(jnp.zeros(3))]
    [0.0, 0.0, 0.6]
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax import Array

from cgda_jax.builtin import model_path
from cgda_jax.numerics import exact_matmuls
from cgda_jax.sim._mujoco_env import mjx_module
from cgda_jax.sim.marker import (
    MARKER_POINT_SITE,
    Marker,
    check_marker_point,
    marker_spec,
    with_marker_point,
)
from cgda_jax.sim.mjx_prep import collision_free
from cgda_jax.sim.posture import FIXED_RANGE_TOL, start_posture

__all__ = ["FIXED_RANGE_TOL", "KINEMATICS", "Robot", "model_path"]

_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)

#: Forward-kinematics back-ends: "chain" folds the marker's kinematic chain into a few
#: constant transforms (`cgda_jax.sim.chain`); "mjx" runs ``mjx.kinematics`` on the
#: whole model and reads ``site_xpos``.  Both equal ``mujoco.mj_kinematics``.
KINEMATICS = ("chain", "mjx")


def _id(
    mj_model: mujoco.MjModel, kind: mujoco.mjtObj, name: str, what: str, src
) -> int:
    idx = mujoco.mj_name2id(mj_model, kind, name)
    if idx < 0:
        names = [
            mujoco.mj_id2name(mj_model, kind, i)
            for i in range(
                mj_model.njnt if kind == mujoco.mjtObj.mjOBJ_JOINT else mj_model.nsite
            )
        ]
        hint = ("" if kind != mujoco.mjtObj.mjOBJ_SITE else " (or put the marker on "
                "a body: marker = {body = NAME, pos = [x, y, z]})")
        raise KeyError(f"{what} {name!r} not found in {src}; it has {names}{hint}")
    return idx


class Robot:
    """A MuJoCo model with a chosen set of evolved joints and a marker site.

    Build with `Robot.from_mjcf` (or `Robot.from_model` for a compiled ``MjModel``).

    Attributes:
        joint_names: (DoF,) evolved joints, in gene order.
        n_dof: number of evolved joints.
        lower, upper: (DoF,) joint limits from the model (radians / metres).
        mj_model: the compiled ``mujoco.MjModel``.
        mjx_model: the same model on the device (``mjx.put_model``, JAX impl).
        qpos0: (nq,) start posture: the model's own ``qpos0`` (or the keyframe's
            ``qpos``) with the fixed and start values applied; free and ball joints
            keep their quaternions from there, normalized (they are never evolved).
        start_genes: (DoF,) the evolved joints' values in `qpos0`, where every
            execution starts (`Simulator.init_state`).
        qpos_adr: (DoF,) qpos addresses of the evolved joints.
        joint_ids: (DoF,) joint ids of the evolved joints.
        site_id: id of the marker site.
        marker_site: its name (`MARKER_POINT_SITE` for a point on a body).
        marker: the marker as given: a site's name or ``{"body", "pos"}``.
        kinematics: "chain" or "mjx" (see `KINEMATICS`).
        object_bodies: the bodies of the world's objects (`from_world`; their
            contacts are the task's, `cgda_jax.sim.mjx_prep`).
        model_path: the MJCF file it was built from (None: a compiled model);
            world_objects, contact_geoms: `from_world`'s objects and contact geoms.
    """

    object_bodies: tuple[str, ...] = ()
    model_path: str | None = None
    world_objects: tuple[dict, ...] = ()
    contact_geoms: tuple[str, ...] = ()

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        joints: Sequence[str],
        marker_site: Marker,
        fixed: Mapping[str, float] | None = None,
        *,
        kinematics: str = "chain",
        source: str = "the model",
        keyframe: str | None = None,
        spec_factory: Callable[[], mujoco.MjSpec] | None = None,
        start: Mapping[str, float] | None = None,
    ):
        exact_matmuls()  # its programs: full float32 products on GPUs too
        joints = tuple(joints)
        if not joints:
            raise ValueError(f"no joints to evolve given for {source}")
        if len(set(joints)) != len(joints):
            raise ValueError(f"joints {list(joints)} name a joint twice ({source})")
        if kinematics not in KINEMATICS:
            raise ValueError(f"kinematics={kinematics!r}; expected one of {KINEMATICS}")
        fixed = dict(fixed or {})
        both = set(fixed) & set(joints)
        if both:
            raise ValueError(f"joints {sorted(both)} are both evolved and fixed")

        from cgda_jax.sim.model_checks import check_model_numbers

        check_model_numbers(mj_model, source)  # nan / inf / beyond float32, named
        jt = mujoco.mjtObj.mjOBJ_JOINT
        self.joint_names = joints
        self.n_dof = len(joints)
        self.joint_ids = np.array(
            [_id(mj_model, jt, j, "joint", source) for j in joints]
        )
        site, body, pos = marker_spec(marker_site)
        if body is not None:  # a point on a body: a site of our own there
            site = MARKER_POINT_SITE
            if mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_SITE, site) < 0:
                if spec_factory is None:
                    raise ValueError(
                        f"marker on body {body!r}: {source} is a compiled model "
                        "without its MJCF; build the robot with Robot.from_mjcf")
                spec_factory = with_marker_point(spec_factory, body, pos, source)
                mj_model = spec_factory().compile()
            check_marker_point(mj_model, body, pos, source)
        self.marker = marker_site if body is None else {"body": body, "pos": list(pos)}
        self.marker_site = site
        self.site_id = _id(mj_model, mujoco.mjtObj.mjOBJ_SITE, site, "site", source)
        self.mj_model = mj_model
        self.kinematics = kinematics

        lower, upper = [], []
        for name, jid in zip(joints, self.joint_ids):
            jtype = int(mj_model.jnt_type[jid])
            if jtype not in (_HINGE, _SLIDE):
                raise ValueError(
                    f"joint {name!r} in {source} is a {mujoco.mjtJoint(jtype).name}; "
                    "only hinge and slide joints can be evolved"
                )
            if mj_model.jnt_limited[jid]:
                lo, hi = (float(v) for v in mj_model.jnt_range[jid])
            elif jtype == _HINGE:
                lo, hi = -math.pi, math.pi
            else:
                raise ValueError(f"slide joint {name!r} in {source} has no range")
            lower.append(lo)
            upper.append(hi)
        # float32 on the host, one transfer each (no conversion program per shape)
        self.lower = jax.device_put(np.asarray(lower, dtype=np.float32))
        self.upper = jax.device_put(np.asarray(upper, dtype=np.float32))
        self.qpos_adr = np.asarray(mj_model.jnt_qposadr[self.joint_ids], dtype=np.int32)

        start = dict(start or {})
        qpos0 = start_posture(mj_model, joints, self.joint_ids, (lower, upper), fixed,
                              start, keyframe, source)
        self.start = start
        self.fixed = fixed
        self.keyframe = keyframe
        self.source = source
        self._spec_factory = spec_factory
        self._qpos0_np = qpos0
        self.qpos0 = jax.device_put(np.asarray(qpos0, dtype=np.float32))

        self._mjx_model = None  # mjx.put_model on first use (dynamic / "mjx" FK)
        self._data0 = None
        self._fk: Callable[[Array], Array] = self._build_fk(kinematics)

    @classmethod
    def from_mjcf(
        cls,
        path: str | pathlib.Path,
        joints: Sequence[str],
        marker_site: Marker,
        fixed: Mapping[str, float] | None = None,
        *,
        kinematics: str = "chain",
        keyframe: str | None = None,
        start: Mapping[str, float] | None = None,
    ) -> Robot:
        """Load an MJCF file and choose the evolved joints and the marker site.

        Args:
            path: the MJCF file.
            joints: (DoF,) names of the evolved joints, in gene order.
            marker_site: the marker, the point whose position the scenes read: a
                site's name (e.g. the tool tip), or a point fixed on a body,
                ``{"body": name, "pos": [x, y, z]}`` (metres in the body's frame;
                the robot adds a site `MARKER_POINT_SITE` there), or
                ``{"site": name}``.
            fixed: joint name -> value (RADIANS / metres) held during execution,
                finite and within the joint's range if it has one (a value within
                `FIXED_RANGE_TOL` of the range is clipped into it); joints neither
                evolved nor fixed stay at the model's ``qpos0`` (the joints' ``ref``;
                free and ball joints at their body's pose) or the keyframe's.
            keyframe: name of a ``<key>`` whose ``qpos`` is the start posture (its
                ball/free quaternions are normalized; a zero one is an error).
            start: evolved joint name -> start value (RADIANS / metres), over the
                model's ``qpos0`` or the keyframe (default: theirs; one of theirs
                outside the joint's range is moved into it, with a warning).
            kinematics: forward-kinematics back-end, "chain" (default, faster) or
                "mjx"; both match ``mujoco.mj_kinematics``.

        Raises:
            FileNotFoundError: the file does not exist (``~`` is expanded).
            KeyError: a joint, site or marker body is not in the model (the message
                names it).
            ValueError: bad joint types, repeats, an unknown ``kinematics``, a fixed
                value that is not finite or outside the joint's range, or a zero or
                non-finite start value (each message names the joint and value).
        """
        path = pathlib.Path(path).expanduser()
        if not path.is_file():
            raise FileNotFoundError(f"MJCF file not found: {path}")
        factory = lambda: mujoco.MjSpec.from_file(str(path))  # noqa: E731
        _, body, pos = marker_spec(marker_site)
        try:
            if body is None:
                mj_model = mujoco.MjModel.from_xml_path(str(path))
            else:  # the marker's site added once, here
                factory = with_marker_point(factory, body, pos, str(path))
                mj_model = factory().compile()
        except ValueError as err:
            raise ValueError(f"cannot load MJCF {path}: {err}") from err
        robot = cls(
            mj_model,
            joints,
            marker_site,
            fixed,
            kinematics=kinematics,
            source=str(path),
            keyframe=keyframe,
            spec_factory=factory,
            start=start,
        )
        robot.model_path = str(path.resolve())
        return robot

    @classmethod
    def from_world(
        cls,
        path: str | pathlib.Path,
        objects: Sequence[Mapping],
        joints: Sequence[str],
        marker_site: Marker,
        fixed: Mapping[str, float] | None = None,
        *,
        contact_geoms: Sequence[str] = (),
        kinematics: str = "chain",
        keyframe: str | None = None,
        start: Mapping[str, float] | None = None,
    ) -> Robot:
        """The robot's MJCF with object pieces attached (`cgda_jax.sim.world`), as one
        model; otherwise as `from_mjcf`.

        Args:
            path: the robot's MJCF file.
            objects: object dicts (``{"piece": "box", "pos": [x, y, z], ...}``, see
                `cgda_jax.sim.world.compose_world`).
            contact_geoms: robot geoms that touch the objects (e.g. the hand).
            joints, marker_site, fixed, kinematics, keyframe, start: as in
                `from_mjcf` (a marker on a body may be on an object's body).
        """
        from cgda_jax.sim.world import compose_world

        path = pathlib.Path(path).expanduser()
        objects = [dict(o) for o in objects]
        contact_geoms = tuple(contact_geoms)

        def factory() -> mujoco.MjSpec:
            return compose_world(path, objects, contact_geoms)

        names = ", ".join(str(o.get("name", o.get("piece"))) for o in objects)
        source = f"{path} + objects [{names}]"
        _, body, pos = marker_spec(marker_site)
        if body is not None:
            factory = with_marker_point(factory, body, pos, source)
        mj_model = factory().compile()
        robot = cls(mj_model, joints, marker_site, fixed, kinematics=kinematics,
                    source=source, keyframe=keyframe, spec_factory=factory,
                    start=start)
        own = compose_world(path, [], contact_geoms).compile().nbody  # then objects
        robot.object_bodies = tuple(mj_model.body(b).name
                                    for b in range(own, mj_model.nbody))
        robot.model_path = str(path.resolve())
        robot.world_objects = tuple(objects)
        robot.contact_geoms = contact_geoms
        return robot

    def _build_fk(self, kinematics: str) -> Callable[[Array], Array]:
        if kinematics == "chain":
            from cgda_jax.sim.chain import build_chain_fk

            return build_chain_fk(
                self.mj_model,
                self._qpos0_np,
                [int(j) for j in self.joint_ids],
                self.site_id,
            )
        self.make_data()  # the mjx model and data template, outside any trace
        return lambda genes: self.kinematics_data(self.qpos(genes)).site_xpos[
            self.site_id
        ]

    def __repr__(self) -> str:
        return (
            f"Robot(joints={self.joint_names}, marker={self.marker!r}, "
            f"kinematics={self.kinematics!r})"
        )

    def check_genes(self, genes: Array, what: str = "genes") -> None:
        """Raise ValueError unless ``genes`` has shape (DoF,)."""
        if tuple(jnp.shape(genes)) != (self.n_dof,):
            raise ValueError(
                f"{what} has shape {tuple(jnp.shape(genes))}, expected ({self.n_dof},) "
                f"= one value per joint {self.joint_names}"
            )

    def clip(self, genes: Array) -> Array:
        """Clip (..., DoF) genes into the joint limits."""
        return jnp.clip(genes, self.lower, self.upper)

    def qpos(self, genes: Array) -> Array:
        """Full posture: (DoF,) genes written into ``qpos0`` -> (nq,)."""
        self.check_genes(genes)
        return self.qpos0.at[self.qpos_adr].set(jnp.asarray(genes, jnp.float32))

    @property
    def mjx_model(self):
        """The ``mjx.Model`` (JAX impl), put on the device on first use: the chain
        kinematics never needs it, so neither ``mujoco.mjx`` (about 1 s to import)
        nor the model transfer is paid unless dynamic mode or "mjx" FK asks."""
        if self._mjx_model is None:
            with jax.ensure_compile_time_eval():  # concrete arrays even inside a trace
                self._mjx_model = mjx_module().put_model(  # kinematics: no contacts
                    collision_free(self.mj_model, self._spec_factory), impl="jax")
        return self._mjx_model

    def make_data(self, qpos: Array | None = None):
        """An ``mjx.Data`` (from the template made once) with ``qpos`` set."""
        if self._data0 is None:
            with jax.ensure_compile_time_eval():
                self._data0 = mjx_module().make_data(self.mjx_model, impl="jax")
        return self._data0 if qpos is None else self._data0.replace(qpos=qpos)

    def kinematics_data(self, qpos: Array):
        """``mjx.kinematics`` at a (nq,) posture (every body and site placed) ->
        ``mjx.Data``."""
        return mjx_module().kinematics(self.mjx_model, self.make_data(qpos))

    def marker_position(self, genes: Array) -> Array:
        """Marker site position (3,) in the model's root frame for (DoF,) genes."""
        self.check_genes(genes)
        return self._fk(jnp.asarray(genes, jnp.float32))

    def with_kinematics(self, kinematics: str) -> Robot:
        """The same robot with another forward-kinematics back-end."""
        other = Robot(
            self.mj_model,
            self.joint_names,
            self.marker,
            self.fixed,
            kinematics=kinematics,
            source=self.source,
            keyframe=self.keyframe,
            spec_factory=self._spec_factory,
            start=self.start,
        )
        for name in ("object_bodies", "model_path", "world_objects", "contact_geoms"):
            setattr(other, name, getattr(self, name))
        return other

    @property
    def start_genes(self) -> np.ndarray:
        """(DoF,) the evolved joints' start values (from `qpos0`), float32."""
        return self._qpos0_np[self.qpos_adr].astype(np.float32)

    def spec(self) -> mujoco.MjSpec:
        """A fresh ``mujoco.MjSpec`` of the robot's model (dynamic mode rebuilds the
        model from it, see `cgda_jax.sim.physics`).

        Raises:
            ValueError: the robot was built from a compiled ``MjModel`` without its
                source (use `Robot.from_mjcf`, or pass ``spec_factory``).
        """
        if self._spec_factory is None:
            raise ValueError(
                f"{self.source}: dynamic mode rebuilds the model with mujoco.MjSpec and "
                "needs its MJCF; build the robot with Robot.from_mjcf(path, ...)"
            )
        return self._spec_factory()
