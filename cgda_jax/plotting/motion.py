"""The executed motion against the robot's limits: joint positions and speeds over
time, the joint ranges and the speed limits drawn (issue 21)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from cgda_jax.plotting._base import finish, plt

__all__ = ["plot_motion"]


def plot_motion(
    t,
    q,
    qd,
    joint_names: Sequence[str],
    *,
    lower=None,
    upper=None,
    velocity=None,
    waypoint_t=None,
    measured_t=None,
    measured_qd=None,
    title: str | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Joint positions (degrees) and speeds (rad/s) over time, one colour a joint.

    Args:
        t: (T,) seconds.
        q, qd: (T, DoF) radians and rad/s (the commanded profile,
            `cgda_jax.sim.motion_check.motion_profile`).
        joint_names: (DoF,) names for the legend.
        lower, upper: (DoF,) joint ranges in radians, drawn dashed on the top panel.
        velocity: (DoF,) speed limits in rad/s (inf: none), drawn dashed at +/- on
            the bottom panel.
        waypoint_t: (N,) the times the waypoints are reached (thin grey lines; the
            first one ends the approach).
        measured_t, measured_qd: a measured speed trace (dynamic replay), drawn
            thin over the commanded one.
    """
    t = np.asarray(t, float)
    q, qd = np.asarray(q, float), np.asarray(qd, float)
    if q.shape != qd.shape or q.ndim != 2 or q.shape[0] != t.shape[0]:
        raise ValueError(f"t {t.shape}, q {q.shape} and qd {qd.shape} do not match "
                         "(T,), (T, DoF), (T, DoF)")
    n = q.shape[1]
    if len(joint_names) != n:
        raise ValueError(f"{len(joint_names)} joint names for {n} joints")
    colours = plt.get_cmap("tab10")(np.arange(n) % 10)
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7.2, 5.2))
    for j in range(n):
        top.plot(t, np.rad2deg(q[:, j]), color=colours[j], lw=1.4,
                 label=joint_names[j])
        bottom.plot(t, qd[:, j], color=colours[j], lw=1.4)
        for bound in (lower, upper):
            if bound is not None and np.isfinite(bound[j]):
                top.axhline(np.rad2deg(bound[j]), color=colours[j], ls="--", lw=0.7,
                            alpha=0.7)
        if velocity is not None and np.isfinite(velocity[j]):
            for sign in (-1, 1):
                bottom.axhline(sign * velocity[j], color=colours[j], ls="--", lw=0.8,
                               alpha=0.8)
        if measured_qd is not None:
            bottom.plot(np.asarray(measured_t, float), np.asarray(measured_qd)[:, j],
                        color=colours[j], lw=0.6, alpha=0.6)
    if waypoint_t is not None:
        for ax in (top, bottom):
            for k, tw in enumerate(np.asarray(waypoint_t, float)):
                ax.axvline(tw, color="0.6" if k else "0.3", lw=0.5, zorder=0)
    top.set_ylabel("joint position [deg]")
    bottom.set_ylabel("joint speed [rad/s]")
    bottom.set_xlabel("time [s] (first grey line: end of the approach)")
    dashed = []
    if lower is not None or upper is not None:
        dashed.append("joint ranges (top)")
    if velocity is not None and np.any(np.isfinite(velocity)):
        dashed.append("speed limits (bottom)")
    note = f"\ndashed: {', '.join(dashed)}" if dashed else ""
    top.set_title((title or "Executed motion and the robot's limits") + note,
                  fontsize=9)
    top.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return finish(fig, path)
