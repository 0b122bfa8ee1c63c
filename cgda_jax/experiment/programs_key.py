"""What determines a run's compiled programs, as one key taken before tracing
(`run_programs_key`; `cgda_jax.programs.program_scope` uses it): the resolved
config (its output section aside), the content of every file the run can read (the
robot model's folder, the built-in models with their object pieces, the data
folder) and the environment (`cgda_jax.programs.environment_digest`: the package's
source, the libraries' versions, backend and devices).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os

from cgda_jax.builtin import models_dir
from cgda_jax.experiment.config import XGNITIVE_ENV, ExperimentConfig
from cgda_jax.experiment.locate import resolve_data_dir, resolve_model
from cgda_jax.numerics import exact_matmuls
from cgda_jax.programs import environment_digest, files_digest

__all__ = ["run_programs_key"]


def _inputs(cfg: ExperimentConfig) -> list:
    """The files and folders the run can read."""
    paths = [models_dir()]
    try:
        paths.append(resolve_model(cfg.robot.model).parent)
    except FileNotFoundError:
        pass  # a recognition run names no robot it uses
    if cfg.data.data_dir or os.environ.get(XGNITIVE_ENV):
        try:
            paths.append(resolve_data_dir(cfg))
        except (FileNotFoundError, ValueError):
            pass
    return paths


def run_programs_key(cfg: ExperimentConfig, phase: str) -> str | None:
    """The key of the programs that ``phase`` (``"check"``, ``"compute"``) of a run
    of ``cfg`` compiles, or None when its input files are too large to read for
    a key (`cgda_jax.programs.files_digest`)."""
    exact_matmuls()  # the run sets it while building: its key sees it as the run does
    files = files_digest(_inputs(cfg))
    if files is None:
        return None
    table = dataclasses.asdict(cfg)
    # where results go and which are drawn change no program of the run: a run
    # with its figures or video off finds those of one with them on (the drawing
    # runs after the run's programs and compiles its own, by their own keys)
    table.pop("output", None)
    text = json.dumps([phase, table, files, environment_digest(),
                       os.environ.get(XGNITIVE_ENV, "")], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()
