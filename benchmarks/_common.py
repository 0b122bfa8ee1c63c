"""Timing, table and JSON helpers shared by the benchmark scripts.

Rules (STYLE.md convention 14): compile time is measured apart with
``jax.jit(f).lower(*args).compile()``; every timed call ends in
``jax.block_until_ready``; the figure reported is the median of repeats.
"""

from __future__ import annotations

import json
import os
import pathlib
import platform
import statistics
import time
from collections.abc import Callable, Sequence
from typing import Any

import jax

OUT = pathlib.Path(__file__).resolve().parent / "out"
REPO = OUT.parents[1]


def compile_jax(fn: Callable, *args) -> tuple[Callable, float]:
    """``(compiled, seconds)``: lower and compile ``jax.jit(fn)`` for ``args``."""
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    return compiled, time.perf_counter() - t0


def median_time(fn: Callable[[], Any], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time in seconds of ``fn()`` (its result is blocked on)."""
    for _ in range(warmup):
        jax.block_until_ready(fn())
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def machine() -> dict[str, Any]:
    """What the figures were measured on."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "jax_backend": jax.default_backend(),
        "jax_devices": [str(d) for d in jax.devices()],
        "jax": jax.__version__,
        "python": platform.python_version(),
        "load_avg_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


def print_table(rows: list[dict[str, Any]], columns: list[str]) -> None:
    """A plain aligned text table of ``rows`` (dicts) over ``columns``."""

    def fmt(v):
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    cells = [[fmt(r.get(c, "")) for c in columns] for r in rows]
    widths = [
        max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)
    ]
    print("  ".join(c.ljust(w) for c, w in zip(columns, widths)))
    print("  ".join("-" * w for w in widths))
    for row in cells:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths)))


def find_row(rows: list[dict[str, Any]], **match: Any) -> dict[str, Any] | None:
    """The first row whose items include ``match``, or None."""
    return next((r for r in rows if all(r.get(k) == v for k, v in match.items())), None)


def report_target(text: str, value: float | None, ok: bool | None) -> None:
    """Print one ``target: ...`` line (skipped when the case was not run)."""
    if value is not None:
        print(f"target: {text}: {value:.3g} ({'met' if ok else 'NOT met'})")


def write_json(name: str, payload: dict[str, Any]) -> pathlib.Path:
    """Write ``payload`` and the machine description to benchmarks/out/NAME.json."""
    OUT.mkdir(exist_ok=True)
    path = OUT / f"{name}.json"
    payload = {"benchmark": name, "machine": machine(), **payload}
    path.write_text(json.dumps(payload, indent=2, default=float))
    print(f"wrote {path}")
    return path


def experiment_setup(name: str, overrides: Sequence[str] = ()):
    """``experiments/NAME.toml``'s config, simulator and goal as ``cgda run`` builds
    them (with ``KEY=VALUE`` `overrides`, as ``cgda run --set``)."""
    from cgda_jax import experiment as ex

    cfg = ex.load_config(REPO / "experiments" / f"{name}.toml", overrides)
    goal, demos, _ = ex.build_goal(cfg)
    sim = ex.build_simulator(cfg, ex.build.default_waypoint_s(demos, len(goal)))
    return cfg, sim, goal


def experiment_trials(name: str, n_seeds: int, overrides: Sequence[str] = (), *,
                      seed: int = 0, setup=None):
    """Seeds seed..seed+n_seeds-1 of ``experiments/NAME.toml``'s strategy as ONE
    batched `run_trials` call, on its goal and simulator (`experiment_setup`, or
    ``setup``: its (cfg, sim, goal) from an earlier call, whose programs are
    reused).

    Returns:
        (cfg, sim, goal, results, total_s): the config, the simulator, the goal,
        the `ExecutionResult` per seed and the call's wall time (compile included).
    """
    from cgda_jax import run_trials

    cfg, sim, goal = setup or experiment_setup(name, overrides)
    s = cfg.strategy
    t0 = time.perf_counter()
    results = run_trials(
        s.name, sim, goal, n_seeds, seed=seed, algorithm=s.algorithm,
        population_size=s.population_size, tolerance=s.tolerance,
        max_generations=s.max_generations, chunk_size=s.chunk_size, **s.options)
    return cfg, sim, goal, results, time.perf_counter() - t0


def timed_process(cmd: list[str], env: dict) -> float:
    """Wall seconds of one process ``cmd`` run in the repository with ``env``
    (its output captured; a failure raises with it)."""
    import subprocess

    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=REPO, capture_output=True, text=True,
                          check=False)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stdout}\n{proc.stderr}")
    return elapsed
