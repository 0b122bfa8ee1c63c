"""Simulation: robot models, scenes, batched execution in MJX, offscreen rendering."""

# ``mujoco.mjx`` is imported (quietly) only when dynamic mode or the "mjx" kinematics
# needs it, and the public names below are imported on first access.  The offscreen
# OpenGL back-end is chosen when rendering (`cgda_jax.sim._mujoco_env.make_renderer`);
# `headless_backends` (those a headless machine can use) and `last_backend` (the one
# a render used) are public here for the experiment layer and the CLI, and
# `make_renderer` for renders of other scenes (`cgda_jax.vision.record`).
import importlib as _importlib

_LAZY = {
    "MODES": "cgda_jax.sim.sim_state",
    "SimState": "cgda_jax.sim.sim_state",
    "Simulator": "cgda_jax.sim.simulator",
    "render_trajectory": "cgda_jax.sim.render",
    "FeatureSet": "cgda_jax.sim.features",
    "FeatureSpec": "cgda_jax.sim.features",
    "add_sensors": "cgda_jax.sim.features",
    "ObjectLocator": "cgda_jax.sim.relocate",
    "compile_world": "cgda_jax.sim.world",
    "compose_world": "cgda_jax.sim.world",
    "list_pieces": "cgda_jax.sim.world",
    "KINEMATICS": "cgda_jax.sim.robot",
    "Robot": "cgda_jax.sim.robot",
    "model_path": "cgda_jax.sim.robot",
    "MarkerScene": "cgda_jax.sim.scenes",
    "PaintWall": "cgda_jax.sim.scenes",
    "ObjectScene": "cgda_jax.sim.scenes",
    "headless_backends": "cgda_jax.sim._mujoco_env",
    "last_backend": "cgda_jax.sim._mujoco_env",
    "make_renderer": "cgda_jax.sim._mujoco_env",
}

__all__ = [
    "FeatureSet",
    "FeatureSpec",
    "KINEMATICS",
    "MODES",
    "MarkerScene",
    "ObjectLocator",
    "ObjectScene",
    "PaintWall",
    "Robot",
    "SimState",
    "Simulator",
    "add_sensors",
    "compile_world",
    "compose_world",
    "headless_backends",
    "last_backend",
    "list_pieces",
    "make_renderer",
    "model_path",
    "render_trajectory",
]


def __getattr__(name: str):
    """Import a public name on first access."""
    if name not in _LAZY:
        raise AttributeError(f"module 'cgda_jax.sim' has no attribute {name!r}")
    value = getattr(_importlib.import_module(_LAZY[name]), name)
    globals()[name] = value
    return value
