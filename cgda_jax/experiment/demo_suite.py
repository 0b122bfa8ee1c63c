"""The experiments of ``cgda demo``."""

from __future__ import annotations

from typing import Any

from cgda_jax.experiment.config import ExperimentConfig, merge_table

#: The main job of ``cgda demo``: overrides of the defaults per experiment (the same
#: settings as the files of the same name in the repository's ``experiments/``).
DEMO_EXPERIMENTS: dict[str, dict[str, Any]] = {
    "recognition_all_features": {"kind": "recognition", "data": {"features": "marker"}},
    "recognition_spatial": {"kind": "recognition", "data": {"features": "spatial"}},
    "recognition_arm_points": {"kind": "recognition", "data": {"features": "arm"}},
    "clean_ie": {
        "kind": "execution",
        "data": {"source": "clean_circle"},
        "robot": {"fixed": {"r_forearm_rotation": 45.0}},
        "scene": {"kind": "marker"},
        "strategy": {"name": "ie", "population_size": 32, "tolerance": 0.02,
                     "max_generations": 200},
    },
    "paint_iet": {
        "kind": "execution",
        "data": {"source": "paint_ramp", "goal_points": 17},
        "robot": {"fixed": {"r_forearm_rotation": 45.0}, "waypoint_s": 1.5},
        "scene": {"kind": "paint"},
        "strategy": {"name": "iet", "population_size": 32, "tolerance": 3.0,
                     "max_generations": 200, "options": {"backtracks": 24}},
    },
}

_SMALL = {"strategy": {"max_generations": 100}, "recognition": {"n_samples": 60}}


def demo_configs(small: bool = False) -> list[ExperimentConfig]:
    """The configs of ``cgda demo`` (``small``: fewer generations and samples)."""
    out = []
    for name, table in DEMO_EXPERIMENTS.items():
        cfg = ExperimentConfig(name=name)
        merge_table(cfg, table)
        if small:
            merge_table(cfg, {k: v for k, v in _SMALL.items()
                         if k == "recognition" or cfg.kind == "execution"})
        out.append(cfg)
    return out
