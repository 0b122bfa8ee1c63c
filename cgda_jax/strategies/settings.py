"""A strategy's settings and what every strategy checks before it runs.

`Settings` holds what every strategy takes (algorithm, population size, tolerance,
generation budget, chunk size, aim, devices); each strategy's settings dataclass
(`cgda_jax.strategies.fte.FTESettings`, ``ie.IESettings``, ``iet.IETSettings``,
``oet.OETSettings``) adds its own options. A field is declared with `option`: its
default and the kind of value it takes, so the defaults, the checks (`Settings.check`,
run when the settings are made) and the config's checks of ``strategy.options``
(`option_problem`, through `cgda_jax.strategies.STRATEGIES`) are written once, in
the dataclass. A new option is one `option` field there, and its use in the plan.

Also here: the goal checked against the simulator (`check_config`) and whether a
simulator's points are independent (`points_independent`).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any

import jax
import numpy as np

__all__ = ["RUN_FIELDS", "Settings", "check_config", "option",
           "option_problem", "points_independent"]

#: The kinds of value an `option` takes (rule: see `option_problem`).
OPTION_KINDS = ("int", "number", "bool", "choice", "devices", "table", "api", "any")


def option(default: Any, kind: str = "any", rule: Any = None, *,
           none: bool = False, callables: bool = False) -> Any:
    """A settings field: its ``default``, the ``kind`` of value it takes and the
    kind's ``rule`` (see `option_problem`); ``none``: None is also accepted (the
    Python API's "off"; a config cannot write None); ``callables``: a "choice" a
    Python caller may also give as a function."""
    if kind not in OPTION_KINDS:
        raise ValueError(f"unknown option kind {kind!r}; one of {list(OPTION_KINDS)}")
    return dataclasses.field(default=default, metadata={
        "kind": kind, "rule": rule, "none": none, "callables": callables})


def _number_ok(value: float, rule: str) -> bool:
    if rule == "in [0, 1)":
        return 0 <= value < 1
    if rule == "in (0, 1]":
        return 0 < value <= 1
    return value > 0


def option_problem(kind: str, rule: Any, value: Any) -> str | None:
    """What is wrong with ``value`` for an option of ``kind`` (None: nothing):
    "int" (a whole number >= rule), "number" (a finite number; rule "> 0",
    "in [0, 1)" or "in (0, 1]"), "bool", "choice" (one of the tuple rule), "devices"
    ("all" or a device count of this machine), "table" (a dict), "api" (only a
    Python caller can pass it, e.g. an array), "any" (not checked here)."""
    is_int = isinstance(value, int) and not isinstance(value, bool)
    if kind == "int":
        if not is_int:
            return f"must be a whole number >= {rule}, got {value!r}"
        return None if value >= rule else f"must be >= {rule}, got {value}"
    if kind == "number":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"must be a number {rule}, got {value!r}"
        ok = math.isfinite(value) and _number_ok(float(value), rule)
        return None if ok else f"must be a finite number {rule}, got {value}"
    if kind == "bool":
        return None if isinstance(value, bool) else f"must be true or false, got " \
            f"{value!r}"
    if kind == "choice":
        return None if value in rule else f"{value!r} is not one of {list(rule)}"
    if kind == "devices":
        if value == "all":
            return None
        if not is_int:
            return f"must be \"all\" or a device count, got {value!r}"
        have = jax.device_count()
        return None if 1 <= value <= have else (
            f"{value} devices asked, this machine has {have}")
    if kind == "table":
        return None if isinstance(value, dict) else f"must be a table, got {value!r}"
    if kind == "api":
        return "only a Python caller can pass it (an array), not a config"
    return None


#: `Settings` fields the run itself uses (not passed to the plan).
RUN_FIELDS = ("chunk_size", "devices")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Settings:
    """What every strategy takes; a strategy's settings dataclass adds its own.

    Attributes:
        algorithm: an evosax algorithm: a name (see
            `cgda_jax.strategies.evolution.ALGORITHMS`), a class, or a configured
            instance (its population and solution sizes must match; see
            `cgda_jax.strategies.evolution.make_algorithm`).
        population_size: individuals per generation (and per point).
        tolerance: a point is met when its error is below this (feature units;
            the paper used 20 mm).
        max_generations: generation budget of one evolution.
        chunk_size: generations per compiled `lax.scan` chunk.
        aim: the share of the tolerance each evolution aims for, in (0, 1]: it
            stops, restarts and ranks by least motion at ``aim * tolerance``; the
            run is still judged at ``tolerance``.  Below 1 it leaves room for a
            finer replay, the exported trajectory or a robot to differ a little
            (1: the paper's rule, anything within tolerance).
        algorithm_kwargs, algorithm_params: see `make_algorithm`.
        devices: None (default: one device, the unsharded program), "all" or a
            device count: a single run splits each generation's batched simulator
            call (its population axis, padded to a multiple of the device count by
            repeating the last candidate, whose results are dropped), batched
            trials split the trials; same results as unsharded. Multi-host: see
            `cgda_jax.sharding`.
        judge: with feasibility, "ranked" (default): judge only the moves whose
            rank matters (CMA-ES: its best half, exact; the rest told a bound;
            `cgda_jax.strategies.fitness.judge_best`; kinematic mode: dynamic
            mode judges every move, with what the physics executed), "all":
            every candidate.
    """

    algorithm: Any = option("CMA_ES")
    population_size: int = option(16, "int", 1)
    tolerance: float = option(0.02, "number", "> 0")
    max_generations: int = option(100, "int", 1)
    chunk_size: int = option(10, "int", 1)
    aim: float = option(1.0, "number", "in (0, 1]")
    algorithm_kwargs: dict | None = option(None, "table", none=True)
    algorithm_params: dict | None = option(None, "table", none=True)
    devices: int | str | None = option(None, "devices", none=True)
    judge: str = option("ranked", "choice", ("ranked", "all"))

    def __post_init__(self):
        self.check()

    @classmethod
    def of(cls, settings: Settings | None = None, **changes: Any) -> Settings:
        """``settings`` (of this class; None: the defaults) with ``changes``.

        Raises:
            TypeError: ``settings`` of another strategy, or a change that is no
                field (named, with the fields there are).
            ValueError: a value of the wrong kind (`check`).
        """
        unknown = sorted(set(changes) - set(cls.fields()))
        if unknown:
            raise TypeError(f"unknown setting(s) {unknown} of {cls.__name__}; it "
                            f"takes {sorted(cls.fields())}")
        if settings is None:
            return cls(**changes)
        if not isinstance(settings, cls):
            raise TypeError(f"settings must be {cls.__name__}; got "
                            f"{type(settings).__name__}")
        return dataclasses.replace(settings, **changes) if changes else settings

    @classmethod
    def fields(cls) -> dict[str, dataclasses.Field]:
        """The settings' fields by name."""
        return {f.name: f for f in dataclasses.fields(cls)}

    @classmethod
    def defaults(cls) -> dict[str, Any]:
        """Every field's default by name."""
        return {k: f.default for k, f in cls.fields().items()}

    @classmethod
    def option_problem(cls, key: str, value: Any) -> str | None:
        """What is wrong with ``value`` for the field ``key`` (None: nothing; a key
        that is no field: None, the caller says it is unknown)."""
        f = cls.fields().get(key)
        if f is None:
            return None
        return option_problem(f.metadata["kind"], f.metadata["rule"], value)

    def check(self) -> None:
        """Every field's value of its kind (`option_problem`), else ValueError
        naming the field (``tolerance`` as "a finite number > 0").

        Checks of the values the plan uses with the simulator (an init that needs
        independent points, an algorithm's own sizes) are the plan's."""
        for key, f in self.fields().items():
            value, kind = getattr(self, key), f.metadata["kind"]
            if (value is None and f.metadata["none"]) or kind in ("api", "devices"):
                continue  # arrays of the caller; devices resolved by the run
            if isinstance(value, numbers.Real) and not isinstance(value, bool):
                # NumPy numbers and whole floats (10.0) as Python ones
                whole = kind == "int" and math.isfinite(value) and value == int(value)
                value = int(value) if whole else float(value) if kind == "number" \
                    else value
            if kind == "choice" and value not in f.metadata["rule"]:
                if f.metadata["callables"] and callable(value):
                    continue
                raise ValueError(
                    f"unknown {key} {value!r}; choose one of {list(f.metadata['rule'])}"
                    + (" or pass a callable" if f.metadata["callables"] else "")
                    if f.metadata["callables"] else
                    f"{key}={value!r}; expected one of {list(f.metadata['rule'])}")
            problem = option_problem(kind, f.metadata["rule"], value)
            if problem is not None:
                extra = " or None" if f.metadata["none"] else ""
                raise ValueError(f"{key} {problem}".replace(", got", f"{extra}; got"))

    def plan_kwargs(self) -> dict[str, Any]:
        """The fields the plan takes (all but `RUN_FIELDS`)."""
        return {k: getattr(self, k) for k in self.fields() if k not in RUN_FIELDS}


def points_independent(sim: Any) -> bool:
    """Whether a step's features depend only on its waypoint, not on where it starts:
    kinematic mode (``sim.mode``, default kinematic) and a scene state with no arrays
    (the marker; a paint wall remembers what was painted)."""
    if getattr(sim, "mode", "kinematic") != "kinematic":
        return False
    scene = getattr(sim, "scene", None)
    return scene is None or not jax.tree.leaves(scene.init_state())


def check_config(
    sim: Any,
    goal: Any,
    *,
    tolerance: float | None = None,
    max_generations: int | None = None,
    min_points: int = 1,
) -> jax.Array:
    """Checks a goal (N, F) against a simulator and common settings; returns it f32.

    The checks run in NumPy on the host (eager JAX ops would each compile once).
    """
    from cgda_jax.checks import check_float32

    g64 = np.asarray(goal, dtype=np.float64)
    if np.all(np.isfinite(g64)):  # NaN/inf: the per-point message below
        check_float32(g64, "goal")
    g = g64.astype(np.float32)
    if g.ndim == 1 and sim.n_features == 1:
        g = g[:, None]
    if g.ndim != 2:
        raise ValueError(f"goal must have shape (N, F); got shape {tuple(g.shape)}")
    if g.shape[1] != sim.n_features:
        names = getattr(sim, "feature_names", None)
        raise ValueError(
            f"goal has {g.shape[1]} features per point but the simulator's scene has "
            f"{sim.n_features}" + (f" ({', '.join(names)})" if names else "")
        )
    if g.shape[0] < min_points:
        raise ValueError(f"goal needs at least {min_points} point(s); got {g.shape[0]}")

    if not np.all(np.isfinite(g)):
        bad = int(np.argmax(~np.all(np.isfinite(g), axis=1)))
        raise ValueError(f"goal has a non-finite value at point {bad}")
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance must be a finite number > 0; got {tolerance}")
    if max_generations is not None and int(max_generations) < 1:
        raise ValueError(f"max_generations must be >= 1; got {max_generations}")
    return jax.device_put(g)  # a transfer (jnp.asarray compiles a copy program)
