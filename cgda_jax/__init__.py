"""cgda_jax: Continuous Goal-Directed Actions in JAX.

Generalize demonstrated object-feature trajectories, recognize actions by DTW or
Euclidean distance, and execute them on a simulated robot by evolving joint
trajectories, with whole populations simulated at once in MuJoCo MJX.

References:
    Morante, Victores, Jardón, Balaguer. "Humanoid Robot Imitation through
    Continuous Goal-Directed Actions: An Evolutionary Approach." Advanced
    Robotics, 2015.
"""

__version__ = "0.1.0"

# Every public name is imported on first access (PEP 562 ``__getattr__``), so
# ``import cgda_jax`` costs almost nothing: JAX, MuJoCo, mujoco.mjx, evosax/flax and
# matplotlib load only when a name that needs them is used.  Each section maps its
# public names to the module that defines them (same names as ``from ... import``).

import importlib as _importlib
import sys as _sys
import types as _types
from typing import TYPE_CHECKING as _TYPE_CHECKING

_LAZY: dict[str, str] = {}  # public name -> module that defines it

# --- core (data, generalization, distances, recognition) ---------------------
_LAZY.update({
    "Demonstration": "cgda_jax.data",
    "load_csv": "cgda_jax.data",
    "load_npz": "cgda_jax.data",
    "load_xgnitive": "cgda_jax.data",
    "load_xgnitive_force": "cgda_jax.data",
    "xgnitive_clock_offsets": "cgda_jax.data",
    "save_csv": "cgda_jax.data",
    "save_npz": "cgda_jax.data",
    "validate_demonstrations": "cgda_jax.data",
    "dtw": "cgda_jax.distance",
    "dtw_multi": "cgda_jax.distance",
    "euclidean": "cgda_jax.distance",
    "point_sum": "cgda_jax.distance",
    "resample": "cgda_jax.distance",
    "soft_dtw": "cgda_jax.distance",
    "GeneralizedAction": "cgda_jax.generalize",
    "generalize": "cgda_jax.generalize",
    "generalize_streams": "cgda_jax.generalize",
    "rbf_interpolate": "cgda_jax.generalize",
    "ActionLibrary": "cgda_jax.recognize",
    "Recognition": "cgda_jax.recognize",
    "cost_matrix": "cgda_jax.recognize",
    "recognize": "cgda_jax.recognize",
    "Segment": "cgda_jax.segment",
    "execute_sequence": "cgda_jax.segment",
    "segment": "cgda_jax.segment",
})
# --- selection of features and demonstrations (issue 44) ---------------------
_LAZY.update({
    "dtw_per_feature": "cgda_jax.distance",
    "DemonstrationSelection": "cgda_jax.select",
    "FeatureSelection": "cgda_jax.select",
    "select_demonstrations": "cgda_jax.select",
    "select_features": "cgda_jax.select",
})


# --- simulation (robot, scenes, execution, rendering) ------------------------
_LAZY.update({
    "SimState": "cgda_jax.sim.sim_state",
    "Simulator": "cgda_jax.sim.execute",
    "render_trajectory": "cgda_jax.sim.render",
    "FeatureSet": "cgda_jax.sim.features",
    "FeatureSpec": "cgda_jax.sim.features",
    "compile_world": "cgda_jax.sim.world",
    "compose_world": "cgda_jax.sim.world",
    "Robot": "cgda_jax.sim.robot",
    "model_path": "cgda_jax.sim.robot",
    "MarkerScene": "cgda_jax.sim.scenes",
    "PaintWall": "cgda_jax.sim.scenes",
    "ObjectScene": "cgda_jax.sim.scenes",
})


# --- strategies (FTE, IE, IET, OET) ------------------------------------------
_LAZY.update({
    name: "cgda_jax.strategies"
    for name in (
        "ALGORITHMS",
        "STRATEGIES",
        "ExecutionResult",
        "SimulationDiverged",
        "run_fte",
        "run_ie",
        "run_iet",
        "run_oet",
        "run_trials",
    )
})


# --- user layer (datasets, experiments) --------------------------------------
_LAZY.update({
    "ExperimentConfig": "cgda_jax.experiment",
    "load_config": "cgda_jax.experiment",
    "load_run": "cgda_jax.experiment.load",
    "Run": "cgda_jax.experiment.load",
    "run_experiment": "cgda_jax.experiment",
})


# --- from simulation to a robot (export, replay) ------------------------------
_LAZY.update({
    "ExportedTrajectory": "cgda_jax.reality.export",
    "time_parameterize": "cgda_jax.reality.export",
    "load_trajectory": "cgda_jax.reality.files",
    "save_trajectory": "cgda_jax.reality.files",
    "replay_trajectory": "cgda_jax.reality.replay",
    "Reality": "cgda_jax.reality.protocol",
    "Measurement": "cgda_jax.reality.protocol",
    "RealityError": "cgda_jax.reality.protocol",
    "Mismatch": "cgda_jax.reality.mismatch",
    "MismatchedWorld": "cgda_jax.reality.mismatch",
    "estimate_offsets": "cgda_jax.reality.calibrate",
    "OffsetEstimate": "cgda_jax.reality.calibrate",
    "export_trajectory": "cgda_jax.experiment.export",
    "check_exported": "cgda_jax.experiment.export",
    "run_oet_closed_loop": "cgda_jax.strategies.closed_loop",
})


_SUBMODULES = ("checks", "datasets", "sizes")

__all__: list[str] = ["__version__", *_LAZY, *_SUBMODULES]


def __getattr__(name: str):
    """Import a public name (or the ``checks`` / ``datasets`` / ``sizes`` module) on
    first access."""
    if name in _SUBMODULES:
        module = _importlib.import_module(f"cgda_jax.{name}")
    elif name in _LAZY:
        module = getattr(_importlib.import_module(_LAZY[name]), name)
    else:
        raise AttributeError(f"module 'cgda_jax' has no attribute {name!r}")
    globals()[name] = module
    return module


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(_types.ModuleType):
    """Keeps a public function bound when its same-named submodule is imported.

    ``cgda_jax.generalize`` and ``cgda_jax.recognize`` are both functions and
    modules; importing the module makes Python set the package attribute to the
    module, which would hide the function.  The function wins, as with the former
    eager ``from cgda_jax.recognize import recognize``.
    """

    def __setattr__(self, name: str, value) -> None:
        if (
            isinstance(value, _types.ModuleType)
            and _LAZY.get(name) == f"{__name__}.{name}"
            and hasattr(value, name)
        ):
            value = getattr(value, name)
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package


if _TYPE_CHECKING:  # static analysers and IDEs see the real imports
    from cgda_jax import (  # noqa: F401
        checks as checks, datasets as datasets, sizes as sizes,
    )
    from cgda_jax.data import (  # noqa: F401
        Demonstration, load_csv, load_npz, load_xgnitive, load_xgnitive_force,
        save_csv, save_npz, validate_demonstrations, xgnitive_clock_offsets,
    )
    from cgda_jax.distance import (  # noqa: F401
        dtw, dtw_multi, euclidean, point_sum, resample, soft_dtw,
    )
    from cgda_jax.experiment import (  # noqa: F401
        ExperimentConfig, load_config, run_experiment,
    )
    from cgda_jax.experiment.export import check_exported, export_trajectory  # noqa: F401
    from cgda_jax.experiment.load import Run, load_run  # noqa: F401
    from cgda_jax.generalize import (  # noqa: F401
        GeneralizedAction, generalize, generalize_streams, rbf_interpolate,
    )
    from cgda_jax.reality.calibrate import OffsetEstimate, estimate_offsets  # noqa: F401
    from cgda_jax.reality.export import ExportedTrajectory, time_parameterize  # noqa: F401
    from cgda_jax.reality.files import load_trajectory, save_trajectory  # noqa: F401
    from cgda_jax.reality.mismatch import Mismatch, MismatchedWorld  # noqa: F401
    from cgda_jax.reality.protocol import Measurement, Reality, RealityError  # noqa: F401
    from cgda_jax.reality.replay import replay_trajectory  # noqa: F401
    from cgda_jax.strategies.closed_loop import run_oet_closed_loop  # noqa: F401
    from cgda_jax.recognize import (  # noqa: F401
        ActionLibrary, Recognition, cost_matrix, recognize,
    )
    from cgda_jax.select import (  # noqa: F401
        DemonstrationSelection, FeatureSelection, select_demonstrations,
        select_features,
    )
    from cgda_jax.distance import dtw_per_feature  # noqa: F401
    from cgda_jax.sim.execute import Simulator  # noqa: F401
    from cgda_jax.sim.sim_state import SimState  # noqa: F401
    from cgda_jax.sim.features import FeatureSet, FeatureSpec  # noqa: F401
    from cgda_jax.sim.render import render_trajectory  # noqa: F401
    from cgda_jax.sim.robot import Robot, model_path  # noqa: F401
    from cgda_jax.sim.scenes import MarkerScene, PaintWall  # noqa: F401
    from cgda_jax.sim.world import compile_world, compose_world  # noqa: F401
    from cgda_jax.strategies import (  # noqa: F401
        ALGORITHMS, STRATEGIES, ExecutionResult, SimulationDiverged, run_fte, run_ie,
        run_iet, run_oet, run_trials,
    )
