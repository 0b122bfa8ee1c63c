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

Modules, one job each:

- :mod:`~cgda_jax.experiment.config`: schema, TOML reading and writing, overrides.
- :mod:`~cgda_jax.experiment.rules`: the value rules (choices, ranges, files named,
  world and object-scene tables).
- :mod:`~cgda_jax.experiment.build`: the goal, the simulator and the strategy
  function from a config.
- :mod:`~cgda_jax.experiment.validate`: every check that needs no compiled program
  (``--dry-run`` and the start of every run).
- :mod:`~cgda_jax.experiment.run`: recognition and execution runs.
- :mod:`~cgda_jax.experiment.results`: the results folder (written aside, moved into
  place when complete, locked, never mixing two runs).
- :mod:`~cgda_jax.experiment.report`: JSON and ``report.md``.
- :mod:`~cgda_jax.experiment.figures`: the figures and the robot's video of a run,
  drawn from what its folder stores (also ``cgda plot``).
- :mod:`~cgda_jax.experiment.load`: a results folder back in Python (`load_run`).
- :mod:`~cgda_jax.experiment.demo`: the experiments of ``cgda demo``.

Every name is re-exported here, so ``from cgda_jax.experiment import X`` keeps working.
"""

from cgda_jax.experiment.build import (
    _SET_BY_CONFIG as _SET_BY_CONFIG,
    _check_strategy_options as _check_strategy_options,
    build_goal as build_goal,
    build_simulator as build_simulator,
    strategy_function as strategy_function,
)
from cgda_jax.experiment.config import (
    KINDS as KINDS,
    SCENES as SCENES,
    SOURCES as SOURCES,
    STRATEGIES as STRATEGIES,
    XGNITIVE_ENV as XGNITIVE_ENV,
    ConfigError as ConfigError,
    DataConfig as DataConfig,
    ExperimentConfig as ExperimentConfig,
    OutputConfig as OutputConfig,
    RecognitionConfig as RecognitionConfig,
    RobotConfig as RobotConfig,
    SceneConfig as SceneConfig,
    StrategyConfig as StrategyConfig,
    _apply_override as _apply_override,
    _coerce as _coerce,
    _merge as _merge,
    _parse_value as _parse_value,
    _type_name as _type_name,
    dump_config as dump_config,
    load_config as load_config,
)
from cgda_jax.experiment.demo import (
    _SMALL as _SMALL,
    DEMO_EXPERIMENTS as DEMO_EXPERIMENTS,
    demo_configs as demo_configs,
)
from cgda_jax.experiment.figures import (
    draw_figures as draw_figures,
    render_run as render_run,
)
from cgda_jax.experiment.load import (
    Run as Run,
    load_run as load_run,
)
from cgda_jax.experiment.report import (
    _close_all as _close_all,
    _jsonable as _jsonable,
    _report as _report,
    _write_json as _write_json,
    log as log,
)
from cgda_jax.experiment.results import (
    FolderBusy as FolderBusy,
    FolderError as FolderError,
    RunFolder as RunFolder,
    plan_folder as plan_folder,
)
from cgda_jax.experiment.rules import (
    _choice as _choice,
    resolve_data_dir as resolve_data_dir,
    resolve_model as resolve_model,
    validate_config as validate_config,
)
from cgda_jax.experiment.run import (
    Outputs as Outputs,
    _synthetic as _synthetic,
    default_folder as default_folder,
    run_execution as run_execution,
    run_experiment as run_experiment,
    run_recognition as run_recognition,
    start_run as start_run,
    write_run as write_run,
)
from cgda_jax.experiment.validate import (
    MAX_SEED as MAX_SEED,
    check_experiment as check_experiment,
)

__all__ = [
    "ConfigError",
    "DataConfig",
    "ExperimentConfig",
    "FolderBusy",
    "FolderError",
    "OutputConfig",
    "RecognitionConfig",
    "RobotConfig",
    "Run",
    "RunFolder",
    "SceneConfig",
    "StrategyConfig",
    "check_experiment",
    "dump_config",
    "load_config",
    "load_run",
    "run_experiment",
    "validate_config",
]
