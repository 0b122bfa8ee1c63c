"""Demonstrations: a validated container and loaders (CSV, NPZ, xgnitive logs).

A :class:`Demonstration` is one repetition of an action: sample times in seconds and
the object-feature trajectory measured at those times. Arrays live on the host as
float64 NumPy arrays; generalization turns them into JAX arrays.

Values: features must be finite and within float32's range (``|x| <= 3.4e38``): the
library computes in float32, and a larger value would become ``inf`` there.  Text
files must be UTF-8 (a byte-order mark is accepted); paths may start with ``~``.

File layouts:
    * CSV: a header row ``time,<feature names...>`` then one row per sample.
    * NPZ: arrays ``times`` (T,), ``features`` (T, F), ``feature_names`` (F,) and a
      scalar string ``name``.
    * xgnitive (ICRA 2018 TEO demonstrations, see the data README): space-separated
      logs ``data-N.log`` or their every-10th-row reductions ``reduced-data-N.csv``.
"""

from __future__ import annotations

import dataclasses
import pathlib
import re
from collections.abc import Sequence

import numpy as np

__all__ = [
    "Demonstration",
    "validate_demonstrations",
    "load_csv",
    "save_csv",
    "load_npz",
    "save_npz",
    "load_xgnitive",
    "load_xgnitive_force",
    "xgnitive_clock_offsets",
    "XGNITIVE_ACTIONS",
    "XGNITIVE_COLUMNS",
]

PathLike = str | pathlib.Path

#: Largest float32: feature values beyond it would become inf in the float32 kernels.
_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _path(path: PathLike) -> pathlib.Path:
    """A user path with ``~`` expanded."""
    return pathlib.Path(path).expanduser()


def _find_problem(
    times: np.ndarray, features: np.ndarray, names: Sequence[str] = ()
) -> tuple[int, str] | None:
    """First bad sample of a trajectory as (row index, message), or None."""

    def column(col: int) -> str:
        return f"feature {col} ({names[col]!r})" if col < len(names) else (
            f"feature {col}"
        )

    bad_t = ~np.isfinite(times)
    if bad_t.any():
        row = int(np.argmax(bad_t))
        return row, f"time is {times[row]} (not finite)"
    bad_f = ~np.isfinite(features)
    if bad_f.any():
        row, col = (int(v) for v in np.argwhere(bad_f)[0])
        return row, f"{column(col)} is {features[row, col]} (not finite)"
    big = np.abs(features) > _FLOAT32_MAX
    if big.any():
        row, col = (int(v) for v in np.argwhere(big)[0])
        return row, (
            f"{column(col)} is {features[row, col]:g}, beyond float32's range "
            f"(+/-{_FLOAT32_MAX:.4g}); rescale it (e.g. other units)"
        )
    steps = np.diff(times)
    if (steps <= 0).any():
        row = int(np.argmax(steps <= 0)) + 1
        return row, (
            f"time does not increase ({times[row - 1]!r} then {times[row]!r})"
        )
    return None


@dataclasses.dataclass(frozen=True, eq=False)
class Demonstration:
    """One demonstrated repetition of an action.

    Attributes:
        times: (T,) sample times in seconds, strictly increasing, T >= 2.
        features: (T, F) object features at those times (a (T,) array means F = 1).
        feature_names: (F,) unique names of the features.
        name: label used in error messages (loaders use the file path).
    """

    times: np.ndarray
    features: np.ndarray
    feature_names: tuple[str, ...]
    name: str = "demo"

    def __post_init__(self) -> None:
        where = f"demonstration {self.name!r}"
        times = np.asarray(self.times, dtype=np.float64)
        features = np.asarray(self.features, dtype=np.float64)
        if features.ndim == 1:
            features = features[:, None]
        names = (
            (self.feature_names,)
            if isinstance(self.feature_names, str)
            else tuple(str(n) for n in self.feature_names)
        )
        if times.ndim != 1:
            raise ValueError(f"{where}: times must be 1-D, got shape {times.shape}")
        if features.ndim != 2:
            raise ValueError(
                f"{where}: features must be (T, F), got shape {features.shape}"
            )
        if times.shape[0] < 2:
            raise ValueError(
                f"{where}: needs at least 2 samples, got {times.shape[0]}"
            )
        if features.shape[0] != times.shape[0]:
            raise ValueError(
                f"{where}: {times.shape[0]} times but {features.shape[0]} feature rows"
            )
        if features.shape[1] < 1:
            raise ValueError(f"{where}: has no features")
        if len(names) != features.shape[1]:
            raise ValueError(
                f"{where}: {len(names)} feature names {names} for "
                f"{features.shape[1]} feature columns"
            )
        if len(set(names)) != len(names):
            raise ValueError(f"{where}: duplicate feature names {names}")
        problem = _find_problem(times, features, names)
        if problem is not None:
            row, msg = problem
            raise ValueError(f"{where}, sample {row}: {msg}")
        times.setflags(write=False)
        features.setflags(write=False)
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "features", features)
        object.__setattr__(self, "feature_names", names)

    @property
    def n_samples(self) -> int:
        return self.times.shape[0]

    @property
    def n_features(self) -> int:
        return self.features.shape[1]

    @property
    def duration(self) -> float:
        """Duration in seconds, last time minus first."""
        return float(self.times[-1] - self.times[0])

    @property
    def normalized_times(self) -> np.ndarray:
        """(T,) times rescaled to [0, 1] (paper 2.1, step 1)."""
        rel = self.times - self.times[0]
        return rel / rel[-1]

    def select(self, columns: Sequence[str]) -> Demonstration:
        """A demonstration with only the named feature columns, in that order."""
        idx = [_column_index(self.feature_names, c, self.name) for c in columns]
        return Demonstration(
            self.times, self.features[:, idx], tuple(columns), self.name
        )


def _column_index(names: Sequence[str], column: str, where: str) -> int:
    try:
        return list(names).index(column)
    except ValueError:
        raise KeyError(
            f"{where}: no column {column!r}; available: {tuple(names)}"
        ) from None


def validate_demonstrations(demos: Sequence[Demonstration]) -> None:
    """Check that the demonstrations of one action can be generalized together.

    Raises:
        ValueError: if ``demos`` is empty, holds something that is not a
            Demonstration, or the feature counts or names differ (names the demo).
    """
    if isinstance(demos, Demonstration):
        raise ValueError("expected a sequence of Demonstration, got a single one")
    demos = list(demos)
    if not demos:
        raise ValueError("no demonstrations given")
    for k, d in enumerate(demos):
        if not isinstance(d, Demonstration):
            raise ValueError(f"item {k} is {type(d).__name__}, not a Demonstration")
    first = demos[0]
    for d in demos[1:]:
        if d.n_features != first.n_features:
            raise ValueError(
                f"demonstration {d.name!r} has {d.n_features} features but "
                f"{first.name!r} has {first.n_features}"
            )
        if d.feature_names != first.feature_names:
            raise ValueError(
                f"demonstration {d.name!r} has feature names {d.feature_names} but "
                f"{first.name!r} has {first.feature_names}"
            )


def _from_table(
    path: pathlib.Path,
    times: np.ndarray,
    features: np.ndarray,
    names: Sequence[str],
    name: str,
    first_line: int,
    every: int = 1,
) -> Demonstration:
    """Build a Demonstration, reporting bad rows by their line in ``path``."""
    if times.shape[0] < 2:
        raise ValueError(f"{path}: needs at least 2 samples, got {times.shape[0]}")
    problem = _find_problem(times, features, names)
    if problem is not None:
        row, msg = problem
        raise ValueError(f"{path}, line {first_line + row * every}: {msg}")
    return Demonstration(times, features, tuple(names), name)


def _read_rows(path: pathlib.Path, delimiter: str | None) -> list[list[str]]:
    if not path.is_file():
        raise FileNotFoundError(f"no such file: {path}")
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8-sig")  # a leading byte-order mark is dropped
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        raise ValueError(
            f"{path}, line {line}: not UTF-8 text (byte {raw[err.start]:#04x} at "
            f"offset {err.start}); save the file as UTF-8"
        ) from None
    lines = text.splitlines()
    rows = [(ln.split(delimiter) if delimiter else ln.split()) for ln in lines]
    if not any(any(c.strip() for c in r) for r in rows):
        raise ValueError(f"{path}: file is empty")
    return rows


def _to_float(path: pathlib.Path, rows: list[list[str]], first_line: int) -> np.ndarray:
    width = len(rows[0])
    out = np.empty((len(rows), width))
    for k, r in enumerate(rows):
        if len(r) != width:
            raise ValueError(
                f"{path}, line {first_line + k}: {len(r)} columns, expected {width}"
            )
        try:
            out[k] = [float(c) for c in r]
        except ValueError:
            raise ValueError(
                f"{path}, line {first_line + k}: not a number in {r}"
            ) from None
    return out


def load_csv(
    path: PathLike, columns: Sequence[str] | None = None, name: str | None = None
) -> Demonstration:
    """Load a demonstration from a CSV file with header ``time,<feature names...>``.

    Args:
        path: file path.
        columns: feature columns to keep, in this order (default: all).
        name: demonstration name (default: the path).

    Returns:
        The Demonstration.

    Raises:
        FileNotFoundError: missing file.
        ValueError: empty file, not UTF-8, bad header, bad values (non-numbers,
            NaN/inf, beyond float32's range; names the line and column).
        KeyError: unknown column.
    """
    path = _path(path)
    rows = [r for r in _read_rows(path, ",") if any(c.strip() for c in r)]
    header = [c.strip() for c in rows[0]]
    if len(header) < 2 or header[0] != "time":
        raise ValueError(
            f"{path}, line 1: header must be 'time,<feature names...>', got {header}"
        )
    if len(rows) < 2:
        raise ValueError(f"{path}: header only, no samples")
    table = _to_float(path, rows[1:], first_line=2)
    feats, names = table[:, 1:], header[1:]
    if columns is not None:
        idx = [_column_index(names, c, str(path)) for c in columns]
        feats, names = feats[:, idx], list(columns)
    return _from_table(path, table[:, 0], feats, names, name or str(path), 2)


def save_csv(demo: Demonstration, path: PathLike) -> None:
    """Write a demonstration in the CSV layout read by :func:`load_csv`."""
    path = _path(path)
    table = np.column_stack([demo.times, demo.features])
    header = ",".join(("time", *demo.feature_names))
    np.savetxt(
        path, table, delimiter=",", header=header, comments="", fmt="%.17g",
        encoding="utf-8",
    )


def load_npz(path: PathLike) -> Demonstration:
    """Load a demonstration saved by :func:`save_npz`."""
    path = _path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such file: {path}")
    if path.stat().st_size == 0:
        raise ValueError(f"{path}: file is empty")
    with np.load(path, allow_pickle=False) as z:
        missing = {"times", "features", "feature_names"} - set(z.files)
        if missing:
            raise KeyError(f"{path}: missing arrays {sorted(missing)}")
        name = str(z["name"]) if "name" in z.files else str(path)
        times, feats = np.asarray(z["times"], float), np.asarray(z["features"], float)
        names = [str(n) for n in z["feature_names"]]
    if feats.ndim == 1:
        feats = feats[:, None]
    if feats.shape[0] != times.shape[0]:
        raise ValueError(
            f"{path}: {times.shape[0]} times but {feats.shape[0]} feature rows"
        )
    return _from_table(path, times, feats, names, name, first_line=0)


def save_npz(demo: Demonstration, path: PathLike) -> None:
    """Write a demonstration as NPZ (times, features, feature_names, name)."""
    path = _path(path)
    np.savez(
        path,
        times=demo.times,
        features=demo.features,
        feature_names=np.array(demo.feature_names),
        name=np.array(demo.name),
    )


# Column names of the ICRA 2018 xgnitive logs (see the data README codebook).
XGNITIVE_COLUMNS: dict[str, tuple[str, ...]] = {
    "jr3": ("seq", "t", "Fx", "Fy", "Fz", "Tx", "Ty", "Tz"),
    "paintSquaresOnScreen": ("flag", "t", "percent"),
    "teo/leftArm": ("flag", "t", "X", "Y", "Z", "ax", "ay", "az", "angle"),
    "teo/rightArm": ("flag", "t", "X", "Y", "Z", "ax", "ay", "az", "angle"),
}
#: The actions recorded in the xgnitive ICRA 2018 data.
XGNITIVE_ACTIONS = ("paint", "iron")


def _xgnitive_dir(root: pathlib.Path, action: str, stream: str) -> pathlib.Path:
    for base in (root, root / "xgnitive_icra2018"):
        if (base / action / stream).is_dir():
            return base / action / stream
    raise FileNotFoundError(
        f"no folder {action}/{stream} under {root} or {root / 'xgnitive_icra2018'}"
    )


def load_xgnitive(
    root: PathLike,
    action: str,
    stream: str,
    columns: Sequence[str] | None = None,
    *,
    reduced: bool = True,
    repetitions: Sequence[int] | None = None,
) -> list[Demonstration]:
    """Load the xgnitive ICRA 2018 TEO demonstrations of one action and stream.

    Times are made relative to each file's own first sample (this removes the jr3
    clock offset of about 609 s against the other streams; `load_xgnitive_force`
    puts the jr3 beside the arm on one clock).

    Args:
        root: the xgnitive data folder (holding ``xgnitive_icra2018``) or that
            folder itself.
        action: ``"paint"`` or ``"iron"``.
        stream: ``"jr3"``, ``"paintSquaresOnScreen"``, ``"teo/leftArm"`` or
            ``"teo/rightArm"``.
        columns: feature columns by codebook name (see ``XGNITIVE_COLUMNS``), e.g.
            ``["Fx", "Fy", "Fz"]``; default: all but the first two (counter, time).
        reduced: read ``reduced-data-N.csv`` (every 10th row, what the authors'
            generalization used) instead of the full ``data-N.log``.
        repetitions: repetition numbers N to load (default: all present, sorted).
            Note ``paint/teo/rightArm`` has no repetition 2 (never recorded).

    Returns:
        One Demonstration per repetition, named ``"{action}/{stream}/{file}"``.
    """
    _check_stream(action, stream)
    all_cols = XGNITIVE_COLUMNS[stream]
    columns = list(all_cols[2:] if columns is None else columns)
    idx = [_column_index(all_cols, c, f"xgnitive stream {stream!r}") for c in columns]
    demos = []
    for path, table in _xgnitive_tables(root, action, stream, reduced, repetitions):
        times = table[:, 1] - table[0, 1]
        demos.append(
            _from_table(
                path, times, table[:, idx], columns,
                f"{action}/{stream}/{path.name}", first_line=1,
            )
        )
    return demos


def _xgnitive_tables(root: PathLike, action: str, stream: str, reduced: bool,
                     repetitions: Sequence[int] | None
                     ) -> list[tuple[pathlib.Path, np.ndarray]]:
    """(path, table with every codebook column) of each repetition, in order."""
    all_cols = XGNITIVE_COLUMNS[stream]
    folder = _xgnitive_dir(_path(root), action, stream)
    pattern = re.compile(r"reduced-data-(\d+)\.csv" if reduced else r"data-(\d+)\.log")
    found = {
        int(m.group(1)): p
        for p in folder.iterdir()
        if (m := pattern.fullmatch(p.name))
    }
    if repetitions is None:
        repetitions = sorted(found)
        if not repetitions:
            raise FileNotFoundError(f"no {pattern.pattern} files in {folder}")
    out = []
    for rep in repetitions:
        if rep not in found:
            raise FileNotFoundError(
                f"repetition {rep} of {action}/{stream} not found in {folder} "
                f"(present: {sorted(found)})"
            )
        path = found[rep]
        table = _to_float(path, _read_rows(path, None), first_line=1)
        if table.shape[1] != len(all_cols):
            raise ValueError(
                f"{path}: {table.shape[1]} columns, expected {len(all_cols)} "
                f"{all_cols}"
            )
        out.append((path, table))
    return out


def _check_stream(action: str, stream: str) -> None:
    if action not in XGNITIVE_ACTIONS:
        raise ValueError(f"unknown action {action!r}; expected one of {XGNITIVE_ACTIONS}")
    if stream not in XGNITIVE_COLUMNS:
        raise ValueError(
            f"unknown stream {stream!r}; expected one of {tuple(XGNITIVE_COLUMNS)}"
        )


def xgnitive_clock_offsets(
    root: PathLike,
    action: str = "iron",
    stream: str = "jr3",
    reference: str = "teo/rightArm",
    *,
    reduced: bool = True,
    repetitions: Sequence[int] | None = None,
) -> np.ndarray:
    """Seconds to ADD to ``stream``'s timestamps to put them on ``reference``'s clock.

    The jr3 force/torque stream was logged by a host whose clock ran about 609 s
    behind the one that logged the arm and screen streams (codebook: 608.5-609.1 s);
    every stream of a demonstration was connected within about 0.1 s of the others
    (the yarpdatadumper ``info.log`` files), so the offset of a repetition is the
    difference of the streams' first timestamps, ``t0(reference) - t0(stream)``
    (positive for the jr3: its clock is behind).  Over a whole demonstration the
    last timestamps of the full logs differ by the same amount within 0.04 s.

    Returns:
        (R,) offsets [s], one per repetition (sorted repetition numbers, or
        ``repetitions``).
    """
    _check_stream(action, stream)
    _check_stream(action, reference)
    ref = _xgnitive_tables(root, action, reference, reduced, repetitions)
    reps = repetitions or [int(re.search(r"(\d+)", p.name).group(1)) for p, _ in ref]
    own = _xgnitive_tables(root, action, stream, reduced, reps)
    return np.array([r[0, 1] - o[0, 1] for (_, r), (_, o) in zip(ref, own)])


def load_xgnitive_force(
    root: PathLike,
    action: str = "iron",
    columns: Sequence[str] = ("X", "Y", "Z"),
    force_columns: Sequence[str] = ("Fz",),
    *,
    stream: str = "teo/rightArm",
    reduced: bool = True,
    repetitions: Sequence[int] | None = None,
) -> list[Demonstration]:
    """An arm stream with the wrist force/torque (jr3) columns beside it, on the
    arm's clock.

    Each jr3 timestamp is moved onto the arm's clock with `xgnitive_clock_offsets`
    (added: ``t_arm = t_jr3 + offset``, offset about +609 s), and the jr3 columns are
    interpolated linearly at the arm's sample times (the streams run at about the
    same rate, 50 Hz, or 5 Hz reduced).  Times start at the arm's first sample.

    Sign and frame (as logged; the codebook): F [N] and T [N m] in the jr3's own
    frame at TEO's right wrist, between the forearm and the hand holding the iron.
    With the iron held still in the air the logged Fz is 0 to +9 N (the sensor is
    not zeroed between demonstrations); pressing the iron on the board drives Fz
    negative (to about -70 N at the hardest push).  In MuJoCo terms: the force the
    forearm exerts on the hand-and-iron beyond the sensor along the sensor's z axis,
    the axis pointing from the iron towards the forearm (`cgda_jax.sim.features`,
    quantity ``fz``: a hanging tool reads +m g, pressing reads less).

    Args:
        root: the xgnitive data folder.
        action: ``"iron"`` (the only action whose jr3 stream matters) or ``"paint"``.
        columns: arm columns (``XGNITIVE_COLUMNS[stream]``).
        force_columns: jr3 columns (``Fx`` ... ``Tz``).
        stream: the arm stream (``"teo/rightArm"``).
        reduced, repetitions: as `load_xgnitive`.

    Returns:
        One Demonstration per repetition with features ``columns + force_columns``.
    """
    _check_stream(action, stream)
    arm_cols, f_cols = XGNITIVE_COLUMNS[stream], XGNITIVE_COLUMNS["jr3"]
    a_idx = [_column_index(arm_cols, c, f"xgnitive stream {stream!r}") for c in columns]
    f_idx = [_column_index(f_cols, c, "xgnitive stream 'jr3'") for c in force_columns]
    arm = _xgnitive_tables(root, action, stream, reduced, repetitions)
    reps = repetitions or [int(re.search(r"(\d+)", p.name).group(1)) for p, _ in arm]
    force = _xgnitive_tables(root, action, "jr3", reduced, reps)
    demos = []
    for (path, a), (_, f) in zip(arm, force):
        offset = a[0, 1] - f[0, 1]
        t_force = f[:, 1] + offset
        values = np.column_stack([np.interp(a[:, 1], t_force, f[:, k]) for k in f_idx])
        demos.append(_from_table(
            path, a[:, 1] - a[0, 1], np.column_stack([a[:, a_idx], values]),
            [*columns, *force_columns], f"{action}/{stream}+jr3/{path.name}",
            first_line=1))
    return demos
