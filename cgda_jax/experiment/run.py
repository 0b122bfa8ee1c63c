"""Running an experiment (recognition or execution, see the package docstring) into
a results folder: ``config.toml``, ``result.json``, ``arrays.npz``, ``plots/*.png``
(+ the robot's video ``plots/execution.mp4`` and ``.gif``), ``report.md``; read it
back with `cgda_jax.load_run`. Every execution run also replays its result on a finer
simulator (dynamic: finer physics; kinematic: more sub-steps). The folder itself
(temporary folder, lock, move into place) belongs to
`cgda_jax.experiment.results`.
"""

from __future__ import annotations

import json
import os
import pathlib
import time
from collections.abc import Callable

import numpy as np

from cgda_jax.experiment.build import (
    build_goal,
    build_simulator,
    default_waypoint_s,
    strategy_function,
)
from cgda_jax.experiment.config import (
    ConfigError,
    ExperimentConfig,
    dump_config,
)
from cgda_jax.experiment.figures import (
    draw_figures,
    error_unit,
    feature_labels,
    render_run,
)
from cgda_jax.experiment.load import run_in_memory
from cgda_jax.experiment.report import _report, _write_json
from cgda_jax.experiment.results import RunFolder, expand
from cgda_jax.experiment.validate import check_experiment


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
    """Generalize, then recognize the held-out repetitions (paper Tables 2-4); save
    and plot."""
    pending = _recognize(cfg, out)
    pending.draw()
    return pending.result


def _recognize(cfg: ExperimentConfig, out: pathlib.Path) -> Outputs:
    """`run_recognition` up to its figures (drawn by the returned `Outputs`)."""
    from cgda_jax.generalize import generalize, sample_actions
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
        reduced = [generalize([t], d.interval_s, d.method) for _, t in tests]
        queries = list(np.asarray(sample_actions(reduced, r.n_samples)))
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
        "feature_labels": feature_labels(cfg, library.feature_names),
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
    arrays = {"cost_matrix": costs}
    for a in names:
        arrays[f"knot_times_{a}"] = np.asarray(library[a].knot_times)
        arrays[f"knots_{a}"] = np.asarray(library[a].knots)
        arrays.update(_demo_arrays(demos[a][: d.n_train], f"demo_{a}_"))
    np.savez(out / "arrays.npz", **arrays)
    return Outputs(cfg, out, result, arrays)


def _demo_arrays(demos, prefix: str, scale: float = 1.0) -> dict[str, np.ndarray]:
    """``{prefix}{k}_times`` and ``{prefix}{k}_features`` (times scale) per demo."""
    out = {}
    for k, d in enumerate(demos):
        out[f"{prefix}{k}_times"] = np.asarray(d.times, np.float64)
        out[f"{prefix}{k}_features"] = np.asarray(d.features, np.float64) * scale
    return out


#: How much finer a result is replayed: dynamic runs at timestep / 4 (MuJoCo C),
#: kinematic runs at 16 x the sub-steps.
REPLAY_FACTOR = {"dynamic": 4, "kinematic": 16}


def replay_check(sim, res, factor: int | None = None) -> dict:
    """Re-execute the reported joints on a `factor` x finer simulator
    (`Simulator.finer`: dynamic mode timestep / factor on MuJoCo C, kinematic mode
    factor x the sub-steps; default `REPLAY_FACTOR`): the features must agree, or
    the optimiser exploited the resolution it was evaluated at."""
    fine = sim.finer(factor or REPLAY_FACTOR[sim.mode])
    feats = np.asarray(fine.execute(np.asarray(res.joints, np.float32)), np.float64)
    errors = np.linalg.norm(feats - np.asarray(res.goal), axis=-1)
    out = ({"timestep": fine.physics.timestep} if fine.mode == "dynamic"
           else {"substeps": fine.substeps})
    return out | {
        "max_feature_difference": float(np.abs(feats - res.features).max()),
        "max_point_error": float(errors.max()),
        "success": bool(np.all(errors < res.tolerance)),
    }


def run_execution(
    cfg: ExperimentConfig, out: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
) -> dict:
    """Build the goal and the simulator, run the strategy, save and plot."""
    pending = _execute(cfg, out, progress_fn)
    pending.draw()
    return pending.result


def _execute(
    cfg: ExperimentConfig, out: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
) -> Outputs:
    """`run_execution` up to its figures and video (drawn by the returned
    `Outputs`)."""
    goal, demos, gen = build_goal(cfg)
    waypoint_s = default_waypoint_s(demos, len(goal))
    sim = build_simulator(cfg, waypoint_s, goal)
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
    labels = feature_labels(cfg, sim.feature_names)
    summary.update({"kind": "execution", "name": cfg.name,
                    "feature_names": list(sim.feature_names),
                    "feature_labels": labels, "error_unit": error_unit(labels),
                    "build": {"waypoint_s": waypoint_s}})
    with np.load(out / "arrays.npz") as z:
        arrays = {k: z[k] for k in z.files}
    if gen is not None:  # the generalization and demonstrations, in the goal's units
        arrays["knot_times"] = np.asarray(gen.knot_times, np.float64)
        arrays["knots"] = np.asarray(gen.knots, np.float64) * cfg.data.scale
        arrays.update(_demo_arrays(demos, "demo", cfg.data.scale))
    np.savez(out / "arrays.npz", **arrays)
    if sim.mode == "dynamic":
        summary["physics"] = {
            "backend": sim.backend.name, "waypoint_s": sim.waypoint_s,
            "timestep": sim.physics.timestep, "physics_steps": sim.physics_steps,
            "welded_joints": list(sim.physics.welded),
        }
    else:
        summary["substeps"] = sim.substeps
    summary["replay"] = replay_check(sim, res)
    return Outputs(cfg, out, summary, arrays, sim)


class Outputs:
    """What is left of a run once its numbers are saved: the figures, the robot's
    video (execution), ``result.json`` and ``report.md``.

    `start_run` returns one; `finish` writes them (in any thread: ``cgda demo`` draws
    one experiment's outputs while the next one computes). ``result`` is the result
    dict, already final except for ``plots``, ``render`` and ``total_time_s``.
    """

    def __init__(self, cfg: ExperimentConfig, folder: pathlib.Path, result: dict,
                 arrays: dict[str, np.ndarray], sim=None):
        self.cfg, self.folder, self.result = cfg, folder, result
        self.arrays, self.sim = arrays, sim
        self.compute_s = 0.0

    def draw(self) -> None:
        """The figures and (execution) the video, into ``folder/plots``."""
        if not (self.cfg.output.plots or self.cfg.output.render):
            return
        run = run_in_memory(self.folder, self.cfg, self.result, self.arrays)
        if self.cfg.output.plots:
            draw_figures(run, self.folder / "plots")
        if self.cfg.output.render and self.sim is not None:
            self.result["render"] = render_run(run, self.folder / "plots", self.sim)

    def finish(self) -> dict:
        """`draw`, then write ``result.json`` and ``report.md``; the result dict
        (``total_time_s``: the run's own time, computing plus outputs)."""
        t0 = time.perf_counter()
        self.draw()
        plots = self.folder / "plots"
        result = self.result
        result["plots"] = sorted(
            str(p.relative_to(self.folder)) for p in plots.glob("*.png")
        ) if plots.is_dir() else []
        result["total_time_s"] = self.compute_s + time.perf_counter() - t0
        _write_json(self.folder / "result.json", result)
        (self.folder / "report.md").write_text(_report(self.cfg, result))
        return result


def start_run(
    cfg: ExperimentConfig,
    folder: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
) -> Outputs:
    """Run ``cfg`` (already checked) into the existing, empty ``folder`` up to its
    outputs: ``config.toml`` and ``arrays.npz`` are written, the result is known
    (``.result``); ``.finish()`` draws and writes the rest."""
    t0 = time.perf_counter()
    (folder / "config.toml").write_text(dump_config(cfg))
    if cfg.kind == "recognition":
        pending = _recognize(cfg, folder)
    else:
        pending = _execute(cfg, folder, progress_fn)
    pending.compute_s = time.perf_counter() - t0
    return pending


def write_run(
    cfg: ExperimentConfig,
    folder: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
) -> dict:
    """Run ``cfg`` (already checked) and write its results into the existing, empty
    ``folder``; return the result dict. `run_experiment` and ``cgda`` call it inside
    a `~cgda_jax.experiment.results.RunFolder`."""
    return start_run(cfg, folder, progress_fn).finish()


def default_folder(cfg: ExperimentConfig) -> pathlib.Path:
    """``<output.dir>/<name>`` (``~`` expanded)."""
    return expand(cfg.output.dir) / cfg.name


def run_experiment(
    cfg: ExperimentConfig,
    out: str | os.PathLike | None = None,
    progress_fn: Callable[[dict], None] | None = None,
    *,
    overwrite: bool = False,
) -> dict:
    """Check and run ``cfg``; write its results folder; return the result dict.

    The folder is written aside and moved into place when complete
    (`~cgda_jax.experiment.results.RunFolder`): a failed or interrupted run leaves
    it as it was.

    Args:
        cfg: the experiment.
        out: results folder; it must be missing or empty unless ``overwrite``.
            Default: the first free one of ``<output.dir>/<name>``,
            ``<output.dir>/<name>-2``, ...
        progress_fn: called with the strategies' progress dicts (execution).
        overwrite: replace an existing results folder ``out`` whole.

    Returns:
        The result (as in ``result.json``), plus ``folder``: where it was written.

    Raises:
        ConfigError, FileNotFoundError: a bad config (see `check_experiment`).
        FolderError: ``out`` is not empty, in use by another run (`FolderBusy`),
            or not writable.
    """
    check_experiment(cfg)
    target = expand(out) if out is not None else default_folder(cfg)
    with RunFolder(target, overwrite=overwrite, fresh=out is None) as rf:
        result = write_run(cfg, rf.work, progress_fn)
    result["folder"] = str(rf.path)
    return result
