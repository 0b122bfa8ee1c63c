"""A robot interface: the `Reality` protocol a strategy (or a final check) can run
against instead of the internal simulator.

A user implements it for their robot driver: ``reset()`` brings the robot to its
start posture and measures the features there; ``execute(trajectory)`` sends an
`cgda_jax.reality.control_trajectory.ExportedTrajectory` (position targets at its
control rate, from the robot's current posture) and measures, at each waypoint's feature time
(``trajectory.feature_t``), the features and the joints.  The library ships one
implementation, `cgda_jax.reality.mismatch.MismatchedWorld` (the same scene in
MuJoCo C with perturbed parameters).

`measure` calls a reality and checks what it returned: a measurement with NaN, of
the wrong shape, or a reality that raises, stops the run with an error naming the
reality, the call and the problem (`RealityError`).
"""

from __future__ import annotations

from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from cgda_jax.reality.control_trajectory import ExportedTrajectory

__all__ = ["Measurement", "Reality", "RealityError", "measure"]


class Measurement(NamedTuple):
    """What a reality measured.

    Attributes:
        features: (N, F) the features at each waypoint's feature time (``reset``:
            (1, F), at the start posture).
        joints: (N, DoF) the joints measured there (radians / metres, in the
            robot's own frame: what its encoders read).
        marker: optional (N, 3) the tool (the simulator's marker point) measured
            there, in the model's world frame [m] (a tracker on the hand, a camera
            that sees the tool); None: not measured.  With it a closed loop
            estimates the joints' calibration offsets
            (`cgda_jax.reality.calibrate`).
    """

    features: np.ndarray
    joints: np.ndarray
    marker: np.ndarray | None = None


@runtime_checkable
class Reality(Protocol):
    """The robot (or another simulator) a result is executed on.

    Attributes:
        feature_names: (F,) the features it measures, in the goal's order.
        joint_names: (DoF,) the joints it moves, in the trajectory's order.
    """

    feature_names: tuple[str, ...]
    joint_names: tuple[str, ...]

    def reset(self) -> Measurement:
        """Go to the start posture and measure there ((1, F), (1, DoF))."""
        ...

    def execute(self, trajectory: ExportedTrajectory) -> Measurement:
        """Follow ``trajectory`` (from the current posture) and measure at each of
        its waypoints' feature times ((N, F), (N, DoF))."""
        ...


class RealityError(RuntimeError):
    """A reality failed or measured something unusable; the run stops."""


def _name(reality) -> str:
    return type(reality).__name__


def measure(reality: Reality, trajectory: ExportedTrajectory | None = None
            ) -> Measurement:
    """``reality.reset()`` (``trajectory`` None) or ``reality.execute(trajectory)``,
    checked: finite arrays of shape (N, F) and (N, DoF).

    Raises:
        RealityError: the reality raised, or returned NaN / inf or wrong shapes
            (the message names the reality, the call and the problem).
    """
    call = "reset()" if trajectory is None else "execute()"
    try:
        out = reality.reset() if trajectory is None else reality.execute(trajectory)
    except Exception as e:  # a user's driver may raise anything: said once
        raise RealityError(f"{_name(reality)}.{call} failed: {type(e).__name__}: "
                           f"{e}") from e
    n = 1 if trajectory is None else len(trajectory.feature_index)
    try:
        feats = np.asarray(out.features, np.float64)
        joints = np.asarray(out.joints, np.float64)
    except (AttributeError, TypeError, ValueError) as e:
        raise RealityError(f"{_name(reality)}.{call} returned {type(out).__name__}, "
                           "not a Measurement(features, joints)") from e
    f, dof = len(reality.feature_names), len(reality.joint_names)
    if feats.shape != (n, f) or joints.shape != (n, dof):
        raise RealityError(f"{_name(reality)}.{call} measured features "
                           f"{feats.shape} and joints {joints.shape}; expected "
                           f"({n}, {f}) and ({n}, {dof})")
    marker = getattr(out, "marker", None)
    checked = [("features", feats), ("joints", joints)]
    if marker is not None:
        marker = np.asarray(marker, np.float64)
        if marker.shape != (n, 3):
            raise RealityError(f"{_name(reality)}.{call} measured the tool (marker) "
                               f"{marker.shape}; expected ({n}, 3) or None")
        checked.append(("marker", marker))
    for what, arr in checked:
        if not np.all(np.isfinite(arr)):
            rows = sorted(set(np.flatnonzero(~np.all(np.isfinite(arr), axis=1))))
            raise RealityError(f"{_name(reality)}.{call} measured NaN or inf "
                               f"{what} (waypoints {[int(r) + 1 for r in rows]}): the "
                               "run stops")
    return Measurement(feats, joints, marker)
