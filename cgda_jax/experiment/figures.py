"""A run's figures, drawn from what its results folder stores (a `Run`): the same
code draws them at the end of a run and in ``cgda plot FOLDER``. Also the robot's
video (MP4 + GIF, 640x480) and frame strip, with the goal drawn in."""

from __future__ import annotations

import importlib
import logging
import math
import os
import pathlib
import textwrap
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from cgda_jax.experiment.build import error_unit, feature_labels
from cgda_jax.experiment.load import Run
from cgda_jax.experiment.rules import check_camera

log = logging.getLogger("cgda_jax")

VIDEO_SIZE = (640, 480)


def _close_all() -> None:
    import matplotlib.pyplot as plt

    plt.close("all")


def import_drawing(plots: bool, render: bool) -> threading.Thread | None:
    """Import what drawing needs (the figures with matplotlib; MuJoCo's renderer
    and the video writer) in a thread, while the run computes (its programs run
    without Python's lock); the drawing finds them loaded, or waits for the
    import under way (Python's import lock)."""
    if not (plots or render):
        return None

    def load() -> None:
        try:
            from cgda_jax import plotting

            for name in plotting.__all__:  # each figure's module, matplotlib
                getattr(plotting, name)
            if render:
                importlib.import_module("cgda_jax.sim.render")
                importlib.import_module("cgda_jax.sim.video")
        except Exception:  # noqa: BLE001 - the drawing imports it and says why
            return

    thread = threading.Thread(target=load, name="cgda-import-drawing", daemon=True)
    thread.start()
    return thread


def draw_figures(run: Run, out: str | os.PathLike) -> list[pathlib.Path]:
    """Every PNG figure of ``run`` into the folder ``out``; the files written."""
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        if run.kind == "recognition":
            return _recognition_figures(run, out)
        return _execution_figures(run, out)
    finally:
        _close_all()


def _recognition_figures(run: Run, out: pathlib.Path) -> list[pathlib.Path]:
    from cgda_jax.plotting import plot_cost_matrix, plot_demonstrations

    r, cfg = run.result, run.config
    labels = r.get("feature_labels") or feature_labels(cfg, r["features"])
    unit = error_unit(labels)
    metric = r["metric"].upper()
    written = [out / "cost_matrix.png"]
    rows = [q.lower() for q in r["truth"]]
    if r.get("split") == "leave_one_out":  # every repetition a row: number them
        rows = [f"{q} {rows[:k].count(q) + 1}" for k, q in enumerate(rows)]
    plot_cost_matrix(
        run.arrays["cost_matrix"], rows, r["actions"],
        label=f"{metric} cost [{unit or 'mixed units'}]",
        title=f"{run.name}: {metric} cost, test (rows) vs generalized\n"
              + textwrap.fill(f"{len(labels)} features: {', '.join(r['features'])}",
                              width=70),
        path=written[0],
    )
    cols = None if cfg.data.features == "marker" else list(range(min(3, len(labels))))
    shown = "" if cols is None or len(cols) == len(labels) else (
        f"\n(drawn: {', '.join(r['features'][c] for c in cols)} of "
        f"{len(labels)} features)")
    for a in r["actions"]:
        path = out / f"generalization_{a}.png"
        plot_demonstrations(
            run.demonstrations(a), run.generalization(a), features=cols, names=labels,
            title=f"{run.name}: {a} demonstrations and generalization{shown}",
            path=path,
        )
        written.append(path)
    return written + _selection_figures(run, out)


def _selection_figures(run: Run, out: pathlib.Path) -> list[pathlib.Path]:
    """The z-scores of a ``[selection]`` against alpha, features and
    demonstrations of each action (none without a selection)."""
    from cgda_jax.plotting import plot_zscores

    sel = run.result.get("selection")
    written = []
    for part, what in (("features", "feature"), ("demonstrations", "demonstration")):
        panels = {a: (rec[part]["names"], [np.nan if z is None else z
                                          for z in rec[part]["zscores"]])
                  for a, rec in (sel or {}).get("actions", {}).items() if part in rec}
        if panels:
            written.append(out / f"selection_{part}.png")
            plot_zscores(
                panels, sel["alpha"], what=what, path=written[-1],
                title=f"{run.name}: {what} selection, z-scores of the summed DTW "
                      f"({sel['normalization']} normalization)")
    return written


def _execution_figures(run: Run, out: pathlib.Path) -> list[pathlib.Path]:
    from cgda_jax import plotting

    r, a = run.result, run.arrays
    labels = r.get("feature_labels") or feature_labels(run.config, r["feature_names"])
    unit = r["error_unit"] if "feature_labels" in r else error_unit(labels)
    what = f"{run.name} ({r['strategy'].upper()})"
    written = []

    def path(name: str) -> pathlib.Path:
        written.append(out / name)
        return written[-1]

    plotting.plot_goal_vs_executed(
        a["goal"], a["features"], labels, tolerance=r["tolerance"],
        tolerance_unit=unit, title=f"{what}: goal vs executed per point",
        path=path("goal_vs_executed.png"),
    )
    plotting.plot_point_errors(
        a["point_errors"], r["tolerance"], unit=unit,
        title=f"{what}: error per point vs tolerance", path=path("point_errors.png"),
    )
    from cgda_jax.strategies import strategy_of

    per_point = strategy_of(r["strategy"]).plan.per_point
    points = np.ndim(a["fitness_history"]) == 2
    plotting.plot_fitness(
        a["fitness_history"], unit=unit, parallel=r["strategy"] == "ie",
        tolerance=r["tolerance"] if points else None,
        errors=a["point_errors"] if per_point and points else None,
        least_motion=points and bool(run.config.strategy.feasibility),
        title=f"{what}: best fitness per generation ({r['generations']} "
              "generations)", path=path("fitness.png"),
    )
    demos, gen = run.demonstrations(), run.generalization()
    if demos or gen is not None:  # 3 features: in 3-D (paper Fig. 7)
        plotting.plot_demonstrations(
            demos, gen, a["features"], names=labels,
            title=f"{what}: demonstrations, goal and executed",
            path=path("trajectory_3d.png" if len(labels) == 3 else
                      "demonstrations.png"),
        )
    per_point = (r.get("info") or {}).get("point_generations")
    if per_point is not None and np.ndim(a["fitness_history"]) == 2:
        plotting.plot_time_per_point(
            per_point, ylabel="generations run (restarts included)",
            title=f"{what}: effort per point", path=path("effort_per_point.png"),
        )
    motion = r.get("motion")
    if motion and "motion_t" in a:  # the motion against the limits
        lim = motion["limits"]
        names = motion["joints"]

        def per_joint(table) -> np.ndarray:
            return np.array([np.inf if table[j] is None else table[j] for j in names])

        rc = run.config.robot
        lower = upper = None
        if "joint_lower" in a:
            lower, upper = a["joint_lower"], a["joint_upper"]
        verdict = "feasible" if motion["feasible"] else "NOT feasible"
        plotting.plot_motion(
            a["motion_t"], a["motion_q"], a["motion_qd"], names, lower=lower,
            upper=upper, velocity=per_joint(lim["velocity"]),
            waypoint_t=a["motion_waypoint_t"],
            title=f"{what} on {rc.model}: commanded motion, {verdict}",
            path=path("motion.png"),
        )
    return written


def _arm_points(sim, joints) -> np.ndarray:
    """World positions of the arm: its first evolved joint's anchor and the marker
    at the start and at every waypoint (M, 3)."""
    import mujoco

    robot = sim.robot
    model = robot.mj_model
    data = mujoco.MjData(model)
    data.qpos[:] = np.asarray(robot.qpos0, np.float64)
    mujoco.mj_kinematics(model, data)
    points = [data.xanchor[int(robot.joint_ids[0])].copy(),
              data.site_xpos[robot.site_id].copy()]
    for q in np.asarray(joints, np.float64):
        if np.all(np.isfinite(q)):
            data.qpos[robot.qpos_adr] = np.clip(q, robot.lower, robot.upper)
            mujoco.mj_kinematics(model, data)
            points.append(data.site_xpos[robot.site_id].copy())
    return np.asarray(points)


def _camera(sim, goal=None, joints=None, camera: dict | None = None) -> dict[str, Any]:
    """The video's free camera: ``camera`` (``[output] camera``) over a default
    that frames the goal and the arm. The marker scene: from in front of the arm,
    55 degrees to its outer side, looking slightly down at the goal points, the
    marker's waypoints and the shoulder; the paint wall: the robot and the wall;
    the object scenes: their goal path and the hand."""
    paint = getattr(sim.scene, "centres", None) is not None
    view: dict[str, Any] = {
        "distance": (1.9 if paint else 1.3) * float(sim.robot.mj_model.stat.extent)}
    path = getattr(sim.scene, "goal_path", None)
    if path is not None:  # objects: look at them and the hand, from their side
        hand = np.asarray(sim.robot.marker_position(sim.robot.start_genes), float)
        points = np.vstack([np.asarray(path, float), hand[None]])
        centre = (2.0 * points[:-1].mean(axis=0) + hand) / 3.0
        spread = float(np.linalg.norm(points - centre, axis=1).max())
        view = {"lookat": centre, "elevation": -35.0,
                "distance": max(0.6, 3.5 * spread),
                "azimuth": math.degrees(math.atan2(-centre[1], -centre[0])) + 30.0}
    elif goal is not None and type(sim.scene).__name__ == "MarkerScene":
        goal = np.asarray(goal, float)
        points = np.vstack([goal, _arm_points(sim, joints if joints is not None
                                              else np.zeros((0, sim.n_dof)))])
        lo, hi = points.min(axis=0), points.max(axis=0)
        centre = (lo + hi) / 2
        spread = float(np.linalg.norm(points - centre, axis=1).max())
        side = math.copysign(55.0, centre[1]) if abs(centre[1]) > 1e-6 else 55.0
        view = {"lookat": centre, "elevation": -15.0,
                "distance": max(0.5, 2.8 * spread),
                # from in front (the robot faces +x), turned to the arm's side
                "azimuth": math.degrees(math.atan2(centre[1], centre[0])) + 180.0
                - side}
    view.update(check_camera(camera or {}))
    return view


def _captions(run: Run, sim):
    """Per frame: the point being reached, or reached with its error (paint: the
    target and the painted %)."""
    goal = np.asarray(run.arrays["goal"], float)
    errors = np.asarray(run.arrays["point_errors"], float)
    n = len(goal)
    paint = getattr(sim.scene, "centres", None) is not None
    unit = run.result.get("error_unit")

    def text(k: int, state, reached: bool = True) -> str:
        if k == 0:
            return f"{run.name}: start"
        if paint:
            painted = 100.0 * float(np.mean(np.asarray(state, bool)))
            target = f"target {goal[k - 1, 0]:.2f} %"
            if reached:
                return (f"{run.name}: point {k} of {n} reached\n"
                        f"painted {painted:.2f} % ({target})")
            return (f"{run.name}: moving to point {k} of {n} ({target})\n"
                    f"painted so far {painted:.2f} %")
        if not reached:
            return f"{run.name}: moving to point {k} of {n}"
        err = errors[k - 1] if k - 1 < len(errors) else np.nan
        if not np.isfinite(err):
            return f"{run.name}: point {k} of {n} reached"
        shown = (f"{1e3 * err:.1f} mm" if unit == "m" else
                 f"{err:.3g}{' ' + unit if unit else ''}")
        return f"{run.name}: point {k} of {n} reached, error {shown}"

    return text


#: Frames per waypoint of the robot's video: a kinematic paint run shows the arm
#: sweeping (the wall is painted from every simulated sub-step whatever the frames,
#: `cgda_jax.sim.render`), the others move straight from point to point.
PAINT_FRAMES_PER_WAYPOINT = 4
FRAMES_PER_WAYPOINT = 3


def frames_per_waypoint(sim) -> int:
    """Frames per waypoint in `render_run`'s video of ``sim``: at most
    `PAINT_FRAMES_PER_WAYPOINT` (and the sub-steps) for a kinematic paint run,
    else `FRAMES_PER_WAYPOINT`; the video plays ``max(4, 2 * fpw)`` frames a second
    (2 waypoints a second where ``fpw >= 2``)."""
    if getattr(sim.scene, "centres", None) is not None and sim.mode == "kinematic":
        return min(int(sim.substeps), PAINT_FRAMES_PER_WAYPOINT)
    return FRAMES_PER_WAYPOINT


def render_run(run: Run, out: str | os.PathLike, sim=None, *, n_strip: int = 8,
               size: tuple[int, int] = VIDEO_SIZE,
               alongside: Callable[[], object] | None = None) -> dict:
    """The robot executing the run's best joints: ``execution.mp4``,
    ``execution.gif`` (``size`` pixels; the start, then `frames_per_waypoint`
    frames per goal point; the GIF in one shared palette) and the frame strip
    ``frames.png`` in ``out``.

    The goal is drawn in: the marker scene's goal points as spheres (the one being
    reached in yellow), the object scenes' goal path, and a caption with the point
    being reached (paint: its target and the painted percentage). Shadows are off
    (half a frame's time; no pixel of the built-in scenes changes, `cgda_jax.sim.render`).

    ``alongside`` (e.g. the figures) is called in this thread while the frames
    render and the videos are written in another (OpenGL and the encoders run
    without Python's lock; matplotlib stays in this thread); its errors are
    raised once the videos are done.

    Never raises (but for ``alongside``): when offscreen OpenGL (or anything else
    in rendering) fails, logs one warning on the ``cgda_jax`` logger and returns
    ``{"ok": False, "reason": ...}``; otherwise ``{"ok": True, "gif": ..., "mp4":
    ..., "frames": ..., "backend": ...}`` (paths relative to the results folder).
    """
    out = pathlib.Path(out)
    done: dict[str, Any] = {}

    def videos() -> None:
        try:
            done["frames"] = _render_videos(run, out, sim, size)
        except Exception as err:  # noqa: BLE001 - reported below, never fatal
            done["error"] = err

    if alongside is None:
        videos()
    else:
        thread = threading.Thread(target=videos, name="cgda-render", daemon=True)
        thread.start()
        try:
            alongside()
        finally:
            thread.join()
    try:
        if "error" in done:
            raise done["error"]
        from cgda_jax import plotting
        from cgda_jax.sim import last_backend

        frames = done["frames"]
        at = frames.at_points()  # start, point 1, ..., point N
        pick = np.unique(np.linspace(0, len(at) - 1, min(n_strip, len(at)))
                         .round().astype(int))
        plotting.plot_frames(
            [frames.images[at[k]] for k in pick],
            labels=["start" if k == 0 else f"point {k}" for k in pick],
            title=f"{run.name}: the robot executing the best trajectory",
            path=out / "frames.png",
        )
        _close_all()
    except Exception as err:  # noqa: BLE001 - no GL, a missing library: never fatal
        reason = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
        log.warning("%s: frames not rendered (%s); set MUJOCO_GL=egl or osmesa, or "
                    "output.render=false", run.name, reason)
        return {"ok": False, "reason": reason}
    return {"ok": True, "gif": "plots/execution.gif", "mp4": "plots/execution.mp4",
            "frames": "plots/frames.png", "size": list(size),
            "backend": last_backend()}


def _render_videos(run: Run, out: pathlib.Path, sim, size: tuple[int, int]):
    """`render_run`'s frames and its two videos (no matplotlib: any thread)."""
    from cgda_jax.sim.render import render_frames
    from cgda_jax.sim.video import write_video

    sim = sim if sim is not None else run.simulator()
    joints = np.asarray(run.arrays["joints"], np.float32)
    fpw = frames_per_waypoint(sim)
    marker = type(sim.scene).__name__ == "MarkerScene"
    goal = np.asarray(run.arrays["goal"], float)
    camera = _camera(sim, goal if marker else None, joints,
                     getattr(run.config.output, "camera", None))
    frames = render_frames(
        sim, joints, frames_per_waypoint=fpw, width=size[0], height=size[1],
        goal_points=goal if marker else None, captions=_captions(run, sim),
        shadows=False, trace=True, **camera,
    )
    out.mkdir(parents=True, exist_ok=True)
    fps = max(4, 2 * fpw)
    write_video(frames.images, out / "execution.mp4", fps)
    write_video(frames.images, out / "execution.gif", fps)
    return frames
