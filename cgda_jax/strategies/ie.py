"""Individual Evolution (IE, paper 3.2): every goal point evolved on its own, all at once.

Each point i has its own evolution of DoF genes; its fitness is the Euclidean distance
between the features reached by moving from the start state to the candidate posture
and goal point i. The N evolutions are independent, so they run as ONE batched
evolution (`vmap` over points); each point stops when its error drops below
`tolerance` (or at `max_generations`) and is frozen from then on.

Points are only independent when a step's features do not depend on where it starts:
kinematic mode with a scene that carries no state (the marker).  Otherwise (dynamic
mode: the arm moves from the previous posture and may not have settled; a scene with
state, e.g. a painted wall) every generation first executes the current best
postures of all points in order, from the start (one sequential rollout of N
waypoints), and evaluates point i's candidates from the state reached after points
0..i-1, the way the final sequential execution will run them; each point's best is
re-scored in that context before the stop test.  ``info["sequential_context"]`` says
which variant ran.

The sequential context (`IEPlan.contexts`, `IEPlan.rescore`): each generation first
executes the current best postures of all points in order from the start (one
rollout of N waypoints), so that point i's candidates are evaluated from the state
after points 0..i-1, and re-scores each point's best where its predecessors now
leave it before the stop test.

With feasibility the rollout does not judge its moves: `IEPlan.judged_generation`
evaluates every point's candidates and, first in each row, its current best in one
batched call, so that the move's judgement (the collision check, the most expensive
code to compile) appears once in the generation's program, not once more in the
rollout (clean_ie's chunk: 287 XLA fusions instead of 368).  The values are those of
judging the rollout's moves: the same move from the same state.  The violations of
the bests' moves are kept (``IEState.judged_u``, ``judged_violation``), and the run is
done only when the kept ones are the current bests' (`IEState.fresh`): the result's
execution then takes them (`IEPlan.judged_execution`) and the finish program carries
no collision check either.  A run its generation budget cuts before they are fresh is
judged again on the host (`cgda_jax.strategies.base.PlanBase.rejudge`).

Backtracks (`IESettings.backtracks`, `IEPlan.backtrack`): in the sequential context a
point that met its goal fixes where the next point starts; when the next one's tries
all miss, the points before it are reopened (IET's rule, `backtrack_to`) and evolved
again from random means, inside the same compiled step (the state's shapes do not
change: per-point budgets ``IEState.entered`` and a backtrack count).

Pooled points (`IEPool`, `IEPlan.pool_step`): with independent points the batched
trials of `cgda_jax.strategies.runner.drive_ie_points` run the (trial, point)
evolutions still going as one pool, each point's restarts started from its
neighbours' bests as in a single run (`better_neighbour`).
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
    from_joints,
    points_independent,
    ragged_rows,
)
from cgda_jax.strategies.evolution import evolution_ask, evolution_tell
from cgda_jax.strategies.fitness import distances
from cgda_jax.strategies.refine import REFINE, nearest_samples, polish, reachability
from cgda_jax.strategies.settings import Settings, option

__all__ = ["BACKTRACKS", "LOCAL_STD", "RESTARTS", "RESTART_SAMPLES", "SAMPLE_WIDTH",
           "STAGNATION", "IEPlan", "IEPool", "IESettings", "IEState", "backtrack_to",
           "better_neighbour", "point_keys", "position_kinematics"]

#: Default restarts of a point and generations without improvement that stop a try.
RESTARTS = 9
STAGNATION = 40
#: Default backtracks per run (IE with the sequential context; IET's too).
BACKTRACKS = 8
#: Initial search width of a local restart (from a sampled or a neighbour's
#: posture), relative to the algorithm's own (distribution-based algorithms).
LOCAL_STD = 0.15
#: Postures sampled (one batched kinematics call per run) to seed the restarts.
RESTART_SAMPLES = 4096
#: `IESettings.sample_positions` with `warm_start`: the samples' spread around the
#: start posture (share of each joint's half range).
SAMPLE_WIDTH = 0.3


def backtrack_to(point: jax.Array, stuck: jax.Array, depth: jax.Array
                 ) -> tuple[jax.Array, jax.Array]:
    """The backtrack rule of IE (sequential context) and IET: ``point`` missed
    its tolerance after every try, ``stuck`` is the point that made the last
    backtrack and ``depth`` how many points back it went.  The k-th backtrack in a
    row from the same point goes k points back (re-evolving only the previous
    point rarely changes what is left: where the arm stands, what remains
    unpainted).  Returns the first point to evolve again (>= 0) and the new
    depth."""
    depth = jnp.where(stuck == point, depth + 1, 1)
    return jnp.maximum(point - depth, 0), depth


def point_keys(key: jax.Array, n_points: int) -> jax.Array:
    """The per-point keys (N,) IE derives from a run's key: ``fold_in(key, i)``."""
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(n_points))


@struct.dataclass
class IEState:
    """Carry of an IE run (every field stacked over the N points).

    Attributes:
        evo: the current try of each point.
        keys: the point keys; try t > 0 uses ``fold_in(key, t)``.
        samples: (N, K, D) the K sampled postures nearest each goal point (nearest
            first; K = 0 without restart samples), restart means.
        tries: tries started per point (1 + restarts used).
        best_u, best_fitness: the best over every try (inf: nothing valid yet).
        done: the point is finished (tolerance met, or out of tries).
        generations, evaluations, invalid: spent by the finished tries.
        judged_u, judged_violation: with feasibility (sequential context): the
            bests the last generation judged in context and their moves'
            violations (`IEPlan.judged_generation`); None otherwise.
        chain_u, chain_error, chain_violation: with the sequential context, the
            bests of the generation whose in-order execution had the lowest
            largest point error, its errors (N) and (with feasibility) its moves'
            violations (N) (`IEPlan.keep_chain`); None otherwise.
        entered: with backtracks (`IESettings.backtracks`, sequential context):
            the tries each point had started when a backtrack last gave it a
            new budget (0: never); its restarts count from there.  None
            otherwise.
        backtracks, stuck, depth: with backtracks: backtracks spent, the point
            that made the last one (-1: none) and how many points back it went
            (`backtrack_to`); None otherwise.
    """

    evo: Evolution
    keys: jax.Array
    samples: jax.Array
    tries: jax.Array
    best_u: jax.Array
    best_fitness: jax.Array
    done: jax.Array
    generations: jax.Array
    evaluations: jax.Array
    invalid: jax.Array
    judged_u: jax.Array | None = None
    judged_violation: jax.Array | None = None
    chain_u: jax.Array | None = None
    chain_error: jax.Array | None = None
    chain_violation: jax.Array | None = None
    entered: jax.Array | None = None
    backtracks: jax.Array | None = None
    stuck: jax.Array | None = None
    depth: jax.Array | None = None

    def fresh(self) -> jax.Array:
        """Whether the last judged bests (``judged_u``) are the current ones: their
        stored violations are then those of executing the result."""
        return jnp.all(self.judged_u == self.best_u)


def better_neighbour(prev_u: jax.Array, prev_f: jax.Array, next_u: jax.Array,
                     next_f: jax.Array) -> jax.Array:
    """(N, D) the best genes of each point's better-solved neighbour (previous or
    next, the one with the lower error ``prev_f`` / ``next_f`` (N)); NaN where
    neither has a valid one (both errors inf)."""
    u = jnp.where((prev_f <= next_f)[:, None], prev_u, next_u)
    ok = jnp.isfinite(jnp.minimum(prev_f, next_f))
    return jnp.where(ok[:, None], u, jnp.nan)


@struct.dataclass
class IEPool:
    """IE points gathered from several trials (`IEPlan.pool_step`): `IEState`
    fields (P, ...) plus each point's goal and its neighbours (position in the pool,
    or -1 and their frozen best genes and fitness; inf / NaN where there is no
    neighbour)."""

    s: IEState
    goal: jax.Array
    prev_pos: jax.Array
    next_pos: jax.Array
    prev_u: jax.Array
    prev_f: jax.Array
    next_u: jax.Array
    next_f: jax.Array


@dataclasses.dataclass(frozen=True, kw_only=True)
class IESettings(Settings):
    """IE's settings (beyond `Settings`'s: algorithm, population_size per point,
    tolerance, max_generations per point's try, chunk_size, aim, ...).

    Attributes:
        restarts: a point whose try stopped above the aim (budget spent or
            stalled) is tried again with a fresh key, up to this many times (inside
            the compiled step); the best over its tries is kept and
            ``info["point_tries"]`` says how many it took. Restart t starts
            (cycling) from the sampled posture nearest the goal point (see
            `restart_samples`), a better-solved neighbour's best posture, or a
            random mean (without samples: neighbour and random alternately); see
            `IEPlan`.
        backtracks: with the sequential context (point i evolved from where
            points 0..i-1 leave the arm: feasibility on, dynamic mode or a scene
            with state), a point whose tries all stopped short of the tolerance,
            every point before it having met its own, reopens earlier points, up
            to this many times per run: the k-th backtrack in a row from the same
            point reopens the k points before it (IET's rule, `backtrack_to`).
            Their bests are discarded and each is evolved again from a random
            mean with the full search width (so it may settle in another branch
            of the arm's inverse kinematics); the missed point and those after it
            get a new budget of tries and evolve on from where the reopened points
            now leave the arm.  ``info["backtracks_used"]`` says how many were
            spent.  0: a missed point stays missed.  Independent points (no
            sequential context) never backtrack.
        stagnation: a try stops after this many generations without improvement
            (None: only at `max_generations`), so a stuck point restarts early.
        restart_samples: with independent points (kinematic mode, stateless
            scene) and restarts > 0, this many postures drawn uniformly in the joint
            limits are evaluated once per run (one batched kinematics call, inside
            the compiled init) and the nearest to each goal point is a restart mean:
            a point stuck in a local minimum restarts in the goal's basin. 0: off.
        warm_start: every point's first try searches locally (initial width
            `LOCAL_STD`) around the start posture (where the arm is before the
            approach) instead of over the whole joint ranges from their middle
            (restarts as without it).  All points then start in the same branch of
            the arm's inverse kinematics, so in dynamic mode each point's posture
            is a short move from its neighbour's, within the speed limits (a
            7-joint arm's clean circle: 13-19 generations against 74-120 without).
        refine: "none" (default), "adam" or "lbfgs": after evolution, polish every
            point's best posture by gradient descent through the differentiable
            kinematic simulator (optax, `cgda_jax.strategies.refine.polish`),
            keeping the best iterate (never worse).
        refine_steps: optimiser steps of the polish.
        reach_check: before evolving, sample 2,048 postures (one batched
            kinematics call) and descend from the nearest ones; points no posture
            brings within `tolerance` are not evolved (no budget spent) and listed
            in ``info["unreachable_points"]`` with their nearest approach.
            `refine` and `reach_check` need kinematic mode and a stateless scene.
        sample_positions: dynamic mode with the sequential context and an object
            scene's sensor features (e.g. a tool point and a wrist force): the
            restart samples (`restart_samples` postures; around the start
            posture, +- `SAMPLE_WIDTH` of each joint's half range, with
            `warm_start`) are placed by kinematics alone and the nearest to each
            goal point by the position-like columns only (sites', bodies' and
            joints' positions; not forces, which need the physics): the tool put
            where the goal point puts it, a local restart there finds the force.
            Only for features of the robot and what it carries (an object it
            pushes is not where kinematics puts it).
        check_finer: dynamic mode with the sequential context: each generation
            the current bests are also executed in order at ``timestep /
            check_finer`` (`Simulator.finer`, MuJoCo C, the replay check's
            physics), and each point's error is the larger of the two (its
            re-score, the stop test, the kept chain, the result's choice): a best
            whose features depend on the physics step (a contact the coarse step
            resolves differently) is not met, and its evolution goes on.  0: off.
        keys: optional explicit per-point keys (N,) replacing the seed's (to re-run
            one point of a batched run alone; Python callers only).
    """

    restarts: int = option(RESTARTS, "int", 0)
    backtracks: int = option(BACKTRACKS, "int", 0)
    stagnation: int | None = option(STAGNATION, "int", 1, none=True)
    restart_samples: int = option(RESTART_SAMPLES, "int", 0)
    warm_start: bool = option(False, "bool")
    refine: str = option("none", "choice", REFINE)
    refine_steps: int = option(100, "int", 1)
    reach_check: bool = option(False, "bool")
    sample_positions: bool = option(False, "bool")
    check_finer: int = option(0, "int", 0)
    keys: jax.Array | None = option(None, "api", none=True)


def position_kinematics(sim) -> tuple[np.ndarray, Any]:
    """`IESettings.sample_positions`: the columns of ``sim``'s features that
    kinematics gives (its sensor features' positions: not forces or torques) and a
    function of joints (S, DoF) -> those columns (S, C) by ``mjx.kinematics`` of
    the robot's world model.

    Raises:
        ValueError: not dynamic mode with object-scene sensor features, or none of
            them is a position.
    """
    from cgda_jax.sim.features import FeatureSet

    fset = getattr(getattr(sim, "physics", None), "features", None)
    if getattr(sim, "mode", "kinematic") != "dynamic" or fset is None:
        raise ValueError("sample_positions needs dynamic mode and an object scene's "
                         "features (e.g. a tool site's xyz beside a wrist force)")
    cols, start, kept = [], 0, []
    for spec in fset.specs:
        n = len(spec.columns())
        if not spec.is_wrench:
            cols += range(start, start + n)
            kept.append(spec)
        start += n
    if not kept:
        raise ValueError("sample_positions: no feature is a position (all forces "
                         "or torques)")
    robot = sim.robot
    kin = FeatureSet(robot.mj_model, kept)
    robot.make_data()  # the device model and template, outside any trace

    def positions(joints):
        return jax.vmap(lambda q: kin.from_data(robot.kinematics_data(
            robot.qpos(q))))(joints)

    return np.asarray(cols, np.int32), positions


class IEPlan(PlanBase):
    """IE as a plan for `runner.drive` (see there), built from `IESettings` (or
    its fields as keywords, changing the defaults); ``info`` extends its
    ``info``, ``sharding`` splits each generation's population (`PlanBase`).
    Restart means: see `_try`.
    """

    name = "ie"
    per_point = True

    def __init__(self, sim, goal, settings: IESettings | None = None, *,
                 info=None, sharding=None, **changes):
        st = IESettings.of(settings, **changes)
        keys, refine, reach_check = st.keys, st.refine, st.reach_check
        if keys is not None and keys.shape[0] != goal.shape[0]:
            raise ValueError(
                f"keys has {keys.shape[0]} entries for {goal.shape[0]} points"
            )
        # with feasibility the moves between points count: point i is evolved from
        # where points 0..i-1 leave the arm, like the final execution
        feasible_moves = getattr(sim, "feasibility", None) is not None
        self.sequential = not points_independent(sim) or feasible_moves
        if not points_independent(sim) and (refine != "none" or reach_check):
            raise ValueError(
                "refine and reach_check need independent points: kinematic mode and a "
                "scene without state (e.g. the marker); this simulator is "
                f"{getattr(sim, 'mode', '?')} with {type(sim.scene).__name__}")
        info = {**(info or {}), "sequential_context": self.sequential,
                "refine": refine}
        super().__init__(sim, goal, int(sim.n_dof), st, info=info, sharding=sharding)
        warm_start, restarts = st.warm_start, st.restarts
        refine_steps = st.refine_steps
        self.keys = keys
        self.warm_start = bool(warm_start)
        self.info["warm_start"] = self.warm_start
        self.refine, self.refine_steps = refine, int(refine_steps)
        self.restarts = int(restarts)
        # sampled restart means need postures whose features do not depend on the
        # context (independent features; with feasibility the move to them is still
        # judged in context) and at least one restart to use them
        self.restart_samples = self.sampled_postures(st, sim)[0]
        #: sample_positions: the goal's position-like columns and their kinematics
        self.position_columns, self._positions = None, None
        if st.sample_positions:
            self.position_columns, self._positions = position_kinematics(sim)
        self.finer = None  # the finer simulator the bests are judged on too
        if st.check_finer:
            if getattr(sim, "mode", "kinematic") != "dynamic" or not self.sequential:
                raise ValueError(
                    "check_finer needs dynamic mode (a physics step to refine); this "
                    f"simulator is {getattr(sim, 'mode', '?')}")
            if st.check_finer < 2:
                raise ValueError(f"check_finer must be 0 (off) or >= 2 (the step "
                                 f"divided by it), got {st.check_finer}")
            self.finer = sim.finer(int(st.check_finer))
            self.info["check_finer"] = int(st.check_finer)
        #: backtracks per run: only points evolved in sequence have a prefix to go
        #: back to (`backtrack`)
        self.backtracks = int(st.backtracks) if self.sequential else 0
        self.n_nearest = min(self.restart_samples, max(1, (self.restarts + 1) // 2))
        self.max_generations_total = (self.max_generations * (1 + self.restarts)
                                      * (1 + self.backtracks))
        self.unreachable = np.zeros(self.n_points, bool)
        self.reach_genes = np.zeros((self.n_points, self.n_dof), np.float32)
        self.reach_nearest = np.full(self.n_points, np.inf, np.float32)
        if reach_check:
            reach = reachability(sim, goal, self.tolerance)
            self.unreachable[reach["unreachable"]] = True
            self.reach_genes = reach["genes"].astype(np.float32)
            self.reach_nearest = reach["nearest"].astype(np.float32)
            self.info["reach_check_s"] = reach["seconds"]
            self.info["unreachable_points"] = [
                {"index": i, "nearest_approach": float(reach["nearest"][i])}
                for i in reach["unreachable"]]

    @classmethod
    def sampled_postures(cls, settings: IESettings, sim) -> tuple[int, str]:
        """``restart_samples`` with independent points (or IE's `sample_positions`;
        IET's settings have none) and a restart to use them, else none (see
        `PlanBase.sampled_postures`)."""
        placed = points_independent(sim) or getattr(settings, "sample_positions",
                                                     False)
        use = placed and int(settings.restarts) > 0
        return int(settings.restart_samples) if use else 0, "restart_samples"

    def point_stop(self, evo: Evolution) -> jax.Array:
        """One try of a point stops: tolerance met, its budget spent, or stalled."""
        return self.stop(evo) | self.stalled(evo)

    def _try(self, key, goal_point, state, t, neighbour_u=None, samples=None,
             reopened=None):
        """Try ``t`` of a point. Try 0 starts from the mid-range mean (with
        `warm_start`: a local search at the start posture) with the point key;
        restart ``t > 0`` uses key ``fold_in(key, t)``. With restart samples,
        odd restarts start from the sampled postures nearest the goal point in turn
        (restart t from the (t-1)//2-th nearest: each near the goal, in whichever
        basin, whatever the previous tries converged to) and even restarts
        alternate between a solved neighbour's best genes (the goal curve is
        continuous, so a neighbour's posture is often in the right basin) and a
        random mean; without samples: neighbour, random, alternately.
        Without a solved neighbour a random mean replaces it. Sample and neighbour
        restarts search locally (initial std scaled by `LOCAL_STD`).  A point a
        backtrack ``reopened`` (bool) starts from a random mean, whole width."""
        k_mean, k_evo = jax.random.split(jax.random.fold_in(key, t))
        mean = jax.random.uniform(k_mean, (self.n_dof,), minval=-1.0, maxval=1.0)
        k = 0 if samples is None else samples.shape[0]
        restart = t > 0
        if k:  # odd restarts: the samples in turn; even: neighbour, random, ...
            use_sample = restart & ((t - 1) % 2 == 0)
            use_neighbour = restart & ((t - 1) % 4 == 1)
        else:  # alternate: neighbour, random
            use_sample, use_neighbour = jnp.bool_(False), restart & ((t - 1) % 2 == 0)
        if reopened is not None:  # `backtrack`: anywhere, another branch perhaps
            use_sample, use_neighbour = use_sample & ~reopened, use_neighbour & ~reopened
        if neighbour_u is None:
            use_neighbour = jnp.bool_(False)
        else:
            use_neighbour = use_neighbour & jnp.all(jnp.isfinite(neighbour_u))
            mean = jnp.where(use_neighbour, jnp.nan_to_num(neighbour_u), mean)
        if k:
            mean = jnp.where(use_sample, samples[jnp.clip((t - 1) // 2, 0, k - 1)],
                             mean)
        # a sampled or neighbouring posture is near a solution: search locally there
        local = use_sample | use_neighbour
        first = 0.0
        if self.warm_start:  # try 0: a local search from where the arm starts
            first = from_joints(self.sim.init_state().genes, self.lower, self.upper)
            local = local | ~restart
        mean = jnp.where(restart, mean, first)
        return self.start(jnp.where(restart, k_evo, key),
                          self.point_fitness(state, goal_point), mean=mean,
                          std_scale=jnp.where(local, LOCAL_STD, 1.0))

    def _neighbours(self, best_u, best_fitness):
        """(N, D) the best genes of each point's better-solved neighbour (i-1 or
        i+1, the one with the lower error); NaN where neither has a valid one."""
        inf = jnp.full((1,), jnp.inf)
        nan = jnp.full((1, self.n_dof), jnp.nan)
        return better_neighbour(
            jnp.concatenate([nan, best_u[:-1]]), jnp.concatenate([inf, best_fitness[:-1]]),
            jnp.concatenate([best_u[1:], nan]), jnp.concatenate([best_fitness[1:], inf]))

    def init(self, key):
        keys = point_keys(key, self.n_points) if self.keys is None else self.keys
        states, _ = self.contexts(jnp.zeros((self.n_points, self.n_dof)))
        zero = jnp.zeros((self.n_points,), jnp.int32)
        if self.restart_samples and self.position_columns is not None:
            around = None
            if self.warm_start:
                around = from_joints(self.sim.init_state().genes, self.lower,
                                     self.upper)
            samples, _ = nearest_samples(
                lambda u: self._positions(self.joints(u)),
                self.goal[:, self.position_columns],
                jax.random.fold_in(key, 2**31 - 1), self.n_dof, self.restart_samples,
                self.n_nearest, around=around, width=SAMPLE_WIDTH)
        elif self.restart_samples:  # one batched kinematics call (points independent)
            start = self.sim.init_state()
            samples, _ = nearest_samples(
                lambda u: self.point_features(start, u), self.goal,
                jax.random.fold_in(key, 2**31 - 1), self.n_dof, self.restart_samples,
                self.n_nearest)
        else:
            samples = jnp.zeros((self.n_points, 0, self.n_dof))
        evo = jax.vmap(self._try)(keys, self.goal, states, zero)
        # no posture reaches the unreachable points: keep the nearest approach
        off = jnp.asarray(self.unreachable)
        best_u = jnp.where(off[:, None], jnp.asarray(self.reach_genes), evo.best_u)
        best_f = jnp.where(off, jnp.asarray(self.reach_nearest), evo.best_fitness)
        return IEState(
            evo=evo.replace(done=evo.done | off), keys=keys, samples=samples,
            tries=zero + 1,
            best_u=best_u, best_fitness=best_f,
            done=(best_f < self.aim_tolerance) | off,
            generations=zero, evaluations=zero, invalid=zero,
            **({} if not self.judges_in_step else {
                "judged_u": jnp.full_like(best_u, jnp.nan),
                "judged_violation": jnp.full((self.n_points,), jnp.nan)}),
            **({} if not self.keeps_chain else {
                "chain_u": jnp.full_like(best_u, jnp.nan),
                "chain_error": jnp.full((self.n_points,), jnp.inf),
                "chain_violation": jnp.zeros((self.n_points,))}),
            **({} if not self.backtracks else {
                "entered": zero, "backtracks": zero[0], "stuck": zero[0] - 1,
                "depth": zero[0]}),
        )

    @property
    def judges_in_step(self) -> bool:
        """Feasibility with the sequential context: the bests' moves are judged
        with the candidates each generation (`judged_generation`)."""
        return self.sequential and self.feasibility is not None

    @property
    def finish_takes_judged(self) -> bool:
        """`judges_in_step` and no polish: the result's execution takes the
        kept judgements (`judged_execution`); a polish judges its
        postures in the finish."""
        return self.judges_in_step and self.refine == "none"

    @property
    def keeps_chain(self) -> bool:
        """The sequential context without a polish: the best in-order execution
        seen is kept (`keep_chain`) and replaces a failing result (`kept_chain`)."""
        return self.sequential and self.refine == "none"

    def done(self, s: IEState) -> jax.Array:
        """Every point finished (and, `finish_takes_judged`, its move judged as
        executed: `IEState.fresh`)."""
        if not self.finish_takes_judged:
            return jnp.all(s.done)
        return jnp.all(s.done) & s.fresh()

    def step(self, s: IEState):
        states, errors = self.contexts(s.best_u)
        asked, violation = None, None
        if self.judges_in_step:  # the bests' moves judged with the candidates
            errors, violation, asked = self.judged_generation(
                s.evo, s.best_u, states, s.judged_u, s.judged_violation)
            s = s.replace(judged_u=s.best_u, judged_violation=violation)
        if self.finer is not None:  # a best the finer step disagrees with: not met
            errors = jnp.maximum(errors, self.finer_errors(self.joints(s.best_u)))
        if self.keeps_chain:
            s = self.keep_chain(s, errors, violation)
        if self.sequential:  # re-score the bests where the others now leave them
            s, evo = self.rescore(s, errors)
        else:
            evo = s.evo
        if asked is None:
            evo, metrics = jax.vmap(
                lambda e, g, st: self.evolve(e, self.point_fitness(st, g),
                                             self.point_stop)
            )(evo, self.goal, states)
        else:
            evo, metrics = jax.vmap(
                lambda e, pop, a, f: evolution_tell(self.algo, self.params, e, pop,
                                                    a, f, self.point_stop)
            )(evo, *asked)
        s = self.settle(s, evo, self.goal, states, self._neighbours)
        return s, {"best_fitness": s.best_fitness, "invalid": metrics["invalid"],
                   "try": s.tries - 1}

    def settle(self, s, evo, goal, states, neighbours_of):
        """After a generation: keep each point's best over its tries, restart the
        tries that stopped short of the tolerance while tries are left (`_try`,
        starting from ``neighbours_of(best_u, best_fitness)`` or the sampled
        postures), and mark the points done. Shared by `step` and the pooled
        points of `pool_step` (``goal``, ``states``: per point)."""
        better = evo.best_fitness < s.best_fitness
        best_u = jnp.where(better[:, None], evo.best_u, s.best_u)
        best_f = jnp.where(better, evo.best_fitness, s.best_fitness)
        met = best_f < self.aim_tolerance
        # a try that stopped short of the tolerance restarts while tries are left
        again = evo.done & ~met & self.tries_left(s) & ~s.done
        reopened = renewed = None
        if self.backtracks:  # a missed point reopens the points before it
            s, reopened, renewed = self.backtrack(s, met | (evo.done & ~again),
                                                  best_f)
            again = again | reopened
        if self.restarts == 0 and reopened is None:  # never restarts: no trace
            fresh = evo
        else:
            neighbours = neighbours_of(best_u, best_f)
            fresh = jax.lax.cond(  # (population-based algorithms evaluate at start)
                jnp.any(again), lambda: jax.vmap(self._try)(
                    s.keys, goal, states, s.tries, neighbours,
                    s.samples if self.restart_samples else None, reopened),
                lambda: evo)
        if reopened is not None:  # their bests discarded: the new try's
            best_u = jnp.where(reopened[:, None], fresh.best_u, best_u)
            best_f = jnp.where(reopened, fresh.best_fitness, best_f)
            met = best_f < self.aim_tolerance
        s = s.replace(
            generations=s.generations + jnp.where(again, evo.generation, 0),
            evaluations=s.evaluations + jnp.where(again, evo.evaluations, 0),
            invalid=s.invalid + jnp.where(again, evo.invalid, 0),
            evo=jax.tree.map(
                lambda f, e: jnp.where(again.reshape((-1,) + (1,) * (e.ndim - 1)),
                                       f, e), fresh, evo),
            tries=s.tries + again, best_u=best_u, best_fitness=best_f)
        if renewed is None:
            return s.replace(done=met | (evo.done & ~again))
        # a missed point given new tries restarts next generation, in its new context
        return s.replace(done=met | (evo.done & ~again & ~renewed))

    def tries_left(self, s: IEState) -> jax.Array:
        """(N,) the points that may start another try (their budget: 1 +
        `restarts` tries, counted since a backtrack last renewed it)."""
        tries = s.tries if s.entered is None else s.tries - s.entered
        return tries <= self.restarts

    def backtrack(self, s: IEState, done: jax.Array, best_f: jax.Array
                  ) -> tuple[IEState, jax.Array, jax.Array]:
        """`IESettings.backtracks`: where the first point not finished within the
        tolerance (the points before it finished within it) is ``done`` (N,)
        with its tries spent and ``best_f`` (N) above the tolerance, and
        backtracks are left, the points `backtrack_to` names before it are
        reopened and every point from the first of them on gets a new budget of
        tries (`IEState.entered`; a try in progress counts as its first).
        Returns ``s`` with the backtrack counted, the reopened points (N,) (to
        evolve again from a random mean, their bests discarded: `settle`) and
        the renewed ones (N,); all False when no backtrack is made."""
        k = jnp.arange(self.n_points)
        settled = done & ((best_f < self.tolerance) | jnp.asarray(self.unreachable))
        i = jnp.argmax(~settled)  # the first point not settled (0: all are)
        go = done[i] & ~settled[i] & (i > 0) & (s.backtracks < self.backtracks)
        first, depth = backtrack_to(i, s.stuck, s.depth)
        reopened = go & (k >= first) & (k < i)
        renewed = go & (k >= first)
        s = s.replace(
            entered=jnp.where(renewed, s.tries - (~done).astype(s.tries.dtype),
                              s.entered),
            backtracks=s.backtracks + go.astype(s.backtracks.dtype),
            stuck=jnp.where(go, i, s.stuck), depth=jnp.where(go, depth, s.depth))
        return s, reopened, renewed

    def progress(self, s):
        gens = np.asarray(s.generations + s.evo.generation)
        return {  # generations: the slowest point's, as the result's
            "generations": gens.max(axis=-1).tolist(),
            "points_done": np.asarray(s.done).sum(axis=-1).tolist(),
            "points_met": (np.asarray(s.best_fitness) < self.tolerance
                           ).sum(axis=-1).tolist(),
            "worst_error": np.asarray(s.best_fitness).max(axis=-1).tolist(),
            **({} if getattr(s, "backtracks", None) is None else
               {"backtracks": np.asarray(s.backtracks).tolist()}),
        }

    def finish(self, s):
        found = jnp.isfinite(s.best_fitness)
        joints = jnp.where(found[:, None], self.joints(s.best_u), jnp.nan)
        if self.finish_takes_judged:
            executed = self.judged_execution(s, joints)
        else:
            executed = self.execution(joints)
        if self.keeps_chain:
            executed = self.kept_chain(s, executed)
        if self.refine != "none":
            u, _ = polish(self.sim, s.best_u, self.goal, method=self.refine,
                          steps=self.refine_steps)
            polished = self.execution(jnp.where(found[:, None], self.joints(u),
                                                joints))
            if "violation" in executed:  # kept only if the motion stays as feasible
                better = polished["violation"] <= executed["violation"]
                polished = jax.tree.map(lambda a, b: jnp.where(better, a, b),
                                        polished, executed)
            executed = polished
        return {
            **executed,
            "generation": s.generations + s.evo.generation,
            "evaluations": s.evaluations + s.evo.evaluations,
            "invalid": s.invalid + s.evo.invalid,
            "found": found,
            "tries": s.tries,
            **({} if s.backtracks is None else {"backtracks": s.backtracks}),
        }

    def to_result(self, final, history, timing):
        final = self.rejudge(final)
        gens = final["generation"]
        hist = history["best_fitness"].astype(np.float64)  # (G, N)
        rows = [hist[: int(g), i] for i, g in enumerate(gens)]
        return self.result(
            final, timing,
            fitness_history=ragged_rows(rows),
            evaluations=final["evaluations"].sum(),
            generations=gens.max(),
            point_generations=gens.tolist(),
            point_tries=final["tries"].tolist(),
            restarts=self.restarts, stagnation=self.stagnation,
            backtracks=self.backtracks,
            invalid_evaluations=final["invalid"].sum(),
            point_invalid=final["invalid"].tolist(),
            points_without_valid=np.flatnonzero(~final["found"]).tolist(),
            **({"kept_chain": bool(final["chain"])} if "chain" in final else {}),
            **({"backtracks_used": int(final["backtracks"])}
               if "backtracks" in final else {}),
        )

    # ---- the sequential context (see the module docstring)
    def contexts(self, best_u: jax.Array) -> tuple[Any, jax.Array | None]:
        """Start states of every point (stacked, N) and each point's error (N,) when
        ``self.joints(best_u)`` (N, DoF) are executed in order; independent points:
        the start state each and inf.  With feasibility the error is None: the moves
        are judged by `judged_generation`."""
        start = self.sim.init_state()
        if not self.sequential:
            states = jax.tree.map(
                lambda x: jnp.broadcast_to(x, (self.n_points, *jnp.shape(x))), start)
            return states, jnp.full((self.n_points,), jnp.inf)
        if self.feasibility is not None:
            return jax.lax.scan(lambda st, w: (self.advance(st, w)[0], st), start,
                                self.joints(best_u))[1], None

        def body(state, w):
            new, feats = self.sim.step(state, w)
            return new, (state, feats, new.move_violation)

        _, (states, feats, violation) = jax.lax.scan(body, start, self.joints(best_u))
        errors = self.penalize(distances(feats, self.goal), violation)
        return states, jnp.where(jnp.isfinite(errors), errors, jnp.inf)

    def finer_errors(self, joints: jax.Array) -> jax.Array:
        """(N,) each point's error when ``joints`` (N, DoF) are executed in
        order on the finer simulator (`IESettings.check_finer`; moves not judged:
        the coarse execution judges them); inf where not finite."""
        def step(state, w):
            return self.finer.step(state, w, judge=False)

        feats = jax.lax.scan(step, self.finer.init_state(), joints)[1]
        errors = distances(feats, self.goal)
        return jnp.where(jnp.isfinite(errors), errors, jnp.inf)

    def frozen(self, evo, best_u, judged_u, judged_violation) -> jax.Array:
        """(N,) the points whose generation changes nothing (ranked judging):
        its evolution done and its best and every earlier point's the ones
        the last generation judged (``judged_u``): the same move from the same
        state, so its violation is the stored one (``judged_violation``), its
        re-score the same and its evolution stays done (its candidates'
        fitness is told to a frozen evolution, unused): nothing is judged."""
        if judged_u is None:
            return jnp.zeros(best_u.shape[:1], bool)
        same = jnp.cumprod(jnp.all(best_u == judged_u, axis=-1)).astype(bool)
        return evo.done & same & jnp.isfinite(judged_violation)

    def judged_generation(self, evo, best_u: jax.Array, states, judged_u=None,
                          judged_violation=None):
        """One batched evaluation of every point's candidates (asked of ``evo``, N
        evolutions) with, first in each row, its best ``best_u`` (N, D) from its
        context ``states``.  Returns the bests' errors (N; inf where not finite),
        their moves' violations (N) and ``(populations (N, P, D), algorithm states,
        fitness (N, P))`` for `cgda_jax.strategies.evolution.evolution_tell`.
        With the last generation's ``judged_u`` and ``judged_violation`` (N),
        the `frozen` points are not judged again."""
        pops, algo_states = jax.vmap(
            lambda e: evolution_ask(self.algo, self.params, e))(evo)
        if self.judge_ranks is None:
            cands = jnp.concatenate([best_u[:, None], pops], axis=1)  # (N, P + 1, D)
            feats, violation = jax.vmap(
                lambda st, c: self.sharded(lambda u: self.point_outcome(st, u))(c)
            )(states, cands)
            fitness = jax.vmap(self.outcome_fitness)(states, pops, feats[:, 1:],
                                                     violation[:, 1:], self.goal)
        else:  # the bests judged with the candidates whose rank matters
            frozen = self.frozen(evo, best_u, judged_u, judged_violation)
            fitness, _, (feats, violation) = jax.vmap(
                lambda st, pop, g, b, z: self.ranked_outcome_with(st, pop, g, b,
                                                                  frozen=z))(
                states, pops, self.goal, best_u, frozen)
            if judged_violation is not None:  # frozen: the stored one
                violation = jnp.where(frozen, judged_violation, violation)
            feats, violation = feats[:, None], violation[:, None]
        errors = self.penalize(distances(feats[:, 0], self.goal),
                               violation[:, 0])
        return (jnp.where(jnp.isfinite(errors), errors, jnp.inf), violation[:, 0],
                (pops, algo_states, fitness))

    def judged_execution(self, s: IEState, joints: jax.Array) -> dict:
        """`PlanBase.execution` of the result ``joints`` (N, DoF; NaN where nothing
        was found) without a judgement of its own: the features of the unjudged
        rollout and the sum of the moves' violations the last generation stored
        (NaN where a point has no posture, as the judged rollout gives), and
        ``judged``: whether those are the current bests' (`IEState.fresh`; else
        `PlanBase.rejudge` on the host)."""
        found = jnp.all(jnp.isfinite(joints))
        return {"joints": joints, "features": self.executed_features(joints),
                "violation": jnp.where(found, jnp.sum(s.judged_violation), jnp.nan),
                "judged": s.fresh()}

    def keep_chain(self, s: IEState, errors: jax.Array,
                   violation: jax.Array | None) -> IEState:
        """``s`` with its bests kept as the chain (`IEState.chain_u`) where their
        in-order execution's ``errors`` (N, penalized; the moves' ``violation``
        (N) with feasibility) have a lower largest error than the kept chain's.

        A point evolves from where its predecessors' bests of the time leave the
        arm; a later try of a predecessor may change that state after the point
        was met (or ran out of tries), so the last generation's bests can execute
        worse than an earlier generation's did (`kept_chain`)."""
        better = jnp.max(errors) < jnp.max(s.chain_error)
        kept_v = s.chain_violation if violation is None else violation
        return s.replace(
            chain_u=jnp.where(better, s.best_u, s.chain_u),
            chain_error=jnp.where(better, errors, s.chain_error),
            chain_violation=jnp.where(better, kept_v, s.chain_violation))

    def kept_chain(self, s: IEState, executed: dict) -> dict:
        """The result's execution: ``executed`` (the last bests in order), or the
        kept chain's (`keep_chain`) where ``executed`` fails the tolerance and the
        chain's largest error is lower (its features from an unjudged rollout,
        its violation the one judged when it was kept).  ``chain``: whether the
        chain was taken.  A run that succeeds is never changed."""
        last = jnp.max(distances(executed["features"], self.goal))
        if "violation" in executed:
            last = self.penalize(last, executed["violation"])
        if self.finer is not None:  # judged as the chain was (`step`)
            found = jnp.all(jnp.isfinite(executed["joints"]))
            safe = jnp.where(found, executed["joints"], 0.0)
            last = jnp.maximum(last, jnp.where(
                found, jnp.max(self.finer_errors(safe)), jnp.inf))
        last = jnp.where(jnp.isnan(last), jnp.inf, last)
        chain_max = jnp.max(s.chain_error)
        use = (last >= self.tolerance) & (chain_max < last)
        joints = jnp.where(use, self.joints(s.chain_u), executed["joints"])
        chain = {"joints": joints,
                 "features": jnp.where(use, self.executed_features(joints),
                                       executed["features"])}
        if "violation" in executed:
            chain["violation"] = jnp.where(use, jnp.sum(s.chain_violation),
                                           executed["violation"])
        if "judged" in executed:
            chain["judged"] = use | executed["judged"]
        return {**executed, **chain, "chain": use}

    def rescore(self, s: IEState, errors: jax.Array):
        """The IE state ``s`` and its evolutions with each point's best re-scored to
        ``errors`` (N) (its error in the current context), the stop test redone."""
        evo = s.evo
        now = jnp.where(jnp.isfinite(s.best_fitness), errors, s.best_fitness)
        same = jnp.all(evo.best_u == s.best_u, axis=-1)
        evo = evo.replace(best_fitness=jnp.where(
            same & jnp.isfinite(evo.best_fitness), now, evo.best_fitness))
        evo = evo.replace(done=jax.vmap(self.point_stop)(evo))
        s = s.replace(best_fitness=now, done=(now < self.aim_tolerance)
                      | (evo.done & ~self.tries_left(s)))
        return s, evo

    # ---- pooled points of several trials (independent points)
    def pool_step(self, p: IEPool, block: int | None
                  ) -> tuple[IEPool, dict[str, jax.Array]]:
        """`step` (independent points) on a pool of points from several trials.

        With `block`, the evolutions (ask, evaluate, tell) run in ``ceil(P / block)``
        equal blocks one after the other (`lax.map`), not as one batch: on a CPU a
        simulator call of many thousand candidates outgrows the caches and costs
        about twice as much per candidate (measured, benchmarks/bench_trials.py).
        """
        s = p.s
        size = s.done.shape[0]
        start = self.sim.init_state()
        states = jax.tree.map(lambda x: jnp.broadcast_to(x, (size, *jnp.shape(x))),
                              start)

        def evolve(e, g, st):
            return jax.vmap(
                lambda e, g, st: self.evolve(e, self.point_fitness(st, g),
                                             self.point_stop)
            )(e, g, st)

        n_blocks = 1 if not block or size <= block else -(-size // block)
        if n_blocks == 1:
            evo, metrics = evolve(s.evo, p.goal, states)
        else:
            split = (lambda t: jax.tree.map(
                lambda x: x.reshape((n_blocks, size // n_blocks, *x.shape[1:])), t))
            evo, metrics = jax.lax.map(lambda a: evolve(*a),
                                       (split(s.evo), split(p.goal), split(states)))
            evo, metrics = jax.tree.map(lambda x: x.reshape((size, *x.shape[2:])),
                                        (evo, metrics))

        def neighbours_of(best_u, best_f):
            # the neighbours of `_neighbours`: in the pool, or frozen outside it
            def at(pos, inside, outside):
                mask = pos >= 0 if inside.ndim == 1 else (pos >= 0)[:, None]
                return jnp.where(mask, inside[jnp.maximum(pos, 0)], outside)

            return better_neighbour(
                at(p.prev_pos, best_u, p.prev_u), at(p.prev_pos, best_f, p.prev_f),
                at(p.next_pos, best_u, p.next_u), at(p.next_pos, best_f, p.next_f))

        s = self.settle(s, evo, p.goal, states, neighbours_of)
        return p.replace(s=s), {"best_fitness": s.best_fitness,
                                "invalid": metrics["invalid"], "try": s.tries - 1}

    @staticmethod
    def gather_pool(flat: IEState, goal, idx, prev_g, next_g, prev_pos, next_pos
                    ) -> IEPool:
        """The pool of the points ``idx`` of the flattened trials ``flat`` (R * N),
        their goal points and neighbours (``prev_g``/``next_g``: a point's
        neighbours in ``flat``, -1: none; ``prev_pos``/``next_pos``: in the pool)."""
        def nb(g):
            ok = g >= 0
            f = jnp.where(ok, flat.best_fitness[jnp.maximum(g, 0)], jnp.inf)
            u = jnp.where(ok[:, None], flat.best_u[jnp.maximum(g, 0)], jnp.nan)
            return u, f

        (pu, pf), (nu, nf) = nb(prev_g[idx]), nb(next_g[idx])
        return IEPool(s=jax.tree.map(lambda x: x[idx], flat), goal=goal[idx],
                      prev_pos=prev_pos, next_pos=next_pos, prev_u=pu, prev_f=pf,
                      next_u=nu, next_f=nf)
