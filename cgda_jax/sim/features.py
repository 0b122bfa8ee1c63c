"""Object features declared by name: body/site positions and yaw, joint angles,
forces and torques at a site.

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
  ``jointpos`` / ``force`` / ``torque``).  This is how a MuJoCo C rollout
  (``mujoco.rollout.rollout(...)`` returning ``sensordata``) or ``mjx.forward``
  gives features.  Forces and torques exist only here (they come from the physics:
  dynamic mode); `from_data` refuses them.

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
site       ``force`` / ``fx`` ..  force [N] (3 or 1 values) of a MuJoCo
           ``fz``                 ``force`` sensor on the site
site       ``torque`` / ``tx`` .. torque [N m] of a ``torque`` sensor
           ``tz``
=========  =====================  ===========================================

A body's position is its frame origin (``xpos``, not the centre of mass ``xipos``).

Forces and torques (a force/torque sensor, e.g. TEO's wrist jr3): MuJoCo's ``force``
and ``torque`` sensors give the interaction between the site's body and its parent:
the force (torque about the site) that the PARENT exerts on the subtree rooted at
the site's body (everything from the sensor outwards: the tool, what it touches).
Put the site on a body of its own between the wrist and the tool (as a real wrist
sensor sits).  ``frame = "sensor"`` (default): components in the site's frame, as a
real sensor reports them; ``frame = "world"``: rotated into the world frame (the
site's orientation is read by a ``framequat`` sensor added for it).  A tool hanging
still with the site's z axis up reads ``fz = +m g`` (m the mass beyond the sensor);
pressing it down on a table makes ``fz`` fall, negative once the push exceeds the
weight.

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

__all__ = ["FRAMES", "FRAME_COLUMNS", "FeatureSet", "FeatureSpec", "add_sensors"]

KINDS = ("body", "site", "joint")
#: site quantity -> (sensor, columns of its (3,) vector, unit): forces and torques.
_WRENCH_QUANTITIES: dict[str, tuple[str, tuple[int, ...], str]] = {
    "force": ("force", (0, 1, 2), "N"),
    "fx": ("force", (0,), "N"),
    "fy": ("force", (1,), "N"),
    "fz": ("force", (2,), "N"),
    "torque": ("torque", (0, 1, 2), "N m"),
    "tx": ("torque", (0,), "N m"),
    "ty": ("torque", (1,), "N m"),
    "tz": ("torque", (2,), "N m"),
}
#: frames a force or torque can be expressed in.
FRAMES = ("sensor", "world")
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
    "site": (*_FRAME_QUANTITIES, *_WRENCH_QUANTITIES),
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
            or ``"yaw"``; for sites also ``"force"``, ``"fx"``, ``"fy"``, ``"fz"``,
            ``"torque"``, ``"tx"``, ``"ty"``, ``"tz"`` (a force/torque sensor on
            the site; dynamic mode); for joints ``"angle"`` (hinge) or
            ``"position"`` (slide).
        frame: forces and torques only: ``"sensor"`` (the site's frame, default)
            or ``"world"``.
        scale: the feature's values are multiplied by it (default 1): a weight
            between features of different units in the strategies' point
            distances, e.g. 1/300 for a force beside positions in metres (the
            CGDA authors' iron fitness counts 300 N like 1 m).  The column's unit
            says so (``"ft.fz [300 N]"``: the force in units of 300 N, so that
            -0.1 is -30 N; `scaled_unit`).

    Raises:
        ValueError: an unknown kind, a quantity that the kind does not have, or a
            frame on a quantity that is not a force or torque.
    """

    kind: str
    name: str
    quantity: str
    frame: str = "sensor"
    scale: float = 1.0

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
        if isinstance(self.scale, bool) or not isinstance(self.scale, (int, float)) \
                or not np.isfinite(self.scale) or self.scale <= 0:
            raise ValueError(f"{self.kind} {self.name!r}: scale must be a positive "
                             f"number, got {self.scale!r}")
        if self.frame not in FRAMES:
            raise ValueError(f"{self.kind} {self.name!r}: frame {self.frame!r} "
                             f"unknown; use one of {FRAMES}")
        if self.frame != "sensor" and not self.is_wrench:
            raise ValueError(f"{self.kind} {self.name!r}: a frame is only for forces "
                             f"and torques, not quantity {self.quantity!r}")

    @property
    def is_wrench(self) -> bool:
        """Whether this is a force or torque (read from the physics only)."""
        return self.kind == "site" and self.quantity in _WRENCH_QUANTITIES

    @classmethod
    def from_dict(cls, entry: Mapping) -> FeatureSpec:
        """Build from the config form, e.g. ``{"body": "box", "quantity": "xy"}``.

        Args:
            entry: exactly one of the keys ``body``, ``site``, ``joint`` (its value
                the element's name) and ``quantity``; ``frame`` for a force or
                torque (``{"site": "wrist_ft", "quantity": "fz"}``).

        Raises:
            ValueError: an unknown key, none or several of body/site/joint, or no
                quantity (the message names the key), or not a mapping.
        """
        if isinstance(entry, FeatureSpec):
            return entry
        if not isinstance(entry, Mapping):
            raise ValueError(f"a feature must be a dict like {{'body': 'box', "
                             f"'quantity': 'xy'}}, got {entry!r}")
        bad = sorted(set(entry) - {*KINDS, "quantity", "frame", "scale"})
        if bad:
            raise ValueError(f"feature {dict(entry)!r}: unknown key(s) {bad}; "
                             f"allowed: 'body' | 'site' | 'joint', 'quantity', "
                             f"'frame', 'scale'")
        kinds = [k for k in KINDS if k in entry]
        if len(kinds) != 1:
            raise ValueError(f"feature {dict(entry)!r}: give exactly one of the keys "
                             f"'body', 'site', 'joint' (got {kinds or 'none'})")
        if "quantity" not in entry:
            raise ValueError(f"feature {dict(entry)!r}: missing key 'quantity' "
                             f"(a {kinds[0]} has {QUANTITIES[kinds[0]]})")
        return cls(kinds[0], entry[kinds[0]], entry["quantity"],
                   entry.get("frame", "sensor"), entry.get("scale", 1.0))

    def columns(self) -> tuple[str, ...]:
        """Column names without units, e.g. ``("box.x", "box.y")``."""
        return self._raw_columns()

    def labels(self) -> tuple[str, ...]:
        """Column names with the values' unit, e.g. ``("box.x [m]",)``,
        ``("ft.fz [300 N]",)`` (`scaled_unit`)."""
        return tuple(f"{c} [{self.scaled_unit}]" for c in self.columns())

    @property
    def scaled_unit(self) -> str:
        """The unit of the values (`unit` times 1 / `scale`): ``"N"``, or ``"300 N"``
        for a force with scale 1/300 (a value -0.1 is -30 N), ``"0.4 m"`` for a
        position with scale 2.5."""
        if self.scale == 1:
            return self.unit
        return f"{1.0 / self.scale:.6g} {self.unit}"

    def _raw_columns(self) -> tuple[str, ...]:
        if self.kind == "joint":
            return (f"{self.name}.{self.quantity}",)
        if self.is_wrench:
            sensor, cols, _ = _WRENCH_QUANTITIES[self.quantity]
            tail = "_world" if self.frame == "world" else ""
            return tuple(f"{self.name}.{sensor[0]}{_AXES[c]}{tail}" for c in cols)
        cols = _FRAME_QUANTITIES[self.quantity][0]
        return tuple(f"{self.name}.{c if c == 'yaw' else _AXES[c]}" for c in cols)

    @property
    def unit(self) -> str:
        """The unit of every column of this feature (``"m"``, ``"rad"``, ``"N"`` or
        ``"N m"``)."""
        if self.is_wrench:
            return _WRENCH_QUANTITIES[self.quantity][2]
        table = _JOINT_QUANTITIES if self.kind == "joint" else _FRAME_QUANTITIES
        return table[self.quantity][1]


def _as_specs(specs: Sequence[FeatureSpec | Mapping]) -> tuple[FeatureSpec, ...]:
    if isinstance(specs, (FeatureSpec, Mapping)):
        specs = [specs]
    out = tuple(FeatureSpec.from_dict(s) for s in specs)
    if not out:
        raise ValueError("no features declared")
    return out


_WRENCH_SENSORS = {"force": mujoco.mjtSensor.mjSENS_FORCE,
                   "torque": mujoco.mjtSensor.mjSENS_TORQUE}


def _sensor_plans(spec: FeatureSpec, prefix: str) -> list[tuple[str, int, int]]:
    """The sensors carrying one feature: its own, then (a force or torque in the
    world frame) the site's ``framequat``."""
    if not spec.is_wrench:
        return [_sensor_plan(spec, prefix)]
    sensor = _WRENCH_QUANTITIES[spec.quantity][0]
    own = (f"{prefix}site:{spec.name}:{sensor}", _WRENCH_SENSORS[sensor],
           _OBJ["site"])
    if spec.frame == "sensor":
        return [own]
    return [own, _sensor_plan(FeatureSpec("site", spec.name, "yaw"), prefix)]


def _sensor_plan(spec: FeatureSpec, prefix: str) -> tuple[str, int, int]:
    """(sensor name, sensor type, object type) carrying one position-like feature."""
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
    sensor, a force or torque a ``force`` / ``torque`` sensor on its site (plus the
    site's ``framequat`` in the world frame); several features of one element share
    a sensor, and sensors already in the spec are kept.  After ``spec.compile()``, build `FeatureSet` on the compiled model
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
        for name, stype, otype in _sensor_plans(f, prefix):
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
        sens: dict[str, list] = {"pos": [], "quat": [], "wrench": [],
                                 "wrench_quat": []}
        slots: list[tuple[str, int]] = []  # (group, index in group) per column
        sensor_ok = True
        for spec in self.specs:
            i = _resolve(mj_model, spec)
            names += spec.labels()
            units += [spec.scaled_unit] * len(spec.columns())
            adrs = []
            for s_name, _, _ in _sensor_plans(spec, sensor_prefix):
                s_id = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_SENSOR, s_name)
                sensor_ok &= s_id >= 0
                adrs.append(int(mj_model.sensor_adr[s_id]) if s_id >= 0 else 0)
            adr = adrs[0]
            if spec.is_wrench:  # sensordata only: (vector start, column, quat start)
                for c in _WRENCH_QUANTITIES[spec.quantity][1]:
                    slots.append(("wrench", len(sens["wrench"])))
                    sens["wrench"].append([adr + k for k in range(3)])
                    sens["wrench_quat"].append(
                        [adrs[1] + k for k in range(4)] if len(adrs) > 1 else
                        [-1] * 4)
                    groups.setdefault("wrench_col", []).append(c)
                continue
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
        scales = np.concatenate([[s.scale] * len(s.columns()) for s in self.specs])
        #: (F,) the declared scales per column (None: all 1)
        self._scales = None if np.all(scales == 1) else scales.astype(np.float32)
        self.feature_names = tuple(names)
        self.units = tuple(units)
        self.n_features = len(names)
        self.has_sensors = bool(sensor_ok)
        #: the declared forces and torques (only `from_sensordata` reads them)
        self.wrenches = tuple(s for s in self.specs if s.is_wrench)
        wrench_col = groups.pop("wrench_col", [])
        self._groups = {
            g: np.asarray(v, dtype=np.int32).reshape(len(v), 2 if "_pos" in g else 1)
            for g, v in groups.items()
        }
        order = ("body_pos", "site_pos", "body_yaw", "site_yaw", "qpos")
        start = dict(zip(order, np.cumsum([0] + [len(groups[g]) for g in order])))
        self._order = np.asarray([start[g] + k for g, k in slots if g != "wrench"],
                                 dtype=np.int32)
        # sensordata: position-like columns (framepos, jointpos), yaw columns, then
        # force/torque columns.
        self._sens_pos = np.asarray(sens["pos"], dtype=np.int32)
        self._sens_quat = np.asarray(sens["quat"], dtype=np.int32).reshape(-1, 4)
        self._sens_wrench = np.asarray(sens["wrench"], np.int32).reshape(-1, 3)
        w_quat = np.asarray(sens["wrench_quat"], np.int32).reshape(-1, 4)
        self._wrench_world = w_quat[:, 0] >= 0
        self._sens_wrench_quat = np.maximum(w_quat, 0)
        self._wrench_col = np.asarray(wrench_col, np.int32)
        counts = {"pos": 0, "yaw": 0, "wrench": 0}
        sens_slots = []
        for g, _ in slots:
            g = "yaw" if g.endswith("_yaw") else g if g == "wrench" else "pos"
            sens_slots.append((g, counts[g]))
            counts[g] += 1
        base = {"pos": 0, "yaw": counts["pos"],
                "wrench": counts["pos"] + counts["yaw"]}
        self._sens_order = np.asarray([base[g] + k for g, k in sens_slots],
                                      dtype=np.int32)

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

        Raises:
            ValueError: the set holds forces or torques (they come from the
                physics: `from_sensordata`, dynamic mode).
        """
        if self.wrenches:
            w = self.wrenches[0]
            raise ValueError(
                f"feature site {w.name!r} quantity {w.quantity!r}: forces and torques "
                "come from the physics (MuJoCo force/torque sensors), not from "
                "kinematics; use dynamic mode (robot.mode = 'dynamic')")
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
        return self._scaled(jnp.concatenate(parts)[self._order])

    def _scaled(self, values: Array) -> Array:
        return values if self._scales is None else values * self._scales

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
        if len(self._sens_wrench):
            vec = s[self._sens_wrench]  # (W, 3) in the site's frame
            if self._wrench_world.any():
                world = _rotate(s[self._sens_wrench_quat], vec)
                vec = jnp.where(self._wrench_world[:, None], world, vec)
            parts.append(vec[np.arange(len(vec)), self._wrench_col])
        return self._scaled(jnp.concatenate(parts)[self._sens_order])


def _rotate(q: Array, v: Array) -> Array:
    """Vectors ``v`` (..., 3) rotated by unit quaternions ``q`` (..., 4) (w, x, y,
    z): ``v + 2 w (u x v) + 2 u x (u x v)`` with u the vector part."""
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * jnp.cross(u, v)
    return v + w * t + jnp.cross(u, t)


def _yaw_from_mat(xmat, ids: np.ndarray) -> Array:
    """``atan2(R[1,0], R[0,0])`` of rotation matrices (flat 9 or 3x3) ``ids``."""
    flat = jnp.reshape(jnp.asarray(xmat), (-1, 9))[ids]
    return jnp.arctan2(flat[:, 3], flat[:, 0])
