"""MuJoCo process matters: the offscreen OpenGL back-end, a quiet ``mujoco.mjx`` import.

- Offscreen rendering: ``import mujoco`` fixes the class of its renderer's OpenGL
  context from ``MUJOCO_GL`` (unset: GLFW, which needs a display; on a headless
  machine its context creation can abort the process instead of raising).  Nothing
  here sets an environment variable: :func:`make_renderer` chooses the back-end when
  a frame is rendered.  It keeps mujoco's choice when ``MUJOCO_GL`` was set or a
  display exists; on a headless Linux machine with ``MUJOCO_GL`` unset it builds
  the ``mujoco.Renderer`` with an EGL context (libEGL, e.g. Debian ``libegl1``),
  else OSMesa (``libosmesa6``).
- ``mujoco.mjx`` tries to import NVIDIA Warp and, when it is not installed (the
  normal case on CPU and for the JAX back-end), prints "Failed to import warp: No
  module named 'warp'" to stdout with ``print``. :func:`import_mjx_quietly`
  drops exactly those "not installed" lines; any other output of that import
  (e.g. Warp installed but broken) is passed through unchanged.
"""

from __future__ import annotations

import contextlib
import ctypes.util
import importlib
import io
import os
import re
import sys
import threading

__all__ = ["headless_backends", "import_mjx_quietly", "last_backend", "make_renderer",
           "mjx_module"]

#: The lines ``mujoco.mjx.warp`` prints when Warp is simply not installed.
_WARP_ABSENT = re.compile(
    r"^Failed to import (warp|mujoco_warp): No module named '(warp|mujoco_warp)[.\w]*'$"
)

_LIBS = (("egl", "EGL"), ("osmesa", "OSMesa"))
_HINT = ("set MUJOCO_GL=egl (package libegl1) or MUJOCO_GL=osmesa (package "
         "libosmesa6) before mujoco is first imported")
_SWAP = threading.Lock()
_LAST = {"backend": ""}


def headless_backends(environ=None, platform: str | None = None) -> list[str]:
    """The offscreen back-ends to try, in order, when mujoco's own choice is GLFW.

    Empty when GLFW should be kept: ``MUJOCO_GL`` set by the user, a display
    (``DISPLAY`` / ``WAYLAND_DISPLAY``), or not Linux.  Otherwise ``egl`` and/or
    ``osmesa``, those whose library is found.  Reads ``environ`` (default
    ``os.environ``), never writes it.
    """
    env = os.environ if environ is None else environ
    platform = sys.platform if platform is None else platform
    if ("MUJOCO_GL" in env or env.get("DISPLAY") or env.get("WAYLAND_DISPLAY")
            or not platform.startswith("linux")):
        return []
    return [backend for backend, lib in _LIBS if ctypes.util.find_library(lib)]


def last_backend() -> str:
    """The OpenGL back-end of the last renderer :func:`make_renderer` made ("egl",
    "osmesa", "glfw", ...; "" before the first)."""
    return _LAST["backend"]


def _name(cls) -> str:
    return getattr(cls, "__module__", "disabled").split(".")[-1]


def _is_glfw(cls) -> bool:
    return cls is not None and getattr(cls, "__module__", "").endswith("glfw")


def make_renderer(model, height: int, width: int):
    """A ``mujoco.Renderer`` whose OpenGL back-end is chosen now (see the module doc).

    Raises:
        RuntimeError: no offscreen OpenGL can be had (the message says what to
            install or set).
    """
    import mujoco

    # the module whose ``GLContext`` mujoco.Renderer instantiates (mujoco 3 and 4)
    gl = getattr(sys.modules[mujoco.Renderer.__module__], "gl_context", None)
    current = getattr(gl, "GLContext", None)
    if not _is_glfw(current):  # MUJOCO_GL chose egl / osmesa / ..., or disabled it
        return _renderer(mujoco, model, height, width, _name(current))
    backends = headless_backends()
    if not backends:
        headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
        if sys.platform.startswith("linux") and headless:
            raise RuntimeError(
                "no offscreen OpenGL: GLFW needs a display"
                + ("" if "MUJOCO_GL" in os.environ else
                   " and neither libEGL nor libOSMesa is installed") + f"; {_HINT}")
        return _renderer(mujoco, model, height, width, _name(current))
    errors = []
    for backend in backends:
        try:
            cls = importlib.import_module(f"mujoco.{backend}").GLContext
            with _SWAP:  # mujoco.Renderer reads gl.GLContext in its __init__ only
                gl.GLContext = cls
                try:
                    renderer = mujoco.Renderer(model, height=height, width=width)
                    _LAST["backend"] = backend
                    return renderer
                finally:
                    gl.GLContext = current
        except Exception as err:  # GL back-ends raise various types
            errors.append(f"{backend}: {type(err).__name__}: {err}")
    raise RuntimeError("cannot create an offscreen MuJoCo renderer "
                       f"({'; '.join(errors)}); {_HINT}")


def _renderer(mujoco, model, height: int, width: int, backend: str):
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
        _LAST["backend"] = backend
        return renderer
    except Exception as err:  # GL back-ends raise various types
        raise RuntimeError(
            f"cannot create an offscreen MuJoCo renderer ({type(err).__name__}: "
            f"{err}); {_HINT}") from err


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
        import_mjx_quietly()
    return sys.modules["mujoco.mjx"]
