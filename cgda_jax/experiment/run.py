"""Running an experiment (recognition or execution, see the package docstring) into
a results folder: ``config.toml``, ``result.json``, ``arrays.npz``, ``plots/*.png``
(+ the robot's video ``plots/execution.mp4`` and ``.gif``), ``report.md``; read it
back with `cgda_jax.load_run`. The numbers are computed by
`cgda_jax.experiment.compute` (every execution run also replays its result on a
finer simulator); the folder itself (temporary folder, lock, move into place)
belongs to `cgda_jax.results_folder`.
"""

from __future__ import annotations

import os
import pathlib
import time
from collections.abc import Callable

import numpy as np

from cgda_jax.experiment.build import BuiltExecution
from cgda_jax.experiment.compute import compute_execution, compute_recognition
from cgda_jax.experiment.config import ExperimentConfig, dump_config
from cgda_jax.experiment.figures import draw_figures, import_drawing, render_run
from cgda_jax.experiment.load import run_in_memory
from cgda_jax.experiment.programs_key import run_programs_key
from cgda_jax.experiment.report import report_markdown, write_json
from cgda_jax.experiment.validate import check_and_build
from cgda_jax.programs import program_scope
from cgda_jax.results_folder.rules import expand
from cgda_jax.results_folder.writing import RunFolder


def run_recognition(cfg: ExperimentConfig, out: pathlib.Path) -> dict:
    """Generalize, then recognize the held-out repetitions (paper Tables 2-4); save
    and plot."""
    pending = Outputs(cfg, out, *compute_recognition(cfg, out))
    pending.draw()
    return pending.result


def run_execution(
    cfg: ExperimentConfig, out: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
) -> dict:
    """Check and build the goal and the simulator, run the strategy, save and
    plot."""
    pending = Outputs(cfg, out, *compute_execution(cfg, out, progress_fn))
    pending.draw()
    return pending.result


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
        plots = self.folder / "plots"
        figures = (lambda: draw_figures(run, plots)) if self.cfg.output.plots else None
        if self.cfg.output.render and self.sim is not None:  # the figures meanwhile
            self.result["render"] = render_run(run, plots, self.sim, alongside=figures)
        elif figures is not None:
            figures()

    def finish(self) -> dict:
        """`draw`, then write ``result.json`` and ``report.md``; the result dict
        (``total_time_s``: the run's own time, ``compute_s`` (what its progress
        line ends on) plus ``outputs_s`` (figures, video, report))."""
        t0 = time.perf_counter()
        self.draw()
        plots = self.folder / "plots"
        result = self.result
        result["plots"] = sorted(
            str(p.relative_to(self.folder)) for p in plots.glob("*.png")
        ) if plots.is_dir() else []
        result["compute_s"] = self.compute_s
        result["outputs_s"] = time.perf_counter() - t0
        result["total_time_s"] = self.compute_s + result["outputs_s"]
        write_json(self.folder / "result.json", result)
        (self.folder / "report.md").write_text(report_markdown(self.cfg, result))
        return result


def start_run(
    cfg: ExperimentConfig,
    folder: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
    built: BuiltExecution | None = None,
) -> Outputs:
    """Run ``cfg`` into the existing, empty ``folder`` up to its outputs:
    ``config.toml`` and ``arrays.npz`` are written, the result is known
    (``.result``); ``.finish()`` draws and writes the rest. An execution runs on
    ``built``, what its checks built (`check_and_build`; default: checked and
    built here)."""
    t0 = time.perf_counter()
    import_drawing(cfg.output.plots, cfg.output.render)  # while computing
    (folder / "config.toml").write_text(dump_config(cfg))
    # its programs found without tracing when this config ran before
    with program_scope(run_programs_key(cfg, "compute")):
        if cfg.kind == "recognition":
            pending = Outputs(cfg, folder, *compute_recognition(cfg, folder))
        else:
            pending = Outputs(cfg, folder, *compute_execution(cfg, folder,
                                                              progress_fn, built))
    pending.compute_s = time.perf_counter() - t0
    return pending


def write_run(
    cfg: ExperimentConfig,
    folder: pathlib.Path,
    progress_fn: Callable[[dict], None] | None = None,
    built: BuiltExecution | None = None,
) -> dict:
    """Run ``cfg`` and write its results into the existing, empty ``folder``
    (`start_run`); return the result dict. `run_experiment` and ``cgda`` call it
    inside a `~cgda_jax.results_folder.writing.RunFolder`."""
    return start_run(cfg, folder, progress_fn, built).finish()


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
    (`~cgda_jax.results_folder.writing.RunFolder`): a failed or interrupted run leaves
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
    _, built = check_and_build(cfg)
    target = expand(out) if out is not None else default_folder(cfg)
    with RunFolder(target, overwrite=overwrite, fresh=out is None) as rf:
        result = write_run(cfg, rf.work, progress_fn, built)
    result["folder"] = str(rf.path)
    return result
