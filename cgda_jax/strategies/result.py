"""`ExecutionResult`: what a strategy run returns, with a JSON + NPZ round trip; and
`SimulationDiverged`, raised when no candidate of a run could be evaluated."""

from __future__ import annotations

import dataclasses
import json
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

    def save(self, directory: str | pathlib.Path) -> pathlib.Path:
        """Writes ``result.json`` (summary) and ``arrays.npz`` into `directory`."""
        d = pathlib.Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        (d / "result.json").write_text(json.dumps(self.summary(), indent=2) + "\n")
        np.savez(d / "arrays.npz", **{k: getattr(self, k) for k in _ARRAYS})
        return d

    @classmethod
    def load(cls, directory: str | pathlib.Path) -> ExecutionResult:
        """Reads a result written by `save`."""
        d = pathlib.Path(directory)
        for name in ("result.json", "arrays.npz"):
            if not (d / name).is_file():
                raise FileNotFoundError(f"{d / name} not found (not a saved result?)")
        meta = json.loads((d / "result.json").read_text())
        with np.load(d / "arrays.npz") as z:
            arrays = {k: z[k] for k in _ARRAYS}
        return cls(
            strategy=meta["strategy"],
            evaluations=meta["evaluations"],
            generations=meta["generations"],
            wall_time_s=meta["wall_time_s"],
            compile_time_s=meta["compile_time_s"],
            success=meta["success"],
            tolerance=meta["tolerance"],
            final_fitness=meta["final_fitness"],
            info=meta.get("info", {}),
            invalid_evaluations=meta.get("invalid_evaluations", 0),
            **arrays,
        )
