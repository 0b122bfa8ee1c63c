"""Compiled programs reused within a process, keyed by what they compute.

A run builds its plan, its simulator and its checks anew, as closures over new
objects; ``jax.jit`` keys its cache on the Python function, so the same
experiment run again in one process would compile every program again (clean_ie:
12 programs, most of a second run's time).  `compile_lowered` keys a compiled
program by its lowered StableHLO text instead (constants included, no source
locations), its argument and result trees, and the backend and devices, the
and every argument's type (an unused argument is pruned from the text but
still checked by the call), the same content JAX's persistent cache keys on: a program identical to one compiled
before in the process is taken from memory, and any difference (another goal,
another robot, another population size, a constant changed by a setting) gives
another text and a fresh compile.  Tracing and lowering still run (a few tenths
of a second for clean_ie), compiling does not.

Programs that call back into Python (``jax.pure_callback``: the MuJoCo C
physics backend) are never shared: their text names the callback by an index,
not by what it calls.  At most `MAX_PROGRAMS` are kept (least recently used
dropped).  Across processes the persistent cache (``cgda`` turns it on,
`cgda_jax.cli.enable_compilation_cache`) serves the same programs from disk.
"""

from __future__ import annotations

import collections
import hashlib
import threading
from collections.abc import Callable
from typing import Any

import jax

__all__ = ["MAX_PROGRAMS", "cache_stats", "clear_programs", "compile_lowered",
           "jit_call"]

#: Compiled programs kept in memory at most.
MAX_PROGRAMS = 64

_PROGRAMS: collections.OrderedDict[str, Any] = collections.OrderedDict()
_STATS = {"hits": 0, "misses": 0, "uncached": 0}
_LOCK = threading.Lock()


def _key(lowered: jax.stages.Lowered) -> str | None:
    """The program's key, or None for one that must not be shared."""
    text = lowered.as_text()
    if "callback" in text:  # host callbacks: named by index, not by what they do
        return None
    devices = [(d.platform, d.id) for d in jax.devices()]
    # every argument's type: an unused one is left out of the text, not the call
    args = [(a.shape, str(a.dtype), a.donated)
            for a in jax.tree.leaves(lowered.args_info)]
    h = hashlib.sha256(text.encode())
    h.update(repr((str(lowered.in_tree), str(lowered.out_tree), args, devices,
                   jax.default_backend())).encode())
    return h.hexdigest()


def compile_lowered(lowered: jax.stages.Lowered) -> jax.stages.Compiled:
    """``lowered.compile()``, or the program compiled before in this process from
    the same lowered text (see the module doc).

    Args:
        lowered: ``jax.jit(f, ...).lower(*args)``.
    """
    key = _key(lowered)
    if key is None:
        with _LOCK:
            _STATS["uncached"] += 1
        return lowered.compile()
    with _LOCK:
        found = _PROGRAMS.get(key)
        if found is not None:
            _PROGRAMS.move_to_end(key)
            _STATS["hits"] += 1
            return found
    compiled = lowered.compile()
    with _LOCK:
        _STATS["misses"] += 1
        _PROGRAMS[key] = compiled
        while len(_PROGRAMS) > MAX_PROGRAMS:
            _PROGRAMS.popitem(last=False)
    return compiled


def jit_call(fn: Callable, *args: Any) -> Any:
    """``jax.jit(fn)(*args)``, its program compiled through `compile_lowered`: for
    a function built anew on each call (a closure over a new simulator) whose
    program is often the same."""
    return compile_lowered(jax.jit(fn).lower(*args))(*args)


def cache_stats() -> dict[str, int]:
    """``hits``, ``misses`` (compiled and kept) and ``uncached`` (host callbacks)
    of `compile_lowered` since the process started (or `clear_programs`), and
    ``programs`` kept now."""
    with _LOCK:
        return dict(_STATS, programs=len(_PROGRAMS))


def clear_programs() -> None:
    """Forget every kept program and zero `cache_stats`."""
    with _LOCK:
        _PROGRAMS.clear()
        for k in _STATS:
            _STATS[k] = 0
