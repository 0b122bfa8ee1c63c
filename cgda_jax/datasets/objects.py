"""Synthetic demonstrations of what an action does to an object: MOVE and ROTATE.

CGDA tracks the object, not the demonstrator (paper section 2).  These generators give
the object's trajectory while a person acts on it, in the robot's waist frame (metres,
radians), in the same `Demonstration` form as the marker datasets:

- `move_box_demos`: a box slid along a table from ``start`` to ``end`` (x, y), with an
  optional sideways bulge (a gently curved push) and the few degrees of yaw a pushed
  box picks up; features ``box.x [m]``, ``box.y [m]``, ``box.yaw [rad]``.
- `rotate_valve_demos`: a valve turned from ``start`` to ``end`` (radians); feature
  ``valve.angle [rad]``.
- `object_actions`: MOVE, SWEEP (a curved push that turns the box) and ROTATE as the
  same three features of the manipulated object (x, y, yaw), for recognition.

Feature names follow `cgda_jax.sim.ObjectScene` (``<name>.<column> [<unit>]``), so a
generalized demonstration is a goal for a scene that reads the same features.

Every repetition has a human's variability: its own duration, pauses before and after,
a hesitation halfway, a slightly different start (where the object was put down) and
amplitude (where the person stopped), and tracking noise.  Host NumPy with
``np.random.default_rng(seed)``: fixtures, not part of any jitted path.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cgda_jax.data import Demonstration
from cgda_jax.datasets.synthetic import check_repetitions, repetition_progress

__all__ = [
    "MOVE_BOX_END",
    "MOVE_BOX_START",
    "OBJECT_ACTIONS",
    "OBJECT_FEATURES",
    "VALVE_END",
    "VALVE_START",
    "move_box_demos",
    "object_actions",
    "rotate_valve_demos",
]

#: Default push: 22 cm to TEO's right on a table in front of its right arm (waist
#: frame, metres; experiments/move_push_box.toml places the box there).
MOVE_BOX_START: tuple[float, float] = (0.26, -0.49)
MOVE_BOX_END: tuple[float, float] = (0.26, -0.71)
#: Default turn: 110 degrees clockwise seen from above (radians).
VALVE_START: float = 0.0
VALVE_END: float = -1.92
#: The actions of `object_actions` and their features (the tracked object's pose).
OBJECT_ACTIONS: tuple[str, ...] = ("MOVE", "SWEEP", "ROTATE")
OBJECT_FEATURES: tuple[str, ...] = ("object.x [m]", "object.y [m]", "object.yaw [rad]")


#: Default mean duration of an object demonstration [s] and the tracker's rate [Hz].
DEFAULT_DURATION_S: float = 7.4
RATE_HZ: float = 30.0


def longest_s(duration_s: float) -> float:
    """The longest repetition of mean push time `duration_s`: 15 % longer, plus
    1.6 s of pauses."""
    return 1.15 * float(duration_s) + 1.6


def check_duration(duration_s: float, rate_hz: float, n: int, width: int) -> None:
    """`duration_s` finite and > 0, and `n` demonstrations of it at `rate_hz`
    within `cgda_jax.sizes.MAX_DEMO_SAMPLES` samples each and the memory
    (checked before any is generated).

    Raises:
        ValueError / cgda_jax.sizes.SizeError: naming ``duration_s``.
    """
    from cgda_jax.sizes import check_samples, samples_estimate

    if not (np.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be a finite number > 0, got {duration_s!r}")
    check_samples(samples_estimate(longest_s(duration_s), rate_hz), "duration_s",
                  f"{duration_s:g} s at {rate_hz:g} Hz", n=n, width=width)


def _timing(rng: np.random.Generator, duration_s: float, rate_hz: float):
    """(times (T,), progress (T,) in [0, 1]) of one repetition, pauses included."""
    duration = duration_s * rng.uniform(0.85, 1.15)
    count = round((duration + 1.6) * rate_hz)
    p, _ = repetition_progress(rng, count, rate_hz, duration)
    return np.arange(count) / rate_hz, p


def _push(rng, start, end, curve, turn, p, noise_m, noise_rad):
    """x, y, yaw (T, 3) of a box pushed from `start` to `end` with progress `p`."""
    start = np.asarray(start, float) + rng.normal(0.0, 0.003, 2)
    delta = np.asarray(end, float) - start
    delta = delta * rng.uniform(0.97, 1.03)  # where the person stopped
    length = np.linalg.norm(delta)
    normal = np.array([-delta[1], delta[0]]) / max(length, 1e-12)
    bulge = curve * rng.uniform(0.8, 1.2) * np.sin(np.pi * p)
    xy = start + p[:, None] * delta + bulge[:, None] * normal
    yaw = (turn * rng.uniform(0.9, 1.1) + rng.normal(0.0, np.radians(2.0))) * p
    out = np.column_stack([xy, yaw])
    return out + rng.normal(0.0, [noise_m, noise_m, noise_rad], size=out.shape)


def _check_point(value, n: int, key: str) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{key} must be {n} finite number(s), got {value!r}")
    return v


def move_box_demos(
    start: Sequence[float] = MOVE_BOX_START,
    end: Sequence[float] = MOVE_BOX_END,
    n: int = 6,
    seed: int = 0,
    *,
    curve: float = 0.0,
    name: str = "box",
    rate_hz: float = RATE_HZ,
    duration_s: float = DEFAULT_DURATION_S,
    noise_m: float = 0.002,
    noise_rad: float = 0.01,
) -> list[Demonstration]:
    """Demonstrations of a box pushed along a table (MOVE), as box x, y, yaw.

    Args:
        start, end: (x, y) of the box before and after the push [m], robot frame.
        n: number of repetitions.
        seed: host random seed.
        curve: sideways bulge of the path at its middle [m] (positive: to the left
            of the push direction); 0 = a straight push.
        name: the box's name in the feature names (``<name>.x [m]`` ...).
        rate_hz: sampling rate of the tracker.
        duration_s: mean duration of the push itself [s]; each repetition adds
            about 1.6 s of pauses, so with ``interval_s = 1`` the default gives
            about 9 goal points.
        noise_m, noise_rad: tracking noise (standard deviations).

    Returns:
        ``n`` Demonstrations ``"move-k"`` with features (T_k, 3) named
        ``<name>.x [m]``, ``<name>.y [m]``, ``<name>.yaw [rad]``.

    Examples:
        >>> d = move_box_demos(n=2, seed=1)
        >>> d[0].feature_names
        ('box.x [m]', 'box.y [m]', 'box.yaw [rad]')
    """
    start = _check_point(start, 2, "start")
    end = _check_point(end, 2, "end")
    check_repetitions(n, rate_hz)
    check_duration(duration_s, rate_hz, n, 3)
    rng = np.random.default_rng(seed)
    names = (f"{name}.x [m]", f"{name}.y [m]", f"{name}.yaw [rad]")
    demos = []
    for k in range(int(n)):
        times, p = _timing(rng, duration_s, rate_hz)
        feats = _push(rng, start, end, curve, 0.0, p, noise_m, noise_rad)
        demos.append(Demonstration(times, feats, names, name=f"move-{k + 1}"))
    return demos


def rotate_valve_demos(
    start: float = VALVE_START,
    end: float = VALVE_END,
    n: int = 6,
    seed: int = 0,
    *,
    name: str = "valve",
    rate_hz: float = RATE_HZ,
    duration_s: float = DEFAULT_DURATION_S,
    noise_rad: float = 0.01,
) -> list[Demonstration]:
    """Demonstrations of a valve turned from ``start`` to ``end`` (ROTATE).

    Args:
        start, end: valve angle before and after the turn [rad] (negative turns
            clockwise seen from above for a valve whose hinge points up).
        n, seed, rate_hz, duration_s: as in `move_box_demos`.
        name: the valve's joint name in the feature name.
        noise_rad: tracking noise [rad].

    Returns:
        ``n`` Demonstrations ``"rotate-k"`` with one feature ``<name>.angle [rad]``.
    """
    start = float(_check_point([start], 1, "start")[0])
    end = float(_check_point([end], 1, "end")[0])
    check_repetitions(n, rate_hz)
    check_duration(duration_s, rate_hz, n, 1)
    rng = np.random.default_rng(seed)
    demos = []
    for k in range(int(n)):
        times, p = _timing(rng, duration_s, rate_hz)
        a0 = start + rng.normal(0.0, np.radians(1.0))
        turn = (end - start) * rng.uniform(0.97, 1.03)
        angle = a0 + turn * p + rng.normal(0.0, noise_rad, size=p.shape)
        demos.append(Demonstration(times, angle[:, None], (f"{name}.angle [rad]",),
                                   name=f"rotate-{k + 1}"))
    return demos


def object_actions(
    n_repetitions: int = 7, seed: int = 0, *, rate_hz: float = 30.0
) -> dict[str, list[Demonstration]]:
    """MOVE, SWEEP and ROTATE as the tracked object's x, y, yaw (for recognition).

    - MOVE: a box pushed 22 cm in a straight line (`move_box_demos`' default path).
    - SWEEP: the same box pushed along a curve (8 cm bulge) while it turns 45 deg.
    - ROTATE: a valve turned 110 deg in place (its hub stays where it is).

    Args:
        n_repetitions: repetitions per action.
        seed: host random seed.
        rate_hz: sampling rate.

    Returns:
        ``{action: [Demonstration, ...]}`` in the order of `OBJECT_ACTIONS`, each
        with the features `OBJECT_FEATURES`.
    """
    check_repetitions(n_repetitions, rate_hz)
    rng = np.random.default_rng(seed)
    hub = np.array([0.23, -0.54])
    out: dict[str, list[Demonstration]] = {a: [] for a in OBJECT_ACTIONS}
    for k in range(int(n_repetitions)):
        for action in OBJECT_ACTIONS:
            times, p = _timing(rng, 5.0, rate_hz)
            if action == "MOVE":
                feats = _push(rng, MOVE_BOX_START, MOVE_BOX_END, 0.0, 0.0, p,
                              0.002, 0.01)
            elif action == "SWEEP":
                feats = _push(rng, MOVE_BOX_START, MOVE_BOX_END, 0.08,
                              np.radians(45.0), p, 0.002, 0.01)
            else:
                turn = (VALVE_END - VALVE_START) * rng.uniform(0.97, 1.03)
                yaw = VALVE_START + turn * p
                xy = np.broadcast_to(hub + rng.normal(0.0, 0.002, 2), (len(p), 2))
                feats = np.column_stack([xy, yaw])
                feats = feats + rng.normal(0.0, [0.002, 0.002, 0.01], feats.shape)
            out[action].append(Demonstration(times, feats, OBJECT_FEATURES,
                                             name=f"{action}-{k + 1}"))
    return out
