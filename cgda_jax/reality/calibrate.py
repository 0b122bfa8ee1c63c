"""Joint offsets estimated from the measured tool: a kinematic calibration that a
closed loop keeps up to date.

A robot whose encoders are off by a fixed angle (a calibration offset) reads the
joints it was commanded while its links sit elsewhere; the features alone cannot
tell the model where its hand is.  A reality that also measures the tool's
position (`cgda_jax.reality.protocol.Measurement.marker`: a tracker on the hand, a
camera that sees the tool) gives, at every measured posture ``q`` (encoder
frame), ``FK(q + offset) = marker``.  `estimate_offsets` solves the offsets from
all the pairs seen so far by damped Gauss-Newton on the robot's own forward
kinematics (`cgda_jax.sim.robot.Robot.marker_position`), a ridge towards zero
(``prior_deg``) keeping a joint the postures do not excite where it was.

`OffsetEstimate` holds the pairs and the current estimate; the closed loop
(`cgda_jax.strategies.closed_loop`) plans in the model's frame (encoder reading +
offset) and sends ``planned - offset``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["OffsetEstimate", "estimate_offsets", "kinematics_of"]


def estimate_offsets(robot, joints, markers, *, noise: float = 0.002,
                     prior_deg: float = 5.0, iterations: int = 10,
                     initial=None) -> tuple[np.ndarray, float]:
    """The joint offsets (DoF,) [rad / m] that best explain the measured tool
    positions ``markers`` (M, 3) at the encoder readings ``joints`` (M, DoF):
    ``robot.marker_position(joints + offsets) ~ markers``.

    Args:
        robot: the `cgda_jax.sim.robot.Robot` (its forward kinematics).
        joints, markers: the measured pairs, M >= 1.
        noise: the tool measurement's standard deviation [m] (weights the data
            against the prior).
        prior_deg: the prior standard deviation of an offset [deg]: a joint the
            postures cannot see stays near 0.
        iterations: Gauss-Newton steps.
        initial: (DoF,) a start (default zeros).

    Returns:
        (offsets (DoF,), rms residual [m] of the fit).

    Raises:
        ValueError: shapes that do not match, no pairs, or non-finite values.
    """
    q = np.asarray(joints, np.float64)
    p = np.asarray(markers, np.float64)
    dof = len(robot.joint_names)
    if q.ndim != 2 or q.shape[1] != dof or p.shape != (len(q), 3) or len(q) == 0:
        raise ValueError(f"estimate_offsets: joints {q.shape} and markers {p.shape}; "
                         f"expected (M, {dof}) and (M, 3) with M >= 1")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(p))):
        raise ValueError("estimate_offsets: NaN or inf in the measured joints or "
                         "tool positions")
    if not (noise > 0 and prior_deg > 0):
        raise ValueError(f"estimate_offsets: noise ({noise}) and prior_deg "
                         f"({prior_deg}) must be > 0")
    fk_jac = kinematics_of(robot)
    x = np.zeros(dof) if initial is None else np.asarray(initial, np.float64)
    ridge = (noise / np.deg2rad(prior_deg)) ** 2

    def residuals(x):
        out = [fk_jac(jnp.asarray(qi + x, jnp.float32)) for qi in q]
        r = p - np.stack([np.asarray(o[0], np.float64) for o in out])   # (M, 3)
        jm = np.concatenate([np.asarray(o[1], np.float64) for o in out])  # (3M, DoF)
        return r, jm

    for _ in range(iterations):
        r, jm = residuals(x)
        a = jm.T @ jm + ridge * np.eye(dof)
        step = np.linalg.solve(a, jm.T @ r.reshape(-1) - ridge * x)
        x = x + step
        if np.max(np.abs(step)) < 1e-7:
            break
    r, _ = residuals(x)
    return x, float(np.sqrt(np.mean(np.sum(r ** 2, axis=1))))


_KINEMATICS: dict = {}  # id(robot) -> (robot, compiled fk and Jacobian)


def kinematics_of(robot):
    """``q (DoF,) -> (marker (3,), d marker / d q (3, DoF))``, compiled once per
    robot (the last few kept)."""
    hit = _KINEMATICS.get(id(robot))
    if hit is not None and hit[0] is robot:
        return hit[1]

    @jax.jit
    def fk_jac(q):
        return robot.marker_position(q), jax.jacfwd(robot.marker_position)(q)

    while len(_KINEMATICS) >= 4:
        _KINEMATICS.pop(next(iter(_KINEMATICS)))
    _KINEMATICS[id(robot)] = (robot, fk_jac)
    return fk_jac


class OffsetEstimate:
    """The measured (joints, tool) pairs of a run and the offsets they give.

    Attributes:
        offsets: (DoF,) the current estimate (zeros before any pair).
        history: the estimate after each `add`, (DoF,) each.
        residual: the last fit's rms tool residual [m].
    """

    def __init__(self, robot, *, noise: float = 0.002, prior_deg: float = 5.0):
        self.robot, self.noise, self.prior_deg = robot, float(noise), float(prior_deg)
        self._q: list[np.ndarray] = []
        self._p: list[np.ndarray] = []
        self.offsets = np.zeros(len(robot.joint_names))
        self.history: list[np.ndarray] = []
        self.residual = float("nan")

    @property
    def pairs(self) -> int:
        """How many (joints, tool) pairs the estimate has."""
        return len(self._q)

    def add(self, joints, markers) -> np.ndarray:
        """Add pairs (M, DoF) / (M, 3) and re-fit; returns the new offsets."""
        self._q += list(np.atleast_2d(np.asarray(joints, np.float64)))
        self._p += list(np.atleast_2d(np.asarray(markers, np.float64)))
        self.offsets, self.residual = estimate_offsets(
            self.robot, np.stack(self._q), np.stack(self._p), noise=self.noise,
            prior_deg=self.prior_deg, initial=self.offsets)
        self.history.append(self.offsets.copy())
        return self.offsets
