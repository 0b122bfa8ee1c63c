"""One move of an exported trajectory: the path parameter ``s`` from 0 to 1 (rest to
rest) sampled at the control rate, on the simulator's own minimum-jerk ramp or on
ruckig's jerk-limited profile (`cgda_jax.reality.control_trajectory` says which to
take and why).  Each mover returns (control periods, (periods, 3) of s, s', s'' at the
samples, whether the limits made the move longer than the run's)."""

from __future__ import annotations

import math

import numpy as np

from cgda_jax.sim.timing import (
    PEAK_ACCELERATION,
    PEAK_JERK,
    PEAK_SPEED,
    shortest_duration,
)

__all__ = ["MAX_PERIODS", "MOVERS", "PROFILES", "min_jerk_move", "periods",
           "ruckig_move", "ruckig_version"]

#: Control periods of one exported trajectory at most (2.8 h at 100 Hz, 17 min at
#: 1 kHz): its arrays are about 24 bytes x 3 x DoF a period, its JSON several times
#: that.
MAX_PERIODS = 1_000_000

#: the move profiles `time_parameterize` offers, and what each is.
PROFILES = {
    "min_jerk": "the simulator's minimum-jerk ramp along straight joint-space "
                "segments, stretched only where a limit needs it",
    "ruckig": "ruckig: jerk-limited rest-to-rest moves of the path parameter "
              "along straight joint-space segments",
}


def ruckig_version() -> str:
    import ruckig

    return getattr(ruckig, "__version__", "?")


def _ruckig_segment(v: float, a: float, j: float, duration: float):
    """A ruckig trajectory of the path parameter 0 -> 1 (rest to rest) within
    ``v``, ``a``, ``j`` lasting at least ``duration`` s."""
    from ruckig import InputParameter, Result, Ruckig, Trajectory

    otg, inp, traj = Ruckig(1), InputParameter(1), Trajectory(1)
    inp.current_position, inp.target_position = [0.0], [1.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
    inp.minimum_duration = float(duration)
    try:
        res = otg.calculate(inp, traj)
    except Exception as err:  # noqa: BLE001 - RuckigError: limits it cannot take
        res = f"{type(err).__name__}: {str(err).strip().splitlines()[0]}"
    if res not in (Result.Working, Result.Finished):
        raise ValueError(f"ruckig could not time a move ({res}; limits on the "
                         f"path v={v:g}, a={a:g}, j={j:g}, duration {duration:g} s)")
    return traj


def _path_limit(limit: np.ndarray, dq: np.ndarray, moving: np.ndarray,
                own: float) -> float:
    """The path parameter's limit: ``min_j limit_j / |dq_j|`` over the moving joints
    with a finite limit; ``own`` (the run's own peak) where none has one."""
    finite = moving & np.isfinite(limit)
    if not finite.any():
        return own
    return float(np.min(limit[finite] / np.abs(dq[finite])))


def periods(seconds: float, rate: float) -> int:
    """Whole control periods covering ``seconds`` (rounded up, tolerant of float
    noise).

    Raises:
        ValueError: more than `MAX_PERIODS` (or not finite), saying the time.
    """
    count = float(seconds) * float(rate)
    if not count <= MAX_PERIODS:  # NaN and inf included
        raise ValueError(f"{seconds:.3g} s at {rate:g} Hz is {count:.3g} control "
                         f"periods, more than {MAX_PERIODS:,}")
    return max(0, math.ceil(count - 1e-6))


def ruckig_move(dq, moving, t_run, move_k, rate, lims):
    """ruckig's jerk-limited profile of the path parameter for the move ``dq``:
    (control periods, (move_k, 3) s, s', s'' at the samples, made longer?)."""
    dt = 1.0 / rate
    v = _path_limit(lims["velocity"], dq, moving, PEAK_SPEED / t_run)
    a = _path_limit(lims["acceleration"], dq, moving, PEAK_ACCELERATION / t_run**2)
    j = _path_limit(lims["jerk"], dq, moving, PEAK_JERK / t_run**3)
    traj = _ruckig_segment(v, a, j, move_k * dt)
    longer = traj.duration > move_k * dt + 1e-9  # the limits need longer
    if longer:
        move_k = periods(traj.duration, rate)
        traj = _ruckig_segment(v, a, j, move_k * dt)
    s = np.array([traj.at_time(m * dt) for m in range(1, move_k + 1)],
                 np.float64)[..., 0]
    return move_k, s, longer


def min_jerk_move(dq, moving, t_run, move_k, rate, lims):
    """The run's own minimum-jerk ramp ``s = 10 tau^3 - 15 tau^4 + 6 tau^5`` over
    ``t_run`` (what the simulator commands), or over the least longer time whose
    peaks (1.875 |dq| / T, 5.7735 |dq| / T^2, 60 |dq| / T^3) keep every limit:
    (control periods, (move_k, 3) s, s', s'' at the samples, made longer?)."""
    del moving  # (a joint that does not move needs no time: shortest_duration)
    dt = 1.0 / rate
    duration = max(t_run, float(shortest_duration(
        np.abs(dq), lims["velocity"], lims["acceleration"], lims["jerk"])))
    longer = duration > t_run * (1 + 1e-9)
    if longer:
        move_k = max(move_k, periods(duration, rate))
    tau = np.minimum(np.arange(1, move_k + 1) * dt / duration, 1.0)
    s = np.stack([tau**3 * (10 + tau * (-15 + 6 * tau)),
                  30 * tau**2 * (1 - tau) ** 2 / duration,
                  60 * tau * (1 - tau) * (1 - 2 * tau) / duration**2], axis=-1)
    return move_k, s, longer


#: profile name -> its mover.
MOVERS = {"min_jerk": min_jerk_move, "ruckig": ruckig_move}
