"""Saved files read back, every failure naming the file: `read_json` (a JSON object,
checked against a schema with `check_fields`) and `read_npz` (every array, those
required named when missing). A damaged, truncated or hand-edited file is a
`~cgda_jax.results_folder.rules.FolderError` that says which file and what is wrong with it,
never a ``BadZipFile`` or ``AttributeError`` from deep inside.

A schema maps keys to type names: ``str``, ``int``, ``bool``, ``number`` (int or
float, not bool), ``null``, ``object``, ``list[T]``, alternatives ``a|b`` (e.g.
``number|null``: JSON has no infinity, so a non-finite number is written null).
Keys the schema does not name are accepted (files written by later versions).

Files written one at a time (not a results folder: `cgda_jax.results_folder.writing`) go through
`write_aside`: written beside their place and renamed over it, so a full disk or
an interrupt leaves the earlier file, or none, never a truncated one.
"""

from __future__ import annotations

import contextlib
import json
import os
import pathlib
import tempfile
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np

from cgda_jax.results_folder.rules import FolderError

__all__ = ["FileMissing", "check_fields", "read_json", "read_npz", "write_aside"]


class FileMissing(FolderError, FileNotFoundError):
    """A file to read back is not there (a `FolderError` and a
    `FileNotFoundError`)."""


def _split_alternatives(spec: str) -> list[str]:
    out, depth, start = [], 0, 0
    for i, ch in enumerate(spec):
        depth += {"[": 1, "]": -1}.get(ch, 0)
        if ch == "|" and depth == 0:
            out.append(spec[start:i])
            start = i + 1
    return [*out, spec[start:]]


def _matches(value: Any, spec: str) -> bool:
    for alt in _split_alternatives(spec.replace(" ", "")):
        if alt.startswith("list[") and alt.endswith("]"):
            if isinstance(value, list) and all(_matches(v, alt[5:-1]) for v in value):
                return True
        elif alt not in _BASE:
            raise ValueError(f"unknown type {alt!r} in a schema")  # a schema's bug
        elif _BASE[alt](value):
            return True
    return False


_BASE = {
    "any": lambda v: True,
    "str": lambda v: isinstance(v, str),
    "bool": lambda v: isinstance(v, bool),
    "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
    "null": lambda v: v is None,
    "object": lambda v: isinstance(v, dict),
}


def _kind(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean",
            int: "an integer", float: "a number", type(None): "null"}.get(
        type(value), type(value).__name__)


def check_fields(data: Any, schema: Mapping[str, str], required: Iterable[str] = (),
                 where: str | os.PathLike = "the file") -> dict[str, Any]:
    """``data`` when it is a dict holding every ``required`` key and each key of
    ``schema`` it holds has that type; returns it.

    Raises:
        FolderError: ``where: ...`` naming the first key missing or of the wrong
            type, with what it holds.
    """
    if not isinstance(data, dict):
        raise FolderError(f"{where}: expected a JSON object (keys and values), got "
                          f"{_kind(data)}")
    missing = [k for k in required if k not in data]
    if missing:
        raise FolderError(f"{where}: {', '.join(map(repr, missing))} missing (not a "
                          "file this version wrote, or damaged)")
    for key, spec in schema.items():
        if key in data and not _matches(data[key], spec):
            shown = json.dumps(data[key], default=str)
            shown = shown if len(shown) <= 60 else shown[:57] + "..."
            raise FolderError(f"{where}: {key!r} must be {spec}, got {_kind(data[key])}"
                              f" {shown}")
    return data


def read_json(path: str | os.PathLike, schema: Mapping[str, str] | None = None,
              required: Iterable[str] = ()) -> dict[str, Any]:
    """The JSON object in ``path``, checked by `check_fields` when a schema is given.

    Raises:
        FolderError: not found (`FileMissing`), unreadable, not JSON, not an
            object, or not of the schema; the message starts with the path.
    """
    path = pathlib.Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileMissing(f"{path}: not found") from None
    except UnicodeDecodeError:
        raise FolderError(f"{path}: not a text file (damaged?)") from None
    except OSError as err:
        raise FolderError(f"{path}: cannot be read ({err.strerror or err})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise FolderError(f"{path}: not valid JSON ({err})") from None
    if schema is None and not required:
        if not isinstance(data, dict):
            raise FolderError(f"{path}: expected a JSON object (keys and values), "
                              f"got {_kind(data)}")
        return data
    return check_fields(data, schema or {}, required, path)


def read_npz(path: str | os.PathLike, required: Iterable[str] = ()
             ) -> dict[str, np.ndarray]:
    """Every array of the NPZ file ``path``, by name (no pickled objects).

    Raises:
        FolderError: not found (`FileMissing`), not an NPZ file, truncated or
            damaged (any array that cannot be read), or an array of ``required``
            missing; the message starts with the path.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise FileMissing(f"{path}: not found")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not hasattr(loaded, "files"):  # np.load read a single .npy array
            raise ValueError(f"a single {loaded.dtype} array, not an archive of arrays")
        with loaded as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as err:  # noqa: BLE001 - BadZipFile, EOFError, zlib, ValueError
        text = str(err).strip().splitlines()[0] if str(err).strip() else ""
        raise FolderError(
            f"{path}: cannot be read as NPZ arrays, the file is damaged or truncated "
            f"({type(err).__name__}{': ' + text if text else ''})") from None
    missing = [k for k in required if k not in arrays]
    if missing:
        raise FolderError(f"{path}: array{'s' * (len(missing) > 1)} "
                          f"{', '.join(missing)} missing")
    return arrays


def write_aside(path: str | os.PathLike, write: Callable[[Any], None],
                binary: bool = False) -> pathlib.Path:
    """Write ``path`` whole or not at all: ``write(f)`` fills a temporary file beside
    it (``.<name>.tmp-XXXX``, same folder, same file system), which is flushed to
    disk and renamed over ``path`` (atomic); on any failure the temporary file is
    removed and ``path`` is left as it was.

    Raises:
        OSError: the write or the rename failed (a full disk: ``ENOSPC`` or
            ``EFBIG``); whatever ``write`` raised.
    """
    path = pathlib.Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.tmp-", dir=path.parent)
    try:
        with os.fdopen(fd, "wb" if binary else "w",
                       **({} if binary else {"encoding": "utf-8"})) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        if path.exists():  # keep the earlier file's permissions
            with contextlib.suppress(OSError):
                os.chmod(tmp, path.stat().st_mode & 0o7777)
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path
