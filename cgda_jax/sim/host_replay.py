"""One replay of a dynamic simulator's timed motion on MuJoCo C (host NumPy): the
physics model stepped along the commanded reference, as the simulator commands it
(`cgda_jax.sim.simulator.Simulator`): each move from the previous waypoint (the
start posture first) to the next, clipped to the joint limits, on the minimum-jerk
share of the move at each physics step (`Simulator.reference_profiles`: the
approach for the first move), the shares turned into actuator targets by
`reference_ctrl`, the same rule the simulator's own step uses.

`replay_steps` is the one loop; the motion check
(`cgda_jax.sim.motion_check.motion_report`: speeds, forces, tracking, contacts) and the
render (`cgda_jax.sim.render`) read what they need after each step.  (The exported
file's replay, `cgda_jax.reality.replay`, replays the file's samples instead.)
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

__all__ = ["ReplayStep", "reference_ctrl", "replay_steps"]


def reference_ctrl(phys, genes_from: Any, genes_to: Any, profile: Any,
                   xp: Any = np) -> Any:
    """(T, nu) actuator targets along the move from ``genes_from`` to ``genes_to``
    (DoF,) at the shares ``profile`` (T,): ``c0 + share * (c1 - c0)``, with c0 and
    c1 the targets that hold each end (`cgda_jax.sim.physics.Physics.ctrl_of` of
    the start posture with the evolved joints set).  ``xp``: ``numpy`` (the host
    replay, float64) or ``jax.numpy`` (the simulator's traced step, float32)."""
    if xp is np:
        q0 = np.array(phys.qpos0, np.float64)
        q1 = q0.copy()
        q0[phys.gene_qadr] = genes_from
        q1[phys.gene_qadr] = genes_to
    else:
        qpos0 = xp.asarray(phys.qpos0, xp.float32)
        q0 = qpos0.at[phys.gene_qadr].set(genes_from)
        q1 = qpos0.at[phys.gene_qadr].set(genes_to)
    c0, c1 = phys.ctrl_of(q0), phys.ctrl_of(q1)
    return c0 + xp.asarray(profile)[:, None] * (c1 - c0)


class ReplayStep:
    """Where `replay_steps` is after one physics step.

    Attributes:
        model, data: the ``MjModel`` and its ``MjData`` just stepped (read, do not
            keep: the next step changes them).
        physics: the `cgda_jax.sim.physics.Physics` stepped.
        move: the waypoint moved to, from 1.
        step: the step within the move, from 1; steps: the move's steps.
        target: (DoF,) the move's clipped waypoint.
    """

    __slots__ = ("model", "data", "physics", "move", "step", "steps", "target",
                 "_ref")

    @property
    def commanded(self) -> np.ndarray:
        """(DoF,) the commanded posture of the evolved joints at this step (the
        reference the step's control holds)."""
        q0, q1, shares = self._ref
        return q0 + shares[self.step - 1] * (q1 - q0)

    @property
    def last(self) -> bool:
        """The move's last step (its waypoint's end)."""
        return self.step == self.steps


def replay_steps(sim, joints: np.ndarray, factor: int = 1) -> Iterator[ReplayStep]:
    """Step MuJoCo C along the commanded reference of ``joints`` (N, DoF) from the
    robot's start posture at rest, on ``sim``'s physics model (``factor`` > 1: at
    ``timestep / factor``, `Simulator.finer`); yields after every step.

    Raises:
        ValueError: a kinematic simulator (no physics to step).
    """
    import mujoco

    if sim.mode != "dynamic":
        raise ValueError("replay_steps: a kinematic simulator has no physics")
    fine = sim.finer(factor) if factor > 1 else sim
    phys = fine.physics
    robot = sim.robot
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    m = phys.model
    d = mujoco.MjData(m)
    prev = np.asarray(robot.start_genes, np.float64)  # `Simulator.init_state`
    d.qpos[:] = np.asarray(phys.qpos0, np.float64)
    d.qpos[phys.gene_qadr] = prev
    mujoco.mj_forward(m, d)
    approach, profile = fine.reference_profiles()
    out = ReplayStep()
    out.model, out.data, out.physics = m, d, phys
    for j, w in enumerate(np.asarray(joints, np.float64), start=1):
        shares = approach if j == 1 else profile
        target = np.clip(w, lo, hi)
        ctrl = reference_ctrl(phys, prev, target, shares)
        out.move, out.steps, out.target = j, len(shares), target
        out._ref = (prev, target, np.asarray(shares, np.float64))
        for k in range(len(shares)):
            d.ctrl[:] = ctrl[k]
            mujoco.mj_step(m, d)
            out.step = k + 1
            yield out
        prev = target
