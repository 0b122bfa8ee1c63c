"""Feasible motions: no penetration, joint speeds and accelerations within limits.

A success must be a motion the robot could perform (DESIGN 3, "Feasible motions").
`Feasibility` judges one move of the simulator, from posture ``q0`` to ``q1`` along
the sub-step postures ``path`` (K, DoF), timed as a minimum-jerk move of
``duration`` seconds:

- **penetration**: the worst signed distance between the robot's collision geoms
  and themselves / the world / the scene's obstacles (the paint board) along the
  move (`cgda_jax.sim.collision.Collider`), against ``penetration`` (default 5 mm).
  By default (``geometry="round"``) the moves are judged on the round geometry
  (`Collider` with ``rounded``): the moving geoms as capsules that hold them (TEO's
  hand box: two capsules), the still ones as closed-form shapes that hold them, so
  every pair is closed form and costs a few tens of nanoseconds; never more
  lenient than the geoms, at most `Collider.excess` stricter (37.5 mm for the
  hand, 0 for capsule pairs).  ``collider`` stays the exact one: the
  independent check of a result (`cgda_jax.sim.motion_check`) judges the geoms.
  The distances are taken at ``samples + 1`` postures equally spaced along the
  move (both ends included), and must stay ``margin`` (default 2 mm) above the
  limit, for what may pass between two samples: a move is infeasible when its
  deepest sampled penetration exceeds ``penetration - margin``.  With
  ``certify=True`` the check is a guarantee instead: between two samples ``k``,
  ``k + 1`` a pair's distance changes at most at the rate
  ``L = Collider.pair_reach @ |dq|`` (per unit of the move), so it stays above
  ``(d_k + d_k+1 - L / samples) / 2``, a lower bound of the distance on the whole
  continuous move.  The bound is far from tight on long moves near an obstacle:
  on TEO's paint board, of 60 moves that paint the hardest square without passing
  5 mm into the board (200 samples each) the bound at 10 samples accepts none,
  while 10 samples with the 2 mm margin accept 51 and let no move deeper than
  5 mm through, of 55,000 random moves (`benchmarks/RESULTS.md`, "Feasible
  motions").  The independent check of a result (`cgda_jax.sim.motion_check`) looks
  at four times as many postures;
- **no flailing**: no joint changes by more than ``max_step`` (90 degrees) between
  two waypoints (the approach excepted);
- **limits**: the move's peak joint speed ``1.875 |dq| / T`` and acceleration
  ``5.77 |dq| / T^2`` against the robot's limits (`cgda_jax.sim.limits`, `cgda_jax.sim.timing`);
- **what the physics executed** (dynamic mode, `executed`): the simulated postures
  of the move (``2 * samples + 1`` of its physics steps) against penetration as
  above, the tracking error of the evolved joints (simulated against commanded
  posture at every step) against ``tracking_deg`` and the share of the move's
  steps with an evolved joint's actuator force at its limit against
  ``saturation``: a commanded path can be clear while the arm, sagging or
  lagging behind it, passes through the board.

The violation of a move is a finite, dimensionless number, 0 when feasible:
``max(relu(peak / limit - 1) over joints and kinds, relu(depth - penetration) /
penetration, relu(max |dq| / max_step - 1))``, in dynamic mode also ``relu(depth'
- penetration) / penetration``, ``relu(tracking / tracking_deg - 1)`` and
``relu(share - saturation) / saturation`` of the executed motion.  The strategies add ``penalty * (1 +
violation)`` to an infeasible candidate's fitness
(`cgda_jax.strategies.fitness.penalized`), so evolution is pushed back into the feasible
region and an infeasible candidate never meets a tolerance.

Pairs are chosen once (`relevant_pairs`): a pair that already overlaps in the start
posture is a modelling overlap (links that meet at a joint) and is left out
(`Feasibility.overlapping`); a pair that cannot come into contact anywhere within
the joint limits (a lower bound over a grid of postures, bounded between the grid's
nodes as above) is left out as well.

The approach (the move from the start posture to the first waypoint) is part of the
execution and judged like every other move, over its own duration
`approach_s`: long enough for a move from the start to ANY posture within the
joint limits to respect the speed and acceleration limits
(`cgda_jax.sim.timing.approach_duration`), and never shorter than a waypoint's move.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax import Array

__all__ = ["CHUNK_MIN", "DEFAULT_MARGIN", "DEFAULT_PENALTY", "DEFAULT_PENETRATION",
           "DEFAULT_SATURATION", "DEFAULT_TRACKING_DEG", "EXECUTED_MARGIN",
           "GEOMETRIES", "PACKED_MIN", "PROVEN", "Feasibility", "relevant_pairs",
           "scene_obstacles"]

#: Grid postures `relevant_pairs` looks at (about; per joint: its root).
GRID_POSTURES = 4096

#: Penetration (m) below which a contact counts as touching, not passing through.
DEFAULT_PENETRATION = 0.005
#: How far (m) the sampled distances must stay above the penetration limit, for
#: what passes between two samples (`Feasibility`, ``certify=False``).
DEFAULT_MARGIN = 0.002
#: Dynamic mode: the largest tracking error of an evolved joint (simulated against
#: commanded posture at any physics step) [deg; a slide: mm] (`Feasibility.executed`).
#: TEO's 30 N m servos lag 17.6-26.2 deg behind the paint task's 0.6 s moves (the
#: limits bound a runaway; the simulated path's penetration is the safety check).
DEFAULT_TRACKING_DEG = 30.0
#: Dynamic mode: the largest share of a move's physics steps at which an evolved
#: joint's actuator force may sit at its limit (`Feasibility.executed`); TEO's
#: paint task: 49-72 % of its worst move.
DEFAULT_SATURATION = 0.75
#: Dynamic mode: the share of the tracking and saturation limits the search keeps
#: in hand (`Feasibility.executed`; the independent replay checks the full limits).
EXECUTED_MARGIN = 0.05
#: What the check's distances measure (`Feasibility`'s ``geometry``).
GEOMETRIES = ("round", "exact")
#: `Feasibility.moves`: metres by which a move's coarse bound must clear the
#: allowed depth to need no more samples (float32 distances err by ~1e-6 m).
PROVEN = 1e-4
#: `Feasibility.moves`: a batch of at most this many sampled postures is judged
#: at once, without the coarse-to-fine loop (paint IET's round of 20 moves: the
#: loop's iterations cost more than the postures they leave out).
PACKED_MIN = 512
#: `Feasibility.moves`: the coarse-to-fine loop takes at least this many
#: postures an iteration (all M moves' when fewer; clean IE's rounds of 189
#: moves: one iteration of 189 postures 20 % cheaper than two of 95).
CHUNK_MIN = 256
#: Fitness added to an infeasible candidate, times (1 + violation): larger than any
#: feature error of the experiments here (paint: 100 %, positions: metres).
DEFAULT_PENALTY = 1e3


def scene_obstacles(scene) -> list[dict]:
    """The obstacles a scene adds to the world (the paint board), as
    `cgda_jax.sim.collision.Obstacle` dicts; [] for scenes without."""
    board = getattr(scene, "board", None)
    return [] if board is None else [board]


class Feasibility:
    """Judges the simulator's moves: collisions along the path and joint limits.

    Args:
        robot: the `cgda_jax.sim.robot.Robot`.
        limits: its `cgda_jax.sim.limits.JointLimits`, or a mapping of overrides
            for `read_limits` (a config's ``[robot.limits]``); None: from the model.
        obstacles: extra world primitives (`cgda_jax.sim.collision.Obstacle` or
            their dict form: a scene's board).
        penetration: metres of penetration tolerated (touching).
        penalty: fitness added to an infeasible candidate, times (1 + violation).
        collisions: check penetration (False: limits only).
        self_collision: include the robot's own pairs.
        exclude: geom or obstacle names the collision check leaves out.
        samples: collision samples per move (plus its start posture).
        margin: metres the sampled distances must stay above ``-penetration``
            (0 <= margin < penetration; not used with ``certify``).
        certify: bound the distance between the samples (a guarantee, but far
            stricter than needed on long moves near obstacles) instead of the
            margin.
        max_step: the largest change of a joint (radians) between two waypoints
            (default 90 degrees; inf: no cap): a larger one is flailing, infeasible.
            The approach is not capped (its duration keeps it within the limits).
        physics_contacts: leave out the pairs that MuJoCo's physics collides
            (``contype``/``conaffinity``: a dynamic simulation keeps them apart
            itself, e.g. the hand pushing a box); False: every pair.
        tracking_deg: dynamic mode: the largest tracking error of an evolved
            joint [deg; a slide: mm] (`executed`).
        saturation: dynamic mode: the largest share of a move's physics steps
            with an evolved joint's force at its limit, in [0, 1] (`executed`).
        geometry: what the check measures: "round" (default) the robot's moving
            geoms as capsules that hold them and the still ones as closed-form
            shapes that hold them (`Collider` with ``rounded``; never more
            lenient, at most `Collider.excess` stricter), or "exact" the geoms
            themselves.

    Attributes:
        limits: the `cgda_jax.sim.limits.JointLimits` judged against.
        collider: the exact `cgda_jax.sim.collision.Collider` of the kept pairs
            (None without collisions or pairs): the independent motion check's.
        check: the `cgda_jax.sim.collision.Collider` the moves are judged with:
            ``collider`` itself, or its rounded twin (``geometry="round"``).
        geometry: "round" or "exact".
        penetration: metres of penetration tolerated.
        penalty: fitness added to an infeasible candidate, times (1 + violation).
        overlapping: pairs left out because they overlap in the start posture.
        physical: pairs left out because the physics collides them
            (``physics_contacts``).
    """

    def __init__(
        self,
        robot,
        limits: Any = None,
        obstacles: Sequence[Any] = (),
        *,
        penetration: float = DEFAULT_PENETRATION,
        penalty: float = DEFAULT_PENALTY,
        collisions: bool = True,
        self_collision: bool = True,
        exclude: Sequence[str] = (),
        samples: int = 10,
        physics_contacts: bool = False,
        max_step: float = math.pi / 2,
        margin: float = DEFAULT_MARGIN,
        certify: bool = False,
        tracking_deg: float = DEFAULT_TRACKING_DEG,
        saturation: float = DEFAULT_SATURATION,
        geometry: str = "round",
    ):
        from cgda_jax.sim.limits import JointLimits, read_limits

        if not (np.isfinite(penetration) and penetration > 0):
            raise ValueError(f"feasibility penetration must be > 0 metres, got "
                             f"{penetration}")
        if not (np.isfinite(penalty) and penalty > 0):
            raise ValueError(f"feasibility penalty must be > 0, got {penalty}")
        if not isinstance(limits, JointLimits):
            limits = read_limits(robot.mj_model, robot.joint_names, limits)
        self.limits = limits
        unlimited = limits.unlimited(effort=physics_contacts)  # dynamic: efforts too
        if unlimited:
            logging.getLogger("cgda_jax").warning("%s", unlimited)
        self.penetration = float(penetration)
        self.penalty = float(penalty)
        if int(samples) < 1:
            raise ValueError(f"feasibility samples must be >= 1, got {samples}")
        if not max_step > 0:
            raise ValueError(f"feasibility max_step must be > 0 radians, got {max_step}")
        self.max_step = float(max_step)
        self.samples = int(samples)
        if not (np.isfinite(margin) and 0 <= margin < penetration):
            raise ValueError(f"feasibility margin must be >= 0 and below the "
                             f"penetration ({penetration:g} m), got {margin}")
        self.margin = float(margin)
        self.certify = bool(certify)
        self._executed_limits(robot, tracking_deg, saturation)
        if geometry not in GEOMETRIES:
            raise ValueError(f"feasibility geometry must be one of {GEOMETRIES}, got "
                             f"{geometry!r}")
        self.geometry = geometry
        # as given (`cgda_jax.sim.description` writes them into a config)
        self.obstacles = list(obstacles)
        self.collisions, self.self_collision = bool(collisions), bool(self_collision)
        self.exclude = tuple(exclude)
        self.physics_contacts = bool(physics_contacts)
        self.collider = self.check = None
        self.overlapping: list[tuple[str, str]] = []
        self.physical: list[tuple[str, str]] = []
        if collisions:
            from cgda_jax.sim.collision import Collider, Obstacle

            obs = [o if isinstance(o, Obstacle) else Obstacle(**_obstacle_args(o))
                   for o in obstacles]
            args = {"self_collision": self_collision, "exclude": tuple(exclude)}
            full = Collider(robot, obs, **args)
            keep, self.overlapping = relevant_pairs(full, robot, obs)
            if physics_contacts:
                self.physical = [p for p in keep if _collides(robot.mj_model, *p)]
                keep = [p for p in keep if p not in self.physical]
            if keep:
                self.collider = self.check = Collider(robot, obs, only=keep, **args)
                if geometry == "round":
                    self.check = Collider(robot, obs, only=keep, rounded=True, **args)
                self._reach = np.asarray(self.check.pair_reach, np.float32)
        self._velocity = np.asarray(limits.velocity, np.float32)
        self._acceleration = np.asarray(limits.acceleration, np.float32)

    def __repr__(self) -> str:
        pairs = 0 if self.collider is None else self.collider.n_pairs
        check = "certify" if self.certify else f"margin={self.margin:g}"
        return (f"Feasibility(pairs={pairs}, penetration={self.penetration:g}, "
                f"samples={self.samples}, {check}, geometry={self.geometry}, "
                f"limits={self.limits!r})")

    def approach_s(self, robot, floor: float) -> float:
        """Duration (s) of the approach from the robot's start posture: a min-jerk
        move to any posture within the joint limits stays within the speed and
        acceleration limits (at least ``floor``)."""
        from cgda_jax.sim.timing import approach_duration

        return float(approach_duration(robot.lower, robot.upper, robot.start_genes,
                                       self.limits, floor))

    def limit_violation(self, dq: Array, duration: Array) -> Array:
        """Violation (scalar) of a min-jerk move of ``dq`` (DoF,) over ``duration``
        seconds against the speed and acceleration limits."""
        from cgda_jax.sim.timing import move_peaks, violation

        speed, acc = move_peaks(dq, duration)
        return violation(speed, acc, self.limits)

    def depth(self, q0: Array, dq: Array) -> Array:
        """The deepest penetration (m, >= 0) of the straight joint-space move from
        ``q0`` by ``dq`` (DoF,) each, at its samples (with ``certify``: a bound on
        the whole move; see the module doc)."""
        return jnp.maximum(self.worst(q0, dq), 0.0)

    def worst(self, q0: Array, dq: Array) -> Array:
        """Minus the smallest signed distance (m) of the move's pairs at its
        ``samples + 1`` postures, or with ``certify`` minus its lower bound on the
        whole move: > 0 penetrates, < 0 is the clearance."""
        if self.check is None:
            return jnp.float32(-jnp.inf)
        alphas = jnp.arange(self.samples + 1, dtype=jnp.float32) / self.samples
        path = q0 + alphas[:, None] * dq  # (S + 1, DoF)
        # the depth is what counts: with the exact geometry, separated box-box
        # and box-cylinder pairs get a lower bound of their distance
        # (Collider.distances); the round one is closed form throughout.  (The
        # start posture apart, computed once under a vmap over one state's
        # moves, saved ~4 % of a clean_ie generation but doubled the check's
        # compile time: a second copy of it; benchmarks/RESULTS.md)
        d = jax.vmap(self._distances)(path)
        if not self.certify:
            return -jnp.min(d)
        # between two samples h = 1/S apart the distance changes at most at the
        # rate L = reach @ |dq| per unit of the move: above (d_k + d_k+1 - L h) / 2
        rate = jnp.asarray(self._reach) @ jnp.abs(dq)  # (pairs,)
        low = 0.5 * (d[:-1] + d[1:] - rate / self.samples)  # (S, pairs)
        return -jnp.min(jnp.minimum(low, d[1:]))

    @property
    def allowed(self) -> float:
        """The deepest sampled penetration (m) a feasible move may have:
        ``penetration - margin`` (``penetration`` with ``certify``)."""
        return self.penetration - (0.0 if self.certify else self.margin)

    def move(self, q0: Array, dq: Array, duration: Array,
             approach: Array | bool = False) -> Array:
        """Violation (scalar, 0 = feasible) of one move from ``q0`` by ``dq``
        (DoF,) each in ``duration`` seconds (``approach``: the move from the start
        posture, which `max_step` does not cap)."""
        return self._violation(dq, duration, approach, self._penetration(q0, dq))

    def _penetration(self, q0: Array, dq: Array) -> Array:
        """The penetration term of `move` (scalar): the sampled depth past
        `allowed`, in units of ``penetration``."""
        return jnp.maximum(self.worst(q0, dq) - self.allowed, 0.0) / self.penetration

    def _violation(self, dq: Array, duration: Array, approach: Array | bool,
                   over: Array) -> Array:
        """`move`'s violation of one move from its penetration term ``over``: the
        largest of it, the speed/effort limits' and the flail (a step over
        `max_step`, the approach aside)."""
        flail = jnp.maximum(jnp.max(jnp.abs(dq)) / self.max_step - 1.0, 0.0)
        flail = jnp.where(approach, 0.0, flail)
        return jnp.maximum(jnp.maximum(self.limit_violation(dq, duration), over), flail)

    def moves(self, q0: Array, dq: Array, duration: Array, approach: Array,
              need: Array | None = None) -> Array:
        """`move` of M moves at once: violations (M,) of the moves from ``q0``
        by ``dq`` (M, DoF) in ``duration`` seconds (M,), ``approach`` (M,) as
        there; the same values, bit for bit, with fewer distances taken.  With
        ``need`` (M,) bool, the moves where it is False are not checked for
        collisions (their violation leaves the penetration out): for a caller
        that discards them.

        Coarse to fine (`_over_moves`): every needed move's distances first at
        three of its sampled postures (its ends and middle); between two of
        them ``h`` apart (a share of the move) a pair's distance is at least
        ``(d_k + d_k+1 - L h) / 2`` (``L = pair_reach @ |dq|``, as ``certify``
        bounds it), and a move whose bound over its pairs and segments stays
        `PROVEN` above the allowed depth has no sampled posture past it: its
        penetration term is 0, as the full samples give.  Only the other moves
        take their remaining samples.  The postures to take are packed
        together, half of M (at least `CHUNK_MIN`) an iteration of one loop
        (one copy of the distances in the program).  Batched (``vmap``, any
        depth) the moves of every batch entry are packed together
        (`jax.custom_batching.custom_vmap`), so that the moves a batch entry
        does not need cost nothing.  With ``certify``, without a check, with
        fewer than 4 samples or at most `PACKED_MIN` postures in all:
        ``vmap(move)``'s distances."""
        need = jnp.ones(dq.shape[:1], bool) if need is None else need
        if self.check is None or self.certify or self.samples < 4:
            over = jnp.where(need, jax.vmap(self._penetration)(q0, dq), 0.0)
        else:
            over = self._over_moves(q0, dq, need)
        return jax.vmap(self._violation)(dq, duration, approach, over)

    @functools.cached_property
    def _distances(self):
        """The check's signed distances of one posture (DoF,) -> (pairs,), as the
        depth counts (``exact=False``), traced once: ``jax.jit``'s trace cache
        serves every later call with the same types, and vmap batches the traced
        program once (clean_ie's generation chunk calls it three times, under
        the loop's and custom_vmap's batching passes: lowering 3.3 -> 2.7 s
        CPU, the same XLA program after inlining)."""
        return jax.jit(lambda q: self.check.distances(q, exact=False))

    @functools.cached_property
    def _over_moves(self):
        """The penetration term (M,) of `moves` (q0, dq (M, DoF), need (M,)),
        batched by flattening every batch axis into the moves (`moves`)."""

        @jax.custom_batching.custom_vmap
        def over(q0, dq, need):
            return self._over_flat(q0, dq, need)

        @over.def_vmap
        def _batched(axis_size, in_batched, q0, dq, need):
            q0, dq, need = (x if b else jnp.broadcast_to(x, (axis_size, *x.shape))
                            for x, b in zip((q0, dq, need), in_batched, strict=True))
            d = q0.shape[-1]
            flat = over(q0.reshape(-1, d), dq.reshape(-1, d), need.reshape(-1))
            return flat.reshape(need.shape), True

        return over

    def _over_flat(self, q0: Array, dq: Array, need: Array) -> Array:
        """`_over_moves` of one flat batch of moves (see `moves`)."""
        m, s = q0.shape[0], self.samples
        if m * (s + 1) <= PACKED_MIN:  # a loop would cost more than it saves
            return jnp.where(need, jax.vmap(self._penetration)(q0, dq), 0.0)
        alphas = jnp.arange(s + 1, dtype=jnp.float32) / s  # as `worst`'s
        coarse = np.asarray([0, s // 2, s], np.int32)  # first: ends and middle
        rest = np.setdiff1d(np.arange(s + 1), coarse).astype(np.int32)
        nc, nr, n_pairs = len(coarse), len(rest), self.check.n_pairs
        # postures an iteration: half of M, at least `CHUNK_MIN` (each
        # iteration's fixed cost against the postures a last one leaves over)
        chunk = max(-(-m // 2), min(m, CHUNK_MIN))
        rate = jnp.abs(dq) @ jnp.asarray(self._reach).T  # (M, pairs)
        h = jnp.asarray(np.diff(coarse) / s, jnp.float32)  # (nc - 1,)
        # the needed moves first; the coarse entry e: move first[e // nc]'s
        # sample coarse[e % nc], postures chunk * i .. of iteration i
        first, at_first = _partition(need)
        n_coarse = -(-(jnp.sum(need) * nc) // chunk)  # iterations
        n_c, n_r = -(-nc * m // chunk), -(-nr * m // chunk)

        def coarse_of(cbuf):  # (nc, M, pairs) in the moves' order
            per = cbuf.reshape(n_c * chunk, n_pairs)[:nc * m].reshape(m, nc, n_pairs)
            return per[at_first].transpose(1, 0, 2)

        def unproven(cbuf):  # the moves the coarse bound leaves open, first
            dc = coarse_of(cbuf)
            low = 0.5 * (dc[:-1] + dc[1:] - rate[None] * h[:, None, None])
            bound = jnp.min(jnp.minimum(low, dc[1:]), axis=(0, 2))  # (M,)
            open_ = need & ~(bound >= PROVEN - self.allowed)
            return dc, open_, *_partition(open_), jnp.sum(open_)

        def body(c):
            it, cbuf, fbuf, order, n_open = c
            in_coarse = it < n_coarse
            i = jnp.where(in_coarse, it, it - n_coarse)
            e = i * chunk + jnp.arange(chunk)
            move = jnp.where(in_coarse, first[jnp.minimum(e // nc, m - 1)],
                             order[jnp.minimum(e // nr, m - 1)])
            k = jnp.where(in_coarse, jnp.asarray(coarse)[e % nc],
                          jnp.asarray(rest)[e % nr])
            q = q0[move] + alphas[k][:, None] * dq[move]
            d = jax.vmap(self._distances)(q)
            cbuf = jnp.where(in_coarse, jax.lax.dynamic_update_index_in_dim(
                cbuf, d, jnp.minimum(i, n_c - 1), 0), cbuf)
            fbuf = jnp.where(in_coarse, fbuf, jax.lax.dynamic_update_index_in_dim(
                fbuf, d, jnp.minimum(i, n_r - 1), 0))
            # once the coarse postures are in: the open moves' order, kept
            order, n_open = jax.lax.cond(
                it + 1 == n_coarse, lambda: tuple(unproven(cbuf)[2::2]),
                lambda: (order, n_open))
            return it + 1, cbuf, fbuf, order, n_open

        def more(c):
            it, _, _, _, n_open = c
            return (it < n_coarse) | ((it - n_coarse) * chunk < n_open * nr)

        inf = jnp.float32(jnp.inf)
        zero = jnp.zeros((), jnp.int32)
        _, cbuf, fbuf, _, _ = jax.lax.while_loop(
            more, body, (zero, jnp.full((n_c, chunk, n_pairs), inf),
                         jnp.full((n_r, chunk, n_pairs), inf),
                         jnp.zeros((m,), jnp.int32), zero))
        dc, open_, _, at_open, _ = unproven(cbuf)
        # fine entry e: move order[e // nr]'s sample rest[e % nr]
        fine = jnp.min(fbuf.reshape(n_r * chunk, n_pairs)[:nr * m].reshape(
            m, nr, n_pairs), axis=(1, 2))[at_open]
        worst = -jnp.minimum(jnp.min(dc, axis=(0, 2)), fine)
        over = jnp.maximum(worst - self.allowed, 0.0) / self.penetration
        return jnp.where(open_, over, 0.0)

    # -- the executed motion (dynamic mode: what the physics did) ----------------
    def _executed_limits(self, robot, tracking_deg: float, saturation: float):
        if not (np.isfinite(tracking_deg) and tracking_deg > 0):
            raise ValueError(f"feasibility tracking_deg must be > 0, got "
                             f"{tracking_deg}")
        if not (np.isfinite(saturation) and 0 <= saturation <= 1):
            raise ValueError(f"feasibility saturation must be in [0, 1], got "
                             f"{saturation}")
        self.tracking_deg, self.saturation = float(tracking_deg), float(saturation)
        slide = np.asarray(robot.mj_model.jnt_type)[np.asarray(robot.joint_ids)] \
            == int(mujoco.mjtJoint.mjJNT_SLIDE)
        #: per evolved joint: radians (metres) -> degrees (millimetres)
        self.tracking_scale = np.where(slide, 1e3, 180.0 / np.pi).astype(np.float32)

    def postures(self, path: Array) -> Array:
        """Minus the smallest signed distance (m) of the pairs at the postures
        ``path`` (K, DoF) (-inf without pairs): > 0 penetrates."""
        if self.check is None:  # the geometry the moves are judged with (`worst`)
            return jnp.float32(-jnp.inf)
        d = jax.vmap(self._distances)(path)
        return -jnp.min(d)

    def executed(self, path: Array, tracking: Array, saturation: Array) -> Array:
        """Violation (scalar, 0 = feasible) of what the physics executed in one
        move: its simulated postures ``path`` (K, DoF) against penetration (as
        `move` judges the commanded ones), the tracking error (DoF,) [rad or m]
        against ``tracking_deg`` and the share of its steps at the force limit
        against ``saturation``; each a normalized excess, their max."""
        over = (jnp.maximum(self.postures(path) - self.allowed, 0.0)
                / self.penetration)
        # the search keeps EXECUTED_MARGIN of each limit in hand, for what the
        # finer replay differs (clean_ie_dynamic: 30.5 deg at timestep / 4 where
        # its own 0.01 s steps stayed within 30)
        keep = 1.0 - EXECUTED_MARGIN
        worst = jnp.max(tracking * jnp.asarray(self.tracking_scale))
        track = jnp.maximum(worst / (keep * self.tracking_deg) - 1.0, 0.0)
        # (a share of 1 may come out 1 + 1e-7 in float32)
        sat = jnp.maximum(saturation - keep * self.saturation - 1e-6, 0.0) / max(
            keep * self.saturation, 1e-3)
        return jnp.maximum(jnp.maximum(over, track), sat)


def _partition(mask: Array) -> tuple[Array, Array]:
    """The stable partition of ``mask`` (M,) bool, True first: the order
    (``jnp.argsort(~mask, stable=True)``) and each entry's place in it (its
    inverse), from running counts (XLA on the CPU sorts 189 entries in about
    35 us, several times these counts' cost)."""
    n = jnp.sum(mask, dtype=jnp.int32)
    place = jnp.where(mask, jnp.cumsum(mask, dtype=jnp.int32) - 1,
                      n + jnp.cumsum(~mask, dtype=jnp.int32) - 1)
    order = jnp.zeros(mask.shape, jnp.int32).at[place].set(
        jnp.arange(mask.shape[0], dtype=jnp.int32), unique_indices=True)
    return order, place


def _collides(m: mujoco.MjModel, a: str, b: str) -> bool:
    """Whether MuJoCo's collision filter lets the geoms named ``a`` and ``b``
    collide (obstacles, not in the model, never do)."""
    from cgda_jax.sim.geoms import geom_ids

    ids = geom_ids(m)
    if a not in ids or b not in ids:
        return False
    ga, gb = ids[a], ids[b]
    return bool((m.geom_contype[ga] & m.geom_conaffinity[gb])
                or (m.geom_contype[gb] & m.geom_conaffinity[ga]))


def _obstacle_args(o: Mapping) -> dict:
    keys = ("name", "type", "pos", "size", "quat")
    return {k: (tuple(np.asarray(o[k], float).tolist()) if k in ("pos", "size", "quat")
                else o[k]) for k in keys if k in o}


def _sdf(kind: str, size, R: np.ndarray, p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Signed distances (K,) from points ``x`` (K, 3) to a geom (world frame ``R``,
    ``p``): `cgda_jax.sim.primitive_distances.sdf_local` in the geom's frame."""
    from cgda_jax.sim.primitive_distances import sdf_local

    loc = jnp.asarray((x - p) @ R, jnp.float32)
    size = jnp.asarray(np.resize(np.asarray(size, np.float32), 3))
    return np.asarray(jax.vmap(lambda y: sdf_local(kind, size, y))(loc), np.float64)


def relevant_pairs(collider, robot, obstacles=()) -> tuple[list, list]:
    """The pairs of ``collider`` worth checking, and those that overlap at start.

    A pair is dropped when (a) it overlaps in the robot's start posture (a
    modelling overlap), or (b) a lower bound of its distance is positive over the
    whole joint box: at the nodes of a grid of about `GRID_POSTURES` postures,
    the distance from the moving geom's bounding sphere (centre from MuJoCo C's
    ``mj_kinematics``) to the other geom (exact for a constant geom, its bounding
    sphere for a moving one), less the most the pair can move from a node to any
    posture of its cell (``pair_reach @ spacing / 2``).  A robot of more evolved
    joints than the grid has postures for 2 nodes a joint (``2**DoF >
    GRID_POSTURES``, 13 joints and up) keeps every pair that does not overlap at
    start: checking more pairs is safe, a grid that grows as a power of the joint
    count is not (2**30 postures would not fit in memory).

    The start posture's distances are one program (`cgda_jax.programs.jit_call`:
    compiled once per process for the same robot; on the run's critical path and
    run once, so compiled unoptimized: `cgda_jax.programs.RUN_ONCE_OPTIONS`; only
    their signs are used); the grid's bounds are NumPy for pairs of moving geoms
    and one batched call a geom kind for the others.

    Returns:
        (kept pair names, overlapping pair names).
    """
    from cgda_jax.programs import RUN_ONCE_OPTIONS, jit_call
    from cgda_jax.sim.geoms import geom_bound, geom_ids, geom_shape

    if collider.n_pairs == 0:
        return [], []
    m = robot.mj_model
    d0 = np.asarray(jit_call(collider.distances, jnp.asarray(robot.start_genes),
                             compiler_options=RUN_ONCE_OPTIONS))
    overlapping = [collider.pair_names[k] for k in np.flatnonzero(d0 < 0)]
    gid = geom_ids(m)
    obs = {o.name: o for o in obstacles}
    if 2**robot.n_dof > GRID_POSTURES:  # no grid of 2 nodes a joint fits
        return [p for p in collider.pair_names if p not in overlapping], overlapping
    lower, upper = np.asarray(robot.lower, float), np.asarray(robot.upper, float)
    n = max(2, round(GRID_POSTURES ** (1.0 / robot.n_dof)))
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(lower, upper)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, robot.n_dof)
    data = mujoco.MjData(m)
    qpos0 = np.asarray(robot.qpos0, float)
    centres = np.empty((len(nodes), m.ngeom, 3))
    for i, q in enumerate(nodes):
        data.qpos[:] = qpos0
        data.qpos[robot.qpos_adr] = q
        mujoco.mj_kinematics(m, data)
        centres[i] = data.geom_xpos
    data.qpos[:] = qpos0  # the constant geoms' poses, below
    mujoco.mj_kinematics(m, data)
    spacing = (upper - lower) / (n - 1)
    bound = np.full(collider.n_pairs, np.inf)  # min over the grid of the bound
    fixed: dict[str, list] = {}  # kind: [(pair, size, local points, radius)]
    for k, (a, b) in enumerate(collider.pair_names):
        if (a, b) in overlapping:
            continue
        ga = gid[a]
        ra = geom_bound(m, ga)
        moving_b = b in gid and np.any(np.ptp(centres[:, gid[b]], axis=0) > 1e-9)
        if moving_b:
            gb = gid[b]
            bound[k] = np.min(np.linalg.norm(centres[:, ga] - centres[:, gb], axis=-1)
                              - ra - geom_bound(m, gb))
            continue
        if b in gid:
            gb = gid[b]
            kind, size, centre = geom_shape(m, gb)
            R = data.geom_xmat[gb].reshape(3, 3)
            p = data.geom_xpos[gb] + R @ centre
        else:
            kind = obs[b].type
            R, p, size = obs[b].frame()
        fixed.setdefault(kind, []).append(
            (k, np.resize(np.asarray(size, np.float32), 3), (centres[:, ga] - p) @ R,
             ra))
    for kind, rows in fixed.items():
        ks, sizes, local, radii = zip(*rows)
        d = np.asarray(_batched_sdf(kind, jnp.asarray(np.stack(sizes)),
                                    jnp.asarray(np.stack(local), jnp.float32)),
                       np.float64)  # (pairs of this kind, nodes)
        bound[list(ks)] = d.min(axis=1) - np.asarray(radii)
    slack = collider.pair_reach @ spacing / 2.0
    keep = [p for k, p in enumerate(collider.pair_names)
            if p not in overlapping and float(bound[k]) - float(slack[k]) <= 0.0]
    return keep, overlapping


@functools.partial(jax.jit, static_argnums=0)
def _batched_sdf(kind: str, size: Array, x: Array) -> Array:
    """Signed distances (P, K) from points ``x`` (P, K, 3), each row in its geom's
    frame, to geoms of one ``kind`` with sizes ``size`` (P, 3):
    `cgda_jax.sim.primitive_distances.sdf_local`."""
    from cgda_jax.sim.primitive_distances import sdf_local

    one = jax.vmap(lambda s, y: sdf_local(kind, s, y), in_axes=(None, 0))
    return jax.vmap(one)(size, x)
