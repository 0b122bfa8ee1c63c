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

__all__: list[str] = ["__version__"]

# --- core (data, generalization, distances, recognition) ---------------------
# (section owned by the core work; keep one import per line, extend __all__)
from cgda_jax.data import Demonstration as Demonstration
from cgda_jax.data import load_csv as load_csv
from cgda_jax.data import load_npz as load_npz
from cgda_jax.data import load_xgnitive as load_xgnitive
from cgda_jax.data import save_csv as save_csv
from cgda_jax.data import save_npz as save_npz
from cgda_jax.data import validate_demonstrations as validate_demonstrations
from cgda_jax.distance import dtw as dtw
from cgda_jax.distance import dtw_multi as dtw_multi
from cgda_jax.distance import euclidean as euclidean
from cgda_jax.distance import resample as resample
from cgda_jax.generalize import GeneralizedAction as GeneralizedAction
from cgda_jax.generalize import generalize as generalize
from cgda_jax.generalize import rbf_interpolate as rbf_interpolate
from cgda_jax.recognize import ActionLibrary as ActionLibrary
from cgda_jax.recognize import Recognition as Recognition
from cgda_jax.recognize import cost_matrix as cost_matrix
from cgda_jax.recognize import recognize as recognize

__all__ += [
    "Demonstration",
    "validate_demonstrations",
    "load_csv",
    "load_npz",
    "save_csv",
    "save_npz",
    "load_xgnitive",
    "dtw",
    "dtw_multi",
    "euclidean",
    "resample",
    "GeneralizedAction",
    "generalize",
    "rbf_interpolate",
    "ActionLibrary",
    "Recognition",
    "cost_matrix",
    "recognize",
]

# --- simulation (robot, scenes, execution, rendering) ------------------------
from cgda_jax.sim.execute import SimState as SimState
from cgda_jax.sim.execute import Simulator as Simulator
from cgda_jax.sim.render import render_trajectory as render_trajectory
from cgda_jax.sim.robot import Robot as Robot
from cgda_jax.sim.robot import model_path as model_path
from cgda_jax.sim.scenes import MarkerScene as MarkerScene
from cgda_jax.sim.scenes import PaintWall as PaintWall

__all__ += [
    "Robot",
    "model_path",
    "MarkerScene",
    "PaintWall",
    "SimState",
    "Simulator",
    "render_trajectory",
]

# --- strategies (FTE, IE, IET, OET) ------------------------------------------
from cgda_jax.strategies import (
    ALGORITHMS as ALGORITHMS,
    STRATEGIES as STRATEGIES,
    ExecutionResult as ExecutionResult,
    run_fte as run_fte,
    run_ie as run_ie,
    run_iet as run_iet,
    run_oet as run_oet,
    run_trials as run_trials,
)

__all__ += [
    "ALGORITHMS",
    "STRATEGIES",
    "ExecutionResult",
    "run_fte",
    "run_ie",
    "run_iet",
    "run_oet",
    "run_trials",
]

# --- user layer (datasets, experiments) --------------------------------------
from cgda_jax import datasets as datasets
from cgda_jax.experiment import (
    ExperimentConfig as ExperimentConfig,
    load_config as load_config,
    run_experiment as run_experiment,
)

__all__ += ["ExperimentConfig", "datasets", "load_config", "run_experiment"]
