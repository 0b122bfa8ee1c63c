"""cgda_jax: Continuous Goal-Directed Actions in JAX.

Generalize demonstrated object-feature trajectories, recognize actions by DTW or
Euclidean distance, and execute them on a simulated robot by evolving joint
trajectories, with whole populations simulated at once in MuJoCo MJX.

References:
    Morante, Victores, Jardón, Balaguer. "Humanoid Robot Imitation through
    Continuous Goal-Directed Actions: An Evolutionary Approach." Advanced
    Robotics, 2015.
"""

import importlib as _importlib

__version__ = "0.1.0"

#: The public names, each listed once, by the module that defines them.  They are
#: imported on first use (PEP 562 ``__getattr__``): every one of these modules
#: imports JAX (most also MuJoCo, evosax or matplotlib), and ``import cgda_jax``
#: would take seconds instead of milliseconds, for the ``cgda`` command's help and
#: listing too (measured: README "Development").
_EXPORTS: dict[str, tuple[str, ...]] = {
    # core: data, generalization, distances, recognition
    "cgda_jax.data": ("Demonstration", "load_csv", "load_npz", "load_xgnitive",
                      "load_xgnitive_force", "save_csv", "save_npz",
                      "validate_demonstrations", "xgnitive_clock_offsets"),
    "cgda_jax.distance": ("dtw", "dtw_multi", "dtw_per_feature", "euclidean",
                          "point_sum", "resample", "soft_dtw"),
    "cgda_jax.generalization": ("GeneralizedAction", "generalize",
                                "generalize_streams", "rbf_interpolate"),
    "cgda_jax.recognition": ("ActionLibrary", "Recognition", "cost_matrix",
                             "recognize"),
    "cgda_jax.segmentation": ("Segment", "execute_sequence", "segment"),
    # selection of features and demonstrations (issue 44)
    "cgda_jax.select": ("DemonstrationSelection", "FeatureSelection",
                        "select_demonstrations", "select_features"),
    # simulation: robot, scenes, execution, rendering
    "cgda_jax.sim.sim_state": ("SimState",),
    "cgda_jax.sim.simulator": ("Simulator",),
    "cgda_jax.sim.render": ("render_trajectory",),
    "cgda_jax.sim.features": ("FeatureSet", "FeatureSpec"),
    "cgda_jax.sim.world": ("compile_world", "compose_world"),
    "cgda_jax.sim.robot": ("Robot", "model_path"),
    "cgda_jax.sim.scenes": ("MarkerScene", "PaintWall", "ObjectScene"),
    # strategies: FTE, IE, IET, OET
    "cgda_jax.strategies": ("ALGORITHMS", "STRATEGIES", "ExecutionResult",
                            "SimulationDiverged", "run_fte", "run_ie", "run_iet",
                            "run_oet", "run_trials"),
    "cgda_jax.strategies.closed_loop": ("run_oet_closed_loop",),
    # experiments and their results folders
    "cgda_jax.experiment": ("ExperimentConfig", "load_config", "run_experiment"),
    "cgda_jax.experiment.load": ("Run", "load_run"),
    "cgda_jax.experiment.trajectory_file": ("export_trajectory", "check_exported"),
    # from simulation to a robot: export, replay, a mismatched world
    "cgda_jax.reality.control_trajectory": ("ExportedTrajectory", "time_parameterize"),
    "cgda_jax.reality.files": ("load_trajectory", "save_trajectory"),
    "cgda_jax.reality.replay": ("replay_trajectory",),
    "cgda_jax.reality.protocol": ("Reality", "Measurement", "RealityError"),
    "cgda_jax.reality.mismatch": ("Mismatch", "MismatchedWorld"),
    "cgda_jax.reality.calibrate": ("estimate_offsets", "OffsetEstimate"),
}
#: Submodules reached as attributes (``cgda_jax.datasets.clean_circle_demos``).
_SUBMODULES = ("checks", "datasets", "plotting", "sizes")

_ORIGIN = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = ["__version__", *_ORIGIN, *_SUBMODULES]


def __getattr__(name: str):
    """A public name (or the ``checks``, ``datasets``, ``plotting`` or ``sizes``
    module), imported on first access."""
    if name in _SUBMODULES:
        value = _importlib.import_module(f"cgda_jax.{name}")
    elif name in _ORIGIN:
        value = getattr(_importlib.import_module(_ORIGIN[name]), name)
    else:
        raise AttributeError(f"module 'cgda_jax' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
