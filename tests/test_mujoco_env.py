"""Importing cgda_jax prints no Warp noise; the headless GL choice respects the user."""

import os
import subprocess
import sys

from cgda_jax.sim import _mujoco_env
from cgda_jax.sim._mujoco_env import choose_gl_backend


def test_import_prints_nothing_about_warp():
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", "import cgda_jax"], env=env,
                          capture_output=True, text=True, timeout=120, check=True)
    assert "warp" not in proc.stdout + proc.stderr


def test_other_output_of_the_mjx_import_is_kept(monkeypatch, capsys):
    lines = ["Failed to import warp: No module named 'warp'",
             "Failed to import warp: CUDA driver too old"]
    kept = [x for x in lines if not _mujoco_env._WARP_ABSENT.match(x)]
    assert kept == ["Failed to import warp: CUDA driver too old"]


def test_gl_choice_never_overrides_the_user_or_a_display(monkeypatch):
    monkeypatch.setattr(sys, "platform", "linux")
    assert choose_gl_backend({"MUJOCO_GL": "glfw"}) == "glfw"
    assert choose_gl_backend({"DISPLAY": ":0"}) is None
    monkeypatch.delitem(sys.modules, "mujoco", raising=False)  # as before the first import
    monkeypatch.setattr(_mujoco_env.ctypes.util, "find_library",
                        lambda name: "libOSMesa.so.8" if name == "OSMesa" else None)
    env = {}
    assert choose_gl_backend(env) == "osmesa" and env["MUJOCO_GL"] == "osmesa"
    monkeypatch.setattr(_mujoco_env.ctypes.util, "find_library", lambda name: None)
    env = {}
    assert choose_gl_backend(env) is None and "MUJOCO_GL" not in env
