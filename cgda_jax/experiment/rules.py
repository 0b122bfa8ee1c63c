"""The value rules of a config: choices, ranges, the world and object-scene tables
(`validate_config`); the files and folders it names are found by
`cgda_jax.experiment.locate`. Deeper checks that build the goal,
robot and algorithm are in `cgda_jax.experiment.validate`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from cgda_jax.experiment.config import (
    KINDS,
    OBJECT_SOURCES,
    SCENES,
    SOURCES,
    ConfigError,
    ExperimentConfig,
    StrategyConfig,
)
from cgda_jax.experiment.locate import (
    demonstration_files,
    resolve_data_dir,
    resolve_model,
    video_folders,
)
from cgda_jax.sizes import MAX_KNOTS

#: Intervals of one generalization (mean demonstration duration / ``interval_s``).
MAX_INTERVALS = MAX_KNOTS


def _choice(value: str, options: Sequence[str], key: str) -> None:
    if value not in options:
        raise ConfigError(f"key '{key}': {value!r} is not one of {list(options)}")


def validate_config(cfg: ExperimentConfig) -> None:
    """Check values and that the files and folders named by ``cfg`` exist.

    Raises:
        ConfigError / FileNotFoundError naming the key or the path.
    """
    _choice(cfg.kind, KINDS, "kind")
    _choice(cfg.data.source, SOURCES, "data.source")
    _choice(cfg.data.method, ("paper", "xgnitive"), "data.method")
    if not cfg.data.interval_s > 0:
        raise ConfigError(f"key 'data.interval_s' must be > 0, got {cfg.data.interval_s}")
    _validate_selection(cfg)
    if cfg.kind == "recognition":
        if cfg.data.source not in ("synthetic", "video", "xgnitive"):
            raise ConfigError("key 'data.source': recognition runs on 'synthetic', "
                              "'video' or 'xgnitive' data")
        if cfg.data.source == "video":
            _choice(cfg.data.features, ("marker", "spatial", "image"), "data.features")
            video_folders(cfg)
        elif cfg.data.source == "xgnitive":
            resolve_data_dir(cfg)
        else:
            _choice(cfg.data.features, ("marker", "spatial", "arm"), "data.features")
        _choice(cfg.recognition.split, ("first", "leave_one_out"), "recognition.split")
        _choice(cfg.recognition.metric, ("dtw", "dtw_multi", "euclidean"),
                "recognition.metric")
        _choice(cfg.recognition.query, ("reduced", "raw"), "recognition.query")
        if cfg.data.source == "synthetic" and not (
            1 <= cfg.data.n_train < cfg.data.n_repetitions
        ):
            raise ConfigError(
                f"keys 'data.n_train'={cfg.data.n_train} and 'data.n_repetitions'="
                f"{cfg.data.n_repetitions}: need 1 <= n_train < n_repetitions"
            )
        return
    if cfg.data.source == "synthetic":
        raise ConfigError(
            "key 'data.source': execution needs a goal: 'clean_circle', 'paint_ramp', "
            "'xgnitive', 'move_box', 'rotate_valve', 'csv' or 'video'"
        )
    if cfg.data.source == "xgnitive":
        resolve_data_dir(cfg)
    if cfg.data.source in ("csv", "video"):
        demonstration_files(cfg)
    _choice(cfg.scene.kind, SCENES, "scene.kind")
    _validate_objects(cfg)
    from cgda_jax.strategies import STRATEGIES

    _choice(cfg.strategy.name, list(STRATEGIES), "strategy.name")
    _choice(cfg.robot.mode, ("kinematic", "dynamic"), "robot.mode")
    _choice(cfg.robot.physics, ("auto", "mjx", "mujoco"), "robot.physics")
    for key in ("waypoint_s", "timestep"):
        if not getattr(cfg.robot, key) >= 0:
            raise ConfigError(f"key 'robot.{key}' must be >= 0 (0 = default)")
    if not 0 < cfg.robot.move_fraction <= 1:
        raise ConfigError("key 'robot.move_fraction' must be in (0, 1]")
    settings = STRATEGIES[cfg.strategy.name].settings
    for key in SET_BY_CONFIG:  # checked by the strategy's settings, as in Python
        problem = settings.option_problem(key, getattr(cfg.strategy, key))
        if problem:
            raise ConfigError(f"key 'strategy.{key}' {problem}")
    _validate_feasibility(cfg)
    _validate_reality(cfg)
    check_strategy_options(cfg.strategy)
    if not cfg.robot.joints:
        raise ConfigError("key 'robot.joints' is empty: name the joints to evolve")
    resolve_model(cfg.robot.model)
    if cfg.world.objects or cfg.scene.kind == "objects":
        validate_world(cfg)


def _validate_selection(cfg: ExperimentConfig) -> None:
    """``[selection]`` and ``data.irrelevant``."""
    from cgda_jax.select import NORMALIZATIONS

    s = cfg.selection
    _choice(s.normalization, NORMALIZATIONS, "selection.normalization")
    if not math.isfinite(s.alpha):
        raise ConfigError(f"key 'selection.alpha' must be a finite number, got "
                          f"{s.alpha}")
    if s.features and cfg.kind != "recognition":
        raise ConfigError("key 'selection.features': feature selection is for "
                          "recognition (an execution goal has the scene's features); "
                          "'selection.demonstrations' applies to both")
    if cfg.data.irrelevant < 0 or (cfg.data.irrelevant and not (
            cfg.kind == "recognition" and cfg.data.source == "synthetic")):
        raise ConfigError(f"key 'data.irrelevant' must be >= 0 and is for synthetic "
                          f"recognition data, got {cfg.data.irrelevant}")


def _validate_feasibility(cfg: ExperimentConfig) -> None:
    """``[feasibility]`` values and the kinds of ``robot.limits`` (the joints and
    numbers are checked against the model when the simulator is built)."""
    f = cfg.feasibility
    for key in ("penetration", "penalty", "max_step_deg", "tracking_deg"):
        v = getattr(f, key)
        if not (math.isfinite(v) and v > 0):
            raise ConfigError(f"key 'feasibility.{key}' must be a number > 0, got {v}")
    if f.samples < 1:
        raise ConfigError(f"key 'feasibility.samples' must be >= 1, got {f.samples}")
    if not (math.isfinite(f.saturation) and 0 <= f.saturation <= 1):
        raise ConfigError(f"key 'feasibility.saturation' must be in [0, 1], got "
                          f"{f.saturation}")
    from cgda_jax.sim.feasibility import GEOMETRIES

    if f.geometry not in GEOMETRIES:
        raise ConfigError(f"key 'feasibility.geometry' must be one of "
                          f"{list(GEOMETRIES)}, got {f.geometry!r}")
    if not (math.isfinite(f.margin) and 0 <= f.margin < f.penetration):
        raise ConfigError(f"key 'feasibility.margin' must be >= 0 and below "
                          f"'feasibility.penetration' ({f.penetration:g} m), got "
                          f"{f.margin}")
    from cgda_jax.sim.limits import KINDS as LIMIT_KINDS

    for key in cfg.robot.limits:
        kind = str(key).partition(".")[0]  # a --set override: "effort.r_elbow"
        if kind not in LIMIT_KINDS:
            raise ConfigError(f"key 'robot.limits.{kind}': unknown; the limits are "
                              f"{list(LIMIT_KINDS)}")


def _validate_reality(cfg: ExperimentConfig) -> None:
    """``[reality]``: each perturbation a number or a range of its kind; a mismatched
    world needs dynamic mode."""
    from cgda_jax.reality.mismatch import Mismatch

    try:
        mm = Mismatch.from_dict(cfg.reality.mismatch_table())
    except ValueError as e:
        raise ConfigError(str(e)) from None
    if isinstance(mm.joint_offset_deg, dict):
        unknown = sorted(set(mm.joint_offset_deg) - set(cfg.robot.joints))
        if unknown:
            raise ConfigError(f"key 'reality.joint_offset_deg': joint(s) {unknown} "
                              f"are not robot.joints {list(cfg.robot.joints)}")
    st = cfg.reality.step_tolerance
    if not (math.isfinite(st) and st >= 0):
        raise ConfigError(f"key 'reality.step_tolerance' = {st}: must be >= 0 (0: the "
                          "strategy's tolerance)")
    if st > cfg.strategy.tolerance:
        raise ConfigError(f"key 'reality.step_tolerance' = {st} is above "
                          f"strategy.tolerance = {cfg.strategy.tolerance}: a step "
                          "would stop before its own goal is met")
    if cfg.reality.enabled and cfg.robot.mode != "dynamic":
        raise ConfigError("key 'reality.enabled': a mismatched world is physics; it "
                          "needs robot.mode = \"dynamic\"")


def _validate_objects(cfg: ExperimentConfig) -> None:
    """Object sources and the objects scene: keys that need no model."""
    d, sc = cfg.data, cfg.scene
    if d.source in OBJECT_SOURCES:
        n = 2 if d.source == "move_box" else 1
        unit = "[x, y] in metres" if n == 2 else "[angle] in radians"
        for key in ("start", "end"):
            v = getattr(d, key)
            if v and len(v) != n:
                raise ConfigError(f"key 'data.{key}': {d.source} takes {unit}, got {v}")
        if not d.duration_s >= 0:
            raise ConfigError("key 'data.duration_s' must be >= 0 (0 = default)")
        if sc.kind != "objects":
            raise ConfigError(f"key 'scene.kind': data.source = '{d.source}' gives "
                              "object features; use scene.kind = 'objects'")
    if sc.kind != "objects":
        for key in ("features", "goal_path", "goal_path_site"):
            if getattr(sc, key):
                raise ConfigError(f"key 'scene.{key}': only for scene.kind = 'objects'")
        return
    if sc.params:
        raise ConfigError("key 'scene.params': the objects scene takes none; declare "
                          "[[scene.features]] instead")
    if not sc.features:
        raise ConfigError("key 'scene.features' is empty: declare what the scene reads, "
                          "e.g. [[scene.features]] body = \"box\", quantity = \"xy\"")
    from cgda_jax.sim.features import FeatureSpec

    for i, entry in enumerate(sc.features):
        try:
            FeatureSpec.from_dict(entry)
        except ValueError as err:
            raise ConfigError(f"key 'scene.features[{i}]': {err}") from None


def validate_world(cfg: ExperimentConfig):
    """Compose and compile the world (cheap) and resolve the scene's feature names:
    unknown pieces, keys, geoms, bodies, joints give one line naming the key.

    Returns:
        The compiled ``mujoco.MjModel`` of robot + objects.
    """
    from cgda_jax.sim.world import compile_world

    path = resolve_model(cfg.robot.model)
    try:
        model = compile_world(path, cfg.world.objects, cfg.world.contact_geoms)
    except (ValueError, KeyError, FileNotFoundError) as err:
        msg = err.args[0] if err.args else str(err)
        key = ("world.contact_geoms" if isinstance(err, KeyError)
               else "world.objects")
        raise ConfigError(f"key '{key}': {msg}") from None
    if cfg.scene.kind == "objects":
        from cgda_jax.sim.features import FeatureSet

        try:
            FeatureSet(model, cfg.scene.features)
        except (ValueError, KeyError) as err:
            msg = err.args[0] if err.args else str(err)
            raise ConfigError(f"key 'scene.features': {msg}") from None
        site = cfg.scene.goal_path_site
        if site:
            import mujoco

            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site) < 0:
                sites = [model.site(i).name for i in range(model.nsite)]
                raise ConfigError(f"key 'scene.goal_path_site': site {site!r} not "
                                  f"found; the world has sites {sites}")
    return model


def check_interval_count(demos: Sequence, interval_s: float, method: str = "paper",
                         key: str = "data.interval_s") -> None:
    """The generalization of ``demos`` at ``interval_s`` has at most `MAX_INTERVALS`
    intervals (checked before `cgda_jax.generalization.generalize` allocates them)."""
    if not demos or not math.isfinite(interval_s) or not interval_s > 0:
        return  # generalize names these itself
    durations = np.asarray([float(d.duration) for d in demos])
    if method == "xgnitive":
        durations = np.ceil(durations)
    mean = float(np.mean(durations))
    n = mean / interval_s
    if not n <= MAX_INTERVALS:
        raise ConfigError(
            f"key '{key}': {interval_s:g} s cuts the {mean:.3g} s demonstrations into "
            f"{n:.3g} intervals, more than {MAX_INTERVALS:,}; use a larger interval_s"
        )


def strategy_function(name: str) -> Callable:
    """``run_<name>`` of `cgda_jax.strategies` for a name of its `STRATEGIES`."""
    from cgda_jax import strategies

    if name not in strategies.STRATEGIES:
        raise ConfigError(f"key 'strategy.name': strategy {name!r} is not available; "
                          f"choose one of {sorted(strategies.STRATEGIES)}")
    return getattr(strategies, f"run_{name}")


#: Settings of a strategy that the config sets itself (not through ``options``).
SET_BY_CONFIG = ("algorithm", "population_size", "tolerance", "max_generations",
                 "chunk_size")


def check_strategy_options(s: StrategyConfig) -> None:
    """Every ``strategy.options`` key must be a field of the strategy's settings
    (`cgda_jax.strategies.STRATEGIES`), and its value of the kind that field
    takes (`cgda_jax.strategies.settings.Settings.option_problem`)."""
    from cgda_jax.strategies import STRATEGIES

    settings = STRATEGIES[s.name].settings
    fields = settings.fields()
    allowed = sorted(k for k in fields if k not in SET_BY_CONFIG)
    for key in s.options:
        if key in SET_BY_CONFIG or key in ("seed", "progress_fn"):
            raise ConfigError(
                f"key 'strategy.options.{key}': set it as 'strategy.{key}' instead"
            )
        if key not in fields:
            raise ConfigError(
                f"key 'strategy.options.{key}': not an option of strategy "
                f"'{s.name}'; it takes {allowed}"
            )
        problem = settings.option_problem(key, s.options[key])
        if problem:
            raise ConfigError(f"key 'strategy.options.{key}': {problem}")


#: ``[output] camera`` keys: the free camera of the robot's video and frames.
CAMERA_KEYS = ("lookat", "distance", "azimuth", "elevation")


def check_camera(camera: dict) -> dict[str, Any]:
    """``[output] camera`` checked: ``lookat`` [x, y, z] m, ``distance`` > 0 m,
    ``azimuth`` and ``elevation`` in degrees (MuJoCo's free camera: azimuth 0 looks
    along +x, 90 along +y; elevation < 0 looks down); the values given.

    Raises:
        ConfigError: an unknown key or a bad value, naming the key.
    """
    out: dict[str, Any] = {}
    for key, value in dict(camera or {}).items():
        where = f"key 'output.camera.{key}'"
        if key not in CAMERA_KEYS:
            raise ConfigError(f"{where}: unknown; the camera keys are "
                              f"{', '.join(CAMERA_KEYS)}")
        if key == "lookat":
            v = np.asarray(value, dtype=object)
            if v.shape != (3,) or not all(isinstance(x, (int, float))
                                          and not isinstance(x, bool)
                                          and math.isfinite(x) for x in v):
                raise ConfigError(f"{where} = {value!r}: expected [x, y, z] in metres")
            out[key] = np.asarray(value, float)
            continue
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or not math.isfinite(value) or (key == "distance" and value <= 0)):
            raise ConfigError(f"{where} = {value!r}: expected a finite number"
                              + (" > 0 (metres)" if key == "distance" else
                                 " (degrees)"))
        out[key] = float(value)
    return out
