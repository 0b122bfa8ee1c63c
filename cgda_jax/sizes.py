"""What a run or a call will allocate, estimated before it allocates: the one place.

Every estimate counts float32 elements of the arrays the programs hold at once and
checks two limits before anything is allocated or compiled:

- **XLA's 32-bit sizes**: one array (and each of its dimensions) must hold fewer
  than 2**31 elements (`INT32_ELEMENTS`); beyond, XLA aborts the process while
  compiling (a C++ check failure, not an exception);
- **memory**: the estimated bytes must fit in `MEMORY_FRACTION` of the memory
  available now (`available_memory`: MemAvailable, or the cgroup's limit if lower).

A refused size raises `SizeError` (a ``ValueError``) whose message names the input,
gives the estimate and the largest value that would fit. The estimates:

- `run_estimate`: an execution run of T trials (``run_trials`` batches them): per
  trial, a generation's candidates (population x points evaluated together) times
  what one evaluation holds (features, genes, 3 per body of the model) and what its
  motion check holds (`motion_width`: each collision pair and geom at every sampled
  posture of the move), the sampled
  postures (``restart_samples`` / ``init_samples``, each with the same width) and
  their distances to every goal point (points x samples x features). Calibrated on
  XLA's ``compiled.memory_analysis()`` (temporaries + outputs, per trial): clean_ie's
  init (TEO, 9 points, 4096 samples) 1.02 MB measured; with feasibility on the
  generation chunk holds the most: clean_ie 15.3 MB measured, 18.0 MB estimated;
  paint_iet 2.0 / 3.3 MB; iron_ie_xgnitive 33.9 / 54.2 MB (`PAIR_FLOATS`).
  `sim_estimate` reads its widths from a simulator.
- `recognition_estimate`: Q queries x A actions compared at n samples (the DTW
  diagonals of every pair at once, 8 x F x n per pair) and its work, Q x A x F x n**2
  DTW cells (`MAX_DTW_CELLS`).
- `samples_estimate`: demonstrations of a given duration and rate.
- `check_processes`: P local processes against the cores and the memory.

Nothing here imports JAX: the estimates run in ``--dry-run`` before any program.
"""

from __future__ import annotations

import dataclasses
import math
import os
import pathlib
from typing import Any

__all__ = [
    "BYTES_PER_PROCESS",
    "INT32_ELEMENTS",
    "MAX_DEMO_SAMPLES",
    "MAX_DTW_CELLS",
    "MAX_KNOTS",
    "MEMORY_FRACTION",
    "PAIR_FLOATS",
    "ROUND_PAIR_FLOATS",
    "Estimate",
    "SizeError",
    "available_memory",
    "check_elements",
    "check_estimate",
    "check_processes",
    "check_recognition",
    "check_samples",
    "cores",
    "dynamic_width",
    "motion_width",
    "recognition_estimate",
    "run_estimate",
    "samples_estimate",
    "sim_estimate",
]

#: XLA indexes array elements and dimensions with signed 32-bit integers.
INT32_ELEMENTS = 2**31 - 1
#: Share of the available memory an estimate may take.
MEMORY_FRACTION = 0.8
#: DTW cells of one recognition (about 20 min at 1e9 cells/s).
MAX_DTW_CELLS = 10**12
#: Samples of one demonstration (9 hours at 30 Hz).
MAX_DEMO_SAMPLES = 1_000_000
#: Knots of one generalization: its RBF system is knots x knots (float64: 800 MB
#: and about 1e12 / 3 operations to solve at this size).
MAX_KNOTS = 10_000
#: Memory a process holds before its first program (Python, JAX, XLA, MuJoCo).
BYTES_PER_PROCESS = 600 * 2**20

_FLOAT = 4  # bytes of a float32


class SizeError(ValueError):
    """A size refused before allocating; the message names the input and gives the
    estimate."""


def gib(nbytes: float) -> str:
    """``nbytes`` in readable units ("3.1 GiB", "12 MiB")."""
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if nbytes >= size:
            return f"{nbytes / size:.3g} {unit}"
    return f"{nbytes / 2**10:.3g} KiB"


def _cgroup_free() -> int | None:
    """Bytes the cgroup (v2) still allows, or None without a limit."""
    base = pathlib.Path("/sys/fs/cgroup")
    try:
        limit = (base / "memory.max").read_text().strip()
        if limit == "max":
            return None
        used = int((base / "memory.current").read_text())
        return max(0, int(limit) - used)
    except (OSError, ValueError):
        return None


def available_memory() -> int | None:
    """Bytes of memory available to this process now (None: unknown)."""
    found = []
    try:
        for line in pathlib.Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    if not found:
        try:
            found.append(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            pass
    cg = _cgroup_free()
    if cg is not None:
        found.append(cg)
    return min(found) if found else None


def cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


@dataclasses.dataclass(frozen=True)
class Estimate:
    """What one run or call will hold at once.

    Attributes:
        what: the run or call, e.g. ``"100000 trials of IE"``.
        largest: elements of its largest array.
        largest_what: that array, in words (its factors).
        nbytes: bytes held at once (estimated).
        scale: what multiplies every size (its limit is given in the refusal),
            e.g. ``"trials"``.
        scale_value: its value.
        part: which part holds the largest array (`run_estimate`: "generation",
            "samples" or "distances"), so that a caller can name its input.
    """

    what: str
    largest: int
    largest_what: str
    nbytes: int
    scale: str
    scale_value: int
    part: str = ""

    def fitting(self, memory: int | None = None) -> int:
        """The largest value of `scale` within both limits (sizes are linear in
        it); 0 if even 1 does not fit."""
        per = max(self.largest / max(self.scale_value, 1), 1e-300)
        n = int(INT32_ELEMENTS // per)
        if memory is not None:
            per_b = max(self.nbytes / max(self.scale_value, 1), 1e-300)
            n = min(n, int(MEMORY_FRACTION * memory // per_b))
        return n


def check_estimate(est: Estimate, name: str, memory: int | None | str = "now") -> None:
    """Refuse `est` if its largest array passes XLA's 32-bit limit or its bytes pass
    `MEMORY_FRACTION` of the available memory.

    Args:
        est: the estimate.
        name: the input to name in the message (``"--trials"``, ``"n_samples"``,
            ``"key 'strategy.population_size'"``).
        memory: bytes available (default: `available_memory` now; None: not checked).

    Raises:
        SizeError: naming `name`, the estimate and what would fit.
    """
    mem = available_memory() if memory == "now" else memory
    fit = est.fitting(mem)
    hint = (f"; at most {fit:,} {est.scale} fit" if fit >= 1 else
            f"; not even 1 {est.scale.rstrip('s')} fits")
    if est.largest > INT32_ELEMENTS:
        raise SizeError(
            f"{name}: {est.what} needs one array of {est.largest:.3g} elements "
            f"({est.largest_what}), beyond XLA's 32-bit limit of 2**31 - 1{hint}")
    if mem is not None and est.nbytes > MEMORY_FRACTION * mem:
        raise SizeError(
            f"{name}: {est.what} needs about {gib(est.nbytes)} of memory, more than "
            f"{MEMORY_FRACTION:.0%} of the {gib(mem)} available{hint}")


def check_elements(count: int, name: str, what: str, itemsize: int = _FLOAT) -> None:
    """One array of `count` elements (of `itemsize` bytes) within XLA's 32-bit size
    and the memory; `what` describes it (``"4 actions x 1e9 samples x 3 features"``).

    Raises:
        SizeError: naming `name`.
    """
    nbytes = int(count) * int(itemsize)
    if count > INT32_ELEMENTS:
        raise SizeError(f"{name}: {what} is one array of {count:.3g} elements, beyond "
                        "XLA's 32-bit limit of 2**31 - 1")
    mem = available_memory()
    if mem is not None and nbytes > MEMORY_FRACTION * mem:
        raise SizeError(f"{name}: {what} needs about {gib(nbytes)}, more than "
                        f"{MEMORY_FRACTION:.0%} of the {gib(mem)} available")


def run_estimate(
    *,
    trials: int,
    population: int,
    points: int,
    features: int,
    dof: int,
    bodies: int,
    strategy: str = "ie",
    samples: int = 0,
    dynamic_width: int = 0,
    motion_width: int = 0,
) -> Estimate:
    """An execution run of `trials` seeds in one batch (1 for a single run).

    Args:
        trials: T, seeds in the batch.
        population: candidates per evolution.
        points: goal points N.
        features: F per point.
        dof: joints evolved per waypoint.
        bodies: bodies of the model (kinematics places each).
        strategy: "fte" and "ie" evaluate a population x N waypoints per
            generation; "iet" and "oet" a population of one point.
        samples: postures sampled once per trial (``restart_samples``, FTE's
            ``init_samples``), 0 for none.
        dynamic_width: floats of one candidate's physics state (dynamic mode).
        motion_width: floats the motion check (`cgda_jax.sim.feasibility`) holds
            for one waypoint's move (`motion_width`), 0 without one.
    """
    t, p, n, f = int(trials), int(population), int(points), int(features)
    width = f + int(dof) + 3 * int(bodies) + int(dynamic_width)
    waypoints = p * n if strategy in ("fte", "ie") else p
    parts = {
        "generation": (f"{waypoints:,} waypoints x {width} values per generation",
                       waypoints * width),
        "samples": (f"{samples:,} sampled postures x {width} values",
                    int(samples) * width),
        "distances": (f"{n} points x {samples:,} samples x {f} features",
                      n * int(samples) * f),
        "motion": (f"{waypoints:,} waypoints' moves x {int(motion_width):,} values of "
                   "the motion check", waypoints * int(motion_width)),
    }
    part, (name, per_trial) = max(parts.items(), key=lambda kv: kv[1][1])
    total = sum(count for _, count in parts.values())
    label = f"{t:,} trials x " if t != 1 else ""
    # one run: what to lower is the count of sampled postures, or of candidates
    by_samples = t == 1 and part in ("samples", "distances") and samples > 0
    scale, value = (("samples", int(samples)) if by_samples
                    else ("candidates", p) if t == 1 and part == "motion"
                    else ("trials", t))
    return Estimate(
        what=f"{t:,} trial{'s' * (t != 1)} of {strategy.upper()}",
        largest=t * per_trial, largest_what=f"{label}{name}", part=part,
        nbytes=_FLOAT * t * total, scale=scale, scale_value=value)


#: Floats the collision check holds per pair and posture: a pair's distance is not
#: one float but the intermediates of its closed form (a capsule-box pair, say, its
#: candidate points). Calibrated on XLA's ``compiled.memory_analysis()`` of the
#: generation chunk (per trial: the difference between 4 and 2 trials, over the
#: postures a generation checks): clean_ie 1,169 floats a posture with 8 pairs (146
#: a pair), paint_iet 1,398 with 11 (127), iron_ie_xgnitive 2,596 with 27 (96);
#: 150 a pair never falls short of these.  That was the exact geometry's check;
#: the round geometry's closed forms (`cgda_jax.sim.feasibility`, the default)
#: hold less: `ROUND_PAIR_FLOATS`.
PAIR_FLOATS = 150
#: Floats a pair and posture of the round geometry's check, calibrated as above
#: (2026-12-06): with 40 the estimate still holds 5.3x what XLA counts on clean_ie
#: (population 32: 5.95 MB for 1.13 MB a trial) and 2.6x on the tiny arm's one pair.
ROUND_PAIR_FLOATS = 40


def motion_width(samples: int, pairs: int, geoms: int, dof: int,
                 pair_floats: int = PAIR_FLOATS) -> int:
    """Floats the motion check holds for one move: at its ``samples + 1`` postures,
    each pair's distance with its intermediates (``pair_floats``: `PAIR_FLOATS`
    for the exact geometry, `ROUND_PAIR_FLOATS` for the round one), each geom's
    pose (12) and the posture."""
    return (int(samples) + 1) * (int(pair_floats) * int(pairs) + 12 * int(geoms)
                                 + int(dof))


def dynamic_width(mj_model) -> int:
    """Floats of one candidate's physics state (MJX data: bodies, geoms, joints,
    sensors), a floor of what ``mjx.make_data`` holds."""
    m = mj_model
    return int(24 * m.nbody + 12 * m.ngeom + 4 * (m.nq + m.nv) + m.nsensordata)


def sim_estimate(sim: Any, *, trials: int, population: int, points: int,
                 strategy: str, samples: int = 0) -> Estimate:
    """What `trials` trials on `sim` in one batch hold at once (`run_estimate`):
    the widths read from the simulator (its bodies, physics state and motion
    check). The one rule for a plan
    (`cgda_jax.strategies.base.PlanBase.estimate`) and for a config's checks
    (``cgda run --dry-run``)."""
    robot = getattr(sim, "robot", None)
    model = getattr(robot, "mj_model", None)
    backend = getattr(getattr(sim, "backend", None), "name", None)
    feas = getattr(sim, "feasibility", None)
    collider = getattr(feas, "collider", None)
    return run_estimate(
        trials=trials, population=population, points=points,
        features=int(sim.n_features), dof=int(sim.n_dof),
        bodies=int(model.nbody) if model is not None else 1, strategy=strategy,
        samples=samples,
        dynamic_width=(dynamic_width(model) if backend == "mjx" and model is not None
                       else 0),
        motion_width=0 if feas is None else motion_width(
            feas.samples, 0 if collider is None else collider.n_pairs,
            0 if collider is None or model is None else model.ngeom,
            int(sim.n_dof),
            ROUND_PAIR_FLOATS if getattr(feas, "geometry", "exact") == "round"
            else PAIR_FLOATS))


def recognition_estimate(queries: int, actions: int, n_samples: int,
                         features: int) -> tuple[Estimate, int]:
    """Q queries against A actions at `n_samples` samples: the estimate (scale:
    ``n_samples``) and the DTW cells it computes."""
    q, a, n, f = int(queries), int(actions), int(n_samples), int(features)
    pairs = q * a
    held = pairs * 8 * f * n + (q + a) * n * f
    largest = max(pairs * f * n, (q + a) * n * f)
    est = Estimate(
        what=f"recognition of {q} quer{'y' if q == 1 else 'ies'} x {a} actions at "
             f"{n:,} samples", largest=largest,
        largest_what=f"{pairs} pairs x {f} features x {n:,} samples",
        nbytes=_FLOAT * held, scale="samples", scale_value=n)
    return est, pairs * f * n * n


def check_recognition(queries: int, actions: int, n_samples: int, features: int,
                      name: str = "n_samples", metric: str = "dtw") -> None:
    """`recognition_estimate` within the limits, and for the DTW metrics within
    `MAX_DTW_CELLS`.

    Raises:
        SizeError: naming `name` (the sample count) and the estimate.
    """
    est, cells = recognition_estimate(queries, actions, n_samples, features)
    if metric != "euclidean" and cells > MAX_DTW_CELLS:
        fit = math.isqrt(MAX_DTW_CELLS // max(queries * actions * features, 1))
        fit = min(fit, est.fitting(available_memory()))
        raise SizeError(
            f"{name}: {est.what} computes {cells:.3g} DTW cells ({queries} x {actions} "
            f"x {features} features x {n_samples:,}**2), more than {MAX_DTW_CELLS:.0e} "
            f"(about 20 min at 1e9 cells/s); at most {fit:,} samples fit")
    check_estimate(est, name)


def samples_estimate(duration_s: float, rate_hz: float) -> int:
    """Samples of one demonstration of `duration_s` at `rate_hz` (inf-safe)."""
    count = float(duration_s) * float(rate_hz)
    return int(count) if math.isfinite(count) and count < 2**62 else 2**62


def check_samples(count: int, name: str, what: str, n: int = 1,
                  width: int = 1) -> None:
    """`count` samples per demonstration within `MAX_DEMO_SAMPLES` (and, for `n`
    demonstrations of `width` floats a sample, the memory).

    Raises:
        SizeError: naming `name` and the estimate.
    """
    nbytes = 8 * int(n) * int(count) * (int(width) + 4)  # float64, with temporaries
    if count > MAX_DEMO_SAMPLES:
        raise SizeError(
            f"{name}: {what} is {count:.3g} samples per demonstration (about "
            f"{gib(nbytes)} for {n}), more than {MAX_DEMO_SAMPLES:,}")
    mem = available_memory()
    if mem is not None and nbytes > MEMORY_FRACTION * mem:
        raise SizeError(f"{name}: {what} needs about {gib(nbytes)} for {n} "
                        f"demonstrations, more than {MEMORY_FRACTION:.0%} of the "
                        f"{gib(mem)} available")


def check_processes(processes: int, run_bytes: int = 0, name: str = "--processes",
                    local: bool = True) -> None:
    """`processes` local processes (each `BYTES_PER_PROCESS` plus its share of
    `run_bytes`) against this machine's cores and memory.

    Args:
        local: all processes on this machine (``--processes P``); False for one
            process of a cluster job (only its own share of memory is checked).

    Raises:
        SizeError: naming `name` with the cores or the memory estimate.
    """
    p = int(processes)
    here = p if local else 1
    if local and p > cores():
        raise SizeError(f"{name} {p}: this machine gives this process {cores()} "
                        f"core{'s' * (cores() != 1)}; each process needs one (use at "
                        f"most {cores()})")
    nbytes = here * (BYTES_PER_PROCESS + int(run_bytes) // max(p, 1))
    mem = available_memory()
    if mem is not None and nbytes > MEMORY_FRACTION * mem:
        raise SizeError(f"{name} {p}: {here} process{'es' * (here != 1)} "
                        f"need{'s' * (here == 1)} about "
                        f"{gib(nbytes)} of memory, more than {MEMORY_FRACTION:.0%} of "
                        f"the {gib(mem)} available")
