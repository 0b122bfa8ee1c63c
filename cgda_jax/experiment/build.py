"""Objects from a config: the goal, the simulator and the strategy function."""

from __future__ import annotations

import importlib
import inspect
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from cgda_jax.experiment.config import (
    ConfigError,
    ExperimentConfig,
    StrategyConfig,
    resolve_data_dir,
    resolve_model,
)


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
    from cgda_jax.experiment.validate import check_interval_count

    check_interval_count(demos, d.interval_s, d.method)  # before generalize allocates
    gen = generalize(demos, d.interval_s, d.method, name=cfg.name)
    return np.asarray(gen.knots, float) * d.scale, demos, gen


def default_waypoint_s(demos: list, n_points: int) -> float:
    """Seconds per waypoint from the demonstrations' timing: mean duration / points
    (1 s without demonstrations)."""
    if not demos or n_points < 1:
        return 1.0
    return float(np.mean([d.duration for d in demos])) / n_points


def build_simulator(cfg: ExperimentConfig, waypoint_s: float | None = None):
    """Robot + scene + Simulator from the config.

    Args:
        cfg: the experiment.
        waypoint_s: dynamic mode: seconds per waypoint when ``robot.waypoint_s`` is
            0 (default 1 s; `run_execution` passes `default_waypoint_s`).
    """
    from cgda_jax.sim.execute import Simulator
    from cgda_jax.sim.robot import Robot
    from cgda_jax.sim.scenes import MarkerScene, PaintWall

    rc = cfg.robot
    robot = Robot.from_mjcf(
        resolve_model(rc.model), list(rc.joints), rc.marker_site,
        {k: math.radians(v) for k, v in rc.fixed.items()},
        keyframe=rc.keyframe or None,
    )
    if cfg.scene.kind == "paint":
        scene = PaintWall.grid(**cfg.scene.params)
    else:
        if cfg.scene.params:
            raise ConfigError("key 'scene.params': the marker scene takes no parameters")
        scene = MarkerScene()
    if rc.mode != "dynamic":
        return Simulator(robot, scene, mode=rc.mode, substeps=rc.substeps)
    return Simulator(
        robot, scene, mode="dynamic", substeps=rc.substeps,
        waypoint_s=rc.waypoint_s or waypoint_s or 1.0, timestep=rc.timestep or None,
        move_fraction=rc.move_fraction, physics=rc.physics, reduce=rc.reduce,
    )


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
