"""Every check of an experiment that needs no compiled program: what
``cgda run --dry-run`` reports and what every run refuses before it starts, the same
way (`check_experiment`).

On top of `validate_config` (keys, types, choices, files and folders named):

- seeds in 0 .. 2**32 - 1 (`MAX_SEED`), the last of ``--trials N`` included;
- sizes a machine can hold: interval count of the generalization, goal points,
  population, population x goal points, simulated steps per generation,
  repetitions, recognition samples (the ``MAX_*`` constants), the samples of object
  demonstrations (``data.duration_s``), and what the run will hold at once:
  trials x population x points x values per evaluation, sampled postures
  (`cgda_jax.sizes`: XLA's 32-bit sizes and the memory available), and
  ``--processes P`` against the cores and the memory;
- the goal, built (demonstrations generalized in NumPy; no JAX program runs): finite,
  as many features as the scene gives;
- the robot and the scene, built as the run builds them (not compiled): joints,
  marker site and keyframe exist, fixed values are finite and inside their joints'
  ranges, scene parameters are accepted;
- the algorithm: its name (`cgda_jax.strategies.base.ALGORITHMS`) and its population
  limits, by building it (`make_algorithm`: evosax's default parameters, one small
  program compiled once, about 0.5 s for CMA_ES, then in the compilation cache).

Every error is a `ConfigError` whose message names the config key.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from cgda_jax.experiment.build import BuiltExecution
from cgda_jax.experiment.config import OBJECT_SOURCES, ConfigError, ExperimentConfig
from cgda_jax.experiment.programs_key import run_programs_key
from cgda_jax.experiment.rules import (
    MAX_INTERVALS,
    check_camera,
    check_interval_count,
    validate_config,
)
from cgda_jax.programs import program_scope
from cgda_jax.sizes import (
    SizeError,
    check_estimate,
    check_processes,
    check_recognition,
    check_samples,
    samples_estimate,
    sim_estimate,
)

#: Seeds are 32-bit unsigned integers (JAX keys, NumPy generators).
MAX_SEED = 2**32 - 1
#: Largest goal value (in its features' units): its square must fit float32 (3.4e38).
MAX_GOAL_VALUE = 1e18
#: Goal points (paint ramp length, generalized knots).
MAX_GOAL_POINTS = 10_000
#: Candidates per generation.
MAX_POPULATION = 1_000_000
#: Candidates x goal points evaluated in one generation.
MAX_CANDIDATE_POINTS = 10_000_000
#: Candidates x goal points x simulated steps per waypoint in one generation.
MAX_SIM_STEPS = 1_000_000_000
#: Repetitions of a synthetic action / clean-circle demonstrations.
MAX_REPETITIONS = 1_000
#: Samples per trajectory compared in recognition (DTW is quadratic in it).
MAX_SAMPLES = 10_000
#: Kinematic sub-steps per waypoint.
MAX_SUBSTEPS = 10_000
#: Physics steps per waypoint (dynamic mode: waypoint time / timestep).
MAX_PHYSICS_STEPS = 1_000_000
#: Generations per compiled chunk.
MAX_CHUNK = 100_000


def _at_most(value: int, limit: int, key: str, what: str = "") -> None:
    if value > limit:
        raise ConfigError(
            f"key '{key}': {value:,}{what} is more than this machine-sane limit of "
            f"{limit:,}"
        )


def check_seed(value: int, key: str) -> None:
    """``value`` is a seed in 0 .. 2**32 - 1."""
    if not 0 <= value <= MAX_SEED:
        raise ConfigError(f"key '{key}': seed {value} is not in 0 .. {MAX_SEED}")


def _check_object_demos(cfg: ExperimentConfig) -> None:
    """An object source's demonstrations (``data.duration_s`` at 30 Hz, each up to
    15 % longer plus 1.6 s of rest) within `cgda_jax.sizes.MAX_DEMO_SAMPLES`, the
    memory, and `MAX_INTERVALS`, before they are generated."""
    from cgda_jax.datasets.objects import DEFAULT_DURATION_S, RATE_HZ, longest_s

    d = cfg.data
    duration = d.duration_s or DEFAULT_DURATION_S
    if not math.isfinite(duration):
        raise ConfigError(f"key 'data.duration_s': {duration} is not a finite number")
    count = samples_estimate(longest_s(duration), RATE_HZ)
    try:
        check_samples(count, "key 'data.duration_s'",
                      f"{duration:g} s at {RATE_HZ:g} Hz", n=d.n_demos,
                      width=3 if d.source == "move_box" else 1)
    except SizeError as err:
        raise ConfigError(str(err)) from None
    n = (duration + 1.6) / d.interval_s
    if not n <= MAX_INTERVALS:
        raise ConfigError(
            f"key 'data.duration_s': {duration:g} s demonstrations cut at "
            f"data.interval_s = {d.interval_s:g} s are {n:.3g} intervals, more than "
            f"{MAX_INTERVALS:,}; use a shorter duration or a larger interval_s")


def _check_static(cfg: ExperimentConfig, trials: int | None = None) -> None:
    """Seeds and sizes known before anything is built."""
    d, s, r = cfg.data, cfg.strategy, cfg.robot
    check_seed(d.seed, "data.seed")
    _at_most(d.n_repetitions, MAX_REPETITIONS, "data.n_repetitions")
    if cfg.kind == "recognition":
        _at_most(cfg.recognition.n_samples, MAX_SAMPLES, "recognition.n_samples")
        if cfg.recognition.n_samples < 2:
            raise ConfigError("key 'recognition.n_samples' must be >= 2")
        return
    check_seed(s.seed, "strategy.seed")
    check_seed(cfg.reality.seed, "reality.seed")
    check_camera(cfg.output.camera)  # names a bad [output] camera key
    if trials is not None and s.seed + trials - 1 > MAX_SEED:
        raise ConfigError(
            f"key 'strategy.seed' with --trials {trials}: the seeds {s.seed} .. "
            f"{s.seed + trials - 1} pass {MAX_SEED} (seeds are 32-bit); use "
            f"strategy.seed <= {MAX_SEED - trials + 1} or fewer trials")
    _at_most(d.n_demos, MAX_REPETITIONS, "data.n_demos")
    if d.source in OBJECT_SOURCES:
        _check_object_demos(cfg)
    if d.source == "clean_circle" and d.n_demos < 1:
        raise ConfigError("key 'data.n_demos' must be >= 1")
    if d.source == "paint_ramp":
        if d.goal_points < 2:
            raise ConfigError("key 'data.goal_points' must be >= 2")
        _at_most(d.goal_points, MAX_GOAL_POINTS, "data.goal_points")
    if not math.isfinite(d.scale):
        raise ConfigError(f"key 'data.scale': {d.scale} is not a finite number")
    _at_most(s.population_size, MAX_POPULATION, "strategy.population_size")
    _at_most(s.chunk_size, MAX_CHUNK, "strategy.chunk_size")
    if not 1 <= r.substeps:
        raise ConfigError("key 'robot.substeps' must be >= 1")
    _at_most(r.substeps, MAX_SUBSTEPS, "robot.substeps")
    for name, value in r.fixed.items():
        if not math.isfinite(value):
            raise ConfigError(
                f"key 'robot.fixed.{name}': {value} is not a finite number")


def _check_recognition(cfg: ExperimentConfig) -> dict[str, Any]:
    from cgda_jax.experiment.build import recognition_demos

    d = cfg.data
    if d.source == "video":  # the folders were checked; tracking is the run's
        from cgda_jax.experiment.locate import video_folders

        return {"actions": len(video_folders(cfg))}
    demos = recognition_demos(cfg)
    loo = cfg.recognition.split == "leave_one_out"
    for action, reps in demos.items():
        n_train = len(reps) - 1 if loo else d.n_train
        if loo and n_train < 1:
            raise ConfigError(f"key 'recognition.split': leave_one_out needs at least "
                              f"2 repetitions an action; {action!r} has {len(reps)}")
        if not 1 <= n_train < len(reps):
            raise ConfigError(f"key 'data.n_train'={d.n_train}: {action!r} has "
                              f"{len(reps)} repetitions; need 1 <= n_train < "
                              f"{len(reps)} (or recognition.split = 'leave_one_out')")
        check_interval_count(reps[:n_train], d.interval_s, d.method)
        for t in reps[n_train:] if not loo else reps:
            check_interval_count([t], d.interval_s, d.method)
    queries = sum(len(reps) if loo else len(reps) - d.n_train
                  for reps in demos.values())
    features = len(next(iter(demos.values()))[0].feature_names)
    try:
        check_recognition(queries, len(demos), cfg.recognition.n_samples, features,
                          name="key 'recognition.n_samples'",
                          metric=cfg.recognition.metric)
    except SizeError as err:
        raise ConfigError(str(err)) from None
    return {"actions": len(demos)}


#: Which config key a robot-building message is about (first matching prefix).
_ROBOT_KEYS = (("kinematic mode", "robot.mode"), ("model", "robot.model"),
               ("fixed joint", "robot.fixed"), ("joint", "robot.joints"),
               ("site", "robot.marker_site"), ("keyframe", "robot.keyframe"),
               ("marker", "robot.marker"), ("control", "robot.control"),
               ("physics", "robot.physics"))


def _robot_key(message: str) -> str:
    text = message.strip("'\"")
    named = re.match(r"fixed joint '([^']+)'", text)
    if named:  # the Robot names the joint: point at its own key
        return f"robot.fixed.{named.group(1)}"
    for prefix, key in _ROBOT_KEYS:
        if text.startswith(prefix):
            return key
    return "robot"


def _check_physics_steps(cfg: ExperimentConfig, waypoint_s: float) -> None:
    """Dynamic mode: waypoint time / timestep within `MAX_PHYSICS_STEPS` (checked
    before the simulator allocates its per-step profile)."""
    import mujoco

    from cgda_jax.experiment.locate import resolve_model

    rc = cfg.robot
    timestep = rc.timestep
    if not timestep:
        try:
            timestep = mujoco.MjModel.from_xml_path(
                str(resolve_model(rc.model))).opt.timestep
        except ValueError as err:
            raise ConfigError(f"key 'robot.model': cannot load it: {err}") from None
    waypoint = rc.waypoint_s or waypoint_s
    steps = waypoint / timestep if timestep > 0 else math.inf
    if not steps <= MAX_PHYSICS_STEPS:
        raise ConfigError(
            f"keys 'robot.waypoint_s' / 'robot.timestep': {waypoint:g} s per waypoint "
            f"at a {timestep:g} s timestep is {steps:.3g} physics steps per waypoint, "
            f"more than {MAX_PHYSICS_STEPS:,}"
        )


def _build_simulator(cfg: ExperimentConfig, waypoint_s: float, goal: np.ndarray):
    from cgda_jax.experiment.build import build_simulator

    if cfg.robot.mode == "dynamic":
        _check_physics_steps(cfg, waypoint_s)
    try:
        return build_simulator(cfg, waypoint_s, goal)
    except ConfigError:
        raise
    except KeyError as err:
        msg = str(err.args[0]) if err.args else str(err)
        raise ConfigError(f"key '{_robot_key(msg)}': {msg}") from None
    except TypeError as err:  # the scene's constructor refused a parameter
        raise ConfigError(f"key 'scene.params': {err}") from None
    except ValueError as err:
        raise ConfigError(f"key '{_robot_key(str(err))}': {err}") from None


def _check_algorithm(cfg: ExperimentConfig, n_genes: int) -> None:
    from cgda_jax.strategies.evolution import (
        ALGORITHMS,
        default_kwargs,
        make_algorithm,
    )

    s = cfg.strategy
    if s.algorithm not in ALGORITHMS:
        raise ConfigError(
            f"key 'strategy.algorithm': {s.algorithm!r} is not one of "
            f"{sorted(ALGORITHMS)}"
        )
    kwargs = s.options.get("algorithm_kwargs") or {}
    params = s.options.get("algorithm_params") or {}
    for key, value in (("algorithm_kwargs", kwargs), ("algorithm_params", params)):
        if not isinstance(value, dict):
            raise ConfigError(f"key 'strategy.options.{key}' must be a table")
    try:
        make_algorithm(s.algorithm, s.population_size, n_genes,
                       algorithm_kwargs={**default_kwargs(s.algorithm), **kwargs},
                       algorithm_params=params)
    except (ValueError, TypeError) as err:
        text = str(err)
        key = ("strategy.population_size" if text.startswith("population_size")
               else "strategy.options.algorithm_params" if "algorithm_params" in text
               else "strategy.options.algorithm_kwargs" if "algorithm_kwargs" in text
               else "strategy.algorithm")
        raise ConfigError(f"key '{key}': {text}") from None


def _sampled_postures(cfg: ExperimentConfig, sim) -> tuple[int, str]:
    """Postures the strategy samples once per trial and the option that sets them:
    the plan's own rule (`cgda_jax.strategies.base.PlanBase.sampled_postures`)."""
    from cgda_jax.strategies import STRATEGIES

    entry = STRATEGIES[cfg.strategy.name]
    return entry.plan.sampled_postures(entry.settings.of(None, **cfg.strategy.options),
                                       sim)


def _check_option_combinations(cfg: ExperimentConfig, sim) -> None:
    """Options that need independent points (kinematic mode, a stateless scene),
    refused as the plans refuse them, before the run."""
    from cgda_jax.strategies.base import points_independent

    o = cfg.strategy.options
    if points_independent(sim):
        return
    for key, asks in (("init", o.get("init") == "reach"),
                      ("refine", o.get("refine", "none") != "none"),
                      ("reach_check", o.get("reach_check") is True)):
        if asks:
            raise ConfigError(
                f"key 'strategy.options.{key}': {o[key]!r} needs independent points "
                f"(kinematic mode and a scene without state, e.g. the marker); this "
                f"run is {sim.mode} mode with the '{cfg.scene.kind}' scene")


def _check_run_size(cfg: ExperimentConfig, sim, n_points: int, trials: int | None,
                    processes: int, local: bool) -> None:
    """What the run will hold at once (`cgda_jax.sizes.sim_estimate`)
    within XLA's 32-bit sizes and the memory of each process; `processes` against
    the cores."""

    s = cfg.strategy
    samples, option = _sampled_postures(cfg, sim)
    n = trials or 1
    share = -(-n // max(processes, 1))  # each process batches its own seeds
    est = sim_estimate(sim, trials=share, population=s.population_size,
                       points=n_points, strategy=s.name, samples=samples)
    name = ("--trials" if trials and trials > 1
            else "keys 'strategy.population_size' and 'feasibility.samples'"
            if est.part == "motion"
            else f"key 'strategy.options.{option}'" if est.part != "generation"
            else "key 'strategy.population_size'")
    try:
        check_estimate(est, name)
        if processes > 1:
            check_processes(processes, est.nbytes * processes, local=local)
    except SizeError as err:
        raise ConfigError(str(err)) from None


def _check_execution(cfg: ExperimentConfig, trials: int | None = None,
                     processes: int = 1, local: bool = True
                     ) -> tuple[dict[str, Any], BuiltExecution]:
    from cgda_jax.experiment.build import build_goal, default_waypoint_s
    from cgda_jax.strategies.base import check_config

    s = cfg.strategy
    try:
        goal, demos, gen = build_goal(cfg)
    except ConfigError:
        raise
    except ValueError as err:  # demonstrations or their generalization
        raise ConfigError(f"key 'data': {err}") from None
    n_points = int(goal.shape[0])
    _at_most(n_points, MAX_GOAL_POINTS, "data", " goal points")
    top = float(np.max(np.abs(goal))) if goal.size else 0.0
    if not top <= MAX_GOAL_VALUE:  # squared feature errors must fit float32
        raise ConfigError(
            f"key '{'data.scale' if cfg.data.scale != 1 else 'data'}': the goal "
            f"reaches {top:.3g} (its demonstrations x data.scale = {cfg.data.scale:g}), "
            f"beyond {MAX_GOAL_VALUE:.0e}: its squared errors would overflow float32")
    _at_most(s.population_size * n_points, MAX_CANDIDATE_POINTS,
             "strategy.population_size", f" x {n_points} goal points")
    waypoint_s = default_waypoint_s(demos, n_points)
    sim = _build_simulator(cfg, waypoint_s, goal)
    steps = sim.physics_steps if sim.mode == "dynamic" else sim.substeps
    _at_most(s.population_size * n_points * steps, MAX_SIM_STEPS,
             "robot.timestep" if sim.mode == "dynamic" else "robot.substeps",
             f" simulated steps per generation (population x {n_points} points x "
             f"{steps} steps per waypoint)")
    if goal.shape[1] != sim.n_features:
        raise ConfigError(
            f"key 'scene.kind': the goal has {goal.shape[1]} feature(s) "
            f"{cfg.data.columns} but the '{cfg.scene.kind}' scene gives "
            f"{sim.n_features} {list(sim.feature_names)}"
        )
    try:
        check_config(sim, goal, tolerance=s.tolerance,
                     max_generations=s.max_generations)
    except ValueError as err:
        raise ConfigError(f"key 'data': {err}") from None
    n_genes = n_points * sim.n_dof if s.name == "fte" else sim.n_dof
    _check_algorithm(cfg, n_genes)
    _check_option_combinations(cfg, sim)
    _check_run_size(cfg, sim, n_points, trials, processes, local)
    return ({"goal_points": n_points, "features": int(goal.shape[1]),
             "genes": int(n_genes)},
            BuiltExecution(goal, demos, gen, waypoint_s, sim))


def check_and_build(cfg: ExperimentConfig, trials: int | None = None,
                    processes: int = 1, local: bool = True
                    ) -> tuple[dict[str, Any], BuiltExecution | None]:
    """`check_experiment`, and the objects its checks built (an execution's goal
    and simulator; None for a recognition), which the run then uses: each is
    built once per run."""
    validate_config(cfg)
    _check_static(cfg, trials)
    # its programs found without tracing when this config was checked before
    with program_scope(run_programs_key(cfg, f"check {trials} {processes} {local}")):
        if cfg.kind == "recognition":
            return _check_recognition(cfg), None
        return _check_execution(cfg, trials, processes, local)


def check_experiment(cfg: ExperimentConfig, trials: int | None = None,
                     processes: int = 1, local: bool = True) -> dict[str, Any]:
    """Everything a run of ``cfg`` would check, without compiling it (see the
    module docstring).

    Args:
        cfg: the experiment.
        trials: ``--trials N`` (None: one run): the seed range and the batch size.
        processes: processes the trials are split over (``--processes P`` or a
            cluster job's size).
        local: the processes all run on this machine (``--processes P``): checked
            against its cores; False for one process of a cluster job.

    Returns:
        A few facts found on the way: recognition ``actions``; execution
        ``goal_points``, ``features`` and ``genes`` (per candidate).

    Raises:
        ConfigError / FileNotFoundError: naming the config key or the file.
    """
    return check_and_build(cfg, trials, processes, local)[0]
