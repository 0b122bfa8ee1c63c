"""Results of a run: JSON writing, plots, rendered frames and ``report.md``."""

from __future__ import annotations

import json
import logging
import math
import os
import pathlib
from typing import Any

import numpy as np

from cgda_jax.experiment.config import ExperimentConfig

log = logging.getLogger("cgda_jax")


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _write_json(path: pathlib.Path, data: dict) -> None:
    path.write_text(json.dumps(_jsonable(data), indent=2) + "\n")


def _close_all() -> None:
    import matplotlib.pyplot as plt

    plt.close("all")


def render_execution(cfg: ExperimentConfig, folder: pathlib.Path, joints, sim,
                     *, width: int = 320, height: int = 240, n_strip: int = 8) -> dict:
    """The robot executing ``joints`` (N, DoF): ``execution.gif`` + ``frames.png``.

    Never raises: when offscreen OpenGL (or anything else in rendering) fails,
    logs one warning on the ``cgda_jax`` logger and returns ``{"ok": False,
    "reason": ...}``; otherwise ``{"ok": True, "gif": ..., "frames": ..., "backend": ...}``
    (paths relative to the results folder).
    """
    joints = np.asarray(joints, np.float32)
    paint = getattr(sim.scene, "centres", None) is not None
    # the paint wall sees every sub-step whatever the frames (render._postures)
    fpw = min(int(sim.substeps), 8) if paint and sim.mode == "kinematic" else 3
    distance = None if paint else 1.6 * float(sim.robot.mj_model.stat.extent)
    camera: dict[str, Any] = {"distance": distance}
    path = getattr(sim.scene, "goal_path", None)
    if path is not None:  # objects: look at them and the hand, from their side
        hand = np.asarray(sim.robot.marker_position(sim.robot.start_genes), float)
        points = np.vstack([np.asarray(path, float), hand[None]])
        centre = (2.0 * points[:-1].mean(axis=0) + hand) / 3.0
        spread = float(np.linalg.norm(points - centre, axis=1).max())
        camera = {"lookat": centre, "elevation": -35.0,
                  "distance": max(0.6, 3.5 * spread),
                  "azimuth": math.degrees(math.atan2(-centre[1], -centre[0])) + 30.0}
    try:
        from PIL import Image

        from cgda_jax import plotting
        from cgda_jax.sim.render import render_trajectory

        gif = folder / "execution.gif"
        render_trajectory(sim, joints, gif, frames_per_waypoint=fpw, width=width,
                          height=height, fps=max(4, 2 * fpw), **camera)
        with Image.open(gif) as im:
            n_frames = getattr(im, "n_frames", 1)
            points = np.unique(np.linspace(0, len(joints), min(n_strip, len(joints) + 1))
                               .round().astype(int))
            frames = []
            for k in points:
                im.seek(min(int(k) * fpw, n_frames - 1))
                frames.append(np.asarray(im.convert("RGB")))
        plotting.plot_frames(
            frames, labels=["start" if k == 0 else f"point {k}" for k in points],
            title=f"{cfg.name}: robot executing the best trajectory",
            path=folder / "frames.png",
        )
        _close_all()
    except Exception as err:  # no GL, missing library, driver trouble: never fatal
        reason = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
        log.warning("%s: frames not rendered (%s); set MUJOCO_GL=egl or osmesa, or "
                    "output.render=false", cfg.name, reason)
        return {"ok": False, "reason": reason}
    return {"ok": True, "gif": "plots/execution.gif", "frames": "plots/frames.png",
            "backend": os.environ.get("MUJOCO_GL", "")}


def _execution_plots(cfg, plots: pathlib.Path, res, sim, demos, gen) -> None:
    from cgda_jax import plotting

    names = list(sim.feature_names)
    plotting.plot_goal_vs_executed(
        res.goal, res.features, names, tolerance=res.tolerance,
        title=f"{cfg.name}: goal vs executed ({res.strategy.upper()})",
        path=plots / "goal_vs_executed.png",
    )
    hist = np.asarray(res.fitness_history, float)
    plotting.plot_fitness(
        hist, labels=None if hist.ndim == 1 else [f"point {i}" for i in range(len(hist))],
        title=f"{cfg.name}: best fitness per generation", path=plots / "fitness.png",
    )
    if demos:  # 3 features: in 3-D (paper Fig. 7); else one panel per feature
        plotting.plot_demonstrations(
            demos, gen, res.features, title=f"{cfg.name}: demos, goal, executed",
            path=plots / ("trajectory_3d.png" if len(names) == 3
                          else "demonstrations.png"),
        )
    per_point = res.info.get("point_generations") if isinstance(res.info, dict) else None
    if per_point is not None and hist.ndim == 2:
        plotting.plot_time_per_point(
            per_point, ylabel="generations per point",
            title=f"{cfg.name}: effort per point", path=plots / "effort_per_point.png",
        )
    _close_all()


def _report(cfg: ExperimentConfig, result: dict) -> str:
    lines = [f"# {cfg.name}", ""]
    if cfg.description:
        lines += [cfg.description, ""]
    if result["kind"] == "recognition":
        acts = result["actions"]
        lines += [
            f"Recognition, {len(result['features'])} features "
            f"({', '.join(result['features'])}), metric {result['metric']}.",
            "",
            "| test \\ generalized | " + " | ".join(acts) + " |",
            "|---" * (len(acts) + 1) + "|",
        ]
        for q, row in zip(result["truth"], np.asarray(result["cost_matrix"])):
            best = int(np.argmin(row))
            cells = [f"**{v:.4g}**" if j == best else f"{v:.4g}" for j, v in enumerate(row)]
            lines.append(f"| {q.lower()} | " + " | ".join(cells) + " |")
        lines += ["", f"Accuracy: {result['accuracy']:.0%}."]
    else:
        lines += [
            f"Strategy {result['strategy'].upper()} ({cfg.strategy.algorithm}, population "
            f"{cfg.strategy.population_size}) on {cfg.robot.model}, joints "
            f"{', '.join(cfg.robot.joints)}.",
            "",
            "| figure | value |", "|---|---|",
            f"| success | {result['success']} |",
            f"| points | {result['points']} |",
            f"| max point error | {result['max_point_error']:.4g} "
            f"(tolerance {result['tolerance']:.4g}) |",
            f"| final fitness | {result['final_fitness']:.4g} |",
            f"| generations | {result['generations']} |",
            f"| evaluations | {result['evaluations']} |",
            f"| run time (compiled generations) | {result['wall_time_s']:.2f} s |",
            f"| compile time | {result['compile_time_s']:.2f} s |",
        ]
        if result.get("invalid_evaluations"):
            lines += [f"| diverged (invalid) evaluations | "
                      f"{result['invalid_evaluations']} of {result['evaluations']} |"]
        phys, replay = result.get("physics"), result.get("replay")
        if phys:
            lines += [
                f"| physics | {phys['backend']}, {phys['waypoint_s']:.3g} s per "
                f"waypoint, timestep {phys['timestep']:g} s, "
                f"{len(phys['welded_joints'])} joints welded |",
            ]
        if result.get("substeps"):
            lines += [f"| kinematic sub-steps per waypoint | {result['substeps']} |"]
        if replay:
            where = (f"timestep {replay['timestep']:g} s (MuJoCo C)"
                     if "timestep" in replay
                     else f"{replay['substeps']} sub-steps per waypoint")
            lines += [
                f"| replay at {where} | "
                f"success {replay['success']}, max point error "
                f"{replay['max_point_error']:.4g}, max feature difference "
                f"{replay['max_feature_difference']:.3g} |",
            ]
        render = result.get("render")
        if render and render.get("ok"):
            lines += ["", "The robot executing the best trajectory (paper Fig. 8/11):", "",
                      f"![robot executing]({render['gif']})"]
        elif render:
            lines += ["", f"Frames not rendered: {render['reason']} (set MUJOCO_GL=egl "
                      "or osmesa; `output.render = false` turns rendering off)."]
    plots = sorted(p for p in result.get("plots", []))
    if plots:
        lines += ["", "Plots:", ""] + [f"![{p}]({p})" for p in plots]
    return "\n".join(lines) + "\n"
