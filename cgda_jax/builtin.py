"""The files that ship with cgda_jax: robot models, object pieces, experiment configs.

They live in the repository's top-level ``models/`` and ``experiments/`` folders,
installed as the packages ``cgda_jax._models`` and ``cgda_jax._experiments`` (see
pyproject.toml), and are found with `importlib.resources`, so a wheel install, an
editable install and a source checkout on ``PYTHONPATH`` (not installed) all find
them.
"""

from __future__ import annotations

import functools
import importlib.resources
import pathlib
import tomllib

__all__ = [
    "experiment_description",
    "experiment_lines",
    "experiment_names",
    "experiment_path",
    "experiments_dir",
    "model_path",
    "models_dir",
    "resolve_config",
]

_SOURCE = pathlib.Path(__file__).resolve().parents[1]  # a checkout's root


def _folder(package: str, source: str) -> pathlib.Path:
    """The folder of ``package`` (installed), else ``source`` of a source checkout."""
    try:
        root = importlib.resources.files(package)
    except ModuleNotFoundError:  # not installed: cgda_jax imported from a checkout
        root = _SOURCE / source
    path = pathlib.Path(str(root))
    if not path.is_dir():
        raise FileNotFoundError(
            f"the built-in {source}/ folder of cgda_jax is missing ({package} at "
            f"{path}); reinstall cgda_jax")
    return path


@functools.cache
def models_dir() -> pathlib.Path:
    """Folder of the built-in models (robots; object pieces in ``objects/``)."""
    return _folder("cgda_jax._models", "models")


def model_path(name: str) -> pathlib.Path:
    """Path of a built-in model (the repository's ``models/``, installed with the
    package as ``cgda_jax._models``).

    Args:
        name: file name, e.g. ``"teo.xml"`` or ``"tiny_arm.xml"``.

    Raises:
        FileNotFoundError: no such built-in model (the message lists the ones there),
            or a name that is a path (only the models folder's own files are
            built-in ones).
    """
    folder = models_dir()
    path = folder / name
    if pathlib.Path(name).name != name or name in ("", ".", ".."):
        have = sorted(p.name for p in folder.glob("*.xml"))
        raise FileNotFoundError(f"no built-in model {name!r}: a built-in model is a "
                                f"file name of {folder}, not a path; have {have}")
    if not path.is_file():
        have = sorted(p.name for p in folder.glob("*.xml"))
        raise FileNotFoundError(f"no built-in model {name!r} in {folder}; have {have}")
    return path


@functools.cache
def experiments_dir() -> pathlib.Path:
    """Folder of the built-in experiment configs (``*.toml``)."""
    return _folder("cgda_jax._experiments", "experiments")


def experiment_names() -> tuple[str, ...]:
    """Names of the built-in experiments (``cgda run NAME``), sorted."""
    return tuple(sorted(p.stem for p in experiments_dir().glob("*.toml")))


def experiment_path(name: str) -> pathlib.Path:
    """The config file of the built-in experiment ``name`` (``.toml`` optional).

    Raises:
        FileNotFoundError: no such built-in experiment (the message lists them).
    """
    stem = name.removesuffix(".toml")
    names = experiment_names()
    if stem not in names:
        raise FileNotFoundError(
            f"{name!r} is neither a config file nor a built-in experiment; the "
            f"built-in ones (`cgda list`): {', '.join(names)}")
    return experiments_dir() / f"{stem}.toml"


def experiment_description(path: str | pathlib.Path) -> str:
    """One line about a config: its ``description`` key, else its first comment;
    where the config sets ``strategy.options.stagnation``, the stop rule read from it
    (the number is written once, in the config)."""
    text = pathlib.Path(path).read_text()
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        data = {}
    description = str(data.get("description", "")).strip()
    if description:
        return description.splitlines()[0] + _stop_rule(data.get("strategy"))
    for line in text.splitlines():
        if line.startswith("#") and line.lstrip("# ").strip():
            return line.lstrip("# ").strip()
    return ""


def _stop_rule(strategy) -> str:
    """`` Stops after N stagnant generations (at most M).`` from a config's
    ``[strategy]`` table, when it sets ``options.stagnation``."""
    if not isinstance(strategy, dict):
        return ""
    options = strategy.get("options")
    stagnation = options.get("stagnation") if isinstance(options, dict) else None
    if not isinstance(stagnation, int):
        return ""
    most = strategy.get("max_generations")
    return (f" Stops after {stagnation} stagnant generations"
            + (f" (at most {most})." if isinstance(most, int) else "."))


def resolve_config(config: str) -> pathlib.Path:
    """``cgda run``'s argument: an existing config file, else a built-in name.

    Raises:
        FileNotFoundError: neither (the message lists the built-in experiments).
    """
    path = pathlib.Path(config).expanduser()
    if path.is_file():
        return path
    if path.name == config:  # a bare name: clean_ie or clean_ie.toml
        return experiment_path(config)
    raise FileNotFoundError(
        f"config file not found: {config}; or run a built-in experiment by name "
        f"(`cgda list`): {', '.join(experiment_names())}")


def experiment_lines() -> list[str]:
    """``cgda list``: one line per built-in experiment, its name and description."""
    names = experiment_names()
    width = max(map(len, names), default=0)
    return [f"{n:<{width}}  {experiment_description(experiments_dir() / f'{n}.toml')}"
            for n in names]
