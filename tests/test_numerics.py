"""Exact float32 products (cgda_jax.numerics): JAX's default precision computes
float32 matrix products in TensorFloat-32 on recent NVIDIA GPUs (TEO's marker 0.54
mm off MuJoCo's on an H200); cgda_jax's programs must ask for full float32."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp

from cgda_jax.sim import Robot, model_path
from cgda_jax.sim.feasibility import Feasibility

IMPORT = "import jax, cgda_jax.sim.robot, cgda_jax.strategies; "
BUILD = ("from cgda_jax import Robot, model_path; Robot.from_mjcf(model_path("
         "'tiny_arm.xml'), ['yaw', 'shoulder', 'elbow'], 'marker'); ")
PRINT = "print(jax.config.jax_default_matmul_precision)"


def _precision_after(code: str, env_value=None) -> str:
    env = {k: v for k, v in os.environ.items() if k != "JAX_DEFAULT_MATMUL_PRECISION"}
    if env_value is not None:
        env["JAX_DEFAULT_MATMUL_PRECISION"] = env_value
    env["JAX_PLATFORMS"] = "cpu"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=120, check=True)
    return out.stdout.strip().splitlines()[-1]


def test_importing_changes_no_setting_building_a_robot_asks_for_full_float32():
    """The precision is set where programs are built (a Robot, a plan), not as a
    side effect of an import."""
    assert _precision_after(IMPORT + PRINT) == "None"
    assert _precision_after(IMPORT + BUILD + PRINT) == "highest"


def test_a_precision_the_user_chose_is_kept():
    assert _precision_after(IMPORT + BUILD + PRINT, "bfloat16") == "bfloat16"


def _dot_precisions(jaxpr) -> list:
    found = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "dot_general":
            found.append(eqn.params.get("precision"))
        for v in eqn.params.values():  # inside pjit / cond / scan bodies
            inner = getattr(v, "jaxpr", v)
            if hasattr(inner, "eqns"):
                found += _dot_precisions(inner)
    return found


def test_marker_and_collision_programs_trace_every_product_at_highest():
    robot = Robot.from_mjcf(model_path("teo.xml"),
                            ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"],
                            "marker")
    feas = Feasibility(robot)
    genes = jnp.zeros((4, 3), jnp.float32)
    for fn in (robot.marker_position, feas.collider.distances):
        jaxpr = jax.make_jaxpr(jax.vmap(fn))(genes).jaxpr
        precisions = _dot_precisions(jaxpr)
        assert precisions, "no matrix product traced: the check would be empty"
        highest = (jax.lax.Precision.HIGHEST, jax.lax.Precision.HIGHEST)
        assert all(p == highest for p in precisions), precisions
