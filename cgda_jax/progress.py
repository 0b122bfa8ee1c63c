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
    """Callable progress reporter: ``[label] gen 40 | points 8/11 | worst 0.034 | 1.2 s``.

    Args:
        label: prefix (the experiment name).
        total_points: goal points, to show "points done / total".
        stream: where to write (stderr); nothing is written when ``quiet``.
    """

    _KEYS = (("points_done", "points"), ("point", "point"), ("best_fitness", "best"),
             ("worst_error", "worst"))

    def __init__(self, label: str, total_points: int | None = None,
                 stream: TextIO | None = None, quiet: bool = False):
        self.label = label
        self.total = total_points
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.t0 = time.perf_counter()
        self.width = 0

    def __call__(self, info: dict[str, Any]) -> None:
        if self.quiet:
            return
        parts = [f"[{self.label}] gen {info.get('generations', '?')}"]
        for key, name in self._KEYS:
            if key in info:
                text = _short(info[key])
                if name in ("points", "point") and self.total:
                    text = f"{text}/{self.total}"
                parts.append(f"{name} {text}")
        parts.append(f"{time.perf_counter() - self.t0:.1f} s")
        line = " | ".join(parts)
        pad = max(self.width - len(line), 0)
        self.width = len(line)
        end = "\n" if info.get("done") else ""
        self.stream.write("\r" + line + " " * pad + end)
        self.stream.flush()

    def message(self, text: str) -> None:
        """A plain status line (not overwritten)."""
        if not self.quiet:
            self.stream.write(text + "\n")
            self.stream.flush()
