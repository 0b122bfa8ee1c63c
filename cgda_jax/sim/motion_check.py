"""An executed trajectory looked at as a motion: timing, speeds, efforts, collisions.

`motion_report` is the independent check of a result's joints (issue 21): it does not
trust the values the optimiser saw.  It

- times the moves as the simulator does (minimum jerk over ``move_s`` per waypoint,
  the approach from the start posture over ``approach_s``) and reads each joint's
  peak speed and acceleration from that profile (`motion_profile`);
- looks for collisions along the joint path ``factor`` times more finely than the
  simulator did, with every geom of the model colliding
  (`cgda_jax.sim.collision.Collider`, the scene's obstacles included);
- in dynamic mode, replays the commanded reference on MuJoCo C at ``timestep /
  factor`` and reads the joints' measured speeds, the actuators' forces and how far
  each joint ends each waypoint from its target (`tracking_note`: one sentence when
  a joint cannot reach its commanded postures, with the reason); and judges the
  replayed path as the search judged the simulated one (``executed``: every
  replayed posture against collisions, the tracking error along the path, the
  worst move's share of steps at the force limit, each with its limit);
- measures the joint travel (the summed joint motion) and the largest change of a
  joint between consecutive postures (flailing).

Everything is in host NumPy (float64); the result is a JSON-ready dict.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

__all__ = ["TRACKING_WARNING_DEG", "MotionProfile", "compile_collisions_ahead",
           "motion_profile", "motion_report", "tracking_note"]

#: A joint ending a waypoint farther than this from its target [deg] (a slide: mm)
#: cannot reach its commanded postures: the report says so, once.
TRACKING_WARNING_DEG = 2.0


class MotionProfile(NamedTuple):
    """Joint positions, speeds and accelerations over time (host arrays).

    Attributes:
        t: (T,) seconds from the start.
        q, qd, qdd: (T, DoF) rad, rad/s, rad/s^2.
        waypoint_t: (N,) the time each waypoint is reached.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    waypoint_t: np.ndarray


def _durations(sim, n: int) -> np.ndarray:
    move = float(sim.move_s)
    approach = float(getattr(sim, "approach_s", move))
    return np.array([approach] + [move] * (n - 1))


def motion_profile(sim, joints: np.ndarray, samples: int = 64) -> MotionProfile:
    """The commanded motion of ``joints`` (N, DoF) from the start posture: each
    move a minimum-jerk profile over its duration (the approach over
    ``sim.approach_s``, the others over ``sim.move_s``) followed by the hold until
    the waypoint's time (``sim.waypoint_s``) is up.

    Args:
        sim: the `cgda_jax.sim.simulator.Simulator`.
        joints: (N, DoF) waypoints.
        samples: samples per move.
    """
    from cgda_jax.sim.timing import min_jerk, min_jerk_d1, min_jerk_d2

    joints = np.asarray(joints, np.float64)
    q_all = np.concatenate([np.asarray(sim.robot.start_genes, np.float64)[None],
                            joints])
    durs = _durations(sim, len(joints))
    hold = float(sim.waypoint_s) - float(sim.move_s)
    tau = np.linspace(0.0, 1.0, samples)
    s, d1, d2 = (np.asarray(f(tau), np.float64)
                 for f in (min_jerk, min_jerk_d1, min_jerk_d2))
    ts, qs, qds, qdds, reached = [], [], [], [], []
    t0 = 0.0
    for i, dur in enumerate(durs):
        q0, dq = q_all[i], q_all[i + 1] - q_all[i]
        ts.append(t0 + tau * dur)
        qs.append(q0 + s[:, None] * dq)
        qds.append(d1[:, None] * dq / dur)
        qdds.append(d2[:, None] * dq / dur**2)
        t0 += dur
        if hold > 0:
            ts.append(np.array([t0 + hold]))
            qs.append(q_all[i + 1][None])
            qds.append(np.zeros((1, len(dq))))
            qdds.append(np.zeros((1, len(dq))))
            t0 += hold
        reached.append(t0)
    return MotionProfile(np.concatenate(ts), np.concatenate(qs), np.concatenate(qds),
                         np.concatenate(qdds), np.asarray(reached))


def _check_collider(sim):
    """The collider the check uses: the feasibility's pairs, or every pair of the
    model and the scene's obstacles without one (None: no pairs)."""
    collider = getattr(getattr(sim, "feasibility", None), "collider", None)
    if collider is None:
        from cgda_jax.sim.feasibility import Feasibility, scene_obstacles

        collider = Feasibility(sim.robot, obstacles=scene_obstacles(sim.scene)).collider
    return collider


def _collision_program(collider, sim, n_moves: int, factor: int) -> tuple:
    """`cgda_jax.programs.compile_jit`'s arguments for the distances of
    ``collider`` at ``substeps * factor`` postures of each of ``n_moves`` moves:
    (N, K, DoF) -> (N, K, pairs)."""
    import jax
    import jax.numpy as jnp

    k = max(2, int(sim.substeps) * int(factor))
    return ("motion_check.collisions", jax.vmap(jax.vmap(collider.distances)),
            jax.ShapeDtypeStruct((int(n_moves), k, sim.n_dof), jnp.float32))


def compile_collisions_ahead(sim, n_moves: int, factor: int = 4) -> None:
    """Start compiling, in a thread, the collision program of `motion_report` for
    ``n_moves`` reported waypoints (`cgda_jax.programs.compile_ahead`): while the
    search runs, on the other core. Nothing without the feasibility's collider."""
    from cgda_jax.programs import compile_ahead

    collider = getattr(getattr(sim, "feasibility", None), "collider", None)
    if collider is not None:
        # traced behind the strategy's programs, asked with them (`compile_ahead`)
        compile_ahead(*_collision_program(collider, sim, n_moves, factor), rank=2,
                      defer=True)


def _collisions(sim, joints: np.ndarray, factor: int) -> dict[str, Any] | None:
    """Worst signed distance along the joint path at ``substeps * factor`` postures
    per move, its pair and move (None without a collider)."""
    import jax.numpy as jnp

    from cgda_jax.programs import compile_jit

    feas = getattr(sim, "feasibility", None)
    collider = _check_collider(sim)
    if collider is None:
        return None
    q_all = np.concatenate([np.asarray(sim.robot.start_genes, np.float64)[None],
                            np.asarray(joints, np.float64)])
    name, fn, spec = _collision_program(collider, sim, len(joints), factor)
    k = spec.shape[1]
    alphas = np.arange(1, k + 1) / k
    path = q_all[:-1, None] + alphas[None, :, None] * np.diff(q_all, axis=0)[:, None]
    # (N, K, pairs): one program, compiled once a process for a collider and shape
    d = np.asarray(compile_jit(name, fn, spec)(jnp.asarray(path, jnp.float32)),
                   np.float64)
    move, step, pair = np.unravel_index(int(np.argmin(d)), d.shape)
    worst = float(d[move, step, pair])
    per_move = d.min(axis=(1, 2))
    return {
        "worst_distance_m": worst,
        "penetration_m": max(0.0, -worst),
        "pair": list(collider.pair_names[pair]),
        "move": int(move),
        "moves_penetrating": int(np.sum(per_move < -float(
            getattr(feas, "penetration", 0.005)))),
        "postures_checked": int(d.shape[0] * d.shape[1]),
        "pairs": int(collider.n_pairs),
    }


def _dynamic_replay(sim, joints: np.ndarray, factor: int) -> dict[str, np.ndarray]:
    """MuJoCo C replay of the commanded reference at ``timestep / factor``
    (`cgda_jax.sim.host_replay.replay_steps`): the evolved joints' measured speeds
    (T, DoF), their actuator forces at the joint (T, DoF; ``qfrc_actuator``, a PD's
    gravity compensation included), and at each waypoint's end the error from its
    target and the force (N, DoF)."""
    import mujoco

    from cgda_jax.sim.geoms import geom_name
    from cgda_jax.sim.host_replay import replay_steps

    from cgda_jax.sim.physics import saturated

    speeds, forces, ends, end_forces = [], [], [], []
    postures, commanded, moves = [], [], []  # the executed path, per step
    deepest = (np.inf, -1, -1)
    m = gene_dof = robot_geom = None
    for st in replay_steps(sim, joints, factor):
        d = st.data
        if m is None:  # the first step: the model's evolved dofs and arm geoms
            m = st.model
            jt = mujoco.mjtObj.mjOBJ_JOINT
            jids = [mujoco.mj_name2id(m, jt, n) for n in sim.robot.joint_names]
            gene_dof = np.array([m.jnt_dofadr[j] for j in jids])
            moving = np.zeros(m.nbody, bool)  # bodies the evolved joints move
            for j in jids:
                moving[m.jnt_bodyid[j]] = True
            for b in range(1, m.nbody):  # parents come first
                moving[b] |= moving[m.body_parentid[b]]
            robot_geom = moving[m.geom_bodyid]
        for c in d.contact[:d.ncon]:  # the physics' own contacts of the arm
            if (robot_geom[c.geom1] or robot_geom[c.geom2]) and c.dist < deepest[0]:
                deepest = (float(c.dist), int(c.geom1), int(c.geom2))
        speeds.append(d.qvel[gene_dof].copy())
        forces.append(d.qfrc_actuator[gene_dof].copy())
        postures.append(d.qpos[st.physics.gene_qadr].copy())
        commanded.append(st.commanded)
        moves.append(st.move - 1)
        if st.last:
            ends.append(d.qpos[st.physics.gene_qadr] - st.target)
            end_forces.append(forces[-1])
    contact = None
    if deepest[1] >= 0:
        pair = [geom_name(m, g) for g in deepest[1:]]
        contact = {"deepest_m": max(0.0, -deepest[0]), "pair": pair}
    at_limit = np.any(saturated(np.asarray(forces), st.physics.force_range), axis=1)
    moves = np.asarray(moves)
    return {"speed": np.asarray(speeds), "force": np.asarray(forces),
            "tracking": np.abs(np.asarray(ends)), "end_force": np.asarray(end_forces),
            "timestep": float(m.opt.timestep), "contact": contact,
            "postures": np.asarray(postures), "moves": moves,
            "path_tracking": np.abs(np.asarray(postures) - np.asarray(commanded)),
            "saturation": np.bincount(moves, at_limit) / np.bincount(moves)}


def _executed(sim, rep: dict[str, Any], penetration: float) -> dict[str, Any]:
    """The replayed path judged as `Feasibility.executed` judges the simulated
    one: its deepest penetration (every replayed posture, the check's pairs), the
    largest tracking error along it and the worst move's share of steps at the
    force limit, each with its limit (the defaults without feasibility)."""
    import jax
    import jax.numpy as jnp

    from cgda_jax.sim.feasibility import DEFAULT_SATURATION, DEFAULT_TRACKING_DEG

    feas = getattr(sim, "feasibility", None)
    scale = getattr(feas, "tracking_scale", None)
    if scale is None:
        scale = np.full(sim.n_dof, np.rad2deg(1.0))
    track = rep["path_tracking"].max(axis=0) * np.asarray(scale, np.float64)
    out = {"tracking_deg": dict(zip(sim.robot.joint_names, track.tolist())),
           "tracking_limit_deg": float(getattr(feas, "tracking_deg",
                                               DEFAULT_TRACKING_DEG)),
           "saturation": float(np.max(rep["saturation"])),
           "saturation_per_move": rep["saturation"].tolist(),
           "saturation_limit": float(getattr(feas, "saturation", DEFAULT_SATURATION)),
           "penetration_m": 0.0, "pair": None, "move": None,
           "postures_checked": int(len(rep["postures"])),
           "penetration_allowed_m": penetration}
    collider = _check_collider(sim)
    if collider is not None:
        d = np.asarray(jax.jit(jax.vmap(collider.distances))(
            jnp.asarray(rep["postures"], jnp.float32)), np.float64)  # (T, pairs)
        step, pair = np.unravel_index(int(np.argmin(d)), d.shape)
        out.update(penetration_m=max(0.0, -float(d[step, pair])),
                   pair=list(collider.pair_names[pair]),
                   move=int(rep["moves"][step]),
                   samples_penetrating=int(np.sum(d.min(axis=1) < -penetration)))
    return out


def tracking_note(sim, tracking: np.ndarray, end_force: np.ndarray,
                  threshold_deg: float = TRACKING_WARNING_DEG,
                  contact: dict[str, Any] | None = None) -> str | None:
    """One sentence naming the evolved joint that ends its waypoints farthest from
    the commanded posture, when that is more than ``threshold_deg`` (radians /
    metres: ``threshold_deg`` in degrees, or its value in mm for a slide), and why:
    its force limit (saturation) or not (a load the gain cannot hold: gravity, a
    contact); None when every joint reaches its commands.

    Args:
        sim: the dynamic `cgda_jax.sim.simulator.Simulator`.
        tracking: (N, DoF) |error| at each waypoint's end.
        end_force: (N, DoF) the joint's actuator force there.
        contact: the replay's deepest contact of the arm (``{"pair", "deepest_m"}``),
            named in the note as what may hold the joint; None: no contact.
    """
    import mujoco

    names = list(sim.robot.joint_names)
    slide = np.array([int(sim.robot.mj_model.jnt_type[j]) == int(
        mujoco.mjtJoint.mjJNT_SLIDE) for j in sim.robot.joint_ids])
    scale = np.where(slide, 1e3, np.rad2deg(1.0))  # mm or degrees
    err = np.asarray(tracking, np.float64) * scale
    if not np.nanmax(err) > threshold_deg:
        return None
    i, j = np.unravel_index(int(np.nanargmax(err)), err.shape)
    name, unit = names[j], "mm" if slide[j] else "deg"
    drive = sim.physics.control.drive(name)
    lo, hi = drive.force if drive is not None else (-np.inf, np.inf)
    f = float(end_force[i, j])
    saturated = (np.isfinite(hi) and f >= 0.99 * hi) or (np.isfinite(lo)
                                                        and f <= 0.99 * lo)
    servo = drive is not None and drive.kind == "position"
    how = "its position servo" if servo else "its PD"
    if saturated:
        why = (f"{how} is at its force limit ({f:.3g} of [{lo:g}, {hi:g}]); a "
               "larger limit (robot.control.force_limit for a PD, the model's "
               "forcerange / ctrlrange) or postures it can hold would reach them")
    elif servo:
        why = (f"{how} holds {f:.3g} within its force limit, short of the target "
               "(gravity against its gain, or a contact); robot.control.mode = "
               "\"pd\" keeps its gains and compensates gravity")
    elif drive is not None and not drive.gravity:
        why = (f"{how} holds {f:.3g} within its force limit, short of the target "
               "(gravity against its gain, or a contact); robot.control.gravity = "
               "true compensates gravity")
    else:
        why = (f"{how} holds {f:.3g} within its force limit, short of the target "
               "(still moving, or a contact); a larger robot.control.kp or a longer "
               "robot.waypoint_s lets it settle")
    worse = int(np.sum(err[:, j] > threshold_deg))
    touched = ""
    if contact:
        a, b = contact["pair"]
        touched = (f"; the arm touched something in the replay ({a} - {b}, deepest "
                   f"{1e3 * contact['deepest_m']:.1f} mm), which may be what holds it")
    return (f"the arm cannot reach its commanded postures: joint {name!r} ends "
            f"waypoint {i + 1} {err[i, j]:.1f} {unit} from its target ({worse} of "
            f"{len(err)} waypoints beyond {threshold_deg:g} {unit}); {why}{touched}. "
            "The evolved waypoints are commands, not the postures reached")


def motion_report(sim, joints: np.ndarray, factor: int = 4) -> dict[str, Any]:
    """The motion of ``joints`` (N, DoF) checked as a roboticist would.

    Args:
        sim: the `cgda_jax.sim.simulator.Simulator` the result was found with.
        joints: (N, DoF) the reported waypoints (radians / metres).
        factor: how much finer than the simulator the check looks (collision
            postures per move; dynamic replay timestep).

    Returns:
        A JSON-ready dict: ``joints`` (names), ``limits`` (`JointLimits.as_dict`),
        per joint ``peak_speed``, ``peak_acceleration`` (commanded profile),
        ``measured_speed`` / ``peak_effort`` / ``tracking_error_deg`` (the largest
        at a waypoint's end; per waypoint ``tracking_deg_per_waypoint``) /
        ``tracking_note`` / ``control`` / ``executed`` (dynamic replay: the
        replayed path's penetration, tracking error and time at the force limit,
        with their limits), ``travel_deg``,
        ``largest_step_deg``; ``moves_over_max_step`` (moves that change a joint
        by more than ``max_step_deg``, the feasibility's, default 90);
        ``approach_s``, ``move_s``;
        ``collisions`` (worst distance, pair, move); ``feasible`` and the reasons
        it is not (``problems``).
    """
    from cgda_jax.sim.limits import read_limits

    joints = np.asarray(joints, np.float64)
    if joints.ndim != 2 or joints.shape[1] != sim.n_dof or not len(joints):
        raise ValueError(f"joints has shape {joints.shape}, expected (N, {sim.n_dof})")
    if not np.all(np.isfinite(joints)):
        raise ValueError("joints contain NaN or inf: no executed motion to check")
    feas = getattr(sim, "feasibility", None)
    limits = feas.limits if feas is not None else read_limits(
        sim.robot.mj_model, sim.robot.joint_names)
    penetration = float(getattr(feas, "penetration", 0.005))
    max_step = float(getattr(feas, "max_step", np.pi / 2))
    names = list(sim.robot.joint_names)
    prof = motion_profile(sim, joints)
    peak_v = np.abs(prof.qd).max(axis=0)
    peak_a = np.abs(prof.qdd).max(axis=0)
    q_all = np.concatenate([np.asarray(sim.robot.start_genes, np.float64)[None],
                            joints])
    steps = np.abs(np.diff(q_all, axis=0))  # (N, DoF), the approach first
    out: dict[str, Any] = {
        "joints": names,
        "limits": limits.as_dict(),
        "approach_s": float(getattr(sim, "approach_s", sim.move_s)),
        "move_s": float(sim.move_s),
        "duration_s": float(prof.waypoint_t[-1]),
        "peak_speed": dict(zip(names, peak_v.tolist())),
        "peak_acceleration": dict(zip(names, peak_a.tolist())),
        "travel_deg": dict(zip(names, np.rad2deg(steps.sum(0)).tolist())),
        "largest_step_deg": dict(zip(names, np.rad2deg(steps[1:].max(0)).tolist()
                                     if len(steps) > 1 else [0.0] * len(names))),
        "approach_deg": dict(zip(names, np.rad2deg(steps[0]).tolist())),
        "max_step_deg": float(np.rad2deg(max_step)),
        "moves_over_max_step": int(np.sum(np.any(steps[1:] > max_step, axis=1))),
    }
    problems = []
    vel, acc, eff = (np.asarray(x, np.float64) for x in
                     (limits.velocity, limits.acceleration, limits.effort))
    tol = 1 + 1e-5
    for j, n in enumerate(names):
        if peak_v[j] > vel[j] * tol:
            problems.append(f"{n}: {peak_v[j]:.2f} rad/s over its {vel[j]:g} rad/s")
        if peak_a[j] > acc[j] * tol:
            problems.append(f"{n}: {peak_a[j]:.2f} rad/s^2 over its {acc[j]:g}")
    if out["moves_over_max_step"]:
        problems.append(f"{out['moves_over_max_step']} move(s) change a joint by more "
                        f"than {out['max_step_deg']:g} degrees")
    if sim.mode == "dynamic":
        rep = _dynamic_replay(sim, joints, factor)
        mv = np.nanmax(np.abs(rep["speed"]), axis=0)
        me = np.nanmax(np.abs(rep["force"]), axis=0)
        out["measured_speed"] = dict(zip(names, mv.tolist()))
        out["peak_effort"] = dict(zip(names, [None if not np.isfinite(v) else v
                                              for v in me.tolist()]))
        out["replay_timestep"] = rep["timestep"]
        out["physics_contact"] = rep["contact"]  # None: the arm touched nothing
        if rep["contact"] and rep["contact"]["deepest_m"] > penetration:
            a, b = rep["contact"]["pair"]
            problems.append(f"physics: {a} {rep['contact']['deepest_m'] * 1e3:.1f} mm "
                            f"into {b}")
        out["tracking_error_deg"] = dict(zip(names, np.rad2deg(
            rep["tracking"].max(axis=0)).tolist()))  # at the waypoints' ends
        out["tracking_deg_per_waypoint"] = np.rad2deg(rep["tracking"]).tolist()
        out["tracking_note"] = tracking_note(sim, rep["tracking"], rep["end_force"],
                                             contact=rep["contact"])
        out["control"] = sim.physics.control.as_dict()
        ex = out["executed"] = _executed(sim, rep, penetration)
        if ex["penetration_m"] > penetration:
            a, b = ex["pair"]
            problems.append(f"executed path: {a} {ex['penetration_m'] * 1e3:.1f} mm "
                            f"into {b} (move {ex['move'] + 1})")
        worst = max(ex["tracking_deg"], key=ex["tracking_deg"].get)
        if ex["tracking_deg"][worst] > ex["tracking_limit_deg"] * tol:
            problems.append(f"{worst}: tracking error {ex['tracking_deg'][worst]:.1f} "
                            f"deg over its {ex['tracking_limit_deg']:g}")
        if ex["saturation"] > ex["saturation_limit"] * tol:
            problems.append(f"at the force limit {100 * ex['saturation']:.0f} % of a "
                            f"move over the {100 * ex['saturation_limit']:g} % allowed")
        for j, n in enumerate(names):
            if mv[j] > vel[j] * tol:
                problems.append(f"{n}: measured {mv[j]:.2f} rad/s over its "
                                f"{vel[j]:g} rad/s")
            if np.isfinite(me[j]) and me[j] > eff[j] * tol:
                problems.append(f"{n}: {me[j]:.1f} N m over its {eff[j]:g} N m")
    col = _collisions(sim, joints, factor)
    out["collisions"] = col
    if col is not None and col["penetration_m"] > penetration:
        a, b = col["pair"]
        problems.append(f"{a} {col['penetration_m'] * 1e3:.1f} mm into {b} "
                        f"(move {col['move'] + 1})")
    out["penetration_allowed_m"] = penetration
    out["feasible"] = not problems
    out["problems"] = problems
    return out
