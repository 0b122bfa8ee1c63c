"""Execution strategies: FTE, IE, IET, OET on a shared batched generation step.

Each strategy is one module (`cgda_jax.strategies.fte`, ``ie``, ``iet``, ``oet``)
holding its settings dataclass (defaults, checks, documentation), its state and its
plan. `STRATEGIES` is the one list of them: the config (``strategy.name`` and the
checks of ``strategy.options``), the batched trials and the CLI read it. A run by
name is `run` (one seed or a batch of trials); `run_fte`, `run_ie`, `run_iet` and
`run_oet` are its single-run forms, `run_trials` / `run_seeds` its batched ones.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

from cgda_jax.strategies.base import (
    ALGORITHMS as ALGORITHMS,
    INVALID_PENALTY as INVALID_PENALTY,
    from_joints as from_joints,
    make_algorithm as make_algorithm,
    to_joints as to_joints,
)
from cgda_jax.strategies.fte import FTEPlan, FTESettings
from cgda_jax.strategies.ie import IEPlan, IESettings, point_keys as point_keys
from cgda_jax.strategies.iet import IETPlan, IETSettings
from cgda_jax.strategies.oet import OETPlan, OETSettings
from cgda_jax.strategies.result import (
    ExecutionResult as ExecutionResult,
    SimulationDiverged as SimulationDiverged,
)
from cgda_jax.strategies.runner import driver as batching_driver, run_plan
from cgda_jax.strategies.settings import Settings as Settings


class Strategy(NamedTuple):
    """One entry of `STRATEGIES`: the plan `cgda_jax.strategies.runner` drives and
    its settings dataclass (`cgda_jax.strategies.settings.Settings`)."""

    plan: type
    settings: type[Settings]


#: Strategy name -> its plan and settings: the one list of strategies.
STRATEGIES: dict[str, Strategy] = {
    "fte": Strategy(FTEPlan, FTESettings),
    "ie": Strategy(IEPlan, IESettings),
    "iet": Strategy(IETPlan, IETSettings),
    "oet": Strategy(OETPlan, OETSettings),
}


def strategy_of(name: str) -> Strategy:
    """The `STRATEGIES` entry of ``name``.

    Raises:
        ValueError: an unknown name (the known ones listed).
    """
    if name not in STRATEGIES:
        raise ValueError(f"unknown strategy {name!r}; choose one of {sorted(STRATEGIES)}")
    return STRATEGIES[name]


def run(
    name: str,
    sim: Any,
    goal: Any,
    settings: Settings | None = None,
    seeds: Any = (0,),
    *,
    batching: str = "auto",
    progress_fn: Callable[[dict], None] | None = None,
    **changes: Any,
) -> list[ExecutionResult]:
    """Runs strategy ``name`` on ``goal`` for each of ``seeds``.

    Args:
        name: "fte", "ie", "iet" or "oet" (`STRATEGIES`).
        sim: a simulator (`n_dof`, `n_features`, `lower`, `upper`, `init_state`,
            `step`, `rollout`; `cgda_jax.sim.simulator.Simulator`).
        goal: goal feature trajectory (N, F).
        settings: the strategy's settings (its `Settings` dataclass, e.g.
            `cgda_jax.strategies.ie.IESettings`; None: its defaults); ``changes``
            replace fields of it (``population_size=32``).
        seeds: the seeds; several run as independent trials in one batched call.
        batching: how several seeds run: "auto" (default: IE points pooled over
            the trials where points are independent, else finished trials
            dropped), "trials", "lockstep" (every trial until the slowest stops;
            one compiled chunk; see `cgda_jax.strategies.runner.driver`) or
            "single": one seed as the single run (the unbatched program, its
            ``devices`` splitting each generation's population; the batched
            modes split the trials).
        progress_fn: called with a dict after each chunk.

    Returns:
        One `ExecutionResult` per seed (``info["seed"]``).
    """
    entry = strategy_of(name)
    st = entry.settings.of(settings, **changes)
    if batching == "single":
        if len(list(seeds)) != 1:
            raise ValueError(f"batching='single' runs one seed; got {list(seeds)}")
        return run_plan(entry.plan, sim, goal, st, list(seeds),
                        progress_fn=progress_fn)
    return run_plan(entry.plan, sim, goal, st, list(seeds), progress_fn=progress_fn,
                    shard="trials", driver=batching_driver(batching))


def run_seeds(strategy: str, sim: Any, goal: Any, seeds: list[int], *,
              batching: str = "auto",
              progress_fn: Callable[[dict], None] | None = None,
              **settings: Any) -> list[ExecutionResult]:
    """`run_trials` for an explicit list of seeds (one trial each, in one batch):
    ``run(strategy, sim, goal, None, seeds, **settings)``.

    Raises:
        ValueError: an unknown strategy or setting, or no seeds.
    """
    entry = strategy_of(strategy)
    unknown = sorted(set(settings) - set(entry.settings.fields()))
    if unknown:
        raise ValueError(f"unknown settings {unknown} for strategy {strategy!r}")
    seeds = [int(x) for x in seeds]
    if not seeds:
        raise ValueError("seeds is empty: give at least one")
    return run(strategy, sim, goal, None, seeds, batching=batching,
               progress_fn=progress_fn, **settings)


def run_trials(strategy: str, sim: Any, goal: Any, n_trials: int, *, seed: int = 0,
               batching: str = "auto",
               progress_fn: Callable[[dict], None] | None = None,
               **settings: Any) -> list[ExecutionResult]:
    """Runs `n_trials` independent trials of a strategy at once.

    Trial r uses seed ``seed + r``; its result is the same bits in any batch of
    trials (any size, any other seeds). The single run with that seed is the
    unbatched program, rounded differently in the last bits; most seeds end within
    about 1e-4 of it, some on another search path (see
    `cgda_jax.strategies.runner`).
    By default the batch shrinks as trials finish (`cgda_jax.strategies.runner`):
    finished trials, or for IE with independent points finished points, leave it
    between chunks, so a trial that stops early costs no more than its own run.

    Args:
        strategy: "fte", "ie", "iet" or "oet".
        sim, goal, progress_fn: as in `run`.
        n_trials: R.
        seed: first seed.
        batching: "auto", "trials" or "lockstep" (see `run`).
        **settings: the strategy's settings (its `Settings` dataclass's fields,
            with its defaults); ``devices``: None (default: one device, the
            unsharded program), "all" or a device count K: the R trials are split
            over K devices, R / K per device (R is padded up to a multiple of K by
            repeating the last trial, whose copies are dropped; choose R a
            multiple of K to waste nothing). Each trial gives the same result as
            unsharded. Multi-host: see `cgda_jax.sharding`. Sharded batches run in
            lock-step.

    Returns:
        R `ExecutionResult`s; their wall/compile times are those of the whole batch;
        ``info["batching"]`` and ``info["batch_sizes"]`` (batch of each chunk) say
        how it shrank.
    """
    if int(n_trials) < 1:
        raise ValueError(f"n_trials must be >= 1; got {n_trials}")
    return run_seeds(strategy, sim, goal, [seed + r for r in range(int(n_trials))],
                     batching=batching, progress_fn=progress_fn, **settings)


def _single(name: str, sim: Any, goal: Any, seed: int,
            progress_fn: Callable[[dict], None] | None, settings: dict
            ) -> ExecutionResult:
    (result,) = run(name, sim, goal, None, [seed], batching="single",
                    progress_fn=progress_fn, **settings)
    return result


def run_fte(sim: Any, goal: Any, *, seed: int = 0,
            progress_fn: Callable[[dict], None] | None = None,
            **settings: Any) -> ExecutionResult:
    """Full Trajectory Evolution (paper 3.1) of ``goal`` (N, F), one seed:
    ``run("fte", sim, goal, None, [seed], batching="single", **settings)``.

    ``settings``: `cgda_jax.strategies.fte.FTESettings`'s fields (its defaults
    otherwise). Returns an `ExecutionResult`; final_fitness is the best fitness
    (``distance``), success = every point's error < tolerance.
    """
    return _single("fte", sim, goal, seed, progress_fn, settings)


def run_ie(sim: Any, goal: Any, *, seed: int = 0,
           progress_fn: Callable[[dict], None] | None = None,
           **settings: Any) -> ExecutionResult:
    """Individual Evolution (paper 3.2) of every point of ``goal`` (N, F), all
    points in one batched evolution, one seed (point i uses
    ``fold_in(key(seed), i)``, `point_keys`):
    ``run("ie", sim, goal, None, [seed], batching="single", **settings)``.

    ``settings``: `cgda_jax.strategies.ie.IESettings`'s fields (its defaults
    otherwise). Returns an `ExecutionResult`; success = every point's executed
    error < tolerance. ``info`` holds per-point generations and tries
    (``point_tries``) and, where the points are evolved in sequence, the
    backtracks used (``backtracks_used``, as IET's).

    Examples:
        >>> res = run_ie(sim, goal, tolerance=0.02)  # doctest: +SKIP
        >>> res.point_errors.max() < 0.02  # doctest: +SKIP
    """
    return _single("ie", sim, goal, seed, progress_fn, settings)


def run_iet(sim: Any, goal: Any, *, seed: int = 0,
            progress_fn: Callable[[dict], None] | None = None,
            **settings: Any) -> ExecutionResult:
    """Incrementally Evolved Trajectories (paper Algorithm 1) of ``goal`` (N, F),
    one seed: ``run("iet", sim, goal, None, [seed], batching="single",
    **settings)``.

    ``settings``: `cgda_jax.strategies.iet.IETSettings`'s fields (its defaults
    otherwise). Returns an `ExecutionResult`; success = every executed point's
    error < epsilon (``tolerance``); final_fitness = the whole trajectory's
    Euclidean fitness. ``info`` holds per-point generations / evaluations / tries,
    each try's best fitness (``try_best_fitness[i][t]``) and the backtracks used;
    fitness_history row i is point i's last evolution. The committed posture of a
    point is the best over its restarts (``point_fitness[i]``), also when every
    one missed epsilon.
    """
    return _single("iet", sim, goal, seed, progress_fn, settings)


def run_oet(sim: Any, goal: Any, *, seed: int = 0,
            progress_fn: Callable[[dict], None] | None = None,
            **settings: Any) -> ExecutionResult:
    """Online Evolved Trajectories of ``goal`` (N, F): localize, evolve one
    posture, execute, repeat; one seed: ``run("oet", sim, goal, None, [seed],
    batching="single", **settings)``.

    ``settings``: `cgda_jax.strategies.oet.OETSettings`'s fields (its defaults
    otherwise). Returns an `ExecutionResult` with joints (S, DoF) / features
    (S, F) the executed steps; point_errors (N,) = each goal point's error when the
    goal must be followed in order (`cgda_jax.strategies.fitness.ordered_point_errors`);
    success = all of them < tolerance, i.e. every point reached in order, the last
    one included.
    """
    return _single("oet", sim, goal, seed, progress_fn, settings)


__all__ = [
    "ALGORITHMS",
    "STRATEGIES",
    "ExecutionResult",
    "INVALID_PENALTY",
    "Settings",
    "SimulationDiverged",
    "Strategy",
    "from_joints",
    "make_algorithm",
    "point_keys",
    "run",
    "run_fte",
    "run_ie",
    "run_iet",
    "run_oet",
    "run_seeds",
    "run_trials",
    "strategy_of",
    "to_joints",
]
