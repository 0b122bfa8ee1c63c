"""The paper's strategies written with pycma's ask/tell and MuJoCo C, for the benchmarks.

The same searches as cgda_jax.strategies with bench_strategies' ``SAME_SEARCH``
settings (no restarts, no backtracks; CMA-ES in the same normalized gene space, same
start mean 0 and step size, same population size, fitness and stopping rules),
written the way a user of pycma would: ask/tell, each candidate executed on its own
(`peers.MujocoMarker`).  `pycma_iet` can also restart and backtrack as our IET does
(``restarts``, ``backtracks``: bench_strategies' ``--to-success``, time to success).

With feasibility (``c_sim`` a `peer_feasibility.FeasibleMarker`) they do what ours do
with a `Feasibility` on the simulator:

- every move is judged (`peer_feasibility.MujocoFeasibility.move`) and an infeasible
  candidate's fitness gets ``penalty * (1 + violation)`` added;
- a point's error that meets the tolerance is replaced by ``tolerance * m / (m + 1)``,
  ``m`` the joint motion from where the point starts (IE and IET, as
  `cgda_jax.strategies.base.PlanBase.least_motion`);
- IE evolves its points in lock-step, each from where the current bests of the
  points before it leave the arm (every generation: the bests executed in order from
  the start, each best re-scored there, a point that no longer meets the tolerance
  evolves again), as `cgda_jax.strategies.ie.IEPlan` does with feasibility;
- success needs a feasible execution (summed violation 0), as ours.
"""

from __future__ import annotations

import time

import numpy as np
from peer_feasibility import FeasibleMarker
from peers import dtai_pair


def to_joints(u, lower, upper) -> np.ndarray:
    """Normalized genes -> joint angles (cgda_jax.strategies.base.to_joints)."""
    mid, half = 0.5 * (upper + lower), 0.5 * (upper - lower)
    return mid + half * np.sin(0.5 * np.pi * np.asarray(u))


def _cma(n_genes: int, popsize: int, sigma0: float, seed: int, max_gens: int,
         x0=None):
    import cma

    opts = {
        "popsize": popsize,
        "seed": seed + 1,  # pycma: seed 0 means "random"
        "verbose": -9,
        "maxiter": max_gens,
        "CMA_diagonal": False,
        # stop by the caller's rule only, as cgda_jax does: none of pycma's own
        # flat-fitness / small-change stops (a paint score is flat over large regions)
        "tolflatfitness": max_gens + 1,
        "tolfun": 0,
        "tolfunhist": 0,
        "tolx": 0,
        "tolstagnation": max_gens + 1,
        "tolxstagnation": False,
    }
    mean = np.zeros(n_genes) if x0 is None else np.asarray(x0, np.float64)
    return cma.CMAEvolutionStrategy(mean, sigma0, opts)


class _Evolution:
    """One pycma evolution with our bookkeeping (best so far, stall, generations)."""

    def __init__(self, n_genes, popsize, sigma0, seed, max_gens, x0=None):
        self.es = _cma(n_genes, popsize, sigma0, seed, max_gens, x0)
        self.best_u, self.best_f = np.zeros(n_genes), np.inf
        self.stall = self.generation = 0
        self.popsize = popsize

    def generation_step(self, fitness) -> None:
        pop = self.es.ask()
        fit = [fitness(u) for u in pop]  # one candidate at a time
        self.es.tell(pop, fit)
        self.generation += 1
        i = int(np.argmin(fit))
        if fit[i] < self.best_f:
            self.best_u, self.best_f, self.stall = np.asarray(pop[i]), fit[i], 0
        else:
            self.stall += 1

    @property
    def evaluations(self) -> int:
        return self.generation * self.popsize


def _evolve(fitness, n_genes, popsize, sigma0, seed, max_gens, stop, x0=None):
    """ask/tell from the mean ``x0`` (None: 0) until ``stop(best, stall,
    generation)`` or pycma stops.

    Returns (best_u, best_f, generations, evaluations)."""
    evo = _Evolution(n_genes, popsize, sigma0, seed, max_gens, x0)
    while not evo.es.stop():
        evo.generation_step(fitness)
        if stop(evo.best_f, evo.stall, evo.generation):
            break
    return evo.best_u, evo.best_f, evo.generation, evo.evaluations


class Stepper:
    """A simulator's step as (state, features, violation) with or without
    feasibility, and the fitness rules that go with it."""

    def __init__(self, c_sim, tolerance):
        self.sim, self.tol = c_sim, float(tolerance)
        self.feas = c_sim.feas if isinstance(c_sim, FeasibleMarker) else None
        self.lower, self.upper = c_sim.lower, c_sim.upper

    def step(self, state, q):
        if self.feas is None:
            state, feats = self.sim.step(state, q)
            return state, feats, 0.0
        return self.sim.step(state, q)

    def least_motion(self, state, q, err):
        if self.feas is None or not err < self.tol:
            return err
        m = float(np.linalg.norm(q - state[0]))
        return self.tol * m / (m + 1.0)

    def penalized(self, f, v):
        return f if self.feas is None else self.feas.penalized(f, v)

    def point_fitness(self, state, g, prefix_sq=None):
        """Fitness of normalized genes (DoF,) stepped to from ``state``: the
        distance of the features to ``g`` (least motion below the tolerance), with
        ``prefix_sq`` ``sqrt(prefix_sq + error^2)``, penalized when infeasible
        (`cgda_jax.strategies.base.PlanBase.point_fitness`)."""

        def fitness(u):
            q = to_joints(u, self.lower, self.upper)
            _, feats, v = self.step(state, q)
            err = self.least_motion(state, q, float(np.linalg.norm(feats - g)))
            f = err if prefix_sq is None else float(np.sqrt(prefix_sq + err**2))
            return self.penalized(f, v)

        return fitness

    def execute(self, joints):
        """(features (N, F), summed violation) from the start."""
        if self.feas is None:
            return self.sim.execute(joints), 0.0
        return self.sim.execute(joints)

    def outcome(self, joints, goal, extra=None) -> dict:
        feats, violation = self.execute(joints)
        errors = np.linalg.norm(feats - goal, axis=-1)
        out = {"success": bool(np.all(errors < self.tol) and violation == 0.0),
               "point_errors": errors, "feasibility": self.feas is not None}
        if self.feas is not None:
            out["violation"] = float(violation)
        return {**out, **(extra or {})}


def pycma_ie(c_sim, goal, popsize, tolerance, max_gens, seed=0, sigma0=1.0) -> dict:
    """IE: fitness = distance of the features after one step to the candidate
    posture; without feasibility each point evolved on its own from the start (one
    after the other), with it in lock-step from the bests before it."""
    sim = Stepper(c_sim, tolerance)
    lo, hi = sim.lower, sim.upper
    goal = np.asarray(goal, np.float64)
    if sim.feas is not None:
        return _ie_sequential(sim, goal, popsize, max_gens, seed, sigma0)
    start = c_sim.init_state()
    postures, evals, gens = [], 0, []
    for i, g in enumerate(goal):

        def fitness(u, g=g):
            return float(np.linalg.norm(c_sim.step(start, to_joints(u, lo, hi))[1] - g))

        u, _, n_gen, n_eval = _evolve(
            fitness, len(lo), popsize, sigma0, seed + 1000 * i, max_gens,
            lambda f, stall, gen: f < tolerance or gen >= max_gens)
        postures.append(to_joints(u, lo, hi))
        evals += n_eval
        gens.append(n_gen)
    return sim.outcome(np.array(postures), goal,
                       {"evaluations": evals, "generations": int(max(gens))})


def _ie_sequential(sim, goal, popsize, max_gens, seed, sigma0) -> dict:
    """IE with feasibility: the points' evolutions in lock-step (IEPlan.step), at
    most ``max_gens`` generations of the run (runner.drive's bound)."""
    lo, hi, tol = sim.lower, sim.upper, sim.tol
    n = len(goal)
    evos = [_Evolution(len(lo), popsize, sigma0, seed + 1000 * i, max_gens)
            for i in range(n)]

    for _ in range(max_gens):  # ours: generations of the run <= max_gens
        # where the current bests leave the arm, and each best re-scored there
        state, states = sim.sim.init_state(), []
        for e, g in zip(evos, goal):
            states.append(state)
            state, feats, v = sim.step(state, to_joints(e.best_u, lo, hi))
            err = sim.penalized(float(np.linalg.norm(feats - g)), v)
            if np.isfinite(e.best_f):
                e.best_f = err if np.isfinite(err) else np.inf
        done = [e.best_f < tol or e.generation >= max_gens for e in evos]
        for e, g, st, d in zip(evos, goal, states, done):
            if not d:
                e.generation_step(sim.point_fitness(st, g))
        if all(e.best_f < tol or e.generation >= max_gens for e in evos):
            break
    joints = np.array([to_joints(e.best_u, lo, hi) for e in evos])
    return sim.outcome(joints, goal, {
        "evaluations": sum(e.evaluations for e in evos),
        "generations": max(e.generation for e in evos)})


def pycma_fte(
    c_sim, goal, popsize, tolerance, max_gens, stagnation=10, seed=0, sigma0=1.0
) -> dict:
    """FTE: one evolution over all N x DoF genes, fitness = the paper's DTW score
    (dtaidistance C) of the whole executed trajectory (penalized when infeasible)."""
    sim = Stepper(c_sim, tolerance)
    lo, hi = sim.lower, sim.upper
    n, dof = goal.shape[0], len(lo)
    goal = np.asarray(goal, np.float64)

    def fitness(u):
        feats, v = sim.execute(to_joints(np.reshape(u, (n, dof)), lo, hi))
        return sim.penalized(dtai_pair(feats, goal), v)

    u, best, gens, evals = _evolve(
        fitness, n * dof, popsize, sigma0, seed, max_gens,
        lambda f, stall, gen: stall >= stagnation or gen >= max_gens)
    return sim.outcome(to_joints(np.reshape(u, (n, dof)), lo, hi), goal, {
        "evaluations": evals, "generations": gens, "final_fitness": best})


def pycma_iet(c_sim, goal, popsize, tolerance, max_gens, seed=0, sigma0=1.0,
              stagnation=None, restarts=0, backtracks=0) -> dict:
    """IET: point i evolved with points 0..i-1 frozen, fitness = the distance of
    executed features 0..i to goal 0..i; the state reached by the frozen prefix is
    carried (one step per candidate), as cgda_jax does.  A point's evolution stops
    when its own error is below the tolerance (fitness^2 - prefix), after
    ``max_gens`` or ``stagnation`` generations without improvement (None: never).

    A point that missed is evolved again (``restarts`` times, each from a random
    mean, the best over its tries kept), then the run backtracks (``backtracks``
    per run: the k-th backtrack in a row from the same point re-evolves from k
    points back, with fresh random means), as `cgda_jax.strategies.iet.IETPlan`
    does (its restart means: random, as ours on a stateful scene such as paint,
    which samples none); a point that still misses when both are spent is
    committed with its best.  0 and 0: the paper's Algorithm 1."""
    sim = Stepper(c_sim, tolerance)
    lo, hi = sim.lower, sim.upper
    goal = np.asarray(goal, np.float64)
    n = len(goal)
    states, prefix = [c_sim.init_state()] + [None] * n, [0.0] + [0.0] * n
    joints, point_fitness = np.zeros((n, len(lo))), np.full(n, np.inf)
    point_times, evals = [0.0] * n, 0
    tries, i, restart, used, stuck, depth = [0] * n, 0, 0, 0, -1, 0
    best_u, best_f = None, np.inf
    while i < n:
        t0, t, g, prefix_sq = time.perf_counter(), tries[i], goal[i], prefix[i]
        tries[i] += 1
        x0 = None if t == 0 else np.random.default_rng(
            (seed, i, t)).uniform(-1.0, 1.0, len(lo))

        def stop(f, stall, gen, prefix_sq=prefix_sq):
            return (f**2 - prefix_sq < tolerance**2 or gen >= max_gens
                    or (stagnation is not None and stall >= stagnation))

        u, f, _, n_eval = _evolve(sim.point_fitness(states[i], g, prefix_sq),
                                  len(lo), popsize, sigma0,
                                  seed + 1000 * i + 100_000 * t, max_gens, stop, x0)
        evals += n_eval
        if restart == 0 or f < best_f:  # a restart keeps the point's best try
            best_u, best_f = u, f
        q = to_joints(best_u, lo, hi)
        state, feats, _ = sim.step(states[i], q)
        own_sq = float(np.sum((feats - g) ** 2))
        point_times[i] += time.perf_counter() - t0
        if own_sq >= tolerance**2 and restart < restarts:
            restart += 1
            continue
        if own_sq >= tolerance**2 and i > 0 and used < backtracks:
            depth = depth + 1 if stuck == i else 1
            used, stuck, restart = used + 1, i, 0
            i = max(i - depth, 0)
            continue
        states[i + 1], prefix[i + 1] = state, prefix_sq + own_sq
        joints[i], point_fitness[i] = q, best_f
        i, restart = i + 1, 0
    return sim.outcome(joints, goal, {
        "evaluations": evals, "point_times_s": point_times,
        "point_fitness": point_fitness, "tries": tries, "backtracks_used": used})
