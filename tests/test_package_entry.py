"""The package entry: each public name listed once and resolving, nothing heavy
imported by ``import cgda_jax``, and JAX's matmul precision set where programs are
built (a `Robot`, a strategy's plan), never as a side effect of an import."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys

import cgda_jax


def _python(code: str) -> str:
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    env.pop("JAX_DEFAULT_MATMUL_PRECISION", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=300, check=True)
    return out.stdout.strip()


def test_every_public_name_is_listed_once_and_resolves():
    names = cgda_jax.__all__
    assert len(names) == len(set(names))
    for name in names:
        assert getattr(cgda_jax, name) is not None, name
    # a function keeps its name when a module of the same concept is imported
    importlib.import_module("cgda_jax.generalization")
    importlib.import_module("cgda_jax.recognition")
    assert callable(cgda_jax.generalize) and callable(cgda_jax.recognize)
    assert cgda_jax.ObjectScene.__name__ == "ObjectScene"


def test_import_is_light_and_precision_is_set_where_programs_are_built():
    out = _python(
        "import sys, cgda_jax\n"
        "print('jax' in sys.modules)\n"
        "import jax, cgda_jax.sim.robot, cgda_jax.strategies.base\n"
        "print(jax.config.jax_default_matmul_precision)\n"
        "cgda_jax.Robot.from_mjcf(cgda_jax.model_path('tiny_arm.xml'),"
        " ['yaw', 'shoulder', 'elbow'], 'marker')\n"
        "print(jax.config.jax_default_matmul_precision)\n")
    assert out.splitlines() == ["False", "None", "highest"]
    # a precision the user chose is kept
    out = _python(
        "import jax; jax.config.update('jax_default_matmul_precision', 'bfloat16')\n"
        "import cgda_jax\n"
        "cgda_jax.Robot.from_mjcf(cgda_jax.model_path('tiny_arm.xml'),"
        " ['yaw', 'shoulder', 'elbow'], 'marker')\n"
        "print(jax.config.jax_default_matmul_precision)\n")
    assert out == "bfloat16"
