"""The files and folders a config names: the robot model (a path or a built-in name),
the xgnitive data folder, an execution run's own demonstration files, a recognition
run's recordings per action. Each error names the config key.
"""

from __future__ import annotations

import os
import pathlib

from cgda_jax.experiment.config import XGNITIVE_ENV, ConfigError, ExperimentConfig


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


def demonstration_files(cfg: ExperimentConfig) -> list[pathlib.Path]:
    """An execution run's own demonstrations: ``data.source = "csv"``: the ``.csv``
    files of ``data.data_dir`` (as ``cgda track --out`` writes them); ``"video"``:
    its recordings (videos, frame folders, recording folders); in name order."""
    d = cfg.data
    what = "demonstration CSV files" if d.source == "csv" else "recordings (videos)"
    if not d.data_dir:
        raise ConfigError(f"key 'data.data_dir' is empty: point it at a folder of {what}")
    root = pathlib.Path(d.data_dir).expanduser()
    if not root.is_dir():
        raise FileNotFoundError(f"folder not found: {root} (key 'data.data_dir')")
    if d.source == "csv":
        files = sorted(root.glob("*.csv"))
    else:
        files = sorted(p for p in root.iterdir() if not p.name.startswith("."))
    if not files:
        raise ConfigError(f"key 'data.data_dir': {root} holds no {what}")
    return files


def video_folders(cfg: ExperimentConfig) -> dict[str, list[pathlib.Path]]:
    """``data.source = "video"``: action name -> its recordings (the entries of
    ``data.data_dir/<action>/``, in name order); each action needs more than
    ``data.n_train`` of them (the first ``n_train`` generalize, the rest are tests)."""
    d = cfg.data
    if not d.data_dir:
        raise ConfigError("key 'data.data_dir' is empty: point it at a folder with one "
                          "folder of recordings (videos) per action")
    root = pathlib.Path(d.data_dir).expanduser()
    if not root.is_dir():
        raise FileNotFoundError(f"video folder not found: {root} (key 'data.data_dir')")
    actions = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))
    if len(actions) < 2:
        raise ConfigError(f"key 'data.data_dir': {root} holds {len(actions)} action "
                          "folder(s); recognition needs at least 2")
    out = {}
    for a in actions:
        videos = sorted(p for p in a.iterdir() if not p.name.startswith("."))
        if not 1 <= d.n_train < len(videos):
            raise ConfigError(
                f"key 'data.n_train' = {d.n_train}: {a} holds {len(videos)} "
                "recording(s); need 1 <= n_train < that (the rest are the tests)")
        out[a.name] = videos
    if d.color != "auto":
        from cgda_jax.vision.blob import ColorRange

        try:
            ColorRange.parse(d.color)
        except ValueError as err:
            raise ConfigError(f"key 'data.color': {err}") from None
    return out
