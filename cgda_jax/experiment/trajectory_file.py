"""A run's result as a trajectory file a robot controller can take (``cgda export``).

    >>> traj = cgda_jax.export_trajectory("results/paint_iet")  # doctest: +SKIP
    >>> cgda_jax.save_trajectory(traj, "paint.json")   # a ROS JointTrajectory inside
    >>> check_exported(run, traj)["success"]           # its replay on MuJoCo C

The trajectory itself is `cgda_jax.reality.control_trajectory`'s (straight
joint-space moves with the run's timing, on its minimum-jerk ramp or ruckig's
profile); its files are `cgda_jax.reality.files`'.
"""

from __future__ import annotations

import os

from cgda_jax.experiment.compute import EXPORT_RATE
from cgda_jax.experiment.load import Run, load_run

__all__ = ["check_exported", "export_trajectory"]


def _run(run: Run | str | os.PathLike) -> Run:
    run = run if isinstance(run, Run) else load_run(run)
    if run.kind != "execution":
        raise ValueError(f"{run.folder}: a {run.kind} run has no trajectory to export "
                         "(export needs an execution run)")
    return run


def _check_ranges(run: Run, robot) -> None:
    """The run's joints within the robot's ranges (to float32 rounding): a joint
    outside is a damaged or hand-edited result, not a posture the run took."""
    import numpy as np

    joints = np.asarray(run.arrays["joints"], np.float64)
    lo, hi = np.asarray(robot.lower, np.float64), np.asarray(robot.upper, np.float64)
    tol = 1e-5 * (1.0 + np.where(np.isfinite(hi - lo), hi - lo, 0.0))
    out = (joints < lo - tol) | (joints > hi + tol)
    if out.any():
        i, j = (int(v) for v in np.argwhere(out)[0])
        raise ValueError(
            f"{run.folder}: arrays.npz's joints of point {i + 1}: "
            f"{robot.joint_names[j]} = {joints[i, j]:.6g} is outside its range "
            f"[{lo[j]:.6g}, {hi[j]:.6g}] (damaged or edited: not a posture the run "
            "took)")


def export_trajectory(run: Run | str | os.PathLike, rate: float = EXPORT_RATE, *,
                      jerk=None, sim=None, profile: str = "min_jerk"):
    """The run's best joints as a time-parameterized trajectory at ``rate`` Hz.

    Args:
        run: a `Run` (`cgda_jax.load_run`) or its results folder.
        rate: control rate [Hz] (default 100).
        jerk: optional jerk limit(s) [rad/s^3], scalar or per joint; None: the
            run's own minimum-jerk peaks.
        sim: the run's simulator if already built (default `Run.simulator()`).
        profile: each move's profile, ``"min_jerk"`` (the run's own ramp) or
            ``"ruckig"`` (`cgda_jax.reality.profiles.PROFILES`).

    Returns:
        `cgda_jax.reality.control_trajectory.ExportedTrajectory` (positions,
        velocities and accelerations of the evolved joints, from the start posture
        through every waypoint, each held as long as the run held it).

    Raises:
        FolderError: not a results folder; ValueError: a recognition run, or joints
            that are NaN (a point without a posture: named) or outside their
            ranges.
    """
    from cgda_jax.reality.control_trajectory import trajectory_of

    run = _run(run)
    sim = sim if sim is not None else run.simulator()
    _check_ranges(run, sim.robot)
    return trajectory_of(sim, run.arrays["joints"], rate=rate, jerk=jerk,
                         profile=profile,
                         info={"run": str(run.folder), "name": run.name,
                               "strategy": run.result.get("strategy")})


def check_exported(run: Run | str | os.PathLike, traj, *, sim=None,
                   factor: int = 4) -> dict:
    """Replay ``traj`` (e.g. read back from its file) on MuJoCo C with the run's
    model and scene (`cgda_jax.reality.replay.replay_trajectory`) and judge its
    features as the run's strategy does.

    Returns:
        ``max_point_error``, ``max_feature_difference`` (against the run's own
        features), ``tolerance``, ``success`` (every point error < tolerance),
        ``features`` (N, F).
    """
    import numpy as np

    from cgda_jax.reality.replay import replay_trajectory

    run = _run(run)
    sim = sim if sim is not None else run.simulator()
    feats = replay_trajectory(sim, traj, factor)
    tol = float(run.result["tolerance"])
    from cgda_jax.strategies.fitness import point_errors  # JAX, evosax: lazily

    errors = point_errors(run.result["strategy"], feats, run.arrays["goal"], tol)
    return {"max_point_error": float(errors.max()),
            "max_feature_difference": float(np.abs(
                feats - run.arrays["features"]).max()),
            "tolerance": tol, "success": bool(np.all(errors < tol)),
            "features": feats}
