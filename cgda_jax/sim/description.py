"""A `Simulator` described in the words of an experiment config: `describe` gives
the ``[robot]``, ``[world]``, ``[scene]``, ``[feasibility]`` tables (and
``strategy.feasibility``) from which `cgda_jax.experiment.build.build_simulator`
builds the same simulator again.

This is what lets a result saved from Python (`cgda_jax.ExecutionResult.save`)
open like a ``cgda run`` folder: its ``config.toml`` is written from these tables.
A simulator built from pieces a config cannot name (a compiled ``MjModel`` without
its file, a scene of another class, a paint wall that is not a grid, a feasibility
check with obstacles of its own) raises `NotDescribable`, saying which piece.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

__all__ = ["NotDescribable", "describe", "setup_of"]


class NotDescribable(ValueError):
    """The simulator holds something an experiment config cannot name (said)."""


def _degrees(table: dict[str, float]) -> dict[str, float]:
    return {k: math.degrees(float(v)) for k, v in table.items()}


def _robot(sim) -> tuple[dict[str, Any], dict[str, Any]]:
    robot = sim.robot
    if robot.model_path is None:
        raise NotDescribable(
            f"the robot was built from a compiled model ({robot.source}), not from "
            "its MJCF file: build it with Robot.from_mjcf or Robot.from_world")
    table: dict[str, Any] = {
        "model": robot.model_path, "joints": list(robot.joint_names),
        "fixed": _degrees(robot.fixed), "start": _degrees(robot.start),
        "keyframe": robot.keyframe or "", "mode": sim.mode,
        "substeps": sim.substeps, "waypoint_s": float(sim.waypoint_s),
        "move_fraction": float(sim.move_fraction),
    }
    if isinstance(robot.marker, str):
        table["marker_site"] = robot.marker
    else:
        table["marker"] = dict(robot.marker)
    if sim.mode == "dynamic":
        args = sim.dynamic_args
        table |= {"timestep": float(sim.physics.timestep),
                  "physics": sim.backend.name, "reduce": bool(args["reduce"]),
                  "control": control_table(args["control"]) or {}}
    world = {"objects": [dict(o) for o in robot.world_objects],
             "contact_geoms": list(robot.contact_geoms)}
    return table, world


def _scene(scene) -> dict[str, Any]:
    from cgda_jax.sim.scenes import MarkerScene, ObjectScene, PaintWall

    if type(scene) is MarkerScene:
        return {"kind": "marker"}
    if type(scene) is ObjectScene:
        return {"kind": "objects", "features": [
            {s.kind: s.name, "quantity": s.quantity} for s in scene.specs]}
    if type(scene) is PaintWall:
        return {"kind": "paint", "params": _paint_grid(scene)}
    raise NotDescribable(f"the scene is a {type(scene).__name__}; a config names a "
                         "MarkerScene, a PaintWall.grid or an ObjectScene")


def _paint_grid(wall) -> dict[str, Any]:
    """``PaintWall.grid``'s arguments that give ``wall`` again (its centres exactly)."""
    from cgda_jax.sim.scenes import PaintWall

    c = np.asarray(wall.centres, np.float64)
    ys = list(dict.fromkeys(c[:, 1].tolist()))
    zs = list(dict.fromkeys(c[:, 2].tolist()))
    params = {"x": float(c[0, 0]), "ys": ys, "zs": zs, "root_height": 0.0,
              "radius": float(wall.radius), "size": float(wall.size),
              "thickness": float(wall.thickness), "margin": float(wall.margin)}
    if wall.path_tolerance is not None:
        params["path_tolerance"] = float(wall.path_tolerance)
    again = PaintWall.grid(**params,
                           **({} if wall.path_tolerance is not None
                              else {"path_tolerance": None}))
    if (again.centres.shape != wall.centres.shape
            or not np.array_equal(again.centres, wall.centres)
            or tuple(again.normal) != tuple(wall.normal)):
        raise NotDescribable("the paint wall is not a PaintWall.grid (its centres "
                             "are not a vertical grid painted from -x)")
    if wall.path_tolerance is None:
        raise NotDescribable("the paint wall has no path_tolerance, which a config "
                             "cannot say")
    return params


def _same(a: Any, b: Any) -> bool:
    """Equal obstacle tables (dicts, lists, arrays and numbers, nested)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (str, bool)) or isinstance(b, (str, bool)) or a is None:
        return a == b
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and (
            len(a) != len(b) or any(isinstance(x, dict) for x in a)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    try:
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    except (TypeError, ValueError):
        return False


def _feasibility(sim) -> tuple[dict[str, Any], dict[str, Any]]:
    from cgda_jax.sim.feasibility import scene_obstacles

    f = sim.feasibility
    if f is None:
        return {}, {}
    if f.physics_contacts != (sim.mode == "dynamic"):
        raise NotDescribable("the feasibility check leaves the physics' own contacts "
                             f"{'to it' if f.physics_contacts else 'in'}, which a "
                             f"config does only in dynamic mode")
    if not _same(list(f.obstacles), scene_obstacles(sim.scene)):
        raise NotDescribable("the feasibility check has obstacles of its own (a "
                             "config gives it the scene's: the paint board)")
    table = {"penetration": f.penetration, "penalty": f.penalty,
             "collisions": f.collisions, "self_collision": f.self_collision,
             "exclude": list(f.exclude), "samples": f.samples, "margin": f.margin,
             "certify": f.certify, "max_step_deg": math.degrees(f.max_step),
             "geometry": f.geometry, "tracking_deg": f.tracking_deg,
             "saturation": f.saturation}
    limits = {kind: {j: float(v) for j, v in zip(f.limits.joint_names,
                                                  getattr(f.limits, kind))}
              for kind in ("velocity", "acceleration", "effort")}
    return table, limits


def describe(sim) -> dict[str, Any]:
    """The config tables that build ``sim`` again: ``robot`` (joint values in
    degrees, as a config gives them; the model's file; timing and, in dynamic
    mode, physics and control), ``world``, ``scene``, ``feasibility`` (with the
    joint limits it judged by in ``robot.limits``) and ``strategy.feasibility``.

    Raises:
        NotDescribable: a piece a config cannot name (the message says which).
    """
    from cgda_jax.sim.simulator import Simulator

    if not isinstance(sim, Simulator):
        raise NotDescribable(f"the simulator is a {type(sim).__name__} of its own, "
                             "not a cgda_jax Simulator")
    robot, world = _robot(sim)
    feasibility, limits = _feasibility(sim)
    if limits:
        robot["limits"] = limits
    out: dict[str, Any] = {"robot": robot, "scene": _scene(sim.scene),
                           "strategy": {"feasibility": sim.feasibility is not None}}
    if world["objects"] or world["contact_geoms"]:
        out["world"] = world
    if feasibility:
        out["feasibility"] = feasibility
    return out


def setup_of(sim) -> dict[str, Any]:
    """What a saved result records of its simulator: ``feature_names`` and
    ``config`` (`describe`), or ``not_described`` (the reason) in its place."""
    names = getattr(sim, "feature_names", None)
    out: dict[str, Any] = {} if names is None else {"feature_names": list(names)}
    try:
        out["config"] = describe(sim)
    except NotDescribable as err:
        out["not_described"] = str(err)
    return out


def control_table(control) -> dict[str, Any] | None:
    """A `cgda_jax.sim.control.Control` (or its table, or None) as a config's
    ``[robot.control]`` table (None: the defaults)."""
    if control is None:
        return None
    if dataclasses.is_dataclass(control):
        return dataclasses.asdict(control)
    return dict(control)
