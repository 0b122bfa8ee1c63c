"""Experiment configs: typed schema, TOML reading and writing, overrides, validation.

A config is :class:`ExperimentConfig`: typed defaults in code, overridden by a TOML
file, overridden again by dotted ``key=value`` settings (``strategy.population_size=64``).
Unknown keys and wrong types are errors that name the key (and the file).
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import tomllib
import typing
from collections.abc import Mapping, Sequence
from typing import Any

import tomli_w

from cgda_jax.experiment.sections import (
    DataConfig,
    FeasibilityConfig,
    OutputConfig,
    RealityConfig,
    RecognitionConfig,
    RobotConfig,
    SceneConfig,
    SelectionConfig,
    StrategyConfig,
    WorldConfig,
)

KINDS = ("recognition", "execution")
SOURCES = ("synthetic", "clean_circle", "paint_ramp", "xgnitive", "move_box",
           "rotate_valve", "video", "csv")
SCENES = ("marker", "paint", "objects")
#: Sources whose demonstrations are object features (goal columns = the scene's).
OBJECT_SOURCES = ("move_box", "rotate_valve")
XGNITIVE_ENV = "CGDA_XGNITIVE_DIR"


class ConfigError(ValueError):
    """A bad configuration: unknown key, wrong type, bad value, missing file."""


# --------------------------------------------------------------------------- config


@dataclasses.dataclass
class ExperimentConfig:
    """A whole experiment (see the module docstring)."""

    name: str = "experiment"
    kind: str = "recognition"
    description: str = ""
    data: DataConfig = dataclasses.field(default_factory=DataConfig)
    recognition: RecognitionConfig = dataclasses.field(default_factory=RecognitionConfig)
    selection: SelectionConfig = dataclasses.field(default_factory=SelectionConfig)
    robot: RobotConfig = dataclasses.field(default_factory=RobotConfig)
    world: WorldConfig = dataclasses.field(default_factory=WorldConfig)
    scene: SceneConfig = dataclasses.field(default_factory=SceneConfig)
    strategy: StrategyConfig = dataclasses.field(default_factory=StrategyConfig)
    feasibility: FeasibilityConfig = dataclasses.field(
        default_factory=FeasibilityConfig)
    output: OutputConfig = dataclasses.field(default_factory=OutputConfig)
    reality: RealityConfig = dataclasses.field(default_factory=RealityConfig)


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


def merge_table(obj: Any, table: Mapping[str, Any], prefix: str = "") -> None:
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
            merge_table(getattr(obj, k), v, key + ".")
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
                prefix = ".".join(parts[:i]) + "." if i else ""
                merge_table(obj, {part: current}, prefix)
                return
            obj = getattr(obj, part, None)
    for part in reversed(parts):
        table = {part: table}
    merge_table(cfg, table)


#: Config keys holding a file or folder: a relative one in a file is relative to it.
PATH_KEYS = (("robot", "model"), ("data", "data_dir"))


def _beside(raw: Any, folder: pathlib.Path) -> str | None:
    """A `PATH_KEYS` value made relative to ``folder``: a relative path there becomes
    that folder's (absolute) path, except a bare file name that is not there (a
    built-in model's name); None where it stays as it is."""
    if not isinstance(raw, str) or not raw:
        return None
    p = pathlib.Path(raw).expanduser()
    if p.is_absolute() or raw.startswith("~"):
        return None
    beside = (folder / p).resolve()
    return str(beside) if beside.exists() or p.name != raw else None


def _relative_to(cfg: ExperimentConfig, table: Mapping[str, Any],
                 folder: pathlib.Path) -> None:
    """The `PATH_KEYS` that ``table`` (a config file's, or the ``--set`` ones) sets,
    made relative to ``folder`` (`_beside`), so that the saved config still
    resolves from its results folder."""
    for section, key in PATH_KEYS:
        raw = (table.get(section) or {}).get(key) if isinstance(
            table.get(section), Mapping) else None
        path = _beside(raw, folder)
        if path is not None:
            setattr(getattr(cfg, section), key, path)


def load_config(
    path: str | os.PathLike | None = None, overrides: Sequence[str] = ()
) -> ExperimentConfig:
    """Defaults, then the TOML file at ``path``, then ``key=value`` overrides.

    File and folder names in the file (`PATH_KEYS`) are relative to its folder,
    those of an override to the current folder.

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
            table = tomllib.loads(path.read_text(encoding="utf-8"))
        except tomllib.TOMLDecodeError as e:
            raise ConfigError(f"{path}: not valid TOML: {e}") from None
        except UnicodeDecodeError as e:
            raise ConfigError(f"{path}: not a UTF-8 text file (byte {e.start}: "
                              f"{e.reason}); a TOML config is UTF-8") from None
        if not table:
            raise ConfigError(f"{path}: the file sets nothing (an empty config); "
                              f"start from a built-in one (`cgda list`, "
                              f"`cgda run NAME --dry-run` prints it)")
        try:
            merge_table(cfg, table)
        except ConfigError as e:
            raise ConfigError(f"{path}: {e}") from None
        if "name" not in table:
            cfg.name = path.stem
        _relative_to(cfg, table, path.parent)
    for setting in overrides:
        try:
            _apply_override(cfg, setting)
        except ConfigError as e:
            raise ConfigError(f"--set: {e}") from None
        section, _, key = setting.partition("=")[0].strip().partition(".")
        if (section, key) in PATH_KEYS:
            value = getattr(getattr(cfg, section), key)
            _relative_to(cfg, {section: {key: value}}, pathlib.Path.cwd())
    return cfg


def dump_config(cfg: ExperimentConfig, applicable_only: bool = False) -> str:
    """The resolved config as TOML text (loads back to an equal config); with
    ``applicable_only`` only the keys that apply to this experiment
    (`applicable_keys`: what ``cgda run --dry-run`` prints)."""
    table = dataclasses.asdict(cfg)
    return tomli_w.dumps(applicable_keys(cfg, table) if applicable_only else table)


_GENERALIZE = ("interval_s", "method", "scale")
#: ``[data]`` keys read per ``data.source`` (beside ``source``).
DATA_KEYS: dict[str, tuple[str, ...]] = {
    "synthetic": ("features", "n_repetitions", "n_train", "seed", *_GENERALIZE),
    "clean_circle": ("centre", "diameter", "n_demos", "seed", *_GENERALIZE),
    "paint_ramp": ("goal_points", "scale"),
    "xgnitive": ("data_dir", "action", "stream", "columns", "force_columns", "n_train",
                 *_GENERALIZE),
    "csv": ("data_dir", "columns", *_GENERALIZE),
    "video": ("data_dir", "features", "color", "n_train", *_GENERALIZE),
    "move_box": ("n_demos", "seed", "start", "end", "curve", "object", "duration_s",
                 *_GENERALIZE),
    "rotate_valve": ("n_demos", "seed", "start", "end", "object", "duration_s",
                     *_GENERALIZE),
}
#: Dynamic mode's ``[robot]`` keys (left out of a kinematic run's dump).
DYNAMIC_ROBOT_KEYS = ("physics", "timestep", "reduce", "control")


def applicable_keys(cfg: ExperimentConfig, table: dict) -> dict:
    """``table`` (``asdict(cfg)``) without the keys that do not apply to ``cfg``:
    ``[data]`` keys of other sources, ``[recognition]`` of an execution (the
    robot, scene, strategy, feasibility and reality of a recognition), dynamic
    mode's robot keys in kinematic mode, ``[feasibility]`` with
    ``strategy.feasibility`` off, a disabled ``[reality]``'s settings, the scene
    keys its kind does not read."""
    out = {k: v for k, v in table.items()}
    keep = DATA_KEYS.get(cfg.data.source)
    if keep is not None:
        out["data"] = {k: v for k, v in table["data"].items()
                       if k == "source" or k in keep}
    if cfg.kind == "recognition":
        for section in ("robot", "world", "scene", "strategy", "feasibility",
                        "reality"):
            out.pop(section, None)
        out["data"].pop("action", None)  # xgnitive: both actions
        return out
    out["data"].pop("n_train", None)
    out.pop("recognition", None)
    if cfg.robot.mode != "dynamic":
        out["robot"] = {k: v for k, v in table["robot"].items()
                        if k not in DYNAMIC_ROBOT_KEYS}
    if not cfg.strategy.feasibility:
        out.pop("feasibility", None)
    if "reality" in out and not cfg.reality.enabled:
        out["reality"] = {"enabled": False}
    scene_keys = {"marker": ("kind",), "paint": ("kind", "params")}.get(cfg.scene.kind)
    if scene_keys is not None:
        out["scene"] = {k: v for k, v in table["scene"].items() if k in scene_keys}
    if not (cfg.world.objects or cfg.world.contact_geoms):
        out.pop("world", None)
    return out
