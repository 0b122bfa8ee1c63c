"""Simulation: robot models, scenes, batched execution in MJX, offscreen rendering."""

# Before the first ``import mujoco``: headless OpenGL choice, quiet mujoco.mjx import.
from cgda_jax.sim._mujoco_env import choose_gl_backend, import_mjx_quietly

choose_gl_backend()
import_mjx_quietly()

from cgda_jax.sim.execute import (  # noqa: E402
    MODES as MODES,
    SimState as SimState,
    Simulator as Simulator,
)
from cgda_jax.sim.render import render_trajectory as render_trajectory  # noqa: E402
from cgda_jax.sim.robot import (  # noqa: E402
    KINEMATICS as KINEMATICS,
    Robot as Robot,
    model_path as model_path,
)
from cgda_jax.sim.scenes import MarkerScene as MarkerScene, PaintWall as PaintWall  # noqa: E402

__all__ = [
    "KINEMATICS",
    "MODES",
    "MarkerScene",
    "PaintWall",
    "Robot",
    "SimState",
    "Simulator",
    "model_path",
    "render_trajectory",
]
