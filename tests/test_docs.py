"""The documentation site builds with `mkdocs build --strict` (warnings are errors)."""

import pathlib
import subprocess
import sys

import pytest

pytest.importorskip("mkdocs")
pytest.importorskip("mkdocstrings")
pytest.importorskip("mkdocs_jupyter")

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        check=False, cwd=ROOT, capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    return out


def test_home_page_is_the_readme(site):
    html = (site / "index.html").read_text(encoding="utf-8")
    assert "What CGDA does" in html and "Tutorials and docs" in html


def test_api_pages_document_the_public_functions(site):
    strategies = (site / "api" / "strategies" / "index.html").read_text(encoding="utf-8")
    assert 'id="cgda_jax.strategies.ie.run_ie"' in strategies
    core = (site / "api" / "core" / "index.html").read_text(encoding="utf-8")
    assert 'id="cgda_jax.generalization.generalize"' in core
    recognition = (site / "api" / "recognition" / "index.html").read_text("utf-8")
    assert 'id="cgda_jax.segmentation.segment"' in recognition
    # a docstring's text reached the page (not just the heading)
    assert "time-normalize" in core.lower() or "interval" in core.lower()


def test_every_notebook_is_a_page(site):
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        page = site / "notebooks" / nb.stem / "index.html"
        assert page.is_file(), f"no page for {nb.name}"
    # saved outputs are shown (figures as embedded PNG), never re-executed
    page = (site / "notebooks" / "01_getting_started" / "index.html").read_text(
        encoding="utf-8")
    assert "data:image/png;base64" in page
