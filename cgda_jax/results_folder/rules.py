"""A results folder: which one, and whether it can be used (the rules below);
`cgda_jax.results_folder.writing.RunFolder` locks it, writes it aside and moves it into place.

Used by every writer of results: ``cgda run`` and `cgda_jax.experiment.run_experiment`
(`cgda_jax.experiment` re-exports these names),
``cgda run --trials N --processes P`` (the launching process holds the folder, its
workers write into the temporary one) and `cgda_jax.ExecutionResult.save`.

A run never writes into its results folder directly. It writes into a temporary folder
beside it (``.<name>.tmp-XXXX``) and, once everything is written, moves that folder into
place with one rename (an atomic exchange on Linux when an older folder is replaced).
So the folder always holds the files of ONE complete run, or the previous run's
untouched, or nothing:

- an existing non-empty folder is refused (`FolderError`) unless ``overwrite=True``,
  which replaces it whole, and only when it is a results folder (holds a
  ``result.json``); with ``fresh=True`` (no folder given by the user) the first free
  name of ``<base>``, ``<base>-2``, ``<base>-3``, ... is taken instead;
- a lock file beside the folder (``.<name>.lock``, ``flock``: released by the kernel
  even when the process is killed) stops two runs sharing a folder: the second gets
  `FolderBusy`;
- a run that fails or is interrupted (SIGINT, SIGTERM) removes its temporary folder:
  the previous results stay as they were, no partial work is kept; leftovers of a
  killed run (SIGKILL) are removed by the next run of the same folder;
- a symbolic link is followed to the folder it names (the results replace that
  folder's content; the link stays), and said so (`RunFolder.note`); a link that
  names nothing (dangling, or a loop) or names a file is refused, by name. Without
  a folder given (``fresh``) a name held by such a link counts as taken.

``report.md`` links only files of its own run, since every run starts from an empty
folder.
"""

from __future__ import annotations

import errno
import os
import pathlib
import tempfile

#: A folder counts as a previous run's results (replaceable with ``overwrite``) when
#: it holds this file.
MARKER = "result.json"

_MAX_FRESH = 1000


class FolderError(ValueError):
    """The results folder cannot be used (not empty, not a folder, not writable, a
    dangling link), or a file in it cannot be read back (`cgda_jax.results_folder.reading`)."""


class FolderBusy(FolderError):
    """Another run holds the results folder's lock."""


def expand(path: str | os.PathLike) -> pathlib.Path:
    """``path`` with ``~`` expanded."""
    return pathlib.Path(path).expanduser()


def is_empty_dir(p: pathlib.Path) -> bool:
    """``p`` is a folder with nothing in it."""
    return p.is_dir() and not any(p.iterdir())


def hidden_name(target: pathlib.Path, what: str) -> str:
    """``.<name>.<what>``: a lock or temporary folder beside ``target``."""
    return f".{target.name}.{what}"


def follow_link(path: pathlib.Path) -> pathlib.Path:
    """``path``, or the folder it names when it is a symbolic link.

    Raises:
        FolderError: a link to nothing (dangling, or a loop of links) or to
            something other than a folder; the message names the link and where it
            points.
    """
    path = pathlib.Path(path)
    if not path.is_symlink():
        return path
    try:
        real = pathlib.Path(os.path.realpath(path, strict=True))
    except OSError as err:
        try:
            dest = os.readlink(path)
        except OSError:  # pragma: no cover - removed meanwhile
            dest = "?"
        if err.errno == errno.ELOOP:
            why, fix = "a loop of links", ""
        else:
            why = "which does not exist (a dangling link)"
            fix = "create the folder it names, "
        raise FolderError(
            f"results folder {path} is a symbolic link to {dest}, {why}: {fix}"
            "remove the link, or choose another folder"
        ) from None
    if not real.is_dir():
        raise FolderError(f"results folder {path} is a symbolic link to {real}, "
                          "which is not a folder")
    return real


def followable(path: pathlib.Path) -> pathlib.Path | None:
    """`follow_link`, or None for a link it refuses."""
    try:
        return follow_link(path)
    except FolderError:
        return None


def check_writable(folder: pathlib.Path, what: str | None = None) -> None:
    """``folder`` exists or can be created, and can be written: checked by creating
    and removing a temporary folder in it or in its nearest existing ancestor.

    Raises:
        FolderError: naming ``what`` (default: the folder) and the reason.
    """
    folder = pathlib.Path(folder)
    what = what or f"folder {folder}"
    probe_in = folder
    while not probe_in.exists() and probe_in != probe_in.parent:
        probe_in = probe_in.parent
    if not probe_in.is_dir():
        raise FolderError(f"{what} cannot be created: {probe_in} is not a folder")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".cgda-probe-", dir=probe_in))
    except OSError as err:
        raise FolderError(
            f"{what} cannot be written: {probe_in}: {err.strerror or err}"
        ) from None


def check_target(target: pathlib.Path, overwrite: bool) -> None:
    if not target.exists():
        return
    if not target.is_dir():
        raise FolderError(f"results folder {target} exists and is not a folder")
    if is_empty_dir(target):
        return
    if not overwrite:
        raise FolderError(
            f"results folder {target} is not empty; replace it (the command "
            f"line's --overwrite, Python's overwrite=True) or choose another folder"
        )
    if not (target / MARKER).is_file():
        raise FolderError(
            f"results folder {target} is not empty and holds no {MARKER} (not a "
            f"results folder): refusing to replace it; choose another folder"
        )


def plan_folder(
    target: str | os.PathLike, *, overwrite: bool = False, fresh: bool = False
) -> pathlib.Path:
    """The folder a run would write to, checked, with nothing created or locked.

    Args:
        target: the folder asked for; with ``fresh`` the base of the names tried.
        overwrite: an existing results folder may be replaced.
        fresh: take the first of ``target``, ``target-2``, ... that is missing or
            empty (``overwrite`` then replaces ``target`` itself).

    Raises:
        FolderError: the folder cannot be used (the message says why and what to do).

    Returns:
        The folder, a symbolic link followed (`follow_link`).
    """
    target = expand(target)
    if fresh and not overwrite:
        check_writable(target.parent, f"results folder {target}")
        for cand in candidates(target):
            real = followable(cand)
            if real is not None and (not real.exists() or is_empty_dir(real)):
                check_writable(real.parent, f"results folder {real}")
                return real
    real = follow_link(target)
    check_writable(real.parent, f"results folder {real}")
    check_target(real, overwrite)
    return real


def candidates(base: pathlib.Path):
    """``base``, ``base-2``, ... ``base-1000``, then `FolderError`."""
    yield base
    for k in range(2, _MAX_FRESH + 1):
        yield base.with_name(f"{base.name}-{k}")
    raise FolderError(f"no free results folder among {base}, {base}-2, ... "
                      f"{base}-{_MAX_FRESH}")
