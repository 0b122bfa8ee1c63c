"""The notebooks execute top to bottom (small settings via CGDA_SMALL=1)."""

import os
import pathlib

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOKS = pathlib.Path(__file__).resolve().parents[1] / "notebooks"


# The longest notebooks (35-74 s each in CI) run with -m slow; the others every time.
SLOW = {"05_objects", "06_your_own_robot", "07_reading_runs"}


@pytest.mark.parametrize(
    "path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW else p
             for p in sorted(NOTEBOOKS.glob("*.ipynb"))],
    ids=lambda p: p.stem)
def test_notebook_runs(path, monkeypatch, request, tmp_path_factory):
    # never the user's compilation cache (~/.cache/cgda_jax), should a notebook enable it
    monkeypatch.setenv("CGDA_JAX_CACHE", str(tmp_path_factory.getbasetemp() / "jaxcache"))
    if "real_teo" in path.stem:
        data = request.getfixturevalue("xgnitive_dir")  # skips when absent
        monkeypatch.setenv("CGDA_XGNITIVE_DIR", str(data))
    monkeypatch.setenv("CGDA_SMALL", "1")
    monkeypatch.setenv("JAX_PLATFORMS", os.environ.get("JAX_PLATFORMS", "cpu"))
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOKS)}}
    )
    client.execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors
