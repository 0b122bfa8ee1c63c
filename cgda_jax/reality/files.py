"""An `ExportedTrajectory` as a file a controller (or a person) reads: CSV, JSON or
NPZ; `load_trajectory` reads any of them back.

JSON (``format: "cgda_jax.trajectory/1"``): the key ``joint_trajectory`` is a ROS
``trajectory_msgs/JointTrajectory`` message, field for field (ROS 2 names;
``builtin_interfaces/Duration`` is ``{sec, nanosec}``, ROS 1's ``{secs, nsecs}``)::

    {"joint_trajectory": {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
        "joint_names": ["r_shoulder_flexion", ...],
        "points": [{"positions": [...], "velocities": [...],
                    "accelerations": [...], "effort": [],
                    "time_from_start": {"sec": 0, "nanosec": 10000000}}, ...]},
     "units": {"r_shoulder_flexion": "rad", ...},   # velocities /s, accelerations /s^2
     "rate_hz": 100.0, "waypoints": [[...], ...], "reached_index": [...],
     "feature_index": [...], "limits": {...}, "info": {...}}

so ``JointTrajectory(**doc["joint_trajectory"])`` (with the nested messages built the
same way) is the message to publish, e.g. to a ``joint_trajectory_controller``'s
``~/joint_trajectory`` topic or its ``FollowJointTrajectory`` action.  Positions
are radians (hinges) or metres (slides), as ROS expects.

CSV: a header row ``time [s],<joint> position [rad],...,<joint> velocity [rad/s],
...,<joint> acceleration [rad/s^2],...`` and one row per sample; the lines before
it start with ``#`` and hold the same metadata as the JSON's other keys, one
``# key: <json>`` line each (``pandas.read_csv(path, comment="#")`` reads the table).

NPZ: arrays ``t``, ``q``, ``qd``, ``qdd``, ``start``, ``waypoints``,
``reached_index``, ``feature_index``, ``joint_names``, ``units``, ``rate``,
``limit_velocity`` / ``limit_acceleration`` / ``limit_jerk`` and ``info`` (JSON text).
"""

from __future__ import annotations

import json
import math
import os
import pathlib

import numpy as np

from cgda_jax.results_folder.reading import write_aside
from cgda_jax.reality.control_trajectory import ExportedTrajectory

__all__ = ["FORMAT", "FORMATS", "from_json_dict", "load_trajectory", "save_trajectory",
           "to_json_dict"]

FORMAT = "cgda_jax.trajectory/1"
FORMATS = ("csv", "json", "npz")
_LIMITS = ("velocity", "acceleration", "jerk")


def _duration(t: float) -> dict:
    ns = round(t * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _num(x: float):
    return float(x) if math.isfinite(x) else None


def _meta(traj: ExportedTrajectory) -> dict:
    return {
        "format": FORMAT,
        "joint_names": list(traj.joint_names),
        "units": dict(zip(traj.joint_names, traj.units)),
        "rate_hz": traj.rate,
        "start": traj.start.tolist(),
        "waypoints": traj.waypoints.tolist(),
        "reached_index": traj.reached_index.tolist(),
        "feature_index": traj.feature_index.tolist(),
        "limits": {k: [_num(v) for v in traj.limits[k]] for k in _LIMITS},
        "info": traj.info,
    }


def to_json_dict(traj: ExportedTrajectory) -> dict:
    """The JSON document (see the module doc): a ROS ``JointTrajectory`` under
    ``joint_trajectory`` and the metadata beside it."""
    points = [{"positions": traj.q[k].tolist(), "velocities": traj.qd[k].tolist(),
               "accelerations": traj.qdd[k].tolist(), "effort": [],
               "time_from_start": _duration(float(traj.t[k]))}
              for k in range(traj.n_samples)]
    meta = _meta(traj)
    meta.pop("joint_names")
    return {"format": FORMAT, "joint_trajectory": {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
        "joint_names": list(traj.joint_names), "points": points}, **meta}


def _limits(meta: dict, n: int) -> dict[str, np.ndarray]:
    lim = meta.get("limits") or {}
    return {k: np.array([np.nan if v is None else v
                         for v in lim.get(k, [None] * n)], np.float64) for k in _LIMITS}


def _from_meta(meta: dict, names, t, q, qd, qdd) -> ExportedTrajectory:
    units = meta["units"]
    return ExportedTrajectory(
        joint_names=tuple(names), units=tuple(units[n] for n in names),
        rate=float(meta["rate_hz"]), t=np.asarray(t, np.float64),
        q=np.asarray(q, np.float64), qd=np.asarray(qd, np.float64),
        qdd=np.asarray(qdd, np.float64),
        start=np.asarray(meta["start"], np.float64),
        waypoints=np.asarray(meta["waypoints"], np.float64).reshape(-1, len(names)),
        reached_index=np.asarray(meta["reached_index"], np.int64),
        feature_index=np.asarray(meta["feature_index"], np.int64),
        limits=_limits(meta, len(names)), info=dict(meta.get("info") or {}))


def from_json_dict(doc: dict) -> ExportedTrajectory:
    """The `ExportedTrajectory` of a JSON document written by `to_json_dict`."""
    if doc.get("format") != FORMAT:
        raise ValueError(f"not a {FORMAT} document (format {doc.get('format')!r})")
    jt = doc["joint_trajectory"]
    pts = jt["points"]
    t = [p["time_from_start"]["sec"] + p["time_from_start"]["nanosec"] * 1e-9
         for p in pts]
    # times to the control grid (nanosecond rounding undone)
    rate = float(doc["rate_hz"])
    t = np.round(np.asarray(t) * rate) / rate
    return _from_meta(doc, jt["joint_names"], t, [p["positions"] for p in pts],
                      [p["velocities"] for p in pts], [p["accelerations"] for p in pts])


def _header(traj: ExportedTrajectory) -> list[str]:
    cols = ["time [s]"]
    for kind, per in (("position", ""), ("velocity", "/s"), ("acceleration", "/s^2")):
        cols += [f"{n} {kind} [{u}{per}]" for n, u in zip(traj.joint_names, traj.units)]
    return cols


def save_trajectory(traj: ExportedTrajectory, path: str | os.PathLike,
                    fmt: str | None = None) -> pathlib.Path:
    """Write ``traj`` to ``path`` as ``fmt`` (csv, json or npz; default: the file's
    suffix), whole or not at all (`cgda_jax.results_folder.reading.write_aside`: an earlier file
    there is kept on failure).  Returns the path."""
    path = pathlib.Path(path)
    fmt = (fmt or path.suffix.lstrip(".")).lower()
    if fmt not in FORMATS:
        raise ValueError(f"{path}: format {fmt!r} unknown; expected one of {FORMATS}")
    if fmt == "json":
        def write(f):
            f.write(json.dumps(to_json_dict(traj)) + "\n")
    elif fmt == "npz":
        def write(f):
            np.savez(f, t=traj.t, q=traj.q, qd=traj.qd, qdd=traj.qdd, start=traj.start,
                     waypoints=traj.waypoints, reached_index=traj.reached_index,
                     feature_index=traj.feature_index,
                     joint_names=np.array(traj.joint_names),
                     units=np.array(traj.units), rate=np.float64(traj.rate),
                     info=np.array(json.dumps(traj.info)),
                     **{f"limit_{k}": traj.limits[k] for k in _LIMITS})
    else:
        def write(f):
            for k, v in _meta(traj).items():
                f.write(f"# {k}: {json.dumps(v)}\n")
            f.write(",".join(_header(traj)) + "\n")
            table = np.concatenate([traj.t[:, None], traj.q, traj.qd, traj.qdd], axis=1)
            for row in table:
                f.write(",".join(repr(float(x)) for x in row) + "\n")
    write_aside(path, write, binary=fmt == "npz")
    return path


def _load_csv(path: pathlib.Path) -> ExportedTrajectory:
    meta, rows, header = {}, [], None
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            key, _, value = line[1:].strip().partition(":")
            meta[key.strip()] = json.loads(value)
        elif header is None:
            header = line.split(",")
        elif line.strip():
            rows.append([float(x) for x in line.split(",")])
    if meta.get("format") != FORMAT or header is None:
        raise ValueError(f"{path}: not a {FORMAT} CSV file (its '# format:' line or "
                         "header row is missing)")
    names = meta["joint_names"]
    n = len(names)
    table = np.asarray(rows, np.float64).reshape(-1, 1 + 3 * n)
    return _from_meta(meta, names, table[:, 0], table[:, 1:1 + n],
                      table[:, 1 + n:1 + 2 * n], table[:, 1 + 2 * n:])


def _load_npz(path: pathlib.Path) -> ExportedTrajectory:
    with np.load(path) as z:
        names = [str(s) for s in z["joint_names"]]
        meta = {"units": dict(zip(names, (str(u) for u in z["units"]))),
                "rate_hz": float(z["rate"]), "start": z["start"],
                "waypoints": z["waypoints"], "reached_index": z["reached_index"],
                "feature_index": z["feature_index"], "info": json.loads(str(z["info"])),
                "limits": {k: [None if np.isnan(v) else float(v)
                               for v in z[f"limit_{k}"]] for k in _LIMITS}}
        return _from_meta(meta, names, z["t"], z["q"], z["qd"], z["qdd"])


def load_trajectory(path: str | os.PathLike) -> ExportedTrajectory:
    """Read a trajectory file written by `save_trajectory` (format by suffix).

    Raises:
        ValueError: not such a file (the path and what is missing named).
        FileNotFoundError: no file there.
    """
    path = pathlib.Path(path)
    fmt = path.suffix.lstrip(".").lower()
    if fmt not in FORMATS:
        raise ValueError(f"{path}: format {fmt!r} unknown; expected one of {FORMATS}")
    if not path.is_file():
        raise FileNotFoundError(f"trajectory file {path} not found")
    try:
        if fmt == "json":
            return from_json_dict(json.loads(path.read_text()))
        return _load_csv(path) if fmt == "csv" else _load_npz(path)
    except (KeyError, json.JSONDecodeError, TypeError) as e:
        raise ValueError(f"{path}: not a {FORMAT} {fmt} file ({type(e).__name__}: "
                         f"{e})") from None
