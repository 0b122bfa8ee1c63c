"""Random serial arms (MJCF text) and reachable goal curves for them.

The paper claims robot-configuration independence: the same goal on another body. To
test that claim on more than TEO, `random_arm_mjcf` writes a plain MJCF arm with
2-7 hinge joints, random segment lengths and random joint axes (a base yaw, then
pitch/roll/yaw axes drawn at random), position actuators for dynamic mode and a
"marker" site at the tip; `reachable_goal` gives a smooth goal curve that the arm can
follow (marker positions along a joint-space path between two random postures), so
a failure is the optimiser's, not the geometry's.

Example:
    >>> import cgda_jax as cg
    >>> xml = random_arm_mjcf(4, seed=0)
    >>> robot = cg.Robot(mujoco.MjModel.from_xml_string(xml), arm_joints(4), "marker")
    >>> reachable_goal(robot, 6, seed=0).shape
    (6, 3)
"""

from __future__ import annotations

import mujoco  # noqa: F401  (the doctest builds a model)
import numpy as np

__all__ = ["arm_joints", "random_arm_mjcf", "reachable_goal"]

_AXES = ((0, 1, 0), (1, 0, 0), (0, 0, 1))


def arm_joints(n_joints: int) -> list[str]:
    """The joint names `random_arm_mjcf` uses: ``j0 .. j{n-1}``."""
    return [f"j{i}" for i in range(n_joints)]


def random_arm_mjcf(n_joints: int, seed: int = 0) -> str:
    """MJCF text of a random serial arm.

    Joint 0 turns about z at the base; every later joint's axis is y, x or z at random,
    with a range of +-(60..150) degrees; segments are 0.12-0.35 m long along the
    previous segment's z axis; a "marker" site sits at the tip.

    Args:
        n_joints: 2 to 7 hinge joints.
        seed: NumPy seed of the geometry.
    """
    if not 2 <= int(n_joints) <= 7:
        raise ValueError(f"n_joints must be in 2..7, got {n_joints}")
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(0.12, 0.35, n_joints)
    body = '<site name="marker" pos="0 0 {:.4f}" size="0.015"/>'.format(lengths[-1])
    for i in reversed(range(n_joints)):
        axis = (0, 0, 1) if i == 0 else _AXES[int(rng.integers(0, 3))]
        if i == 1 and axis == (0, 0, 1):
            axis = (0, 1, 0)  # two stacked yaws would waste a joint
        limit = float(rng.uniform(60, 150))
        pos = 0.05 if i == 0 else lengths[i - 1]
        body = (
            f'<body name="link{i}" pos="0 0 {pos:.4f}">'
            f'<joint name="j{i}" axis="{axis[0]} {axis[1]} {axis[2]}" '
            f'range="{-limit:.1f} {limit:.1f}"/>'
            f'<geom type="capsule" fromto="0 0 0 0 0 {lengths[i]:.4f}" size="0.02"/>'
            f"{body}</body>"
        )
    actuators = "".join(f'<position joint="j{i}"/>' for i in range(n_joints))
    return (
        f'<mujoco model="random_arm_{n_joints}_{seed}">'
        '<compiler angle="degree" autolimits="true"/>'
        '<option timestep="0.002" gravity="0 0 -9.81"/>'
        '<default><geom contype="0" conaffinity="0" density="500"/>'
        '<joint type="hinge" limited="true" damping="2" armature="0.005"/>'
        '<position kp="50"/></default>'
        f"<worldbody>{body}</worldbody><actuator>{actuators}</actuator></mujoco>"
    )


def reachable_goal(robot, n_points: int, seed: int = 0) -> np.ndarray:
    """(N, 3) marker positions along a joint-space line between two random postures
    inside 80 % of the joint ranges: a goal curve the arm can follow exactly."""
    import jax.numpy as jnp

    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    mid, half = (lo + hi) / 2, 0.8 * (hi - lo) / 2
    a, b = (mid + half * rng.uniform(-1, 1, (2, robot.n_dof)))
    path = a + np.linspace(0, 1, n_points)[:, None] * (b - a)
    return np.stack([np.asarray(robot.marker_position(jnp.asarray(q, jnp.float32)))
                     for q in path]).astype(np.float64)
