import os
import pathlib

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
