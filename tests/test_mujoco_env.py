"""Importing cgda_jax prints no Warp noise and sets no environment variable; the
headless GL choice (made when rendering) respects the user."""

import os
import subprocess
import sys

from cgda_jax.sim import _mujoco_env
from cgda_jax.sim._mujoco_env import headless_backends


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


def test_gl_choice_never_overrides_the_user_or_a_display():
    assert headless_backends({"MUJOCO_GL": "glfw"}, "linux") == []
    assert headless_backends({"MUJOCO_GL": ""}, "linux") == []
    assert headless_backends({"DISPLAY": ":0"}, "linux") == []
    assert headless_backends({"WAYLAND_DISPLAY": "w"}, "linux") == []
    assert headless_backends({}, "darwin") == []


def test_gl_choice_on_a_headless_linux_follows_the_libraries(monkeypatch):
    monkeypatch.setattr(_mujoco_env.ctypes.util, "find_library",
                        lambda name: "libOSMesa.so.8" if name == "OSMesa" else None)
    env = {}
    assert headless_backends(env, "linux") == ["osmesa"] and env == {}
    monkeypatch.setattr(_mujoco_env.ctypes.util, "find_library", lambda name: "lib")
    assert headless_backends({}, "linux") == ["egl", "osmesa"]
    monkeypatch.setattr(_mujoco_env.ctypes.util, "find_library", lambda name: None)
    assert headless_backends({}, "linux") == []


def test_import_sets_no_environment_variable():
    """``import cgda_jax`` and the first use of a simulation name change nothing in
    os.environ (the GL back-end is chosen when rendering)."""
    code = ("import os\nbefore = dict(os.environ)\nimport cgda_jax\n"
            "cgda_jax.Robot, cgda_jax.Simulator, cgda_jax.render_trajectory\n"
            "import cgda_jax.cli, cgda_jax.experiment\n"
            "changed = sorted(k for k in set(before) | set(os.environ)\n"
            "                 if before.get(k) != os.environ.get(k))\n"
            "print('CHANGED', changed)\n")
    env = {k: v for k, v in os.environ.items()
           if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=120, check=True)
    assert "CHANGED []" in proc.stdout, proc.stdout + proc.stderr
