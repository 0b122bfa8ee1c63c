import contextlib
import os
import pathlib
import resource
import signal

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
