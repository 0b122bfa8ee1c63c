"""Experiments: typed config -> objects -> run -> results folder.

A config is :class:`ExperimentConfig`: typed defaults in code, overridden by a TOML
file, overridden again by dotted ``key=value`` settings (``strategy.population_size=64``).
Unknown keys and wrong types are errors that name the key (and the file). Two kinds:

- ``recognition``: synthetic MOVE/ROTATE/CLEAN/PAINT demonstrations (paper 4.1-4.2):
  ``n_train`` repetitions generalize each action, the next one is the test query;
  writes the cost matrix (paper Tables 2-4) and the accuracy.
- ``execution``: a goal feature trajectory (generalized clean circle, the paint ramp,
  or generalized real TEO demonstrations) executed on a simulated robot by an
  evolutionary strategy (FTE / IE / IET / OET, paper 3-4).

Each run writes to its folder: ``config.toml`` (resolved), ``result.json``,
``arrays.npz``, ``plots/*.png`` and ``report.md``.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import json
import logging
import math
import os
import pathlib
import time
import tomllib
import typing
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

__all__ = [
    "ConfigError",
    "DataConfig",
    "ExperimentConfig",
    "OutputConfig",
    "RecognitionConfig",
    "RobotConfig",
    "SceneConfig",
    "StrategyConfig",
    "dump_config",
    "load_config",
    "run_experiment",
    "validate_config",
]

KINDS = ("recognition", "execution")
SOURCES = ("synthetic", "clean_circle", "paint_ramp", "xgnitive")
STRATEGIES = ("fte", "ie", "iet", "oet")
SCENES = ("marker", "paint")
XGNITIVE_ENV = "CGDA_XGNITIVE_DIR"

log = logging.getLogger("cgda_jax")


class ConfigError(ValueError):
    """A bad configuration: unknown key, wrong type, bad value, missing file."""


# --------------------------------------------------------------------------- config


@dataclasses.dataclass
class DataConfig:
    """Where the demonstrations (or the goal) come from.

    Attributes:
        source: "synthetic" (MOVE/ROTATE/CLEAN/PAINT, recognition), "clean_circle"
            (circle demos -> clean goal), "paint_ramp" (0 -> 100 % in
            ``goal_points`` steps) or "xgnitive" (real TEO demonstrations).
        features: synthetic: "marker" (8 object features), "spatial" (X, Y, Z) or
            "arm" (12 arm-point coordinates).
        n_repetitions, n_train: synthetic: repetitions per action; the first
            ``n_train`` generalize, the rest are test queries.
        seed: seed of the synthetic demonstrations.
        interval_s, method: generalization interval (s) and method ("paper" |
            "xgnitive").
        centre, diameter, n_demos: clean circle (metres, waist frame).
        goal_points: paint ramp length.
        data_dir: xgnitive data folder (default: $CGDA_XGNITIVE_DIR).
        action, stream, columns: xgnitive action ("paint" | "iron"), stream and
            feature columns (see ``cgda_jax.data.XGNITIVE_COLUMNS``).
        scale: factor applied to the goal's features (e.g. unit changes).
    """

    source: str = "synthetic"
    features: str = "marker"
    n_repetitions: int = 7
    n_train: int = 6
    seed: int = 0
    interval_s: float = 1.0
    method: str = "paper"
    centre: list[float] = dataclasses.field(default_factory=lambda: [0.55, -0.45, 0.35])
    diameter: float = 0.30
    n_demos: int = 6
    goal_points: int = 17
    data_dir: str = ""
    action: str = "paint"
    stream: str = "paintSquaresOnScreen"
    columns: list[str] = dataclasses.field(default_factory=lambda: ["percent"])
    scale: float = 1.0


@dataclasses.dataclass
class RecognitionConfig:
    """Recognition: metric ("dtw" | "dtw_multi" | "euclidean"), query form, samples.

    ``query = "reduced"`` compares the test repetition after the same interval
    averaging as the generalized actions (the paper's "reduced test actions");
    ``"raw"`` compares the raw test samples.
    """

    metric: str = "dtw"
    query: str = "reduced"
    n_samples: int = 100


@dataclasses.dataclass
class RobotConfig:
    """The robot: MJCF model (built-in name or path), evolved joints, marker site.

    ``fixed`` holds joint values in DEGREES (converted to radians for the robot).
    """

    model: str = "teo.xml"
    joints: list[str] = dataclasses.field(
        default_factory=lambda: ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"]
    )
    marker_site: str = "marker"
    fixed: dict[str, float] = dataclasses.field(
        default_factory=lambda: {"r_forearm_rotation": 45.0}
    )
    mode: str = "kinematic"
    substeps: int = 8


@dataclasses.dataclass
class SceneConfig:
    """The scene: "marker" (features X, Y, Z) or "paint" (painted %, a 4 x 4 wall).

    ``params`` go to the scene: for "paint", keyword arguments of
    ``PaintWall.grid`` (x, ys, zs, root_height, radius, size).
    """

    kind: str = "marker"
    params: dict[str, Any] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class StrategyConfig:
    """The execution strategy and its evolutionary algorithm (evosax name).

    ``options`` are extra keyword arguments of the strategy function (e.g.
    ``stagnation`` for FTE).
    """

    name: str = "ie"
    algorithm: str = "CMA_ES"
    population_size: int = 16
    tolerance: float = 0.02
    max_generations: int = 100
    seed: int = 0
    chunk_size: int = 10
    options: dict[str, Any] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass
class OutputConfig:
    """Results: ``dir`` (parent folder), ``plots`` on/off, ``render`` on/off.

    ``render`` (execution runs): an animated GIF of the robot executing the best
    trajectory and a strip of frames (paper Fig. 8/11), rendered offscreen by
    MuJoCo (``MUJOCO_GL=egl`` or ``osmesa``). Without a working offscreen OpenGL
    the run goes on and one warning says why nothing was rendered.
    """

    dir: str = "results"
    plots: bool = True
    render: bool = True


@dataclasses.dataclass
class ExperimentConfig:
    """A whole experiment (see the module docstring)."""

    name: str = "experiment"
    kind: str = "recognition"
    description: str = ""
    data: DataConfig = dataclasses.field(default_factory=DataConfig)
    recognition: RecognitionConfig = dataclasses.field(default_factory=RecognitionConfig)
    robot: RobotConfig = dataclasses.field(default_factory=RobotConfig)
    scene: SceneConfig = dataclasses.field(default_factory=SceneConfig)
    strategy: StrategyConfig = dataclasses.field(default_factory=StrategyConfig)
    output: OutputConfig = dataclasses.field(default_factory=OutputConfig)


def _type_name(tp) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def _coerce(value: Any, tp, key: str) -> Any:
    """``value`` checked against the annotation ``tp`` (int accepted for float)."""
    origin = typing.get_origin(tp)
    bad = ConfigError(
        f"key '{key}': expected {_type_name(tp)}, got {type(value).__name__} {value!r}"
    )
    if tp is Any:
        return value
    if origin is list:
        (item,) = typing.get_args(tp)
        if not isinstance(value, list):
            raise bad
        return [_coerce(v, item, f"{key}[{i}]") for i, v in enumerate(value)]
    if origin is dict:
        _, item = typing.get_args(tp)
        if not isinstance(value, dict):
            raise bad
        return {str(k): _coerce(v, item, f"{key}.{k}") for k, v in value.items()}
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad
        return value
    if tp is bool or tp is str:
        if not isinstance(value, tp):
            raise bad
        return value
    raise bad  # pragma: no cover


def _merge(obj: Any, table: Mapping[str, Any], prefix: str = "") -> None:
    """Apply a (nested) table to a config dataclass in place, checking keys and types."""
    hints = typing.get_type_hints(type(obj))
    for k, v in table.items():
        key = f"{prefix}{k}"
        if k not in hints:
            known = ", ".join(f.name for f in dataclasses.fields(obj))
            raise ConfigError(f"unknown key '{key}' (known here: {known})")
        tp = hints[k]
        if dataclasses.is_dataclass(tp):
            if not isinstance(v, Mapping):
                raise ConfigError(f"key '{key}' must be a table, got {v!r}")
            _merge(getattr(obj, k), v, key + ".")
        else:
            setattr(obj, k, _coerce(v, tp, key))


def _parse_value(text: str) -> Any:
    """A TOML value (``64``, ``1e-3``, ``true``, ``[1, 2]``, ``"x"``) or a bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _apply_override(cfg: ExperimentConfig, setting: str) -> None:
    if "=" not in setting:
        raise ConfigError(f"--set {setting!r}: expected key=value, e.g. strategy.seed=3")
    key, text = setting.split("=", 1)
    parts = key.strip().split(".")
    table: Any = _parse_value(text.strip())
    # dict-valued fields accept deeper keys: robot.fixed.r_elbow=30
    obj: Any = cfg
    for i, part in enumerate(parts[:-1]):
        if dataclasses.is_dataclass(obj):
            hints = typing.get_type_hints(type(obj))
            if part in hints and typing.get_origin(hints[part]) is dict:
                sub = ".".join(parts[i + 1:])
                current = dict(getattr(obj, part))
                current[sub] = table
                _merge(obj, {part: current}, ".".join(parts[:i]) + "." if i else "")
                return
            obj = getattr(obj, part, None)
    for part in reversed(parts):
        table = {part: table}
    _merge(cfg, table)


def load_config(
    path: str | os.PathLike | None = None, overrides: Sequence[str] = ()
) -> ExperimentConfig:
    """Defaults, then the TOML file at ``path``, then ``key=value`` overrides.

    Raises:
        ConfigError: unknown key, wrong type, unparsable file (message names the
            key and the file).
        FileNotFoundError: ``path`` does not exist.
    """
    cfg = ExperimentConfig()
    if path is not None:
        path = pathlib.Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"config file not found: {path}")
        try:
            table = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as e:
            raise ConfigError(f"{path}: not valid TOML: {e}") from None
        try:
            _merge(cfg, table)
        except ConfigError as e:
            raise ConfigError(f"{path}: {e}") from None
        if "name" not in table:
            cfg.name = path.stem
    for setting in overrides:
        try:
            _apply_override(cfg, setting)
        except ConfigError as e:
            raise ConfigError(f"--set: {e}") from None
    return cfg


def _choice(value: str, options: Sequence[str], key: str) -> None:
    if value not in options:
        raise ConfigError(f"key '{key}': {value!r} is not one of {list(options)}")


def resolve_model(model: str) -> pathlib.Path:
    """A model file: an existing path, else a built-in name from ``models/``."""
    p = pathlib.Path(model).expanduser()
    if p.is_file():
        return p
    if p.name == model:  # a bare name: try the built-in models
        from cgda_jax.sim.robot import model_path

        try:
            builtin = pathlib.Path(model_path(model))
        except (FileNotFoundError, KeyError, ValueError):
            builtin = None
        if builtin is not None and builtin.is_file():
            return builtin
    raise FileNotFoundError(f"robot model file not found: {model} (key 'robot.model')")


def resolve_data_dir(cfg: ExperimentConfig) -> pathlib.Path:
    """The xgnitive data folder from ``data.data_dir`` or $CGDA_XGNITIVE_DIR."""
    raw = cfg.data.data_dir or os.environ.get(XGNITIVE_ENV, "")
    if not raw:
        raise ConfigError(
            f"key 'data.data_dir' is empty and ${XGNITIVE_ENV} is not set: "
            f"point one of them at your copy of the xgnitive data"
        )
    p = pathlib.Path(raw).expanduser()
    if not p.is_dir():
        raise FileNotFoundError(f"data folder not found: {p} (key 'data.data_dir')")
    return p


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
    if cfg.kind == "recognition":
        if cfg.data.source != "synthetic":
            raise ConfigError("key 'data.source': recognition runs on 'synthetic' data")
        _choice(cfg.data.features, ("marker", "spatial", "arm"), "data.features")
        _choice(cfg.recognition.metric, ("dtw", "dtw_multi", "euclidean"),
                "recognition.metric")
        _choice(cfg.recognition.query, ("reduced", "raw"), "recognition.query")
        if not 1 <= cfg.data.n_train < cfg.data.n_repetitions:
            raise ConfigError(
                f"keys 'data.n_train'={cfg.data.n_train} and 'data.n_repetitions'="
                f"{cfg.data.n_repetitions}: need 1 <= n_train < n_repetitions"
            )
        return
    if cfg.data.source == "synthetic":
        raise ConfigError(
            "key 'data.source': execution needs a goal: 'clean_circle', 'paint_ramp' "
            "or 'xgnitive'"
        )
    if cfg.data.source == "xgnitive":
        resolve_data_dir(cfg)
    _choice(cfg.scene.kind, SCENES, "scene.kind")
    _choice(cfg.strategy.name, STRATEGIES, "strategy.name")
    _choice(cfg.robot.mode, ("kinematic", "dynamic"), "robot.mode")
    for key in ("population_size", "max_generations", "chunk_size"):
        if getattr(cfg.strategy, key) < 1:
            raise ConfigError(f"key 'strategy.{key}' must be >= 1")
    if not cfg.strategy.tolerance > 0:
        raise ConfigError("key 'strategy.tolerance' must be > 0")
    _check_strategy_options(cfg.strategy)
    if not cfg.robot.joints:
        raise ConfigError("key 'robot.joints' is empty: name the joints to evolve")
    resolve_model(cfg.robot.model)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {v!r} as TOML")


def dump_config(cfg: ExperimentConfig) -> str:
    """The resolved config as TOML text (loads back to an equal config)."""
    top, tables = [], []
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if dataclasses.is_dataclass(v):
            lines = [f"[{f.name}]"] + [
                f"{g.name} = {_toml_value(getattr(v, g.name))}" for g in dataclasses.fields(v)
            ]
            tables.append("\n".join(lines))
        else:
            top.append(f"{f.name} = {_toml_value(v)}")
    return "\n".join(top) + "\n\n" + "\n\n".join(tables) + "\n"


# --------------------------------------------------------------------------- running


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _write_json(path: pathlib.Path, data: dict) -> None:
    path.write_text(json.dumps(_jsonable(data), indent=2) + "\n")


def _synthetic(cfg: ExperimentConfig) -> dict:
    from cgda_jax.datasets import SPATIAL_FEATURES, select_features, synthetic_actions

    d = cfg.data
    demos = synthetic_actions(
        d.n_repetitions, d.seed, features="arm" if d.features == "arm" else "marker"
    )
    if d.features == "spatial":
        demos = {a: select_features(v, SPATIAL_FEATURES) for a, v in demos.items()}
    return demos


def run_recognition(cfg: ExperimentConfig, out: pathlib.Path) -> dict:
    """Generalize, then recognize the held-out repetitions (paper Tables 2-4)."""
    from cgda_jax.generalize import generalize
    from cgda_jax.recognize import ActionLibrary, cost_matrix

    d, r = cfg.data, cfg.recognition
    t0 = time.perf_counter()
    demos = _synthetic(cfg)
    library = ActionLibrary.from_demonstrations(
        {a: v[: d.n_train] for a, v in demos.items()}, d.interval_s, d.method
    )
    names = list(library.names)
    tests = [(a, t) for a, v in demos.items() for t in v[d.n_train:]]
    if r.query == "reduced":
        queries = [
            np.asarray(generalize([t], d.interval_s, d.method).sample(r.n_samples))
            for _, t in tests
        ]
    else:
        queries = [t for _, t in tests]
    costs = np.asarray(cost_matrix(queries, library, r.metric, r.n_samples), float)
    recognized = [names[i] for i in costs.argmin(axis=1)]
    truth = [a for a, _ in tests]
    accuracy = float(np.mean([p == t for p, t in zip(recognized, truth)]))
    result = {
        "kind": "recognition",
        "name": cfg.name,
        "features": list(library.feature_names),
        "metric": r.metric,
        "actions": names,
        "queries": [t.name for _, t in tests],
        "truth": truth,
        "cost_matrix": costs,
        "recognized": recognized,
        "accuracy": accuracy,
        "success": accuracy == 1.0,
        "wall_time_s": time.perf_counter() - t0,
    }
    np.savez(out / "arrays.npz", cost_matrix=costs,
             **{f"knots_{a}": np.asarray(library[a].knots) for a in names})
    if cfg.output.plots:
        from cgda_jax import plotting

        plots = out / "plots"
        plotting.plot_cost_matrix(
            costs, [q.lower() for q in truth], names, label=f"{r.metric.upper()} cost",
            title=f"{r.metric.upper()} cost: test (rows) vs generalized",
            path=plots / "cost_matrix.png",
        )
        cols = (list(library.feature_names)[:3] if d.features != "marker"
                else None)
        for a in names:
            plotting.plot_demonstrations(
                demos[a][: d.n_train], library[a], features=cols,
                title=f"{a}: demonstrations and generalization",
                path=plots / f"generalization_{a}.png",
            )
        _close_all()
    return result


def _close_all() -> None:
    import matplotlib.pyplot as plt

    plt.close("all")


def build_goal(cfg: ExperimentConfig) -> tuple[np.ndarray, list, Any]:
    """The goal (N, F) of an execution run, its demonstrations and generalization."""
    from cgda_jax.generalize import generalize

    d = cfg.data
    if d.source == "paint_ramp":
        from cgda_jax.datasets import paint_ramp

        return paint_ramp(d.goal_points) * d.scale, [], None
    if d.source == "clean_circle":
        from cgda_jax.datasets import clean_circle_demos

        demos = clean_circle_demos(d.centre, d.diameter, d.n_demos, d.seed)
    else:
        from cgda_jax.data import load_xgnitive

        demos = load_xgnitive(resolve_data_dir(cfg), d.action, d.stream, d.columns)
    gen = generalize(demos, d.interval_s, d.method, name=cfg.name)
    return np.asarray(gen.knots, float) * d.scale, demos, gen


def build_simulator(cfg: ExperimentConfig):
    """Robot + scene + Simulator from the config."""
    from cgda_jax.sim.execute import Simulator
    from cgda_jax.sim.robot import Robot
    from cgda_jax.sim.scenes import MarkerScene, PaintWall

    rc = cfg.robot
    robot = Robot.from_mjcf(
        resolve_model(rc.model), list(rc.joints), rc.marker_site,
        {k: math.radians(v) for k, v in rc.fixed.items()},
    )
    if cfg.scene.kind == "paint":
        scene = PaintWall.grid(**cfg.scene.params)
    else:
        if cfg.scene.params:
            raise ConfigError("key 'scene.params': the marker scene takes no parameters")
        scene = MarkerScene()
    return Simulator(robot, scene, mode=rc.mode, substeps=rc.substeps)


def strategy_function(name: str) -> Callable:
    """``run_<name>`` from ``cgda_jax`` (or its strategies package)."""
    import cgda_jax

    fn = getattr(cgda_jax, f"run_{name}", None)
    if fn is None:
        try:
            mod = importlib.import_module(f"cgda_jax.strategies.{name}")
        except ModuleNotFoundError:
            raise ConfigError(f"key 'strategy.name': strategy {name!r} is not available") from None
        fn = getattr(mod, f"run_{name}")
    return fn


#: Arguments of ``run_<name>`` that the config sets itself (not through ``options``).
_SET_BY_CONFIG = ("sim", "goal", "algorithm", "population_size", "tolerance",
                  "max_generations", "seed", "chunk_size", "progress_fn")


def _check_strategy_options(s: StrategyConfig) -> None:
    """Every ``strategy.options`` key must be a keyword of ``run_<name>``."""
    params = inspect.signature(strategy_function(s.name)).parameters
    allowed = sorted(k for k in params if k not in _SET_BY_CONFIG)
    for key in s.options:
        if key in _SET_BY_CONFIG:
            raise ConfigError(
                f"key 'strategy.options.{key}': set it as 'strategy.{key}' instead"
            )
        if key not in params:
            raise ConfigError(
                f"key 'strategy.options.{key}': not an option of strategy "
                f"'{s.name}'; it takes {allowed}"
            )


def run_execution(
    cfg: ExperimentConfig, out: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
) -> dict:
    """Build the goal and the simulator, run the strategy, save and plot."""
    goal, demos, gen = build_goal(cfg)
    sim = build_simulator(cfg)
    if goal.shape[1] != sim.n_features:
        raise ConfigError(
            f"the goal has {goal.shape[1]} feature(s) {cfg.data.columns} but the "
            f"'{cfg.scene.kind}' scene gives {sim.n_features} {list(sim.feature_names)}"
        )
    s = cfg.strategy
    res = strategy_function(s.name)(
        sim, goal, algorithm=s.algorithm, population_size=s.population_size,
        tolerance=s.tolerance, max_generations=s.max_generations, seed=s.seed,
        chunk_size=s.chunk_size, progress_fn=progress_fn, **s.options,
    )
    res.save(out)  # result.json + arrays.npz from the strategy
    summary = json.loads((out / "result.json").read_text())
    summary.update({"kind": "execution", "name": cfg.name,
                    "feature_names": list(sim.feature_names)})
    if cfg.output.plots:
        _execution_plots(cfg, out / "plots", res, sim, demos, gen)
    if cfg.output.render:
        summary["render"] = render_execution(cfg, out / "plots", res.joints, sim)
    return summary


def render_execution(cfg: ExperimentConfig, folder: pathlib.Path, joints, sim,
                     *, width: int = 320, height: int = 240, n_strip: int = 8) -> dict:
    """The robot executing ``joints`` (N, DoF): ``execution.gif`` + ``frames.png``.

    Never raises: when offscreen OpenGL (or anything else in rendering) fails,
    logs one warning on the ``cgda_jax`` logger and returns ``{"ok": False,
    "reason": ...}``; otherwise ``{"ok": True, "gif": ..., "frames": ..., "backend": ...}``
    (paths relative to the results folder).
    """
    joints = np.asarray(joints, np.float32)
    paint = getattr(sim.scene, "centres", None) is not None
    # the paint wall is updated per frame: keep every kinematic sub-step there
    fpw = int(sim.substeps) if paint and sim.mode == "kinematic" else 3
    distance = None if paint else 1.6 * float(sim.robot.mj_model.stat.extent)
    try:
        from PIL import Image

        from cgda_jax import plotting
        from cgda_jax.sim.render import render_trajectory

        gif = folder / "execution.gif"
        render_trajectory(sim, joints, gif, frames_per_waypoint=fpw, width=width,
                          height=height, fps=max(4, 2 * fpw), distance=distance)
        with Image.open(gif) as im:
            n_frames = getattr(im, "n_frames", 1)
            points = np.unique(np.linspace(0, len(joints), min(n_strip, len(joints) + 1))
                               .round().astype(int))
            frames = []
            for k in points:
                im.seek(min(int(k) * fpw, n_frames - 1))
                frames.append(np.asarray(im.convert("RGB")))
        plotting.plot_frames(
            frames, labels=["start" if k == 0 else f"point {k}" for k in points],
            title=f"{cfg.name}: robot executing the best trajectory",
            path=folder / "frames.png",
        )
        _close_all()
    except Exception as err:  # no GL, missing library, driver trouble: never fatal
        reason = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
        log.warning("%s: frames not rendered (%s); set MUJOCO_GL=egl or osmesa, or "
                    "output.render=false", cfg.name, reason)
        return {"ok": False, "reason": reason}
    return {"ok": True, "gif": "plots/execution.gif", "frames": "plots/frames.png",
            "backend": os.environ.get("MUJOCO_GL", "")}


def _execution_plots(cfg, plots: pathlib.Path, res, sim, demos, gen) -> None:
    from cgda_jax import plotting

    names = list(sim.feature_names)
    plotting.plot_goal_vs_executed(
        res.goal, res.features, names, tolerance=res.tolerance,
        title=f"{cfg.name}: goal vs executed ({res.strategy.upper()})",
        path=plots / "goal_vs_executed.png",
    )
    hist = np.asarray(res.fitness_history, float)
    plotting.plot_fitness(
        hist, labels=None if hist.ndim == 1 else [f"point {i}" for i in range(len(hist))],
        title=f"{cfg.name}: best fitness per generation", path=plots / "fitness.png",
    )
    if demos and len(names) == 3:
        plotting.plot_demonstrations(
            demos, gen, res.features, title=f"{cfg.name}: demos, goal, executed",
            path=plots / "trajectory_3d.png",
        )
    per_point = res.info.get("point_generations") if isinstance(res.info, dict) else None
    if per_point is not None and hist.ndim == 2:
        plotting.plot_time_per_point(
            per_point, ylabel="generations per point",
            title=f"{cfg.name}: effort per point", path=plots / "effort_per_point.png",
        )
    _close_all()


def _report(cfg: ExperimentConfig, result: dict) -> str:
    lines = [f"# {cfg.name}", ""]
    if cfg.description:
        lines += [cfg.description, ""]
    if result["kind"] == "recognition":
        acts = result["actions"]
        lines += [
            f"Recognition, {len(result['features'])} features "
            f"({', '.join(result['features'])}), metric {result['metric']}.",
            "",
            "| test \\ generalized | " + " | ".join(acts) + " |",
            "|---" * (len(acts) + 1) + "|",
        ]
        for q, row in zip(result["truth"], np.asarray(result["cost_matrix"])):
            best = int(np.argmin(row))
            cells = [f"**{v:.4g}**" if j == best else f"{v:.4g}" for j, v in enumerate(row)]
            lines.append(f"| {q.lower()} | " + " | ".join(cells) + " |")
        lines += ["", f"Accuracy: {result['accuracy']:.0%}."]
    else:
        lines += [
            f"Strategy {result['strategy'].upper()} ({cfg.strategy.algorithm}, population "
            f"{cfg.strategy.population_size}) on {cfg.robot.model}, joints "
            f"{', '.join(cfg.robot.joints)}.",
            "",
            "| figure | value |", "|---|---|",
            f"| success | {result['success']} |",
            f"| points | {result['points']} |",
            f"| max point error | {result['max_point_error']:.4g} "
            f"(tolerance {result['tolerance']:.4g}) |",
            f"| final fitness | {result['final_fitness']:.4g} |",
            f"| generations | {result['generations']} |",
            f"| evaluations | {result['evaluations']} |",
            f"| run time (compiled generations) | {result['wall_time_s']:.2f} s |",
            f"| compile time | {result['compile_time_s']:.2f} s |",
        ]
        render = result.get("render")
        if render and render.get("ok"):
            lines += ["", "The robot executing the best trajectory (paper Fig. 8/11):", "",
                      f"![robot executing]({render['gif']})"]
        elif render:
            lines += ["", f"Frames not rendered: {render['reason']} (set MUJOCO_GL=egl "
                      "or osmesa; `output.render = false` turns rendering off)."]
    plots = sorted(p for p in result.get("plots", []))
    if plots:
        lines += ["", "Plots:", ""] + [f"![{p}]({p})" for p in plots]
    return "\n".join(lines) + "\n"


def run_experiment(
    cfg: ExperimentConfig,
    out: str | os.PathLike | None = None,
    progress_fn: Callable[[dict], None] | None = None,
) -> dict:
    """Validate and run ``cfg``; write the results folder; return the result dict.

    Args:
        cfg: the experiment.
        out: results folder (default ``<output.dir>/<name>``); created if needed.
        progress_fn: called with the strategies' progress dicts (execution).
    """
    validate_config(cfg)
    t0 = time.perf_counter()
    folder = pathlib.Path(out) if out is not None else pathlib.Path(cfg.output.dir) / cfg.name
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "config.toml").write_text(dump_config(cfg))
    if cfg.kind == "recognition":
        result = run_recognition(cfg, folder)
    else:
        result = run_execution(cfg, folder, progress_fn)
    result["plots"] = sorted(
        str(p.relative_to(folder)) for p in (folder / "plots").glob("*.png")
    ) if (folder / "plots").is_dir() else []
    result["total_time_s"] = time.perf_counter() - t0
    _write_json(folder / "result.json", result)
    (folder / "report.md").write_text(_report(cfg, result))
    return result


# --------------------------------------------------------------------------- demo

#: The main job of ``cgda demo``: overrides of the defaults per experiment (the same
#: settings as the files of the same name in the repository's ``experiments/``).
DEMO_EXPERIMENTS: dict[str, dict[str, Any]] = {
    "recognition_all_features": {"kind": "recognition", "data": {"features": "marker"}},
    "recognition_spatial": {"kind": "recognition", "data": {"features": "spatial"}},
    "recognition_arm_points": {"kind": "recognition", "data": {"features": "arm"}},
    "clean_ie": {
        "kind": "execution",
        "data": {"source": "clean_circle"},
        "scene": {"kind": "marker"},
        "strategy": {"name": "ie", "population_size": 32, "tolerance": 0.02,
                     "max_generations": 200},
    },
    "paint_iet": {
        "kind": "execution",
        "data": {"source": "paint_ramp", "goal_points": 17},
        "scene": {"kind": "paint"},
        "strategy": {"name": "iet", "population_size": 32, "tolerance": 3.0,
                     "max_generations": 200},
    },
}

_SMALL = {"strategy": {"max_generations": 100}, "recognition": {"n_samples": 60}}


def demo_configs(small: bool = False) -> list[ExperimentConfig]:
    """The configs of ``cgda demo`` (``small``: fewer generations and samples)."""
    out = []
    for name, table in DEMO_EXPERIMENTS.items():
        cfg = ExperimentConfig(name=name)
        _merge(cfg, table)
        if small:
            _merge(cfg, {k: v for k, v in _SMALL.items()
                         if k == "recognition" or cfg.kind == "execution"})
        out.append(cfg)
    return out
