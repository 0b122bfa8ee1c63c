"""Prepare the process for ``import mujoco`` / ``mujoco.mjx`` (run before either).

Two things that MuJoCo decides at import time:

- The OpenGL back-end for offscreen rendering (``MUJOCO_GL``, read once by
  ``import mujoco``). On a headless Linux machine (no ``DISPLAY`` /
  ``WAYLAND_DISPLAY``) the default, GLFW, cannot work; :func:`choose_gl_backend`
  picks ``egl`` (libEGL, e.g. Debian ``libegl1``) else ``osmesa`` (libOSMesa,
  ``libosmesa6``). It never overrides a value the user set, never acts when a
  display exists or when mujoco is already imported.
- ``mujoco.mjx`` tries to import NVIDIA Warp and, when it is not installed (the
  normal case on CPU and for the JAX back-end), prints "Failed to import warp: No
  module named 'warp'" to stdout with ``print``. :func:`import_mjx_quietly`
  drops exactly those "not installed" lines; any other output of that import
  (e.g. Warp installed but broken) is passed through unchanged.
"""

from __future__ import annotations

import contextlib
import ctypes.util
import io
import os
import re
import sys

__all__ = ["choose_gl_backend", "import_mjx_quietly", "mjx_module"]

#: The lines ``mujoco.mjx.warp`` prints when Warp is simply not installed.
_WARP_ABSENT = re.compile(
    r"^Failed to import (warp|mujoco_warp): No module named '(warp|mujoco_warp)[.\w]*'$"
)

_LIBS = (("egl", "EGL"), ("osmesa", "OSMesa"))


def choose_gl_backend(environ: dict | None = None) -> str | None:
    """Set ``MUJOCO_GL`` to an available headless back-end if it is unset.

    Args:
        environ: the environment to read and update (default ``os.environ``).

    Returns:
        The value of ``MUJOCO_GL`` afterwards (None when left unset).
    """
    env = os.environ if environ is None else environ
    if "MUJOCO_GL" in env:
        return env["MUJOCO_GL"]
    headless = not (env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))
    if not sys.platform.startswith("linux") or not headless or "mujoco" in sys.modules:
        return None
    for backend, lib in _LIBS:
        if ctypes.util.find_library(lib):
            env["MUJOCO_GL"] = backend
            return backend
    return None


def import_mjx_quietly() -> None:
    """Import ``mujoco.mjx`` without its "warp not installed" lines on stdout."""
    if "mujoco.mjx.warp" in sys.modules:
        return
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            import mujoco.mjx  # noqa: F401
    finally:
        kept = [line for line in buf.getvalue().splitlines()
                if not _WARP_ABSENT.match(line.strip())]
        if kept:
            print("\n".join(kept), flush=True)


def mjx_module():
    """``mujoco.mjx``, imported (quietly) on the first call.

    Only dynamic mode and the "mjx" forward kinematics need it; importing it costs
    about 1 s, so nothing imports it at ``import cgda_jax``.
    """
    if "mujoco.mjx" not in sys.modules:
        choose_gl_backend()
        import_mjx_quietly()
    return sys.modules["mujoco.mjx"]
