"""Joint velocity, acceleration and effort limits, and the timing of a minimum-jerk move.

Limits (`read_limits` -> `JointLimits`), per evolved joint and kind (velocity in rad/s
or m/s, acceleration in rad/s^2 or m/s^2, effort in N m or N), come from the first of
these sources that gives a value (highest precedence first):

a. ``overrides`` (what a config's ``[robot.limits]`` table passes):
   ``{"velocity": 3.0, "effort": {"r_elbow": 20.0}, ...}``: a number applies to every
   evolved joint, a table to the joints it names.  ``inf`` means "no limit".
   Source ``"config"``.
b. an MJCF per-joint numeric, ``<custom><numeric name="velocity_limit:JOINT"
   data="3.0"/></custom>`` (likewise ``acceleration_limit:JOINT``,
   ``effort_limit:JOINT``).  Source ``"mjcf custom velocity_limit:JOINT"``.
c. effort only: the joint's ``actuatorfrcrange`` (``jnt_actfrclimited`` /
   ``jnt_actfrcrange``; the limit is ``max(|lo|, |hi|)``), source
   ``"mjcf actuatorfrcrange"``; else, when every actuator driving the joint (joint
   transmission) is force-limited, the sum of their ``max(|lo|, |hi|) * |gear|``,
   source ``"mjcf forcerange:ACTUATOR[+ACTUATOR...]"`` (a motor without a
   ``forcerange`` is limited by ``|gain| max|ctrlrange|``, source
   ``"mjcf ctrlrange:ACTUATOR"``).
d. an MJCF model-wide numeric ``velocity_limit`` (``acceleration_limit``,
   ``effort_limit``), one value for every joint of the model.  Source
   ``"mjcf custom velocity_limit"``.
e. none: ``inf``, source ``"none"``.

Every value must be a positive number (``inf`` allowed); a bad override or numeric
(wrong length, zero, negative, NaN, a per-joint numeric naming no joint of the model) is
a ValueError naming it.

The timing of a move against these limits: `cgda_jax.sim.timing`.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping, Sequence

import jax
import mujoco
import numpy as np

__all__ = [
    "KINDS",
    "JointLimits",
    "read_limits",
]

#: The limit kinds, in the order `JointLimits` holds them.
KINDS = ("velocity", "acceleration", "effort")



# -- the limits ----------------------------------------------------------------------
def _limit_array(values, n: int, what: str) -> np.ndarray:
    arr = np.array(values, dtype=np.float32).reshape(-1)
    if arr.shape != (n,):
        raise ValueError(f"JointLimits.{what} has shape {arr.shape}, expected ({n},)")
    if np.any(np.isnan(arr)) or np.any(arr <= 0):
        raise ValueError(f"JointLimits.{what} = {arr.tolist()}: every limit must be > 0 "
                         "(inf: no limit)")
    arr.setflags(write=False)
    return arr


@dataclasses.dataclass(frozen=True, eq=False)
class JointLimits:
    """Per-joint velocity, acceleration and effort limits of the evolved joints.

    Also a JAX pytree (the three arrays are its leaves), so it can be passed to
    jitted or vmapped functions such as `min_duration` and `violation`.

    Attributes:
        velocity: (DoF,) float32, rad/s (hinge) or m/s (slide); ``inf``: no limit.
        acceleration: (DoF,) float32, rad/s^2 or m/s^2; ``inf``: no limit.
        effort: (DoF,) float32, N m or N; ``inf``: no limit.
        joint_names: (DoF,) the joints, in gene order.
        source: kind -> (DoF,) where each value came from (``"config"``,
            ``"mjcf custom velocity_limit:r_elbow"``, ``"mjcf actuatorfrcrange"``,
            ``"mjcf forcerange:r_elbow"``, ``"mjcf custom velocity_limit"``,
            ``"none"``; see the module doc).
    """

    velocity: np.ndarray
    acceleration: np.ndarray
    effort: np.ndarray
    joint_names: tuple[str, ...]
    source: Mapping[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        names = tuple(str(j) for j in self.joint_names)
        n = len(names)
        object.__setattr__(self, "joint_names", names)
        for kind in KINDS:
            object.__setattr__(self, kind, _limit_array(getattr(self, kind), n, kind))
        source = {k: tuple(str(s) for s in self.source.get(k, ("none",) * n))
                  for k in KINDS}
        for kind, where in source.items():
            if len(where) != n:
                raise ValueError(f"JointLimits.source[{kind!r}] has {len(where)} "
                                 f"entries, expected {n}")
        object.__setattr__(self, "source", source)

    @property
    def n_dof(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    def unlimited(self, effort: bool = False) -> str | None:
        """What a run with these limits does not judge, as one warning line, or
        None: the joints without a speed limit (and, ``effort``: without an effort
        limit, which dynamic mode judges), what "feasible" then means and where
        to set the limits."""
        kinds = ("velocity", "effort") if effort else ("velocity",)
        words = {"velocity": "speed", "effort": "effort"}
        missing = {k: [j for j, v in zip(self.joint_names, getattr(self, k))
                       if not np.isfinite(v)] for k in kinds}
        missing = {k: js for k, js in missing.items() if js}
        if not missing:
            return None
        what = "; ".join(f"no {words[k]} limit for {', '.join(js)}"
                         for k, js in missing.items())
        return (f"{what} (the model has none and none is set): \"feasible\" then "
                f"means free of collisions and of moves over the step cap, not "
                f"within the robot's {' and '.join(words[k] for k in missing)}. Set "
                f"[robot.limits] (e.g. velocity = 3.0, effort = 30.0; Python: "
                f"Feasibility(robot, {{\"velocity\": 3.0}})) or give the model "
                f"<custom><numeric name=\"velocity_limit:JOINT\" data=\"3\"/> and "
                f"actuatorfrcrange")

    def as_dict(self) -> dict:
        """JSON-ready: ``{"joints": [...], "velocity": {joint: value or None}, ...,
        "source": {kind: {joint: str}}}`` (``None``: no limit)."""
        out: dict = {"joints": list(self.joint_names)}
        for kind in KINDS:
            values = getattr(self, kind)
            out[kind] = {j: (float(v) if np.isfinite(v) else None)
                         for j, v in zip(self.joint_names, values)}
        out["source"] = {k: dict(zip(self.joint_names, self.source[k])) for k in KINDS}
        return out

    def __repr__(self) -> str:
        def fmt(values) -> str:
            vals = {f"{v:g}" for v in np.asarray(values, dtype=np.float64)}
            if len(vals) == 1:
                return vals.pop()
            return "[" + ", ".join(f"{v:g}" for v in np.asarray(values)) + "]"

        if not isinstance(self.velocity, np.ndarray):  # traced leaves
            return f"JointLimits(joints={self.joint_names}, traced)"
        kinds = ", ".join(f"{k}={fmt(getattr(self, k))}" for k in KINDS)
        return f"JointLimits(joints={list(self.joint_names)}, {kinds})"


def _flatten(limits: JointLimits):
    source = tuple((k, limits.source[k]) for k in KINDS)
    return (limits.velocity, limits.acceleration, limits.effort), (
        limits.joint_names, source)


def _unflatten(aux, leaves) -> JointLimits:
    obj = object.__new__(JointLimits)  # leaves may be tracers: no checks
    names, source = aux
    for kind, leaf in zip(KINDS, leaves):
        object.__setattr__(obj, kind, leaf)
    object.__setattr__(obj, "joint_names", names)
    object.__setattr__(obj, "source", dict(source))
    return obj


jax.tree_util.register_pytree_node(JointLimits, _flatten, _unflatten)


def _check_value(value, where: str) -> float:
    """A limit value: a real number > 0 (``inf`` allowed)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{where} = {value!r}: not a number (give a limit > 0, or "
                         "inf for none)")
    v = float(value)
    if math.isnan(v) or v <= 0:
        raise ValueError(f"{where} = {value!r}: a limit must be > 0 (inf: no limit)")
    top = float(np.finfo(np.float32).max)
    if math.isfinite(v) and not float(np.finfo(np.float32).tiny) <= v <= top:
        raise ValueError(f"{where} = {value!r}: outside float32's range (a limit is "
                         f"from {float(np.finfo(np.float32).tiny):.3g} to {top:.3g}; "
                         "inf: no limit)")
    return v


def _numerics(mj_model: mujoco.MjModel) -> dict[str, np.ndarray]:
    out = {}
    for i in range(mj_model.nnumeric):
        name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_NUMERIC, i) or ""
        adr, size = int(mj_model.numeric_adr[i]), int(mj_model.numeric_size[i])
        out[name] = np.array(mj_model.numeric_data[adr:adr + size], dtype=np.float64)
    return out


def _numeric_value(name: str, data: np.ndarray) -> float:
    if data.shape != (1,):
        raise ValueError(f"MJCF custom numeric {name!r} has {data.size} values "
                         f"{data.tolist()}; give one (data=\"3.0\")")
    return _check_value(float(data[0]), f"MJCF custom numeric {name!r}")


def _actuator_effort(mj_model: mujoco.MjModel, jid: int) -> tuple[float, str] | None:
    """(summed max |force| * |gear|, source) of the actuators driving joint ``jid``,
    or None when none drives it or one of them has no force limit (a
    ``forcerange``, or a motor's ``gain x ctrlrange``)."""
    from cgda_jax.sim.control import actuator_kind

    total, names = 0.0, []
    for a in range(mj_model.nu):
        if (int(mj_model.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT)
                or int(mj_model.actuator_trnid[a, 0]) != jid):
            continue
        name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"#{a}"
        bounds = []
        if mj_model.actuator_forcelimited[a]:
            bounds.append((max(abs(float(v)) for v in mj_model.actuator_forcerange[a]),
                           "forcerange"))
        if actuator_kind(mj_model, a) == "motor" and mj_model.actuator_ctrllimited[a]:
            bounds.append((abs(float(mj_model.actuator_gainprm[a, 0])) * max(
                abs(float(v)) for v in mj_model.actuator_ctrlrange[a]), "ctrlrange"))
        if not bounds:
            return None
        force, kind = min(bounds)
        total += force * abs(float(mj_model.actuator_gear[a, 0]))
        names.append((kind, name))
    if not names:
        return None
    if all(kind == "forcerange" for kind, _ in names):
        return total, "mjcf forcerange:" + "+".join(n for _, n in names)
    return total, "mjcf " + "+".join(f"{k}:{n}" for k, n in names)


def read_limits(
    mj_model: mujoco.MjModel,
    joint_names: Sequence[str],
    overrides: Mapping | None = None,
) -> JointLimits:
    """The velocity, acceleration and effort limits of the evolved joints.

    Args:
        mj_model: the compiled model.
        joint_names: (DoF,) the evolved joints, in gene order.
        overrides: ``{kind: number | {joint: number}}`` for kinds ``"velocity"``,
            ``"acceleration"``, ``"effort"`` (a config's ``[robot.limits]``); a number
            applies to every joint in ``joint_names``, a table to the joints it
            names; ``inf`` means no limit.  Wins over the model (see the module doc
            for the whole precedence).

    Returns:
        `JointLimits` with (DoF,) float32 arrays and the source of every value.

    Raises:
        KeyError: a joint in ``joint_names`` is not in the model.
        ValueError: an unknown kind or joint in ``overrides``, a value that is not a
            number > 0 (``inf`` allowed), or a bad custom numeric (not one value,
            not > 0, or ``KIND_limit:JOINT`` naming no joint of the model); the
            message names the key and value.
    """
    names = tuple(joint_names)
    jt = mujoco.mjtObj.mjOBJ_JOINT
    jids = []
    for name in names:
        jid = mujoco.mj_name2id(mj_model, jt, name)
        if jid < 0:
            raise KeyError(f"joint {name!r} not found in the model")
        jids.append(jid)
    n = len(names)

    # a. overrides, checked whole before use
    config: dict[str, dict[str, float]] = {k: {} for k in KINDS}
    for kind, spec in dict(overrides or {}).items():
        if kind not in KINDS:
            raise ValueError(f"limits: unknown kind {kind!r} (= {spec!r}); expected one "
                             f"of {list(KINDS)}")
        if isinstance(spec, Mapping):
            for joint, value in spec.items():
                if joint not in names:
                    raise ValueError(f"limits.{kind}: unknown joint {joint!r} "
                                     f"(= {value!r}); the evolved joints are "
                                     f"{list(names)}")
                config[kind][joint] = _check_value(value, f"limits.{kind}.{joint}")
        else:
            v = _check_value(spec, f"limits.{kind}")
            config[kind] = dict.fromkeys(names, v)

    # b./d. custom numerics, all checked (a typo in a joint name is an error)
    numerics = _numerics(mj_model)
    per_joint: dict[str, dict[str, float]] = {k: {} for k in KINDS}
    model_wide: dict[str, float] = {}
    for nname, data in numerics.items():
        for kind in KINDS:
            key = f"{kind}_limit"
            if nname == key:
                model_wide[kind] = _numeric_value(nname, data)
            elif nname.startswith(key + ":"):
                joint = nname[len(key) + 1:]
                if mujoco.mj_name2id(mj_model, jt, joint) < 0:
                    raise ValueError(f"MJCF custom numeric {nname!r}: no joint "
                                     f"{joint!r} in the model")
                per_joint[kind][joint] = _numeric_value(nname, data)

    values = {k: np.full(n, np.inf, dtype=np.float64) for k in KINDS}
    source = {k: ["none"] * n for k in KINDS}
    for i, (name, jid) in enumerate(zip(names, jids)):
        for kind in KINDS:
            if name in config[kind]:
                v, src = config[kind][name], "config"
            elif name in per_joint[kind]:
                v, src = per_joint[kind][name], f"mjcf custom {kind}_limit:{name}"
            elif kind == "effort" and mj_model.jnt_actfrclimited[jid]:
                lo, hi = (float(x) for x in mj_model.jnt_actfrcrange[jid])
                v = _check_value(max(abs(lo), abs(hi)),
                                 f"actuatorfrcrange of joint {name!r}")
                src = "mjcf actuatorfrcrange"
            elif kind == "effort" and _actuator_effort(mj_model, jid) is not None:
                v, src = _actuator_effort(mj_model, jid)
                v = _check_value(v, f"{src} x gear of joint {name!r}")
            elif kind in model_wide:
                v, src = model_wide[kind], f"mjcf custom {kind}_limit"
            else:
                continue
            values[kind][i], source[kind][i] = v, src
    return JointLimits(values["velocity"], values["acceleration"], values["effort"],
                       names, {k: tuple(s) for k, s in source.items()})
