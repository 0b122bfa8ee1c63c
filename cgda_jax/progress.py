"""A progress display for the strategies' ``progress_fn``: a tqdm bar on a terminal or
in a notebook, whole lines elsewhere (CI logs, files)."""

from __future__ import annotations

import os
import sys
import time
from typing import Any, TextIO


def _in_notebook() -> bool:
    """Running in a Jupyter kernel (where tqdm.auto shows a widget)."""
    ipython = sys.modules.get("IPython")
    try:
        return "IPKernelApp" in ipython.get_ipython().config  # type: ignore[union-attr]
    except (AttributeError, TypeError):
        return False


def _tqdm(**kwargs):
    """A tqdm bar: ``tqdm.auto`` in a notebook (a widget when ipywidgets is there),
    the text bar otherwise."""
    if kwargs.get("file") is None:
        try:
            from tqdm.auto import tqdm

            return tqdm(**kwargs)
        except ImportError:  # notebook without ipywidgets: the text bar
            pass
    from tqdm import tqdm

    return tqdm(**kwargs)


def _size(stream) -> tuple[int, int]:
    """The terminal's columns and rows; 100 x 24 where unknown or 0 (a pty without a
    size, where tqdm would draw nothing)."""
    try:
        size = os.get_terminal_size(stream.fileno())
    except (AttributeError, OSError, ValueError):
        return 100, 24
    return size.columns or 100, size.lines or 24


def _short(v: Any) -> str:
    if isinstance(v, list):  # one entry per trial: one value, or their range
        if len(v) == 1:
            v = v[0]
        elif v and all(isinstance(x, (int, float)) for x in v):
            lo, hi = _short(min(v)), _short(max(v))
            return lo if lo == hi else f"{lo}..{hi}"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


class ProgressLine:
    """Callable progress reporter:
    ``[label] gen 40 | done 8/11 | met 7/11 | worst 0.034 | run 1.2 s``.

    On a terminal a `tqdm` bar over the goal points done (``[label] 8/11 points |###  |,
    gen 40 | met 7/11 | worst 0.034 | run 1.2 s``) is redrawn in place and ended when the run
    is done; in a Jupyter notebook (``stream`` not given) it is ``tqdm.auto``'s bar.
    Elsewhere (CI logs, files) whole lines are written instead: the first update,
    then at most one every ``interval_s`` seconds, and the last.

    The time shown is split when the strategy reports it (``elapsed_s``): ``run``
    is the time spent running compiled generations, ``setup+compile`` the time
    before that (goal, simulator, XLA compilation).

    Args:
        label: prefix (the experiment name).
        total_points: goal points, to show "points done / total" (default: the
            ``points`` entry of each update, which the strategies report).
        stream: where to write (default stderr); nothing is written when ``quiet``.
        quiet: write nothing.
        interval_s: minimum time between two lines when ``stream`` is not a TTY.
    """

    #: info key -> the word shown: ``done`` counts the points whose evolution
    #: ended, ``met`` those within the tolerance ("done 9/9 | met 0/9": finished,
    #: none met); ``gen`` is the count the result reports (`cgda_jax.strategies.runner`).
    _KEYS = (("points_done", "done"), ("points_met", "met"), ("point", "point"),
             ("best_fitness", "best"), ("worst_error", "worst"))

    def __init__(self, label: str, total_points: int | None = None,
                 stream: TextIO | None = None, quiet: bool = False,
                 interval_s: float = 5.0):
        self.label = label
        self.total = total_points
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.interval_s = interval_s
        self.t0 = time.perf_counter()
        self.last_line = None  # perf_counter of the last non-TTY line
        self.pending = None  # a non-TTY line skipped since (written by close())
        try:
            self.tty = bool(self.stream.isatty())
        except (AttributeError, ValueError):
            self.tty = False
        self.notebook = stream is None and not self.tty and _in_notebook()
        self.bar = None  # the tqdm bar while one is shown

    def _text(self, info: dict[str, Any], now: float, bar: bool = False) -> str:
        head = "" if bar else f"[{self.label}] "
        parts = [f"{head}gen {_short(info.get('generations', '?'))}"]
        for key, name in self._KEYS:
            if bar and name in ("done", "point"):
                continue  # the bar shows them
            if key in info:
                text = _short(info[key])
                n_points = self.total or info.get("points")
                if name in ("done", "met", "point") and n_points:
                    text = f"{text}/{n_points}"
                parts.append(f"{name} {text}")
        total = now - self.t0
        run = info.get("elapsed_s")
        if isinstance(run, (int, float)) and 0 <= run <= total:
            parts.append(f"run {run:.1f} s (setup+compile {total - run:.1f} s)")
        else:
            parts.append(f"{total:.1f} s")
        return " | ".join(parts)

    def __call__(self, info: dict[str, Any]) -> None:
        if self.quiet:
            return
        now = time.perf_counter()
        done = bool(info.get("done"))
        if self.tty or self.notebook:
            self._update_bar(info, now, done)
            return
        line = self._text(info, now)
        due = self.last_line is None or now - self.last_line >= self.interval_s
        if not (done or due):
            self.pending = line
            return
        self.last_line, self.pending = now, None
        self.stream.write(line + "\n")
        self.stream.flush()

    def _update_bar(self, info: dict[str, Any], now: float, done: bool) -> None:
        total = self.total or info.get("points")
        total = total if isinstance(total, int) else None
        if self.bar is None:
            self.bar = _tqdm(
                total=total, desc=f"[{self.label}]", unit="point", leave=True,
                file=None if self.notebook else self.stream, mininterval=0.0,
                **({} if self.notebook else dict(zip(("ncols", "nrows"),
                                                     _size(self.stream)))),
                bar_format="{desc} {n_fmt}/{total_fmt} points |{bar:20}|{postfix}")
        if total and self.bar.total != total:
            self.bar.total = total
        n = info.get("points_done", info.get("point"))
        n = n[0] if isinstance(n, list) and len(n) == 1 else n
        if isinstance(n, int):
            self.bar.n = n
        self.bar.set_postfix_str(self._text(info, now, bar=True), refresh=False)
        self.bar.refresh()
        if done:
            self.bar.close()
            self.bar = None

    def close(self) -> None:
        """End the display: close the bar, or write the last skipped line."""
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        elif self.pending is not None:
            self.stream.write(self.pending + "\n")
        self.pending = None
        self.stream.flush()

    def message(self, text: str) -> None:
        """A plain status line, printed above the bar while one is shown."""
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.write(text, file=None if self.notebook else self.stream)
        else:
            self.stream.write(text + "\n")
            self.stream.flush()
