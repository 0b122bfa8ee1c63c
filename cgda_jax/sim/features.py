"""Object features declared by name: body/site positions and yaw, joint angles.

A feature is what CGDA tracks of the world (paper section 2): an object's position or
orientation, a valve's angle.  Declare each one by name with a `FeatureSpec` (or its
dict form, as in a config's ``[[scene.features]]``); a `FeatureSet` resolves the names
to ids once against a compiled ``mujoco.MjModel`` and evaluates every feature of ONE
world state as a flat ``(F,)`` vector, in the order declared:

- `FeatureSet.from_data` reads a kinematics result (``mjx.Data`` after
  ``mjx.kinematics`` / ``mjx.forward``, or any object with the same fields, e.g. a
  ``mujoco.MjData`` whose arrays are wrapped as JAX arrays);
- `FeatureSet.from_sensordata` reads a ``(nsensordata,)`` vector of MuJoCo sensors that
  `add_sensors` put in the model spec beforehand (``framepos`` / ``framequat`` /
  ``jointpos``).  This is how a MuJoCo C rollout (``mujoco.rollout.rollout(...)``
  returning ``sensordata``) or ``mjx.forward`` gives features.

Both are pure ``jnp`` functions for one example: ``jax.jit`` and ``jax.vmap`` them at
the call site.

Quantities (units in `FeatureSet.feature_names`):

=========  =====================  ===========================================
kind       quantity               values
=========  =====================  ===========================================
body/site  ``xyz`` / ``xy``       world position, 3 or 2 values [m]
body/site  ``x`` / ``y`` / ``z``  one coordinate [m]
body/site  ``yaw``                rotation about world z [rad]: the heading
                                  ``atan2(R[1,0], R[0,0])`` of the frame's x
                                  axis (R its rotation matrix)
joint      ``angle``              hinge joint ``qpos`` [rad]
joint      ``position``           slide joint ``qpos`` [m]
=========  =====================  ===========================================

A body's position is its frame origin (``xpos``, not the centre of mass ``xipos``).

Example:
    >>> import mujoco, jax.numpy as jnp
    >>> m = mujoco.MjModel.from_xml_string(
    ...     '<mujoco><worldbody><body name="box" pos="0.5 0 0.1"><freejoint/>'
    ...     '<geom type="box" size=".1 .1 .1"/></body></worldbody></mujoco>')
    >>> fs = FeatureSet(m, [{"body": "box", "quantity": "xy"}])
    >>> fs.feature_names
    ('box.x [m]', 'box.y [m]')
    >>> d = mujoco.MjData(m); mujoco.mj_forward(m, d)
    >>> [round(float(v), 3) for v in fs.from_data(d)]
    [0.5, 0.0]
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import jax.numpy as jnp
import mujoco
import numpy as np
from jax import Array

__all__ = ["FRAME_COLUMNS", "FeatureSet", "FeatureSpec", "add_sensors"]

KINDS = ("body", "site", "joint")
#: quantity -> (columns, unit) for bodies and sites; column = axis index or "yaw".
_FRAME_QUANTITIES: dict[str, tuple[tuple[int | str, ...], str]] = {
    "xyz": ((0, 1, 2), "m"),
    "xy": ((0, 1), "m"),
    "x": ((0,), "m"),
    "y": ((1,), "m"),
    "z": ((2,), "m"),
    "yaw": (("yaw",), "rad"),
}
#: joint quantity -> (the joint type it needs, unit).
_JOINT_QUANTITIES = {
    "angle": (mujoco.mjtJoint.mjJNT_HINGE, "rad"),
    "position": (mujoco.mjtJoint.mjJNT_SLIDE, "m"),
}
#: body/site quantity -> its columns: an axis index (0, 1, 2) or "yaw".
FRAME_COLUMNS = {q: cols for q, (cols, _) in _FRAME_QUANTITIES.items()}
QUANTITIES = {
    "body": tuple(_FRAME_QUANTITIES),
    "site": tuple(_FRAME_QUANTITIES),
    "joint": tuple(_JOINT_QUANTITIES),
}
_JOINT_TYPE_NAMES = {0: "free", 1: "ball", 2: "slide", 3: "hinge"}
_AXES = "xyz"
_PLURAL = {"body": "bodies", "site": "sites", "joint": "joints"}
_OBJ = {
    "body": mujoco.mjtObj.mjOBJ_BODY,
    "site": mujoco.mjtObj.mjOBJ_SITE,
    "joint": mujoco.mjtObj.mjOBJ_JOINT,
}


@dataclasses.dataclass(frozen=True)
class FeatureSpec:
    """One declared feature: a quantity of a named body, site or joint.

    Attributes:
        kind: ``"body"``, ``"site"`` or ``"joint"``.
        name: the element's name in the model.
        quantity: for bodies and sites ``"xyz"``, ``"xy"``, ``"x"``, ``"y"``, ``"z"``
            or ``"yaw"``; for joints ``"angle"`` (hinge) or ``"position"`` (slide).

    Raises:
        ValueError: an unknown kind or a quantity that the kind does not have.
    """

    kind: str
    name: str
    quantity: str

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"feature kind {self.kind!r} unknown; use one of {KINDS}")
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(
                f"feature name must be a non-empty string, got {self.name!r}"
            )
        if self.quantity not in QUANTITIES[self.kind]:
            raise ValueError(
                f"{self.kind} {self.name!r}: quantity {self.quantity!r} unknown; "
                f"a {self.kind} has {QUANTITIES[self.kind]}"
            )

    @classmethod
    def from_dict(cls, entry: Mapping) -> FeatureSpec:
        """Build from the config form, e.g. ``{"body": "box", "quantity": "xy"}``.

        Args:
            entry: exactly one of the keys ``body``, ``site``, ``joint`` (its value
                the element's name) and ``quantity``.

        Raises:
            ValueError: an unknown key, none or several of body/site/joint, or no
                quantity (the message names the key), or not a mapping.
        """
        if isinstance(entry, FeatureSpec):
            return entry
        if not isinstance(entry, Mapping):
            raise ValueError(f"a feature must be a dict like {{'body': 'box', "
                             f"'quantity': 'xy'}}, got {entry!r}")
        bad = sorted(set(entry) - {*KINDS, "quantity"})
        if bad:
            raise ValueError(f"feature {dict(entry)!r}: unknown key(s) {bad}; "
                             f"allowed: 'body' | 'site' | 'joint', 'quantity'")
        kinds = [k for k in KINDS if k in entry]
        if len(kinds) != 1:
            raise ValueError(f"feature {dict(entry)!r}: give exactly one of the keys "
                             f"'body', 'site', 'joint' (got {kinds or 'none'})")
        if "quantity" not in entry:
            raise ValueError(f"feature {dict(entry)!r}: missing key 'quantity' "
                             f"(a {kinds[0]} has {QUANTITIES[kinds[0]]})")
        return cls(kinds[0], entry[kinds[0]], entry["quantity"])

    def columns(self) -> tuple[str, ...]:
        """Column names without units, e.g. ``("box.x", "box.y")``."""
        if self.kind == "joint":
            return (f"{self.name}.{self.quantity}",)
        cols = _FRAME_QUANTITIES[self.quantity][0]
        return tuple(f"{self.name}.{c if c == 'yaw' else _AXES[c]}" for c in cols)

    @property
    def unit(self) -> str:
        """The unit of every column of this feature (``"m"`` or ``"rad"``)."""
        table = _JOINT_QUANTITIES if self.kind == "joint" else _FRAME_QUANTITIES
        return table[self.quantity][1]


def _as_specs(specs: Sequence[FeatureSpec | Mapping]) -> tuple[FeatureSpec, ...]:
    if isinstance(specs, (FeatureSpec, Mapping)):
        specs = [specs]
    out = tuple(FeatureSpec.from_dict(s) for s in specs)
    if not out:
        raise ValueError("no features declared")
    return out


def _sensor_plan(spec: FeatureSpec, prefix: str) -> tuple[str, int, int]:
    """(sensor name, sensor type, object type) carrying one feature."""
    kind, name = spec.kind, spec.name
    if kind == "joint":
        return f"{prefix}joint:{name}:pos", mujoco.mjtSensor.mjSENS_JOINTPOS, _OBJ[kind]
    # XBODY is the body frame (xpos / xquat); BODY would be the inertial frame.
    obj = mujoco.mjtObj.mjOBJ_XBODY if kind == "body" else _OBJ[kind]
    if spec.quantity == "yaw":
        return f"{prefix}{kind}:{name}:quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT, obj
    return f"{prefix}{kind}:{name}:pos", mujoco.mjtSensor.mjSENS_FRAMEPOS, obj


def add_sensors(
    spec: mujoco.MjSpec,
    features: Sequence[FeatureSpec | Mapping],
    prefix: str = "cgda_",
) -> list[str]:
    """Add the MuJoCo sensors that carry ``features`` to a model spec, in place.

    A position (``xyz``/``xy``/``x``/``y``/``z``) becomes a ``framepos`` sensor (body
    frame for bodies), ``yaw`` a ``framequat`` sensor, a joint feature a ``jointpos``
    sensor; several features of one element share a sensor, and sensors already in the
    spec are kept.  After ``spec.compile()``, build `FeatureSet` on the compiled model
    with the same ``prefix`` to read them with `FeatureSet.from_sensordata`.

    Args:
        spec: the model spec (e.g. from `cgda_jax.sim.world.compose_world`).
        features: `FeatureSpec` or dict entries.
        prefix: start of the added sensors' names.

    Returns:
        The names of the sensors added (those already present are not repeated).
    """
    existing = {s.name for s in spec.sensors}
    added = []
    for f in _as_specs(features):
        name, stype, otype = _sensor_plan(f, prefix)
        if name in existing:
            continue
        spec.add_sensor(name=name, type=stype, objtype=otype, objname=f.name)
        existing.add(name)
        added.append(name)
    return added


def _names(m: mujoco.MjModel, kind: str) -> list[str]:
    count = {"body": m.nbody, "site": m.nsite, "joint": m.njnt}[kind]
    return [
        mujoco.mj_id2name(m, _OBJ[kind], i) or f"<unnamed {i}>" for i in range(count)
    ]


def _resolve(m: mujoco.MjModel, spec: FeatureSpec) -> int:
    """The element id of ``spec``, checking its kind (KeyError / ValueError)."""
    i = mujoco.mj_name2id(m, _OBJ[spec.kind], spec.name)
    if i < 0:
        raise KeyError(f"{spec.kind} {spec.name!r} not found; the model has "
                       f"{_PLURAL[spec.kind]} {_names(m, spec.kind)}")
    if spec.kind == "joint":
        need, _ = _JOINT_QUANTITIES[spec.quantity]
        jtype = int(m.jnt_type[i])
        if jtype != int(need):
            raise ValueError(
                f"joint {spec.name!r} is a {_JOINT_TYPE_NAMES[jtype]} joint; quantity "
                f"{spec.quantity!r} needs a {_JOINT_TYPE_NAMES[int(need)]} joint "
                f"(use a body feature of its body for a free or ball joint)"
            )
    return i


def _yaw_from_quat(q: Array) -> Array:
    """Heading of the rotated x axis for quaternions ``(..., 4)`` (w, x, y, z)."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return jnp.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class FeatureSet:
    """Features of one world state, names resolved to ids once.

    Args:
        mj_model: the compiled model (robot + objects).
        specs: `FeatureSpec` or dict entries (``{"body": "box", "quantity": "xy"}``).
        sensor_prefix: prefix of the sensors `add_sensors` added; when the model has
            them `from_sensordata` is available (``has_sensors``).

    Attributes:
        specs: the declared features.
        feature_names: one name per column with its unit, e.g.
            ``("box.x [m]", "box.y [m]", "valve.angle [rad]")``.
        units: the unit of each column.
        n_features: F, the number of columns.
        has_sensors: whether the model holds every sensor `from_sensordata` needs.

    Raises:
        KeyError: an unknown body/site/joint name (the message lists the model's).
        ValueError: a malformed spec or a quantity of the wrong joint type.
    """

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        specs: Sequence[FeatureSpec | Mapping],
        sensor_prefix: str = "cgda_",
    ) -> None:
        self.specs = _as_specs(specs)
        self.sensor_prefix = sensor_prefix
        names, units = [], []
        # Columns grouped by what they read; `_order` puts them back in declared order.
        groups: dict[str, list] = {g: [] for g in
                                   ("body_pos", "site_pos", "body_yaw", "site_yaw",
                                    "qpos")}
        sens: dict[str, list] = {"pos": [], "quat": []}
        slots: list[tuple[str, int]] = []  # (group, index in group) per column
        sensor_ok = True
        for spec in self.specs:
            i = _resolve(mj_model, spec)
            names += [f"{c} [{spec.unit}]" for c in spec.columns()]
            units += [spec.unit] * len(spec.columns())
            s_name, _, _ = _sensor_plan(spec, sensor_prefix)
            s_id = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_SENSOR, s_name)
            sensor_ok &= s_id >= 0
            adr = int(mj_model.sensor_adr[s_id]) if s_id >= 0 else 0
            if spec.kind == "joint":
                slots.append(("qpos", len(groups["qpos"])))
                groups["qpos"].append(int(mj_model.jnt_qposadr[i]))
                sens["pos"].append(adr)
                continue
            for c in _FRAME_QUANTITIES[spec.quantity][0]:
                if c == "yaw":
                    group = f"{spec.kind}_yaw"
                    groups[group].append(i)
                    sens["quat"].append([adr + k for k in range(4)])
                else:
                    group = f"{spec.kind}_pos"
                    groups[group].append((i, c))
                    sens["pos"].append(adr + c)
                slots.append((group, len(groups[group]) - 1))
        self.feature_names = tuple(names)
        self.units = tuple(units)
        self.n_features = len(names)
        self.has_sensors = bool(sensor_ok)
        self._groups = {
            g: np.asarray(v, dtype=np.int32).reshape(len(v), 2 if "_pos" in g else 1)
            for g, v in groups.items()
        }
        order = ("body_pos", "site_pos", "body_yaw", "site_yaw", "qpos")
        start = dict(zip(order, np.cumsum([0] + [len(groups[g]) for g in order])))
        self._order = np.asarray([start[g] + k for g, k in slots], dtype=np.int32)
        # sensordata: position-like columns (framepos, jointpos) then yaw columns.
        self._sens_pos = np.asarray(sens["pos"], dtype=np.int32)
        self._sens_quat = np.asarray(sens["quat"], dtype=np.int32).reshape(-1, 4)
        sens_slots, n_pos, n_yaw = [], 0, 0
        for g, _ in slots:
            if g.endswith("_yaw"):
                sens_slots.append(("yaw", n_yaw))
                n_yaw += 1
            else:
                sens_slots.append(("pos", n_pos))
                n_pos += 1
        self._sens_order = np.asarray(
            [k if g == "pos" else n_pos + k for g, k in sens_slots], dtype=np.int32
        )

    def __repr__(self) -> str:
        return f"FeatureSet({list(self.feature_names)})"

    def from_data(self, data) -> Array:
        """Features of one kinematics result.

        Args:
            data: an ``mjx.Data`` (after ``mjx.kinematics`` or ``mjx.forward``) or any
                object with its fields: ``xpos (nbody, 3)``, ``xmat (nbody, 3, 3)`` or
                ``(nbody, 9)`` (else ``xquat (nbody, 4)``), ``site_xpos (nsite, 3)``,
                ``site_xmat (nsite, 3, 3)`` or ``(nsite, 9)``, ``qpos (nq,)``.  Only
                the fields the declared features use are read.

        Returns:
            ``(F,)`` features in declared order (the dtype of ``data``).
        """
        g = self._groups
        parts = []
        if len(g["body_pos"]):
            body = jnp.asarray(data.xpos)
            parts.append(body[g["body_pos"][:, 0], g["body_pos"][:, 1]])
        if len(g["site_pos"]):
            site = jnp.asarray(data.site_xpos)
            parts.append(site[g["site_pos"][:, 0], g["site_pos"][:, 1]])
        if len(g["body_yaw"]):
            ids = g["body_yaw"][:, 0]
            if getattr(data, "xmat", None) is not None:
                parts.append(_yaw_from_mat(data.xmat, ids))
            else:
                parts.append(_yaw_from_quat(jnp.asarray(data.xquat)[ids]))
        if len(g["site_yaw"]):
            parts.append(_yaw_from_mat(data.site_xmat, g["site_yaw"][:, 0]))
        if len(g["qpos"]):
            parts.append(jnp.asarray(data.qpos)[g["qpos"][:, 0]])
        return jnp.concatenate(parts)[self._order]

    def from_sensordata(self, sensordata: Array) -> Array:
        """Features from one sensor vector of a model with `add_sensors`' sensors.

        Args:
            sensordata: ``(nsensordata,)``, e.g. ``mjx.Data.sensordata`` after
                ``mjx.forward`` or one step of ``mujoco.rollout.rollout``'s output.

        Returns:
            ``(F,)`` features in declared order.

        Raises:
            ValueError: the model this set was built on lacks the sensors.
        """
        if not self.has_sensors:
            raise ValueError(
                "the model has no feature sensors: call add_sensors(spec, features, "
                f"prefix={self.sensor_prefix!r}) on its spec before compiling, and "
                "build the FeatureSet on the compiled model"
            )
        s = jnp.asarray(sensordata)
        parts = [s[self._sens_pos]]
        if len(self._sens_quat):
            parts.append(_yaw_from_quat(s[self._sens_quat]))
        return jnp.concatenate(parts)[self._sens_order]


def _yaw_from_mat(xmat, ids: np.ndarray) -> Array:
    """``atan2(R[1,0], R[0,0])`` of rotation matrices (flat 9 or 3x3) ``ids``."""
    flat = jnp.reshape(jnp.asarray(xmat), (-1, 9))[ids]
    return jnp.arctan2(flat[:, 3], flat[:, 0])
