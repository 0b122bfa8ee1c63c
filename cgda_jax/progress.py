"""A one-line progress display on stderr for the strategies' ``progress_fn``."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO


def _short(v: Any) -> str:
    if isinstance(v, list):  # one entry per trial; show the first
        v = v[0] if len(v) == 1 else v
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


class ProgressLine:
    """Callable progress reporter: ``[label] gen 40 | points 8/11 | worst 0.034 | run 1.2 s``.

    On a terminal one line is rewritten in place (``\\r``) and ended when the run is
    done. Elsewhere (CI logs, files, notebooks) whole lines are written instead: the
    first update, then at most one every ``interval_s`` seconds, and the last.

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

    _KEYS = (("points_done", "points"), ("point", "point"), ("best_fitness", "best"),
             ("worst_error", "worst"))

    def __init__(self, label: str, total_points: int | None = None,
                 stream: TextIO | None = None, quiet: bool = False,
                 interval_s: float = 5.0):
        self.label = label
        self.total = total_points
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.interval_s = interval_s
        self.t0 = time.perf_counter()
        self.width = 0
        self.last_line = None  # perf_counter of the last non-TTY line
        self.pending = None  # a non-TTY line skipped since (written by close())
        try:
            self.tty = bool(self.stream.isatty())
        except (AttributeError, ValueError):
            self.tty = False

    def _text(self, info: dict[str, Any], now: float) -> str:
        parts = [f"[{self.label}] gen {info.get('generations', '?')}"]
        for key, name in self._KEYS:
            if key in info:
                text = _short(info[key])
                n_points = self.total or info.get("points")
                if name in ("points", "point") and n_points:
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
        line = self._text(info, now)
        if self.tty:
            pad = max(self.width - len(line), 0)
            self.width = 0 if done else len(line)
            self.stream.write("\r" + line + " " * pad + ("\n" if done else ""))
        else:
            due = self.last_line is None or now - self.last_line >= self.interval_s
            if not (done or due):
                self.pending = line
                return
            self.last_line, self.pending = now, None
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End the display: finish a TTY line, or write the last skipped line."""
        if self.quiet:
            return
        if self.tty and self.width:
            self.stream.write("\n")
        elif not self.tty and self.pending is not None:
            self.stream.write(self.pending + "\n")
        self.width, self.pending = 0, None
        self.stream.flush()

    def message(self, text: str) -> None:
        """A plain status line (not overwritten); ends a pending TTY line first."""
        if not self.quiet:
            if self.tty and self.width:
                self.stream.write("\n")
                self.width = 0
            self.stream.write(text + "\n")
            self.stream.flush()
