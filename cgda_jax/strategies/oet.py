"""Online Evolved Trajectories (OET; Fernandez-Fernandez et al., arXiv 1807.09177).

From the *current* simulator state: localize the goal step k = argmin_k |f_now - g_k|,
evolve ONE posture minimizing |f_after - g_{k+1}|, execute it, and repeat until the
localized step is the goal's last point or `max_steps` postures were executed.

Localization looks only at the window [k, k + lookahead] of the previous k (and starts
with k = -1, so the first target is g_0): progress along the goal is monotone, and a
closed goal (a circle whose end meets its start) is not mistaken as already finished.
Each step's evolution starts from the current posture (distribution-based algorithms).
A step whose evolution found no valid candidate (every simulation diverged) executes
nothing: the run stops there (``info["points_without_valid"]`` names its target).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from cgda_jax.strategies.base import (
    Evolution,
    PlanBase,
    freeze,
    from_joints,
    ragged_rows,
)
from cgda_jax.strategies.fitness import distances, ordered_point_errors
from cgda_jax.strategies.settings import Settings, option


@struct.dataclass
class OETState:
    """Carry of an OET run: the current evolution, sim state, localized step k and the
    executed postures (S, DoF) / features (S, F) / targets (S,) so far (`steps` of S),
    the invalid evaluations (total and per step (S,)) and `stuck` (the last evolution
    found no valid candidate; the run stopped). Restarts of the current step's
    evolution: `tries` started, the best over the finished ones (`try_best_u`,
    `try_best_fitness`) and what they spent (`try_generations`, `try_evaluations`,
    `try_invalid`); `step_tries` (S,) the tries each executed step took. `bias`
    (F,): what the features measured off the model's prediction at the last step
    (0 in OET; a closed loop's correction of the next target, `relocalize`)."""

    evo: Evolution
    key: jax.Array
    k: jax.Array
    steps: jax.Array
    sim_state: Any
    joints: jax.Array
    features: jax.Array
    targets: jax.Array
    step_generations: jax.Array
    evaluations: jax.Array
    invalid: jax.Array
    step_invalid: jax.Array
    stuck: jax.Array
    tries: jax.Array
    try_best_u: jax.Array
    try_best_fitness: jax.Array
    try_generations: jax.Array
    try_evaluations: jax.Array
    try_invalid: jax.Array
    step_tries: jax.Array
    bias: jax.Array


@dataclasses.dataclass(frozen=True, kw_only=True)
class OETSettings(Settings):
    """OET's settings (beyond `Settings`'s; ``tolerance``: one posture's evolution
    stops when its error to the target goal point is below the aim, and the success
    threshold; ``max_generations``: the budget per executed posture and try).

    Attributes:
        max_steps: budget of executed postures (None: 2 N).
        lookahead: localization window size beyond the current step (>= 1).
        restarts: a step's evolution that stopped short of the aim (stalled, see
            `stagnation`) restarts from a random mean with a fresh key, up to this
            many times (each try has `max_generations`); the best posture over its
            tries is executed (``info["step_tries"]``). 0: the original OET.
        stagnation: a try stops after this many generations without improvement
            (None: only at tolerance or `max_generations`).
        warm_start: start the first step's evolution at the posture the arm is in
            (the start posture; in a closed loop the measured one) instead of the
            middle of the joint ranges (later steps start from the previous posture
            either way); for goals reached by small continuous moves from where
            the arm is (pushing an object).
    """

    max_steps: int | None = option(None, "int", 1, none=True)
    lookahead: int = option(1, "int", 1)
    restarts: int = option(0, "int", 0)
    stagnation: int | None = option(None, "int", 1, none=True)
    warm_start: bool = option(False, "bool")


class OETPlan(PlanBase):
    """OET as a plan for `runner.drive`, built from `OETSettings` (or its fields
    as keywords, changing the defaults); ``info``, ``sharding``: see `PlanBase`.
    """

    name = "oet"

    def __init__(self, sim, goal, settings: OETSettings | None = None, *,
                 info=None, sharding=None, **changes):
        st = OETSettings.of(settings, **changes)
        max_steps = 2 * goal.shape[0] if st.max_steps is None else int(st.max_steps)
        super().__init__(sim, goal, int(sim.n_dof), st, info=info, sharding=sharding)
        lookahead, restarts, warm_start = st.lookahead, st.restarts, st.warm_start
        self.max_steps = max_steps
        self.lookahead = int(lookahead)
        self.restarts = int(restarts)
        self.warm_start = bool(warm_start)
        self.max_generations_total = (self.max_steps * self.max_generations
                                      * (1 + self.restarts))

    def _target(self, k):
        return jnp.minimum(k + 1, self.n_points - 1)

    def _fitness(self, sim_state, k, bias):
        return self.point_fitness(sim_state, self.goal[self._target(k)] - bias)

    def _start(self, key, sim_state, k, steps, mean, bias):
        if mean is None and self.warm_start:  # from where the arm is
            mean = from_joints(sim_state.genes, self.lower, self.upper)
        return self.start(jax.random.fold_in(key, steps),
                          self._fitness(sim_state, k, bias), mean=mean)

    def init(self, key):
        sim_state = self.sim.init_state()
        k = jnp.asarray(-1, jnp.int32)
        steps = jnp.zeros((), jnp.int32)
        s, f = self.max_steps, self.goal.shape[1]
        return OETState(
            evo=self._start(key, sim_state, k, steps, None,
                            jnp.zeros((f,), jnp.float32)),
            key=key, k=k, steps=steps, sim_state=sim_state,
            joints=jnp.zeros((s, self.n_dof), jnp.float32),
            features=jnp.zeros((s, f), jnp.float32),
            targets=jnp.full((s,), -1, jnp.int32),
            step_generations=jnp.zeros((s,), jnp.int32),
            evaluations=jnp.zeros((), jnp.int32),
            invalid=jnp.zeros((), jnp.int32),
            step_invalid=jnp.zeros((s,), jnp.int32),
            stuck=jnp.asarray(False),
            step_tries=jnp.zeros((s,), jnp.int32),
            bias=jnp.zeros((f,), jnp.float32),
            **self._fresh_tries(),
        )

    def _fresh_tries(self) -> dict[str, jax.Array]:
        zero = jnp.zeros((), jnp.int32)
        return {"tries": zero + 1,
                "try_best_u": jnp.zeros((self.n_dof,), jnp.float32),
                "try_best_fitness": jnp.asarray(jnp.inf, jnp.float32),
                "try_generations": zero, "try_evaluations": zero,
                "try_invalid": zero}

    def _try_stop(self, s: OETState):
        """A try stops at tolerance, at `max_generations` (each try has its own,
        as IE's), or after `stagnation` generations without improvement."""

        def stop(evo):
            return ((evo.best_fitness < self.aim_tolerance)
                    | (evo.generation >= self.max_generations) | self.stalled(evo))

        return stop

    def _merged(self, s: OETState) -> OETState:
        """The step's evolution as one: the best over its tries and their totals."""
        e = s.evo
        better = e.best_fitness < s.try_best_fitness
        return s.replace(evo=e.replace(
            best_u=jnp.where(better, e.best_u, s.try_best_u),
            best_fitness=jnp.where(better, e.best_fitness, s.try_best_fitness),
            generation=e.generation + s.try_generations,
            evaluations=e.evaluations + s.try_evaluations,
            invalid=e.invalid + s.try_invalid))

    def _restart(self, s: OETState) -> OETState:
        """Try ``s.tries`` of the current step: a random mean, a fresh key."""
        m = self._merged(s)
        key = jax.random.fold_in(jax.random.fold_in(s.key, s.steps), s.tries)
        k_mean, k_evo = jax.random.split(key)
        mean = jax.random.uniform(k_mean, (self.n_dof,), minval=-1.0, maxval=1.0)
        evo = self.start(k_evo, self._fitness(s.sim_state, s.k, s.bias), mean=mean)
        return s.replace(
            evo=evo, tries=s.tries + 1, try_best_u=m.evo.best_u,
            try_best_fitness=m.evo.best_fitness, try_generations=m.evo.generation,
            try_evaluations=m.evo.evaluations, try_invalid=m.evo.invalid)

    def localize(self, k: jax.Array, feats: jax.Array) -> jax.Array:
        """The goal step nearest ``feats`` (F,) in the window [k, k + lookahead] of
        the previous localized step ``k``."""
        window = jnp.arange(self.n_points)
        inside = (window >= jnp.maximum(k, 0)) & (window <= k + self.lookahead)
        dist = distances(self.goal, feats)
        return jnp.argmin(jnp.where(inside, dist, jnp.inf)).astype(jnp.int32)

    def relocalize(self, s: OETState, prev_k: jax.Array, sim_state: Any,
                   feats: jax.Array, correct: Any = True) -> OETState:
        """``s`` just after a step was executed (in the model), re-localized on what
        was measured instead: the executed step's features ``feats`` (F,), the
        localized step from ``prev_k`` (the one before the step) and the next
        step's evolution started from ``sim_state`` (as `_execute` starts it from
        the model's own state; `cgda_jax.strategies.closed_loop`). With
        ``correct`` the next target is moved against the measured features'
        offset from the model's prediction (``bias``; a model error the joints do
        not show, e.g. a calibration offset, is then corrected at the next step)."""
        k = self.localize(prev_k, feats)
        q = s.joints[s.steps - 1]
        bias = jnp.where(correct, feats - s.features[s.steps - 1], s.bias)
        return s.replace(
            evo=self._start(s.key, sim_state, k, s.steps,
                            from_joints(q, self.lower, self.upper), bias),
            k=k, sim_state=sim_state, bias=bias,
            features=s.features.at[s.steps - 1].set(feats))

    def start_at(self, s: OETState, sim_state: Any) -> OETState:
        """``s`` before its first step (`init`), its first evolution started from
        ``sim_state`` instead (a closed loop's start state rebuilt on what the
        reality measured at its start; the localized step as it was)."""
        return s.replace(evo=self._start(s.key, sim_state, s.k, s.steps, None,
                                         s.bias), sim_state=sim_state)

    def _execute(self, s: OETState) -> OETState:
        q = self.joints(s.evo.best_u)
        sim_state, feats = self.sim.step(s.sim_state, q)
        k = self.localize(s.k, feats)
        steps = s.steps + 1
        return s.replace(
            evo=self._start(s.key, sim_state, k, steps,
                            from_joints(q, self.lower, self.upper), s.bias),
            k=k, steps=steps, sim_state=sim_state,
            joints=s.joints.at[s.steps].set(q),
            features=s.features.at[s.steps].set(feats),
            targets=s.targets.at[s.steps].set(self._target(s.k)),
            step_generations=s.step_generations.at[s.steps].set(s.evo.generation),
            evaluations=s.evaluations + s.evo.evaluations,
            invalid=s.invalid + s.evo.invalid,
            step_invalid=s.step_invalid.at[s.steps].set(s.evo.invalid),
            step_tries=s.step_tries.at[s.steps].set(s.tries),
            **self._fresh_tries(),
        )

    def _stuck(self, s: OETState) -> OETState:
        """The step's evolution found no valid candidate: execute nothing, stop."""
        return s.replace(
            step_generations=s.step_generations.at[s.steps].set(s.evo.generation),
            evaluations=s.evaluations + s.evo.evaluations,
            invalid=s.invalid + s.evo.invalid,
            step_invalid=s.step_invalid.at[s.steps].set(s.evo.invalid),
            stuck=jnp.asarray(True),
        )

    def _end(self, s: OETState) -> OETState:
        """The step's try stopped: restart it, or execute the best of its tries."""
        m = self._merged(s)

        def execute(_):
            return jax.lax.cond(m.evo.found, self._execute, self._stuck, m)

        if self.restarts == 0:
            return execute(None)
        again = (m.evo.best_fitness >= self.aim_tolerance) & (s.tries <= self.restarts)
        return jax.lax.cond(again, lambda _: self._restart(s), execute, None)

    def step(self, s: OETState):
        finished = self.done(s)
        evo, metrics = self.evolve(s.evo, self._fitness(s.sim_state, s.k, s.bias),
                                   self._try_stop(s))
        new = jax.lax.cond(evo.done, self._end, lambda x: x, s.replace(evo=evo))
        new = freeze(finished, s, new)
        best = jnp.minimum(metrics["best_fitness"], s.try_best_fitness)
        return new, {"best_fitness": best,
                     "invalid": metrics["invalid"],
                     "step": jnp.where(finished, -1, s.steps)}

    def done(self, s):
        return (s.k >= self.n_points - 1) | (s.steps >= self.max_steps) | s.stuck

    def progress(self, s):
        running = np.where(np.asarray(self.done(s)), 0, np.asarray(s.evo.generation))
        gens = np.asarray(s.step_generations).sum(-1) + running
        return {"generations": gens.tolist(),  # summed over the steps, as the result's
                "k": np.asarray(s.k).tolist(), "steps": np.asarray(s.steps).tolist()}

    def finish(self, s):
        out = {"joints": s.joints, "features": s.features, "targets": s.targets,
               "steps": s.steps, "k": s.k, "step_generations": s.step_generations,
               "evaluations": s.evaluations, "invalid": s.invalid,
               "step_invalid": s.step_invalid, "stuck": s.stuck,
               "step_tries": s.step_tries}
        if s.sim_state.violation is not None:  # the executed steps, summed
            out["violation"] = s.sim_state.violation
        return out

    def to_result(self, final, history, timing):
        goal = np.asarray(self.goal)
        n = int(final["steps"])
        feats = final["features"][:n]
        dist = distances(goal[:, None, :], feats[None, :, :])
        stuck = bool(final["stuck"])
        gens = final["step_generations"][:n + stuck]  # the stuck evolution ran too
        executed = {"joints": final["joints"][:n], "features": feats}
        if "violation" in final:
            executed["violation"] = final["violation"]
        return self.result(
            executed, timing,
            point_errors=ordered_point_errors(dist, self.tolerance),
            fitness_history=ragged_rows(
                [history["best_fitness"][history["step"] == i] for i in range(n)]
            ),
            evaluations=final["evaluations"],
            generations=gens.sum(),
            steps=n, reached_end=int(final["k"]) >= len(goal) - 1,
            targets=final["targets"][:n].tolist(),
            step_generations=gens.tolist(), lookahead=self.lookahead,
            restarts=self.restarts, stagnation=self.stagnation,
            step_tries=final["step_tries"][:n].tolist(),
            invalid_evaluations=final["invalid"],
            step_invalid=final["step_invalid"][:n + stuck].tolist(),
            points_without_valid=(
                [min(int(final["k"]) + 1, len(goal) - 1)] if stuck else []
            ),
        )
