"""Offscreen rendering of an executed trajectory to PNG frames or an animated GIF.

Uses ``mujoco.Renderer`` (MuJoCo C, on the host), which needs an offscreen OpenGL:
set ``MUJOCO_GL`` BEFORE the first ``import mujoco`` of the process, e.g.

    MUJOCO_GL=egl python my_script.py      # Debian/Ubuntu: apt-get install libegl1
                                           # (Mesa's EGL or the NVIDIA driver's)
    MUJOCO_GL=osmesa python my_script.py   # software: apt-get install libosmesa6

Without it MuJoCo tries GLFW, which needs a display.  The scene's decorations (the
paint wall's squares, red once painted) are drawn into each frame.

Frames follow the simulator: in kinematic mode the joint-space interpolation from
each posture to the next waypoint (``frames_per_waypoint`` frames, the last at the
waypoint); in dynamic mode MuJoCo C runs the same position-actuator physics
on the simulated model (`cgda_jax.sim.physics`: ``physics_steps`` ``mj_step`` calls
per waypoint tracking the same minimum-jerk reference) and frames are sampled from it.
"""

from __future__ import annotations

import pathlib
from collections.abc import Sequence

import mujoco
import numpy as np

__all__ = ["render_trajectory"]

_GEOM = {"box": mujoco.mjtGeom.mjGEOM_BOX, "sphere": mujoco.mjtGeom.mjGEOM_SPHERE}


def _check_gl_backend() -> None:
    """Refuse GLFW without a display: ``mujoco`` fixed its GL back-end when it was first
    imported, and a process that imported it before ``MUJOCO_GL`` was chosen (see
    `cgda_jax.sim._mujoco_env.choose_gl_backend`) would get GLFW, whose context creation
    can abort the whole process on a headless machine instead of raising."""
    import os
    import sys

    from mujoco import gl_context

    headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if (sys.platform.startswith("linux") and headless
            and gl_context.GLContext.__module__.endswith("glfw")):
        raise RuntimeError(
            "mujoco was imported with the GLFW back-end, which needs a display; set "
            "MUJOCO_GL=egl (package libegl1) or MUJOCO_GL=osmesa (package libosmesa6) "
            "before mujoco is first imported (import cgda_jax first does it for you)")


def _renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    _check_gl_backend()
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    try:
        return mujoco.Renderer(model, height=height, width=width)
    except Exception as err:  # GL back-ends raise various types
        raise RuntimeError(
            "cannot create an offscreen MuJoCo renderer "
            f"({type(err).__name__}: {err}); set MUJOCO_GL=egl (package libegl1) or "
            "MUJOCO_GL=osmesa (package libosmesa6) before importing mujoco"
        ) from err


def _camera(sim, lookat, distance, azimuth, elevation) -> mujoco.MjvCamera:
    model = sim.robot.mj_model
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    if lookat is None:
        points = [np.asarray(model.stat.center)]
        centres = getattr(sim.scene, "centres", None)
        if centres is not None:
            points.append(np.asarray(centres).mean(axis=0))
        lookat = np.mean(points, axis=0)
    cam.lookat[:] = lookat
    cam.distance = float(distance if distance is not None else 2.5 * model.stat.extent)
    cam.azimuth = float(azimuth)
    cam.elevation = float(elevation)
    return cam


def _add_decorations(scene: mujoco.MjvScene, decorations) -> None:
    for kind, half, pos, rgba in decorations:
        if scene.ngeom >= scene.maxgeom:
            return
        mujoco.mjv_initGeom(
            scene.geoms[scene.ngeom],
            _GEOM[kind],
            np.asarray(half, np.float64),
            np.asarray(pos, np.float64),
            np.eye(3).ravel(),
            np.asarray(rgba, np.float32),
        )
        scene.ngeom += 1


def _postures(sim, waypoints: np.ndarray, frames_per_waypoint: int):
    """Yield (qpos (nq,) of `_model(sim)`, marker positions since the last frame
    (K, 3)) per frame."""
    robot = sim.robot
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    genes = np.clip(robot.start_genes, lo, hi)  # where `Simulator.init_state` starts
    if sim.mode == "dynamic":  # MuJoCo C on the simulated model, same reference
        phys = sim.physics
        model, data = phys.model, mujoco.MjData(phys.model)

        def ctrl(g):
            q = phys.qpos0.copy()
            q[phys.gene_qadr] = g
            return q[phys.act_qadr]

        data.qpos[:] = phys.qpos0
        data.qpos[phys.gene_qadr] = genes
        mujoco.mj_kinematics(model, data)
        yield data.qpos.copy(), data.site_xpos[phys.site_id][None].copy()
        every = max(1, sim.physics_steps // frames_per_waypoint)
        prev = ctrl(genes)
        for wp in waypoints:
            target = ctrl(np.clip(wp, lo, hi))
            trail = []
            for k in range(1, sim.physics_steps + 1):
                data.ctrl[:] = prev + float(sim._profile[k - 1]) * (target - prev)
                mujoco.mj_step(model, data)
                mujoco.mj_kinematics(model, data)
                trail.append(data.site_xpos[phys.site_id].copy())
                if k % every == 0 or k == sim.physics_steps:
                    yield data.qpos.copy(), np.array(trail)
                    trail = []
            prev = target
        return
    model = robot.mj_model
    data = mujoco.MjData(model)
    data.qpos[:] = np.asarray(robot.qpos0, np.float64)
    data.qpos[robot.qpos_adr] = genes
    mujoco.mj_kinematics(model, data)
    yield data.qpos.copy(), data.site_xpos[robot.site_id][None].copy()
    n, k_sub = frames_per_waypoint, sim.substeps

    def marker(alpha):
        data.qpos[robot.qpos_adr] = genes + alpha * (wp - genes)
        mujoco.mj_kinematics(model, data)
        return data.site_xpos[robot.site_id].copy()

    for wp in waypoints:
        wp = np.clip(wp, lo, hi)
        # the trail holds the simulator's sub-steps since the previous frame
        subs = [marker(j / k_sub) for j in range(1, k_sub + 1)]
        for k in range(1, n + 1):
            trail = subs[(k - 1) * k_sub // n:k * k_sub // n]
            marker(k / n)
            yield data.qpos.copy(), np.array(trail).reshape(-1, 3)
        genes = wp


def _model(sim) -> mujoco.MjModel:
    """The model that is drawn: the simulated one in dynamic mode."""
    return sim.physics.model if sim.mode == "dynamic" else sim.robot.mj_model


def _scene_states(scene, trails: list[np.ndarray]) -> list:
    """The scene state after each frame's marker trail (K_i, 3), on the host.

    A scene with ``sweep`` (a paint wall) sees the polyline through every marker
    of every trail at once, as the simulator's moves do (`PaintWall.near_segment`
    per segment, painted for good); other scenes go through ``scene.update`` per
    marker.
    """
    state = scene.init_state()
    if hasattr(scene, "near_segment"):
        markers = np.concatenate(trails).astype(np.float32)  # (K, 3) as simulated
        hit = np.asarray(scene.near(markers[0]), bool)[None]
        if len(markers) > 1:
            seg = np.asarray(scene.near_segment(markers[:-1], markers[1:]), bool)
            hit = np.concatenate([hit, seg])
        hit = np.logical_or.accumulate(hit, axis=0) | np.asarray(state, bool)
        ends = np.cumsum([len(t) for t in trails]) - 1
        return [hit[k] for k in ends]
    out = []
    for trail in trails:
        for marker in trail:
            state = scene.update(state, np.asarray(marker, np.float32))
        out.append(state)
    return out


def render_trajectory(
    sim,
    waypoints,
    out_path: str | pathlib.Path,
    *,
    frames_per_waypoint: int | None = None,
    width: int = 480,
    height: int = 360,
    fps: int = 12,
    lookat: Sequence[float] | None = None,
    distance: float | None = None,
    azimuth: float = 35.0,
    elevation: float = -20.0,
) -> list[pathlib.Path]:
    """Render the robot executing ``waypoints`` offscreen.

    Args:
        sim: a `Simulator` (its robot, scene and mode are used).
        waypoints: (N, DoF) joint values, clipped into the limits as in execution.
        out_path: a ``.gif`` file (animated; falls back to PNG frames in a folder of
            the same stem when Pillow is missing), or a folder for ``frame_0000.png``...
        frames_per_waypoint: frames per waypoint (default ``sim.substeps``; the paint
            state follows every kinematic sub-step or physics step, as simulated,
            whatever the frames).
        width, height: image size in pixels.
        fps: GIF frame rate.
        lookat, distance, azimuth, elevation: free camera (defaults frame the robot
            and the wall from behind its right shoulder).

    Returns:
        The files written.

    Raises:
        ValueError: waypoints of the wrong shape.
        RuntimeError: no offscreen OpenGL (see the module doc for ``MUJOCO_GL``).
    """
    waypoints = np.asarray(waypoints, dtype=np.float64)
    sim._check_waypoints(waypoints)
    frames_per_waypoint = int(frames_per_waypoint or sim.substeps)
    out_path = pathlib.Path(out_path).expanduser()
    model = _model(sim)
    data = mujoco.MjData(model)
    cam = _camera(sim, lookat, distance, azimuth, elevation)
    scene = sim.scene

    postures = list(_postures(sim, waypoints, frames_per_waypoint))
    states = _scene_states(scene, [trail for _, trail in postures])
    images = []
    renderer = _renderer(model, height, width)
    try:
        for (qpos, _), state in zip(postures, states):
            data.qpos[:] = qpos
            mujoco.mj_kinematics(model, data)
            renderer.update_scene(data, camera=cam)
            _add_decorations(renderer.scene, scene.decorations(state))
            images.append(renderer.render().copy())
    finally:
        renderer.close()
    return _write(images, out_path, fps)


def _write(
    images: list[np.ndarray], out_path: pathlib.Path, fps: int
) -> list[pathlib.Path]:
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - matplotlib ships with Pillow
        Image = None
    if out_path.suffix.lower() == ".gif" and Image is not None:
        out_path.parent.mkdir(parents=True, exist_ok=True)
        frames = [Image.fromarray(img) for img in images]
        frames[0].save(
            out_path,
            save_all=True,
            append_images=frames[1:],
            duration=int(1000 / fps),
            loop=0,
        )
        return [out_path]
    folder = out_path.with_suffix("") if out_path.suffix else out_path
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for i, img in enumerate(images):
        path = folder / f"frame_{i:04d}.png"
        if Image is not None:
            Image.fromarray(img).save(path)
        else:  # pragma: no cover
            import matplotlib.image

            matplotlib.image.imsave(path, img)
        written.append(path)
    return written
