"""cgda_jax installs like a library: built-in models and experiments, CLI, the wheel.

- Built-in files: models, object pieces and experiment configs are found through the
  package (`cgda_jax.builtin`), every experiment has a one-line description.
- CLI: ``cgda list``, ``cgda run NAME``, a clear error for an unknown name,
  ``cgda --version``.
- pyproject.toml lists every package of the source tree and declares every
  third-party package that cgda_jax imports.
- The wheel (slow-ish, ~1 min): see `test_wheel_install_runs_from_anywhere`.
"""

from __future__ import annotations

import ast
import importlib.metadata
import os
import pathlib
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib

import pytest

from cgda_jax import builtin
from cgda_jax.cli import EXIT_USAGE, main

REPO = pathlib.Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())


# ------------------------------------------------------------------ built-in files


def test_builtin_models_and_pieces_are_the_repository_files():
    from cgda_jax import model_path
    from cgda_jax.sim.world import OBJECTS_DIR, list_pieces

    for name in ("teo.xml", "tiny_arm.xml"):
        assert model_path(name).read_bytes() == (REPO / "models" / name).read_bytes()
    assert list_pieces() == tuple(sorted(p.stem for p in
                                         (REPO / "models/objects").glob("*.xml")))
    assert (OBJECTS_DIR / "box.xml").read_bytes() == (
        REPO / "models/objects/box.xml").read_bytes()
    with pytest.raises(FileNotFoundError, match="no built-in model 'nope.xml'.*teo"):
        model_path("nope.xml")


def test_every_builtin_experiment_is_listed_with_one_line_of_description():
    names = builtin.experiment_names()
    assert names == tuple(sorted(p.stem for p in (REPO / "experiments").glob("*.toml")))
    assert "clean_ie" in names
    for name in names:
        path = builtin.experiment_path(name)
        assert path.read_bytes() == (REPO / "experiments" / f"{name}.toml").read_bytes()
        text = builtin.experiment_description(path)
        assert 20 <= len(text) <= 110 and "\n" not in text, (name, text)
    path = builtin.experiment_path("clean_ie")
    assert builtin.experiment_path("clean_ie.toml") == path


def test_description_falls_back_to_the_first_comment(tmp_path):
    p = tmp_path / "x.toml"
    p.write_text("#\n# Push the box along the table.\nkind = 'execution'\n")
    assert builtin.experiment_description(p) == "Push the box along the table."
    p.write_text('# a comment\ndescription = "The description key wins."\n')
    assert builtin.experiment_description(p) == "The description key wins."


def test_a_config_argument_is_a_file_first_then_a_builtin_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert builtin.resolve_config("clean_ie") == builtin.experiment_path("clean_ie")
    (tmp_path / "clean_ie").write_text('kind = "recognition"\n')  # a file wins
    assert builtin.resolve_config("clean_ie") == pathlib.Path("clean_ie")
    with pytest.raises(FileNotFoundError, match="neither a config file nor a built-in"
                       r".*clean_ie, clean_ie_dynamic"):
        builtin.resolve_config("clean")
    with pytest.raises(FileNotFoundError, match="config file not found: sub/x.toml"):
        builtin.resolve_config("sub/x.toml")


# ------------------------------------------------------------------------- CLI


def test_cli_list_version_and_unknown_name(capsys):
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [x.split()[0] for x in lines] == list(builtin.experiment_names())
    assert any(x.startswith("clean_ie ") and "Individual Evolution" in x for x in lines)
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    from cgda_jax import __version__

    assert capsys.readouterr().out.strip() == f"cgda {__version__}"
    assert main(["run", "clean_eye", "--no-cache"]) == EXIT_USAGE
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'clean_eye' is neither" in err[0]
    assert "paint_iet" in err[0]


def test_cli_runs_a_builtin_by_name_from_anywhere(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # no experiments/ here
    assert main(["run", "paint_iet", "--dry-run", "--no-cache"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# paint_iet: valid") and 'name = "paint_iet"' in out


# -------------------------------------------------------------------- pyproject


def test_pyproject_lists_every_package_of_the_source_tree():
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(REPO).parts)
             for p in (REPO / "cgda_jax").rglob("__init__.py")}
    mapped = PYPROJECT["tool"]["setuptools"]["package-dir"]
    assert mapped == {"cgda_jax._models": "models",
                      "cgda_jax._experiments": "experiments"}
    assert listed == found | set(mapped)
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["cgda_jax"]
    assert (REPO / "cgda_jax/py.typed").is_file()


def _imported_top_level_names() -> set[str]:
    names = set()
    for path in (REPO / "cgda_jax").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names - set(sys.stdlib_module_names) - {"cgda_jax", "__future__"}


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def test_every_imported_package_is_a_declared_dependency():
    # the [vision] extra's OpenCV is imported lazily (cgda_jax.vision.cv)
    deps = [*PYPROJECT["project"]["dependencies"],
            *PYPROJECT["project"]["optional-dependencies"]["vision"]]
    declared = {_norm(re.split(r"[<>=!~ \[;]", d)[0]) for d in deps}
    owners = importlib.metadata.packages_distributions()
    missing = {}
    for name in _imported_top_level_names():
        dists = {_norm(d) for d in owners.get(name, [name])}
        if not dists & declared:
            missing[name] = sorted(dists)
    assert not missing, f"imported but not in [project] dependencies: {missing}"


# ----------------------------------------------------------------------- wheel

SOURCES = ("pyproject.toml", "README.md", "cgda_jax", "models", "experiments")


def _readme_python_example() -> str:
    text = (REPO / "README.md").read_text()
    block = re.search(r"^## In Python\n+```python\n(.*?)^```", text,
                      re.MULTILINE | re.DOTALL)
    assert block, "README.md has no '## In Python' ```python block"
    return block.group(1)


def _run(args, cwd, env, timeout=240):
    proc = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout, check=False)
    assert proc.returncode == 0, f"{args}: {proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
    return proc


def test_wheel_install_runs_from_anywhere(tmp_path):
    """Build the wheel (``pip wheel --no-deps --no-build-isolation`` from a copy of
    the sources), install it, not editable, into a fresh virtual environment whose
    dependencies come from this interpreter's site-packages through a .pth line
    (a .pth line only adds the path: the editable install there does not leak in),
    then from a folder outside the repository check that

    - ``cgda_jax`` is imported from the fresh environment, the built-in models and
      experiments and ``py.typed`` are inside it, with no models/ or experiments/
      folder around;
    - ``cgda list`` lists the built-in experiments;
    - ``cgda run clean_ie`` exits 0 (goal met) and writes its results folder;
    - README.md's "In Python" example runs as written (extracted from the README
      here, so a README that drifts from the library fails this test).
    """
    src = tmp_path / "src"
    src.mkdir()
    for name in SOURCES:
        if (REPO / name).is_dir():
            shutil.copytree(REPO / name, src / name,
                            ignore=shutil.ignore_patterns("__pycache__", "scripts"))
        else:
            shutil.copy2(REPO / name, src / name)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(JAX_PLATFORMS="cpu", CGDA_JAX_CACHE=str(tmp_path / "jax_cache"),
               PIP_NO_INDEX="1", PIP_DISABLE_PIP_VERSION_CHECK="1")
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps",
          "--no-build-isolation", "-w", str(tmp_path / "dist"), str(src)],
         tmp_path, env)
    wheel, = (tmp_path / "dist").glob("cgda_jax-*.whl")

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, env)
    py = venv / "bin" / "python"
    where = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    site = pathlib.Path(_run([str(py), "-c", where], tmp_path, env).stdout.strip())
    deps = dict.fromkeys([sysconfig.get_paths()["purelib"],
                          sysconfig.get_paths()["platlib"]])
    (site / "_cgda_test_deps.pth").write_text("\n".join(deps) + "\n")
    _run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q",
          "--no-deps", str(wheel)], tmp_path, env)

    work = tmp_path / "elsewhere"
    work.mkdir()
    check = ("import cgda_jax, pathlib, importlib.resources as r\n"
             "from cgda_jax import builtin\n"
             "print(cgda_jax.__file__)\n"
             "print(builtin.models_dir())\n"
             "print(builtin.experiments_dir())\n"
             "print(r.files('cgda_jax').joinpath('py.typed').is_file())\n")
    out = _run([str(py), "-c", check], work, env).stdout.split()
    assert all(pathlib.Path(p).is_relative_to(site) for p in out[:3]), out
    assert out[1:3] == [str(site / "cgda_jax/_models"),
                        str(site / "cgda_jax/_experiments")] and out[3] == "True"

    cgda = str(venv / "bin" / "cgda")
    listed = _run([cgda, "list"], work, env).stdout.splitlines()
    assert [x.split()[0] for x in listed] == list(builtin.experiment_names())

    run = _run([cgda, "run", "clean_ie", "--set", "output.render=false"], work, env)
    folder = work / "results" / "clean_ie"
    assert run.stdout.strip() == "results/clean_ie/report.md", run.stdout
    for name in ("report.md", "result.json", "config.toml", "arrays.npz"):
        assert (folder / name).is_file(), name
    assert '"success": true' in (folder / "result.json").read_text()

    (work / "example.py").write_text(_readme_python_example())
    example = _run([str(py), "example.py"], work, env).stdout.split()
    assert example[0] == "True" and float(example[1]) < 0.02, example
    assert (work / "results/my_clean/result.json").is_file()
    assert not (work / "models").exists() and not (work / "experiments").exists()
