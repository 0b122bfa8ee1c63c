import contextlib
import os
import pathlib
import resource
import signal
import subprocess
import sys

import pytest

# Run every test on the CPU unless told otherwise; MJX uses its JAX backend there.
os.environ.setdefault("JAX_PLATFORMS", "cpu")

REPO = pathlib.Path(__file__).resolve().parents[1]
XGNITIVE = pathlib.Path(
    os.environ.get("CGDA_XGNITIVE_DIR", REPO.parent / "shared" / "data" / "xgnitive")
)


@pytest.fixture(scope="session")
def xgnitive_dir() -> pathlib.Path:
    """The real TEO demonstrations; tests that need them skip when absent."""
    if not (XGNITIVE / "xgnitive_icra2018").is_dir():
        pytest.skip(f"xgnitive data not found at {XGNITIVE}")
    return XGNITIVE


@pytest.fixture(scope="session")
def models_dir() -> pathlib.Path:
    return REPO / "models"


@pytest.fixture
def full_disk():
    """``with full_disk(nbytes):`` writes of this process past ``nbytes`` bytes of a
    file fail with ``EFBIG`` ("File too large"), as on a full disk (RLIMIT_FSIZE,
    SIGXFSZ ignored); restored after."""
    @contextlib.contextmanager
    def limited(nbytes: int):
        old_limit = resource.getrlimit(resource.RLIMIT_FSIZE)
        old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, old_limit[1]))
        try:
            yield
        finally:
            resource.setrlimit(resource.RLIMIT_FSIZE, old_limit)
            signal.signal(signal.SIGXFSZ, old_handler)
    return limited


@pytest.fixture(scope="session")
def offscreen_script():
    """``offscreen_script(script, out)`` runs a Python ``script`` (given ``out`` as
    its argument; it prints DONE at the end) in a subprocess under MUJOCO_GL=egl,
    then osmesa; skips when neither gives an offscreen OpenGL context, fails on
    any other error."""
    def run(script: str, out: pathlib.Path) -> pathlib.Path:
        for backend in ("egl", "osmesa"):
            env = dict(os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend,
                       JAX_PLATFORMS="cpu", PYTHONPATH=str(REPO))
            proc = subprocess.run([sys.executable, "-c", script, str(out)], env=env,
                                  capture_output=True, text=True, timeout=300,
                                  check=False)
            if proc.returncode == 0 and "DONE" in proc.stdout:
                return out
            gl_words = ("offscreen", "EGL", "OSMesa", "OpenGL", "libGL")
            if not any(word in proc.stderr for word in gl_words):
                raise AssertionError(proc.stderr[-3000:])
        pytest.skip("no offscreen OpenGL (MUJOCO_GL=egl or osmesa) on this machine")
    return run
