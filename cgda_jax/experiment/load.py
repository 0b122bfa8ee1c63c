"""A results folder back in Python: `load_run` and `Run`.

    >>> run = cgda_jax.load_run("results/clean_ie")      # doctest: +SKIP
    >>> run.config.strategy.name, run.result["success"]  # the config as run, result.json
    >>> run.arrays["joints"]                             # everything arrays.npz holds
    >>> sim = run.simulator()                            # rebuilt as the run built it
    >>> np.allclose(run.replay(), run.arrays["features"])

What a results folder holds (written by `cgda_jax.experiment.run`):

- ``config.toml``: the resolved config (`run.config`);
- ``result.json``: the summary (`run.result`), with ``feature_labels`` (names with
  units), ``error_unit`` and, for executions, ``build.waypoint_s`` (what the simulator
  was built with);
- ``arrays.npz`` (`run.arrays`): executions: ``joints`` (N, DoF) in radians, the
  executed ``features`` (N, F), ``goal`` (N, F), ``point_errors`` (N,),
  ``fitness_history``; the generalization (``knot_times`` (N,), ``knots`` (N, F),
  in the goal's units) and the demonstrations (``demo{k}_times``,
  ``demo{k}_features``, k from 0) where the goal came from demonstrations.
  Recognitions: ``cost_matrix`` (Q, A); per action A its generalization
  (``knot_times_A``, ``knots_A``) and training demonstrations
  (``demo_A_{k}_times``, ``demo_A_{k}_features``);
- ``plots/`` and ``report.md``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
import types
from typing import Any

import numpy as np

from cgda_jax.experiment.config import ExperimentConfig, load_config
from cgda_jax.results_folder.rules import MARKER, FolderError, expand
from cgda_jax.results_folder.reading import check_fields, read_json, read_npz

__all__ = ["Run", "load_run"]

#: Files every results folder holds.
REQUIRED = ("config.toml", MARKER, "arrays.npz")


@dataclasses.dataclass
class Run:
    """One run's results (see the module docstring for what each holds).

    Attributes:
        folder: the results folder.
        config: the `ExperimentConfig` as run (``config.toml``).
        result: ``result.json`` as a dict.
        arrays: every array of ``arrays.npz``, by name.
    """

    folder: pathlib.Path
    config: ExperimentConfig
    result: dict[str, Any]
    arrays: dict[str, np.ndarray]

    @property
    def kind(self) -> str:
        """``"execution"`` or ``"recognition"``."""
        return self.result.get("kind", self.config.kind)

    @property
    def name(self) -> str:
        return self.result.get("name", self.config.name)

    def _need_execution(self, what: str) -> None:
        if self.kind != "execution":
            raise ValueError(
                f"{self.folder}: a {self.kind} run has no simulator ({what} needs an "
                "execution run)"
            )

    def demonstrations(self, action: str | None = None) -> list:
        """The stored demonstrations (`cgda_jax.Demonstration`, in the goal's units
        for an execution); recognition: those of ``action``."""
        from cgda_jax.data import Demonstration

        prefix = "demo" if action is None else f"demo_{action}_"
        labels = self.result.get("demo_feature_labels") or self.result.get(
            "feature_labels")
        out, k = [], 0
        while f"{prefix}{k}_times" in self.arrays:
            if f"{prefix}{k}_features" not in self.arrays:
                raise FolderError(f"{self.folder / 'arrays.npz'}: array "
                                  f"{prefix}{k}_features missing (beside "
                                  f"{prefix}{k}_times): damaged or partial")
            feats = self.arrays[f"{prefix}{k}_features"]
            names = labels if labels and len(labels) == feats.shape[1] else [
                f"f{i}" for i in range(feats.shape[1])]
            out.append(Demonstration(self.arrays[f"{prefix}{k}_times"], feats,
                                     tuple(names), name=f"{prefix}{k}"))
            k += 1
        return out

    def generalization(self, action: str | None = None):
        """The generalization's knots: an object with ``knot_times`` (N,) and
        ``knots`` (N, F) (what the figures draw), or None when not stored."""
        suffix = "" if action is None else f"_{action}"
        if f"knots{suffix}" not in self.arrays or f"knot_times{suffix}" not in self.arrays:
            return None
        return types.SimpleNamespace(knot_times=self.arrays[f"knot_times{suffix}"],
                                     knots=self.arrays[f"knots{suffix}"])

    def simulator(self):
        """The `Simulator` of the run, rebuilt from its config as the run built it
        (`cgda_jax.experiment.build.build_simulator` with the stored waypoint time
        and goal).

        Raises:
            ValueError: a recognition run (no simulator).
        """
        from cgda_jax.experiment.build import build_simulator

        self._need_execution("simulator()")
        waypoint_s = (self.result.get("build") or {}).get("waypoint_s")
        return build_simulator(self.config, waypoint_s, self.arrays.get("goal"))

    def replay(self, sim=None) -> np.ndarray:
        """The features (N, F) of executing the stored best joints on `simulator()`
        (or ``sim``) from its start state: equal to ``arrays["features"]``.

        Raises:
            ValueError: a recognition run.
        """
        self._need_execution("replay()")
        sim = sim if sim is not None else self.simulator()
        joints = np.asarray(self.arrays["joints"], np.float32)
        return np.asarray(sim.execute(joints), np.float64)

    def execution_result(self):
        """The strategy's `cgda_jax.ExecutionResult` (``ExecutionResult.load``)."""
        from cgda_jax.strategies.result import ExecutionResult

        self._need_execution("execution_result()")
        return ExecutionResult.load(self.folder)


#: result.json of a run, by kind: key -> type (`cgda_jax.results_folder.reading`); keys it does not
#: name are accepted. Non-finite numbers are written null.
RUN_FIELDS = {
    "kind": "str", "name": "str", "success": "bool", "feature_labels": "list[str]",
    "demo_feature_labels": "list[str]", "plots": "list[str]",
    "total_time_s": "number|null", "wall_time_s": "number|null",
    "compute_s": "number|null", "outputs_s": "number|null",
}
#: An execution's, beside the strategy's own (`cgda_jax.ExecutionResult`'s
#: ``RESULT_FIELDS``).
EXECUTION_FIELDS = {
    "feature_names": "list[str]", "error_unit": "str|null", "build": "object",
    "replay": "object", "export": "object", "reality": "object", "motion": "object",
    "physics": "object", "substeps": "int", "waypoint_s": "number",
    "render": "object|null",
}
RECOGNITION_FIELDS = {
    "features": "list[str]", "metric": "str", "actions": "list[str]",
    "queries": "list[str]", "truth": "list[str]", "recognized": "list[str]",
    "cost_matrix": "list[list[number|null]]", "accuracy": "number",
}
#: What each kind's result.json and arrays.npz must hold.
REQUIRED_KEYS = {
    "execution": ("kind", "name", "success", "strategy", "points", "point_errors",
                  "max_point_error", "evaluations", "generations"),
    "recognition": ("kind", "name", "success", "actions", "recognized",
                    "cost_matrix", "accuracy"),
}
REQUIRED_ARRAYS = {
    "execution": ("joints", "features", "goal", "point_errors", "fitness_history"),
    "recognition": ("cost_matrix",),
}


def _read_result(path: pathlib.Path) -> dict[str, Any]:
    result = read_json(path, RUN_FIELDS, ("kind",))
    kind = result["kind"]
    if kind not in REQUIRED_KEYS:
        hint = (" (a `cgda run --trials` folder: its records are in trials.json)"
                if kind == "trials" else "")
        raise FolderError(f"{path}: 'kind' is {kind!r}; a run is 'execution' or "
                          f"'recognition'{hint}")
    if kind == "execution":
        from cgda_jax.strategies.result import RESULT_FIELDS

        schema = RESULT_FIELDS | EXECUTION_FIELDS
    else:
        schema = RECOGNITION_FIELDS
    return check_fields(result, RUN_FIELDS | schema, REQUIRED_KEYS[kind], path)


def _check_together(folder: pathlib.Path, config: ExperimentConfig, result: dict,
                    arrays: dict[str, np.ndarray]) -> None:
    """The three files describe one run (not files of two runs mixed)."""
    if config.kind != result["kind"]:
        raise FolderError(
            f"{folder}: config.toml is a {config.kind} experiment but result.json "
            f"a {result['kind']} run: files of different runs")
    if result["kind"] == "execution":
        n = arrays["goal"].shape[0] if arrays["goal"].ndim else 0
        if result["points"] != n or len(result["point_errors"]) != n:
            raise FolderError(
                f"{folder}: result.json has {result['points']} points and "
                f"{len(result['point_errors'])} point errors, arrays.npz a goal of "
                f"{n} points: files of different runs")
        for key in ("joints", "features"):
            rows = arrays[key].shape[0] if arrays[key].ndim == 2 else -1
            if rows != n:
                raise FolderError(
                    f"{folder}: arrays.npz's {key} has shape {arrays[key].shape}, "
                    f"expected one row per goal point ({n}): damaged, or files of "
                    "different runs")
    else:
        shape = arrays["cost_matrix"].shape
        rows = (len(result.get("queries", result["recognized"])),
                len(result["actions"]))
        if tuple(shape) != rows:
            raise FolderError(
                f"{folder}: arrays.npz's cost_matrix is {shape}, result.json has "
                f"{rows[0]} queries x {rows[1]} actions: files of different runs")


def _why_no_config(path: pathlib.Path) -> str:
    """`ExecutionResult.save`'s reason for writing no config.toml, as a hint."""
    try:
        saved = read_json(path)
    except FolderError:
        return ""
    why = saved.get("not_described")
    if isinstance(why, str):
        return (f" (saved from Python with a simulator that a config cannot "
                f"describe: {why})")
    if "strategy" in saved and "build" not in saved:  # not a `cgda run` one
        return (" (an ExecutionResult saved without the simulator it ran on: "
                "nothing says how to build it again)")
    return ""


def load_run(folder: str | os.PathLike) -> Run:
    """Read a results folder written by ``cgda run`` / `run_experiment`.

    Every file is checked as it is read, and a failure names the file: result.json
    against its schema (`RUN_FIELDS` and those of its kind), arrays.npz readable
    and holding its kind's arrays, config.toml a valid config of the same kind, and
    the three of one run (the points, or the recognition's table, agree).

    Raises:
        FolderError: not a folder, not a results folder (a file missing: named), or
            a file damaged, truncated or not of its schema (named).
        ConfigError: its ``config.toml`` no longer loads (e.g. a key since renamed).
    """
    folder = expand(folder)
    if not folder.is_dir():
        raise FolderError(f"results folder {folder} not found (or not a folder)")
    missing = [f for f in REQUIRED if not (folder / f).is_file()]
    if missing:
        hint = (" (a `cgda demo` folder: pass one experiment's subfolder)"
                if (folder / MARKER).is_file() and any(
                    (p / MARKER).is_file() for p in folder.iterdir() if p.is_dir())
                else "")
        if missing == ["config.toml"]:
            hint = _why_no_config(folder / MARKER) or hint
        raise FolderError(f"{folder} is not a results folder: {', '.join(missing)} "
                          f"missing{hint}")
    result = _read_result(folder / MARKER)
    config = load_config(folder / "config.toml")
    arrays = read_npz(folder / "arrays.npz", REQUIRED_ARRAYS[result["kind"]])
    _check_together(folder, config, result, arrays)
    if result["kind"] == "execution" and "feature_labels" not in result:
        from cgda_jax.experiment.build import error_unit, feature_labels

        # saved from Python (`ExecutionResult.save`): labels from the names
        labels = feature_labels(config, result.get("feature_names") or [
            f"f{i}" for i in range(arrays["goal"].shape[-1])])
        result |= {"feature_labels": labels, "error_unit": error_unit(labels)}
    return Run(folder, config, result, arrays)


def run_in_memory(folder: pathlib.Path, config: ExperimentConfig, result: dict,
                  arrays: dict) -> Run:
    """The `Run` a folder being written will load as (``result`` through JSON)."""
    from cgda_jax.experiment.report import jsonable

    return Run(pathlib.Path(folder), config, json.loads(json.dumps(jsonable(result))),
               {k: np.asarray(v) for k, v in arrays.items()})
