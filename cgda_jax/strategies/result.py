"""`ExecutionResult`: what a strategy run returns, with a JSON + NPZ round trip; and
`SimulationDiverged`, raised when no candidate of a run could be evaluated."""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
from typing import Any

import numpy as np

_ARRAYS = ("joints", "features", "goal", "point_errors", "fitness_history")


class SimulationDiverged(RuntimeError):
    """Every candidate evaluation of a run diverged (non-finite features).

    Nothing was ever evaluated successfully, so there is no posture to report. The
    message names the strategy and likely causes (actuator gains, timestep).
    """


@dataclasses.dataclass
class ExecutionResult:
    """Outcome of one strategy run (host NumPy arrays).

    Attributes:
        strategy: "fte", "ie", "iet" or "oet".
        joints: best joint trajectory (N, DoF) in radians (OET: the S executed postures).
        features: features produced by executing `joints` from the start state (N, F)
            (OET: (S, F)).
        goal: the goal feature trajectory (N, F).
        point_errors: Euclidean error per goal point (N,) (OET: distance from each goal
            point to the nearest executed feature); inf where the execution gave no
            finite features (a point without any valid candidate).
        fitness_history: best fitness so far per generation: (G,) for FTE; (N, G) per
            point for IE, IET and OET (NaN-padded after a point's generations). IET:
            each point's last evolution (the committed one) only; the generations of
            its restarts and backtracked tries count in ``info["point_generations"]``
            (tries: ``info["point_tries"]``).
        evaluations: fitness evaluations (individuals simulated) spent.
        generations: generations run (IE: the longest point; IET/OET: summed over points).
        wall_time_s: run time without compilation.
        compile_time_s: time to lower and compile the jitted functions.
        success: the run met its tolerance (see each strategy): IE, IET, OET and FTE:
            every point's error < tolerance.
        tolerance: that tolerance (feature units). For a quantized feature (paint:
            multiples of 6.25 %) with goals between the steps, half a step (3.125 %)
            means "each executed point is the nearest achievable value".
        final_fitness: final fitness (FTE: DTW; IE/OET: worst point error; IET: the full
            trajectory's Euclidean fitness).
        info: extra settings (algorithm, population_size, seed, trial, ...); where the
            plan has points, ``point_invalid`` (invalid evaluations per point or OET
            step) and ``points_without_valid`` (points whose every candidate diverged:
            their joints are NaN, no posture was found).
        invalid_evaluations: evaluations whose fitness was not finite (the simulation
            diverged); they are ranked last and never reported as the best.
        setup: the simulator it ran on (`cgda_jax.sim.description.setup_of`):
            ``feature_names`` and ``config`` (the config tables that build it
            again), or ``not_described`` (why a config cannot); `save` writes
            them so that the folder opens like a ``cgda run`` one.
    """

    strategy: str
    joints: np.ndarray
    features: np.ndarray
    goal: np.ndarray
    point_errors: np.ndarray
    fitness_history: np.ndarray
    evaluations: int
    generations: int
    wall_time_s: float
    compile_time_s: float
    success: bool
    tolerance: float
    final_fitness: float
    info: dict[str, Any] = dataclasses.field(default_factory=dict)
    invalid_evaluations: int = 0
    setup: dict[str, Any] = dataclasses.field(default_factory=dict, repr=False)

    @property
    def points(self) -> int:
        """Number of goal points N."""
        return int(self.goal.shape[0])

    @property
    def max_point_error(self) -> float:
        """Largest per-point error."""
        return float(np.max(self.point_errors))

    def summary(self) -> dict[str, Any]:
        """The scalar figures (what `save` writes to result.json)."""
        return {
            "strategy": self.strategy,
            "points": self.points,
            "success": bool(self.success),
            "tolerance": float(self.tolerance),
            "max_point_error": self.max_point_error,
            "point_errors": [float(e) for e in self.point_errors],
            "final_fitness": float(self.final_fitness),
            "evaluations": int(self.evaluations),
            "invalid_evaluations": int(self.invalid_evaluations),
            "generations": int(self.generations),
            "wall_time_s": float(self.wall_time_s),
            "compile_time_s": float(self.compile_time_s),
            "info": self.info,
        }

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays `save` writes to arrays.npz, by name."""
        return {k: getattr(self, k) for k in _ARRAYS}

    def save(self, directory: str | os.PathLike, *, overwrite: bool = False,
             name: str | None = None) -> pathlib.Path:
        """Writes the folder `directory` as ``cgda run`` writes a results folder:
        ``result.json`` (`summary`, with ``kind``, ``name`` and the simulator's
        ``feature_names``), ``arrays.npz`` and ``config.toml`` (the simulator's
        config, `setup`, with the strategy's settings), so that ``cgda plot``,
        ``cgda export`` and `cgda_jax.load_run` open it. A simulator that a config
        cannot describe (`setup`'s ``not_described``) gives no config.toml, and
        those readers say why. By the rules of ``cgda run``'s results folders
        (`cgda_jax.results_folder.writing.RunFolder`): written aside and moved into place
        whole, so the folder holds this result or what it held before; a missing
        or empty folder is taken, an existing results folder (one holding a
        result.json) is refused unless ``overwrite``, which replaces it whole
        (no file of the old one is left); a symbolic link is followed.

        Args:
            name: the run's name (default: the folder's).

        Returns:
            The folder written.

        Raises:
            FolderError: `directory` is not empty (without ``overwrite``), holds
                something other than results, is in use or cannot be written.
        """
        import tomli_w

        from cgda_jax.results_folder.writing import RunFolder

        with RunFolder(directory, overwrite=overwrite) as rf:
            name = name or rf.path.name
            summary = {**self.summary(), "kind": "execution", "name": name,
                       **{k: v for k, v in self.setup.items() if k != "config"}}
            (rf.work / "result.json").write_text(
                json.dumps(summary, indent=2) + "\n")
            np.savez(rf.work / "arrays.npz", **self.arrays())
            if "config" in self.setup:
                (rf.work / "config.toml").write_text(tomli_w.dumps(
                    self._config(name)))
        return rf.path

    def _config(self, name: str) -> dict[str, Any]:
        """`setup`'s config tables as a whole execution config named ``name``."""
        tables = {k: dict(v) for k, v in self.setup["config"].items()}
        strategy = {"name": self.strategy, "tolerance": float(self.tolerance)}
        for key, kind in (("algorithm", str), ("population_size", int),
                          ("max_generations", int), ("seed", int),
                          ("chunk_size", int)):
            value = self.info.get(key)
            if isinstance(value, kind) and not isinstance(value, bool):
                strategy[key] = value
        tables["strategy"] = {**strategy, **tables.get("strategy", {})}
        return {"name": name, "kind": "execution",
                "description": "saved from Python (ExecutionResult.save): the goal "
                               "is arrays.npz's, its source not recorded",
                **tables}

    @classmethod
    def load(cls, directory: str | os.PathLike) -> ExecutionResult:
        """Reads a result written by `save` (or an execution run's folder).

        Raises:
            FolderError: a file missing (`~cgda_jax.results_folder.reading.FileMissing`, also a
                `FileNotFoundError`), damaged or not of its schema (result.json:
                `RESULT_FIELDS`; arrays.npz: every array of `save`, of consistent
                shapes); the message names the file.
        """
        from cgda_jax.results_folder.reading import read_json, read_npz

        d = pathlib.Path(directory).expanduser()
        meta = read_json(d / "result.json", RESULT_FIELDS, RESULT_REQUIRED)
        arrays = read_npz(d / "arrays.npz", _ARRAYS)
        _check_shapes(arrays, d / "arrays.npz")
        info = meta.get("info", {})
        return cls(
            strategy=meta["strategy"],
            evaluations=meta["evaluations"],
            generations=meta["generations"],
            wall_time_s=float(meta["wall_time_s"]),
            compile_time_s=float(meta["compile_time_s"]),
            success=meta["success"],
            tolerance=_number(meta["tolerance"]),
            final_fitness=_number(meta["final_fitness"]),
            info=info,
            invalid_evaluations=meta.get("invalid_evaluations", 0),
            setup={k: meta[k] for k in ("feature_names", "not_described")
                   if k in meta},
            **{k: arrays[k] for k in _ARRAYS},  # a run's folder holds more
        )


#: result.json of a saved `ExecutionResult`: key -> type (`cgda_jax.results_folder.reading`).
RESULT_FIELDS = {
    "strategy": "str", "points": "int", "success": "bool",
    "tolerance": "number|null", "max_point_error": "number|null",
    "point_errors": "list[number|null]", "final_fitness": "number|null",
    "evaluations": "int", "invalid_evaluations": "int", "generations": "int",
    "wall_time_s": "number", "compile_time_s": "number", "info": "object",
    "feature_names": "list[str]", "not_described": "str",
}
#: The keys `ExecutionResult.load` needs.
RESULT_REQUIRED = ("strategy", "success", "tolerance", "final_fitness", "evaluations",
                   "generations", "wall_time_s", "compile_time_s")


def _number(value: float | None) -> float:
    """A JSON number back; null stands for a non-finite one (JSON has none)."""
    return float("inf") if value is None else float(value)


def _check_shapes(arrays: dict[str, np.ndarray], where: pathlib.Path) -> None:
    """The ranks of `ExecutionResult`'s arrays, and the goal's points against the
    point errors and the features' width."""
    from cgda_jax.results_folder.rules import FolderError

    ranks = {"joints": (2,), "features": (2,), "goal": (2,), "point_errors": (1,),
             "fitness_history": (1, 2)}
    for name, allowed in ranks.items():
        if arrays[name].ndim not in allowed:
            raise FolderError(f"{where}: {name} has shape {arrays[name].shape}; "
                              f"expected {' or '.join(f'{r}-D' for r in allowed)}")
    goal = arrays["goal"]
    if arrays["point_errors"].shape[0] != goal.shape[0]:
        raise FolderError(f"{where}: point_errors has {arrays['point_errors'].shape[0]} "
                          f"values for a goal of {goal.shape[0]} points")
    if arrays["features"].shape[1] != goal.shape[1]:
        raise FolderError(f"{where}: features have {arrays['features'].shape[1]} "
                          f"columns, the goal {goal.shape[1]}")
