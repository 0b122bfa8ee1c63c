"""Simulation: robot models, scenes, batched execution in MJX, offscreen rendering."""

from cgda_jax.sim.execute import (
    MODES as MODES,
    SimState as SimState,
    Simulator as Simulator,
)
from cgda_jax.sim.render import render_trajectory as render_trajectory
from cgda_jax.sim.robot import (
    KINEMATICS as KINEMATICS,
    Robot as Robot,
    model_path as model_path,
)
from cgda_jax.sim.scenes import MarkerScene as MarkerScene, PaintWall as PaintWall

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
