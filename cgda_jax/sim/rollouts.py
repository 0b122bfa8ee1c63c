"""Executing whole waypoint sequences and populations of them with a simulator's
`step` (`Executions`, the base of `cgda_jax.sim.simulator.Simulator`)."""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from jax import Array

from cgda_jax.sim.sim_state import SimState, check_waypoints

if TYPE_CHECKING:
    from cgda_jax.sim.robot import Robot

__all__ = ["Executions"]


class Executions(abc.ABC):
    """Rollouts and batched executions built on a simulator's one-move `step`.

    The contract with a subclass (`cgda_jax.sim.simulator.Simulator`):

    - it sets the attributes declared here, `robot`, `mode` and `batch_size`;
    - it defines the abstract `step` (one move) and `_start` (the start state
      of checked genes);
    - its ``__init__`` calls ``Executions.__init__`` once those are set, which
      jits `rollout`'s and `execute_population`'s programs (per simulator) and
      starts `n_traces`.

    Attributes:
        n_traces: how often `execute_population`'s program was traced (tests
            read it: one trace per population shape).
    """

    #: the robot (its evolved joints check the waypoints).
    robot: Robot
    #: "kinematic" or "dynamic" (`map_population` slices only dynamic MJX).
    mode: str
    #: dynamic mode: candidates per slice of `map_population` (None: one batch).
    batch_size: int | None

    def __init__(self) -> None:
        self.n_traces = 0
        self._execute_population = jax.jit(self._execute_batched)
        self._rollout = jax.jit(self._rollout_checked)

    @abc.abstractmethod
    def step(self, state: SimState, waypoint: Array, *,
             judge: bool = True) -> tuple[SimState, Array]:
        """Move to one waypoint: (new state, features (F,) there)."""

    @abc.abstractmethod
    def _start(self, genes0: Array) -> SimState:
        """The start state at checked genes ``genes0`` (DoF,)."""

    def rollout(
        self, waypoints: Array, state: SimState | None = None
    ) -> tuple[Array, SimState]:
        """Execute waypoints in order (``lax.scan`` of `step`).

        Args:
            waypoints: (N, DoF) joint values.
            state: start state; default `init_state()`.

        Returns:
            (features (N, F), final state).
        """
        check_waypoints(waypoints, self.robot)
        return self._rollout(waypoints, state)

    def _rollout_checked(
        self, waypoints: Array, state: SimState | None
    ) -> tuple[Array, SimState]:
        """`rollout` of checked waypoints (jitted per simulator in `__init__`)."""
        if state is None:
            state = self._start(self.robot.start_genes)
        state, features = jax.lax.scan(
            self.step, state, jnp.asarray(waypoints, jnp.float32)
        )
        return features, state

    def violation(self, waypoints: Array, state: SimState | None = None) -> Array:
        """Summed violation (scalar) of executing (N, DoF) waypoints from ``state``
        (0 = feasible; 0 without feasibility)."""
        final = self.rollout(waypoints, state)[1]
        return jnp.float32(0.0) if final.violation is None else final.violation

    def execute(self, waypoints: Array, state: SimState | None = None) -> Array:
        """Features (N, F) of executing (N, DoF) waypoints from ``state`` (default:
        `init_state()`)."""
        return self.rollout(waypoints, state)[0]

    def _execute_traced(self, waypoints: Array) -> Array:
        self.n_traces += 1
        return self.execute(waypoints)

    def map_population(self, fn, xs):
        """``vmap(fn)(xs)``, in dynamic MJX mode as ``lax.map`` over slices of at
        most ``batch_size`` candidates (see `cgda_jax.sim.simulator.Simulator`:
        large LAPACK batches deadlock XLA's CPU thread pool).  Otherwise a plain ``vmap`` (the MuJoCo C
        backend gets the whole batch in one call).

        Args:
            fn: a function of one candidate (pytree of arrays).
            xs: the candidates, stacked on axis 0 (P, ...).
        """
        if self.mode != "dynamic" or self.batch_size is None:
            return jax.vmap(fn)(xs)
        n = jax.tree_util.tree_leaves(xs)[0].shape[0]
        if n <= self.batch_size:
            return jax.vmap(fn)(xs)
        return jax.lax.map(fn, xs, batch_size=self.batch_size)

    def _execute_batched(self, population: Array) -> Array:
        return self.map_population(self._execute_traced, population)

    def execute_population(self, population: Array) -> Array:
        """Execute a population of trajectories at once (jitted ``vmap`` of `execute`;
        dynamic MJX mode: in slices of ``batch_size``, see `map_population`).

        Args:
            population: (P, N, DoF) waypoints, each starting from `init_state()`.

        Returns:
            (P, N, F) features.
        """
        check_waypoints(population, self.robot, batched=True)
        return self._execute_population(jnp.asarray(population, jnp.float32))
