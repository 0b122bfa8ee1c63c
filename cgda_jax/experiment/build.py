"""Objects from a config: the demonstrations and the goal, the robot, world and scene
in a simulator, the feature names and labels. (The strategy function is looked up
by `cgda_jax.experiment.rules.strategy_function`, which checks its options.)"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from cgda_jax.experiment.config import (
    OBJECT_SOURCES,
    ConfigError,
    ExperimentConfig,
)
from cgda_jax.experiment.locate import (
    demonstration_files,
    resolve_data_dir,
    resolve_model,
    video_folders,
)
from cgda_jax.experiment.rules import check_interval_count, validate_world


def build_goal(cfg: ExperimentConfig) -> tuple[np.ndarray, list, Any]:
    """The goal (N, F) of an execution run, its demonstrations and generalization."""
    from cgda_jax.generalization import generalize

    d = cfg.data
    if d.source in OBJECT_SOURCES:
        demos = selected_demos(cfg, {cfg.name: object_demos(cfg)})[0][cfg.name]
        gen = generalize(demos, d.interval_s, d.method, name=cfg.name)
        return np.asarray(gen.knots, float) * goal_scale(cfg), demos, gen
    if d.source == "paint_ramp":
        from cgda_jax.datasets import paint_ramp

        return paint_ramp(d.goal_points) * d.scale, [], None
    if d.source == "clean_circle":
        from cgda_jax.datasets import clean_circle_demos

        demos = clean_circle_demos(d.centre, d.diameter, d.n_demos, d.seed)
    elif d.source == "csv":
        demos = csv_demos(cfg)
    elif d.source == "video":
        demos = [track_recording(cfg, v, v.name) for v in demonstration_files(cfg)]
    elif d.force_columns:
        return xgnitive_force_goal(cfg)
    else:
        from cgda_jax.data import load_xgnitive

        demos = load_xgnitive(resolve_data_dir(cfg), d.action, d.stream, d.columns)
    demos = selected_demos(cfg, {cfg.name: demos})[0][cfg.name]
    check_interval_count(demos, d.interval_s, d.method)  # before generalize allocates
    gen = generalize(demos, d.interval_s, d.method, name=cfg.name)
    return np.asarray(gen.knots, float) * goal_scale(cfg), demos, gen


def xgnitive_force_goal(cfg: ExperimentConfig) -> tuple[np.ndarray, list, Any]:
    """The goal of an xgnitive arm stream with wrist-force columns (``data.columns``
    then ``data.force_columns``): each stream generalized on its own clock as the
    authors did (`cgda_jax.generalization.generalize_streams`; the iron goal is their
    ``target_iron[9][4]``); the demonstrations returned are the arm with the force
    beside it on the arm's clock (`cgda_jax.data.load_xgnitive_force`)."""
    from cgda_jax.data import load_xgnitive, load_xgnitive_force
    from cgda_jax.generalization import generalize_streams

    d = cfg.data
    root = resolve_data_dir(cfg)
    arm = load_xgnitive(root, d.action, d.stream, d.columns)
    force = load_xgnitive(root, d.action, "jr3", d.force_columns)
    for demos in (arm, force):
        check_interval_count(demos, d.interval_s, d.method)
    try:
        gen = generalize_streams([arm, force], d.interval_s, d.method, name=cfg.name)
    except ValueError as err:
        raise ConfigError(f"key 'data.force_columns': {err}") from None
    demos = load_xgnitive_force(root, d.action, d.columns, d.force_columns,
                                stream=d.stream)
    return np.asarray(gen.knots, float) * goal_scale(cfg), demos, gen


def goal_scale(cfg: ExperimentConfig) -> float | np.ndarray:
    """What the demonstrations and the goal are multiplied by: ``data.scale``, times
    each column's ``scale`` of an ``objects`` scene (a weight such as 1/300 on a
    force: the goal must be weighted as the features it is compared with)."""
    from cgda_jax.sim.features import FeatureSpec

    if cfg.scene.kind != "objects" or not cfg.scene.features:
        return cfg.data.scale
    specs = [FeatureSpec.from_dict(e) for e in cfg.scene.features]
    if all(s.scale == 1 for s in specs):
        return cfg.data.scale
    return cfg.data.scale * np.concatenate([[s.scale] * len(s.columns()) for s in specs])


def synthetic_demos(cfg: ExperimentConfig) -> dict:
    """The synthetic demonstrations of a recognition run: action -> repetitions."""
    from cgda_jax.datasets import (
        SPATIAL_FEATURES,
        distractor_names,
        select_features,
        synthetic_actions,
    )

    d = cfg.data
    demos = synthetic_actions(
        d.n_repetitions, d.seed, features="arm" if d.features == "arm" else "marker",
        irrelevant=d.irrelevant,
    )
    if d.features == "spatial":
        demos = {a: select_features(v, SPATIAL_FEATURES + distractor_names(
            d.irrelevant)) for a, v in demos.items()}
    return demos


def selected_demos(cfg: ExperimentConfig, demos: dict) -> tuple[dict, dict | None]:
    """Each action's demonstrations (action -> list) after the ``[selection]``
    section: outlier demonstrations dropped, then (``selection.features``) only
    the features some action keeps. Returns them and what was selected (None
    when the section selects nothing), as ``result.json`` stores it: per action
    its ``demonstrations`` (names, z-scores, kept) and ``features`` (names,
    summed DTW, z-scores, kept); ``features``: the features kept in the end."""
    from cgda_jax.select import select_demonstrations, select_features

    s = cfg.selection
    if not (s.demonstrations or s.features):
        return demos, None
    record: dict[str, Any] = {"normalization": s.normalization, "alpha": s.alpha,
                              "actions": {}}
    out = {}
    try:
        for action, v in demos.items():
            rec = record["actions"][action] = {}
            if s.demonstrations:
                sel = select_demonstrations(v, s.normalization, s.alpha)
                v = sel.apply(v)
                rec["demonstrations"] = {
                    "names": list(sel.names), "zscores": sel.zscores.tolist(),
                    "selected": sel.selected.tolist()}
            if s.features:
                fsel = select_features(v, s.normalization, s.alpha)
                rec["features"] = {
                    "names": list(fsel.feature_names),
                    "distances": fsel.distances.tolist(),
                    "zscores": fsel.zscores.tolist(),
                    "selected": fsel.selected.tolist()}
            out[action] = v
    except ValueError as err:
        raise ConfigError(f"section 'selection', action {action!r}: {err}") from None
    if s.features:
        names = next(iter(out.values()))[0].feature_names
        kept = [n for i, n in enumerate(names) if any(
            r["features"]["selected"][i] for r in record["actions"].values())]
        record["features"] = kept
        out = {a: [d.select(kept) for d in v] for a, v in out.items()}
    return out, record


def video_demos(cfg: ExperimentConfig) -> dict:
    """The tracked demonstrations of a ``data.source = "video"`` recognition run:
    action -> repetitions (`cgda_jax.experiment.locate.video_folders`), each tracked
    as ``cgda track`` tracks it (a recording folder's depth and intrinsics used)."""
    return {action: [track_recording(cfg, v, f"{action}/{v.name}") for v in videos]
            for action, videos in video_folders(cfg).items()}


def track_recording(cfg: ExperimentConfig, v, name: str):
    """One recording of ``data.data_dir`` tracked as ``cgda track`` tracks it (a
    recording folder's depth, intrinsics and frame rate used), with the columns
    ``data.features`` names ("image": every column the tracker gives)."""
    import json
    import pathlib

    from cgda_jax.vision.track import track_video

    d = cfg.data
    columns = {"marker": ("X_m", "Y_m", "Z_m", "area_px", "hue_0_180",
                          "saturation_0_255", "value_0_255", "angle_deg"),
               "spatial": ("X_m", "Y_m", "Z_m")}.get(d.features)
    kw: dict[str, Any] = {"color": d.color, "name": name}
    v = pathlib.Path(v)
    if (v / "rgb").is_dir():
        meta = v / "recording.json"
        if meta.is_file():
            kw["fps"] = json.loads(meta.read_text()).get("fps")
        if d.features != "image" and (v / "depth").is_dir():
            kw["depth"], kw["intrinsics"] = v / "depth", v / "intrinsics.json"
        v = v / "rgb"
    try:
        demo = track_video(v, **kw).demo
        return demo.select(columns) if columns else demo
    except (ValueError, KeyError) as err:
        raise ConfigError(f"key 'data.data_dir': {err}") from None


def csv_demos(cfg: ExperimentConfig) -> list:
    """``data.source = "csv"``: every CSV file of ``data.data_dir`` read with
    `cgda_jax.data.load_csv`, keeping ``data.columns`` in that order."""
    from cgda_jax.data import load_csv

    out = []
    for f in demonstration_files(cfg):
        try:
            out.append(load_csv(f, cfg.data.columns))
        except KeyError as err:
            raise ConfigError(f"key 'data.columns': {err.args[0] if err.args else err}"
                              ) from None
    return out


def xgnitive_demos(cfg: ExperimentConfig) -> dict:
    """The real TEO recordings of both xgnitive actions, action -> repetitions:
    ``data.stream``'s ``data.columns`` (with ``data.force_columns``: the jr3
    columns beside them on the arm's clock, `cgda_jax.data.load_xgnitive_force`)."""
    from cgda_jax.data import XGNITIVE_ACTIONS, load_xgnitive, load_xgnitive_force

    d, root = cfg.data, resolve_data_dir(cfg)
    out = {}
    for action in XGNITIVE_ACTIONS:
        try:
            if d.force_columns:
                out[action] = load_xgnitive_force(root, action, d.columns,
                                                  d.force_columns, stream=d.stream)
            else:
                out[action] = load_xgnitive(root, action, d.stream, d.columns)
        except (KeyError, ValueError) as err:
            raise ConfigError(f"section 'data' (xgnitive {action!r}): "
                              f"{err.args[0] if err.args else err}") from None
    return out


def recognition_demos(cfg: ExperimentConfig) -> dict:
    """A recognition run's demonstrations, action -> repetitions: synthetic,
    tracked from video or the real TEO recordings (xgnitive)."""
    if cfg.data.source == "video":
        return video_demos(cfg)
    if cfg.data.source == "xgnitive":
        return xgnitive_demos(cfg)
    return synthetic_demos(cfg)


def scene_feature_names(cfg: ExperimentConfig) -> list[str]:
    """The feature names (with units) the ``objects`` scene of `cfg` reads."""
    from cgda_jax.sim.features import FeatureSpec

    names = []
    for entry in cfg.scene.features:
        spec = FeatureSpec.from_dict(entry)
        names += spec.labels()
    return names


def feature_labels(cfg: ExperimentConfig, names) -> list[str]:
    """The feature names of a run with their units (``"X [m]"``)."""
    from cgda_jax.plotting import units

    if cfg.kind == "recognition" and cfg.data.source == "xgnitive":
        table = units.XGNITIVE_UNITS
    elif cfg.kind == "recognition":
        table = units.ARM_UNITS if cfg.data.features == "arm" else units.MARKER_UNITS
    else:
        table = units.SIM_UNITS  # the goal is in the simulated scene's features
    return list(units.with_units(names, table))


def error_unit(labels) -> str | None:
    """The unit of a distance between feature points (None: mixed units)."""
    from cgda_jax.plotting import units

    return units.common_unit(labels)


def object_demos(cfg: ExperimentConfig) -> list:
    """The demonstrations of an object source (``move_box`` / ``rotate_valve``),
    restricted to the columns the scene reads, in the scene's order.

    Raises:
        ConfigError: a scene feature that the demonstrations do not have (e.g. a
            different object name; both lists named).
    """
    from cgda_jax.datasets import move_box_demos, rotate_valve_demos, select_features

    d = cfg.data
    kw: dict[str, Any] = {"n": d.n_demos, "seed": d.seed}
    if d.start:
        kw["start"] = d.start if d.source == "move_box" else d.start[0]
    if d.end:
        kw["end"] = d.end if d.source == "move_box" else d.end[0]
    if d.object:
        kw["name"] = d.object
    if d.duration_s:
        kw["duration_s"] = d.duration_s
    try:
        if d.source == "move_box":
            demos = move_box_demos(curve=d.curve, **kw)
        else:
            demos = rotate_valve_demos(**kw)
    except ValueError as err:
        raise ConfigError(f"[data] ({d.source}): {err}") from None
    have = list(demos[0].feature_names)
    want = scene_feature_names(cfg)
    missing = [n for n in want if n not in have]
    if missing:
        raise ConfigError(
            f"key 'scene.features': the {d.source} demonstrations have {have}, not "
            f"{missing} (name the object with data.object or the scene's features)"
        )
    return select_features(demos, want)


def goal_path_points(cfg: ExperimentConfig, model, qpos0, goal) -> np.ndarray | None:
    """The goal drawn in renders (K, 3) (``scene.goal_path``), or None.

    A body's x and y columns give points at the height ``scene.goal_path_z``; else a
    hinge joint's angle column gives the site ``scene.goal_path_site`` with the joint
    turned to each goal angle (forward kinematics of `model` from `qpos0`).
    """
    import mujoco

    from cgda_jax.sim.features import FeatureSpec

    sc = cfg.scene
    if not sc.goal_path or sc.kind != "objects":
        return None
    goal = np.asarray(goal, float)
    col, cols = 0, {}
    for entry in sc.features:
        spec = FeatureSpec.from_dict(entry)
        for c in spec.columns():
            cols[c] = (spec, col)
            col += 1
    for spec, _ in cols.values():
        if spec.kind == "body" and f"{spec.name}.x" in cols and f"{spec.name}.y" in cols:
            x, y = cols[f"{spec.name}.x"][1], cols[f"{spec.name}.y"][1]
            return np.column_stack([goal[:, x], goal[:, y],
                                    np.full(len(goal), sc.goal_path_z)])
    for spec, k in cols.values():
        if spec.kind == "joint" and spec.quantity == "angle":
            if not sc.goal_path_site:
                raise ConfigError("key 'scene.goal_path_site': name the site to draw "
                                  f"the goal of joint {spec.name!r} at (e.g. a rim)")
            data = mujoco.MjData(model)
            site = model.site(sc.goal_path_site).id
            adr = int(model.joint(spec.name).qposadr[0])
            out = []
            for angle in goal[:, k]:
                data.qpos[:] = qpos0
                data.qpos[adr] = angle
                mujoco.mj_kinematics(model, data)
                out.append(data.site_xpos[site].copy())
            return np.asarray(out)
    raise ConfigError("key 'scene.goal_path': the scene has neither a body's x and y "
                      "nor a hinge joint's angle to draw")


def default_waypoint_s(demos: list, n_points: int) -> float:
    """Seconds per waypoint from the demonstrations' timing: mean duration / points
    (1 s without demonstrations)."""
    if not demos or n_points < 1:
        return 1.0
    return float(np.mean([d.duration for d in demos])) / n_points


def robot_marker(cfg: ExperimentConfig):
    """The marker of ``[robot]``: ``marker`` (a table) if given, else
    ``marker_site``.

    Raises:
        ConfigError: both given (``marker_site`` changed from its default).
    """
    rc = cfg.robot
    if not rc.marker:
        return rc.marker_site
    if rc.marker_site != "marker":
        raise ConfigError(f"keys 'robot.marker' and 'robot.marker_site': give one "
                          f"(marker = {rc.marker}, marker_site = {rc.marker_site!r})")
    return dict(rc.marker)


def build_simulator(cfg: ExperimentConfig, waypoint_s: float | None = None,
                    goal=None):
    """Robot (+ the world's objects) + scene + Simulator from the config.

    Args:
        cfg: the experiment.
        waypoint_s: dynamic mode: seconds per waypoint when ``robot.waypoint_s`` is
            0 (default 1 s; `run_execution` passes `default_waypoint_s`).
        goal: (N, F) the goal, drawn in renders when ``scene.goal_path`` is on.
    """
    from cgda_jax.sim.simulator import Simulator
    from cgda_jax.sim.robot import Robot
    from cgda_jax.sim.scenes import MarkerScene, ObjectScene, PaintWall

    rc = cfg.robot
    fixed = {k: math.radians(v) for k, v in rc.fixed.items()}
    start = {k: math.radians(v) for k, v in rc.start.items()}
    marker = robot_marker(cfg)
    if cfg.world.objects or cfg.world.contact_geoms:
        validate_world(cfg)  # one line naming the key for a bad object or feature
        robot = Robot.from_world(
            resolve_model(rc.model), cfg.world.objects, list(rc.joints),
            marker, fixed, contact_geoms=cfg.world.contact_geoms,
            keyframe=rc.keyframe or None, start=start,
        )
    else:
        robot = Robot.from_mjcf(
            resolve_model(rc.model), list(rc.joints), marker, fixed,
            keyframe=rc.keyframe or None, start=start,
        )
    if cfg.scene.kind == "objects":
        path = None
        if goal is not None:
            path = goal_path_points(cfg, robot.mj_model, np.asarray(robot.qpos0), goal)
        scene = ObjectScene(list(cfg.scene.features), goal_path=path)
    elif cfg.scene.kind == "paint":
        scene = PaintWall.grid(**cfg.scene.params)
    else:
        if cfg.scene.params:
            raise ConfigError("key 'scene.params': the marker scene takes no parameters")
        scene = MarkerScene()
    feasibility = build_feasibility(cfg, robot, scene)
    timing = {"waypoint_s": rc.waypoint_s or waypoint_s or 1.0,
              "move_fraction": rc.move_fraction, "feasibility": feasibility}
    control = build_control(cfg)  # checked in either mode
    if rc.mode != "dynamic":
        return Simulator(robot, scene, mode=rc.mode, substeps=rc.substeps, **timing)
    return Simulator(
        robot, scene, mode="dynamic", substeps=rc.substeps,
        timestep=rc.timestep or None, physics=rc.physics, reduce=rc.reduce,
        control=control, **timing,
    )


@dataclasses.dataclass
class BuiltExecution:
    """An execution run's objects, built once: by its checks
    (`cgda_jax.experiment.validate.check_and_build`), then used by the run
    (`cgda_jax.experiment.compute.compute_execution`,
    `cgda_jax.experiment.success_rate.trial_records`).

    Attributes:
        goal: (N, F) the goal; demos: its demonstrations ([] without);
        generalization: theirs (None without); waypoint_s: seconds per waypoint
        from their timing (`default_waypoint_s`); sim: the `Simulator`.
    """

    goal: np.ndarray
    demos: list
    generalization: Any
    waypoint_s: float
    sim: Any


def build_execution(cfg: ExperimentConfig) -> BuiltExecution:
    """The goal and the simulator of an execution run, unchecked (a worker of a
    job whose launcher checked the config; a run checks them with
    `cgda_jax.experiment.validate.check_and_build`)."""
    goal, demos, gen = build_goal(cfg)
    waypoint_s = default_waypoint_s(demos, len(goal))
    return BuiltExecution(goal, demos, gen, waypoint_s,
                          build_simulator(cfg, waypoint_s, goal))


def build_control(cfg: ExperimentConfig):
    """The `cgda_jax.sim.control.Control` of ``[robot.control]``.

    Raises:
        ConfigError: a bad value, naming the key.
    """
    import dataclasses

    from cgda_jax.sim.control import Control

    try:
        return Control.from_dict(dataclasses.asdict(cfg.robot.control))
    except ValueError as err:
        raise ConfigError(f"key 'robot.control': {err}") from None


def nested_limits(limits: dict) -> dict:
    """``robot.limits`` with dotted keys (``effort.r_elbow = 20`` from a ``--set``
    override) nested as tables: ``{"effort": {"r_elbow": 20}}``.

    Raises:
        ConfigError: a kind given both as one number and per joint.
    """
    out: dict = {}
    for key, value in limits.items():
        kind, _, joint = str(key).partition(".")
        if not joint:
            if isinstance(out.get(kind), dict) and not isinstance(value, dict):
                raise ConfigError(f"key 'robot.limits.{kind}': given both as one "
                                  "number and per joint")
            out[kind] = {**out.get(kind, {}), **value} if isinstance(value, dict) \
                else value
            continue
        table = out.setdefault(kind, {})
        if not isinstance(table, dict):
            raise ConfigError(f"key 'robot.limits.{key}': robot.limits.{kind} is "
                              "already one number for every joint")
        table[joint] = value
    return out


def build_feasibility(cfg: ExperimentConfig, robot, scene):
    """The `cgda_jax.sim.feasibility.Feasibility` of ``[feasibility]`` and
    ``robot.limits`` (None with ``strategy.feasibility`` off).  In dynamic mode the
    pairs that the physics itself collides (the contact geoms against the objects)
    are left to it.

    Raises:
        ConfigError: a bad limit or an unknown excluded geom, naming the key.
    """
    if not cfg.strategy.feasibility:
        return None
    from cgda_jax.sim.feasibility import Feasibility, scene_obstacles

    f = cfg.feasibility
    try:
        return Feasibility(
            robot, nested_limits(cfg.robot.limits) or None, scene_obstacles(scene),
            penetration=f.penetration, penalty=f.penalty, collisions=f.collisions,
            self_collision=f.self_collision, exclude=list(f.exclude),
            samples=f.samples, margin=f.margin, certify=f.certify,
            physics_contacts=cfg.robot.mode == "dynamic",
            max_step=math.radians(f.max_step_deg), geometry=f.geometry,
            tracking_deg=f.tracking_deg, saturation=f.saturation)
    except KeyError as e:
        raise ConfigError(f"key 'feasibility.exclude': {e.args[0]}") from None
    except ValueError as e:
        raise ConfigError(f"key 'robot.limits': {e}") from None
