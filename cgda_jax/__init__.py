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

# --- simulation (robot, scenes, execution, rendering) ------------------------

# --- strategies (FTE, IE, IET, OET) ------------------------------------------

# --- user layer (datasets, experiments) --------------------------------------
