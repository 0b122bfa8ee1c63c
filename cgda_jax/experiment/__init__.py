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

Modules, one job each, in their import order: each imports only modules above it
(function-level imports too; tests/test_imports.py checks it), and no module takes
another's ``_private`` name:

1. :mod:`~cgda_jax.experiment.sections`: the config's sections (``[data]``,
   ``[robot]``, ...), one typed dataclass each, with their defaults.
2. :mod:`~cgda_jax.experiment.config`: the schema, TOML reading and writing,
   overrides (`merge_table`).
3. :mod:`~cgda_jax.experiment.demo_suite`: the experiments of ``cgda demo`` (configs).
4. :mod:`~cgda_jax.experiment.locate`: the files and folders a config names (model,
   data folder, demonstration files, recordings per action).
5. :mod:`~cgda_jax.experiment.rules`: checks of the config alone: choices, ranges,
   the world and object-scene tables, the strategy's options
   (`strategy_function`), the interval count.
6. :mod:`~cgda_jax.experiment.build`: the objects: demonstrations and goal, robot,
   world, scene and simulator, feature labels.
7. :mod:`~cgda_jax.experiment.validate`: the checks that need built objects and no
   compiled program (``--dry-run`` and the start of every run: `check_experiment`).
8. :mod:`~cgda_jax.experiment.compute`: running: the numbers of a recognition or
   execution run (and the replay on a finer simulator).
9. :mod:`~cgda_jax.experiment.report`: JSON and ``report.md``.
10. :mod:`~cgda_jax.experiment.load`: a results folder back in Python (`load_run`).
11. :mod:`~cgda_jax.experiment.trajectory_file`: a run as a controller's trajectory file
    (`export_trajectory`, `check_exported`; ``cgda export``).
12. :mod:`~cgda_jax.experiment.figures`: the figures and the robot's video of a run,
    drawn from what its folder stores (also ``cgda plot``).
13. :mod:`~cgda_jax.experiment.run`: one run into its folder (`start_run`,
    `run_experiment`): computes, then draws and writes its outputs; its programs
    are found without tracing by the key of
    :mod:`~cgda_jax.experiment.programs_key` (`run_programs_key`).
14. :mod:`~cgda_jax.experiment.success_rate`: many seeds of one experiment (``cgda
    trials``).

The results folder itself (its rules, writing it aside, reading its files back) is
`cgda_jax.results_folder`; its names are re-exported here too.

Every name is re-exported here, so ``from cgda_jax.experiment import X`` keeps working.
"""

from cgda_jax.experiment.build import (
    build_goal as build_goal,
    build_simulator as build_simulator,
    synthetic_demos as synthetic_demos,
)
from cgda_jax.experiment.compute import (
    compute_execution as compute_execution,
    compute_recognition as compute_recognition,
    replay_check as replay_check,
)
from cgda_jax.experiment.config import (
    KINDS as KINDS,
    SCENES as SCENES,
    SOURCES as SOURCES,
    XGNITIVE_ENV as XGNITIVE_ENV,
    ConfigError as ConfigError,
    DataConfig as DataConfig,
    ExperimentConfig as ExperimentConfig,
    OutputConfig as OutputConfig,
    RecognitionConfig as RecognitionConfig,
    RobotConfig as RobotConfig,
    SceneConfig as SceneConfig,
    SelectionConfig as SelectionConfig,
    StrategyConfig as StrategyConfig,
    dump_config as dump_config,
    load_config as load_config,
    merge_table as merge_table,
)
from cgda_jax.experiment.demo_suite import (
    DEMO_EXPERIMENTS as DEMO_EXPERIMENTS,
    demo_configs as demo_configs,
)
from cgda_jax.experiment.trajectory_file import (
    check_exported as check_exported,
    export_trajectory as export_trajectory,
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
    jsonable as jsonable,
    log as log,
    report_markdown as report_markdown,
    write_json as write_json,
)
from cgda_jax.experiment.locate import (
    resolve_data_dir as resolve_data_dir,
    resolve_model as resolve_model,
)
from cgda_jax.experiment.rules import (
    SET_BY_CONFIG as SET_BY_CONFIG,
    check_strategy_options as check_strategy_options,
    strategy_function as strategy_function,
    validate_config as validate_config,
)
from cgda_jax.experiment.run import (
    Outputs as Outputs,
    default_folder as default_folder,
    run_execution as run_execution,
    run_experiment as run_experiment,
    run_recognition as run_recognition,
    start_run as start_run,
    write_run as write_run,
)
from cgda_jax.experiment.validate import (
    MAX_SEED as MAX_SEED,
    check_and_build as check_and_build,
    check_experiment as check_experiment,
)
from cgda_jax.results_folder.rules import (
    FolderBusy as FolderBusy,
    FolderError as FolderError,
    plan_folder as plan_folder,
)
from cgda_jax.results_folder.writing import RunFolder as RunFolder

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
    "SelectionConfig",
    "StrategyConfig",
    "check_and_build",
    "check_experiment",
    "dump_config",
    "load_config",
    "load_run",
    "run_experiment",
    "validate_config",
]
