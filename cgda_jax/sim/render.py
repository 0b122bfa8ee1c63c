"""Offscreen rendering of an executed trajectory to images, an MP4 or GIF video, or
PNG frames.

Uses ``mujoco.Renderer`` (MuJoCo C, on the host), which needs an offscreen OpenGL.
On a headless Linux machine with ``MUJOCO_GL`` unset the back-end is chosen when
rendering: EGL (Debian/Ubuntu: apt-get install libegl1, Mesa's or the NVIDIA
driver's), else OSMesa (software: apt-get install libosmesa6); see
`cgda_jax.sim._mujoco_env.make_renderer`.  ``MUJOCO_GL=egl`` or ``osmesa`` set
before the first ``import mujoco`` of the process is used as given, and so is
GLFW where a display exists.  The scene's decorations (the
paint wall's squares, red once painted) are drawn into each frame.  ``shadows=False``
halves a frame's time in software OpenGL (the 4096-pixel shadow map) and changes no
pixel of the built-in scenes (marker, paint wall, table and objects): the results
folders' videos (`cgda_jax.experiment.figures.render_run`) are drawn without them; a
model of your own with a floor keeps its shadows by default.

Frames follow the simulator: in kinematic mode the joint-space interpolation from
each posture to the next waypoint (``frames_per_waypoint`` frames, the last at the
waypoint); in dynamic mode MuJoCo C runs the same position-actuator physics
on the simulated model (`cgda_jax.sim.physics`: ``physics_steps`` ``mj_step`` calls
per waypoint tracking the same minimum-jerk reference) and frames are sampled from it.
"""

from __future__ import annotations

import dataclasses
import pathlib
from collections.abc import Callable, Sequence

import mujoco
import numpy as np

from cgda_jax.sim._mujoco_env import make_renderer
from cgda_jax.sim.video import caption, write_video

__all__ = ["Frames", "render_frames", "render_trajectory"]

_GEOM = {"box": mujoco.mjtGeom.mjGEOM_BOX, "sphere": mujoco.mjtGeom.mjGEOM_SPHERE}


def _renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    return make_renderer(model, height, width)  # chooses the GL back-end now


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
    (K, 3), k) per frame: k = 0 at the start, k = j while moving to (and at) the
    j-th waypoint (from 1)."""
    robot = sim.robot
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    genes = np.clip(robot.start_genes, lo, hi)  # where `Simulator.init_state` starts
    if sim.mode == "dynamic":  # MuJoCo C on the simulated model, same reference
        from cgda_jax.sim.host_replay import replay_steps

        phys = sim.physics
        model, data = phys.model, mujoco.MjData(phys.model)
        data.qpos[:] = phys.qpos0
        data.qpos[phys.gene_qadr] = genes
        mujoco.mj_kinematics(model, data)
        yield data.qpos.copy(), data.site_xpos[phys.site_id][None].copy(), 0
        trail: list = []
        for st in replay_steps(sim, waypoints):
            d = st.data
            mujoco.mj_kinematics(st.model, d)
            trail.append(d.site_xpos[phys.site_id].copy())
            every = max(1, st.steps // frames_per_waypoint)
            if st.step % every == 0 or st.last:
                yield d.qpos.copy(), np.array(trail), st.move
                trail = []
        return
    model = robot.mj_model
    data = mujoco.MjData(model)
    data.qpos[:] = np.asarray(robot.qpos0, np.float64)
    data.qpos[robot.qpos_adr] = genes
    mujoco.mj_kinematics(model, data)
    yield data.qpos.copy(), data.site_xpos[robot.site_id][None].copy(), 0
    n, k_sub = frames_per_waypoint, sim.substeps

    def marker(alpha):
        data.qpos[robot.qpos_adr] = genes + alpha * (wp - genes)
        mujoco.mj_kinematics(model, data)
        return data.site_xpos[robot.site_id].copy()

    for j, wp in enumerate(waypoints, start=1):
        wp = np.clip(wp, lo, hi)
        # the trail holds the simulator's sub-steps since the previous frame
        subs = [marker(i / k_sub) for i in range(1, k_sub + 1)]
        for k in range(1, n + 1):
            trail = subs[(k - 1) * k_sub // n:k * k_sub // n]
            marker(k / n)
            yield data.qpos.copy(), np.array(trail).reshape(-1, 3), j
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


@dataclasses.dataclass
class Frames:
    """Rendered frames of an execution.

    Attributes:
        images: (H, W, 3) uint8 images, one per frame.
        points: (len(images),) int: 0 for the start frame, j for the frames moving to
            (and, the last of them, at) the j-th waypoint = goal point j (from 1).
    """

    images: list[np.ndarray]
    points: np.ndarray

    def at_points(self) -> list[int]:
        """Index of the frame at the start and at each waypoint (the last frame of
        each ``points`` value)."""
        p = np.asarray(self.points)
        return [int(np.flatnonzero(p == k)[-1]) for k in np.unique(p)]


def _goal_decorations(goal_points, current: int) -> list:
    """Goal points (K, 3) as spheres: the one being reached (``current``, from 1)
    yellow and larger, the others translucent green."""
    out = []
    for j, pos in enumerate(np.asarray(goal_points, np.float64), start=1):
        if j == current:
            out.append(("sphere", np.full(3, 0.016), pos, (1.0, 0.85, 0.0, 0.95)))
        else:
            out.append(("sphere", np.full(3, 0.011), pos, (0.1, 0.8, 0.2, 0.55)))
    return out


def render_frames(
    sim,
    waypoints,
    *,
    frames_per_waypoint: int | None = None,
    width: int = 640,
    height: int = 480,
    lookat: Sequence[float] | None = None,
    distance: float | None = None,
    azimuth: float = 35.0,
    elevation: float = -20.0,
    goal_points=None,
    captions: Callable[[int, object, bool], str] | None = None,
    shadows: bool = True,
    trace: bool = False,
) -> Frames:
    """Render the robot executing ``waypoints`` offscreen, in memory.

    Args:
        sim: a `Simulator` (its robot, scene and mode are used).
        waypoints: (N, DoF) joint values, clipped into the limits as in execution.
        frames_per_waypoint: frames per waypoint (default ``sim.substeps``; the paint
            state follows every kinematic sub-step or physics step, as simulated,
            whatever the frames).
        width, height: image size in pixels.
        lookat, distance, azimuth, elevation: free camera (defaults frame the robot
            and the wall from behind its right shoulder).
        goal_points: optional (K, 3) world positions drawn as spheres (e.g. the goal
            of the marker scene); the one being reached is highlighted.
        captions: optional ``captions(point, scene_state, reached) -> str`` written
            in the image's top left corner (point: 0 at the start, j towards
            waypoint j; ``reached``: the frame ends the move, the waypoint reached).
        shadows: draw the lights' shadows (off: faster, see the module doc).
        trace: draw the path the marker has executed so far (small red spheres
            at the simulated sub-steps).

    A model whose headlight is dim (a dark scene) is drawn with at least a
    moderate headlight (`MIN_HEADLIGHT`); the model is left as it was.

    Raises:
        ValueError: waypoints of the wrong shape.
        RuntimeError: no offscreen OpenGL (see the module doc for ``MUJOCO_GL``).
    """
    from cgda_jax.sim.sim_state import check_waypoints

    waypoints = np.asarray(waypoints, dtype=np.float64)
    check_waypoints(waypoints, sim.robot)
    frames_per_waypoint = int(frames_per_waypoint or sim.substeps)
    model = _model(sim)
    data = mujoco.MjData(model)
    cam = _camera(sim, lookat, distance, azimuth, elevation)
    scene = sim.scene

    postures = list(_postures(sim, waypoints, frames_per_waypoint))
    states = _scene_states(scene, [trail for _, trail, _ in postures])
    ks = [k for _, _, k in postures]
    ends = {len(ks) - 1 - ks[::-1].index(k) for k in set(ks)}  # a move's last frame
    images, points, path = [], [], []
    light = model.vis.headlight
    kept = (light.ambient.copy(), light.diffuse.copy())
    light.ambient[:] = np.maximum(light.ambient, MIN_HEADLIGHT[0])
    light.diffuse[:] = np.maximum(light.diffuse, MIN_HEADLIGHT[1])
    renderer = _renderer(model, height, width)
    renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = bool(shadows)
    if trace:  # the floor would mirror the path: one path, not two
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
    try:
        for i, ((qpos, trail, k), state) in enumerate(zip(postures, states)):
            data.qpos[:] = qpos
            mujoco.mj_kinematics(model, data)
            renderer.update_scene(data, camera=cam)
            decorations = list(scene.decorations(state))
            if goal_points is not None:
                decorations += _goal_decorations(goal_points, k)
            if trace:
                path += [np.asarray(p, np.float64) for p in np.reshape(trail, (-1, 3))]
                decorations += _path_decorations(path)
            _add_decorations(renderer.scene, decorations)
            img = renderer.render().copy()
            if captions is not None:
                img = caption(img, captions(k, state, i in ends))
            images.append(img)
            points.append(k)
    finally:
        renderer.close()
        light.ambient[:], light.diffuse[:] = kept
    return Frames(images, np.asarray(points, int))


#: The least headlight (ambient, diffuse) a render uses: a model's dimmer one (a
#: scene lit only by its own lights, e.g. MuJoCo's humanoid) would draw it dark.
MIN_HEADLIGHT = (0.35, 0.55)


def _path_decorations(path: list[np.ndarray], most: int = 400) -> list:
    """The executed marker path (K, 3) as small red spheres (at most ``most``, the
    newest kept, evenly thinned)."""
    step = max(1, -(-len(path) // most))
    return [("sphere", np.full(3, 0.005), p, (0.9, 0.15, 0.1, 0.9))
            for p in path[::-1][::step][::-1]]


def render_trajectory(
    sim,
    waypoints,
    out_path: str | pathlib.Path,
    *,
    frames_per_waypoint: int | None = None,
    width: int = 640,
    height: int = 480,
    fps: int = 12,
    lookat: Sequence[float] | None = None,
    distance: float | None = None,
    azimuth: float = 35.0,
    elevation: float = -20.0,
    goal_points=None,
    captions: Callable[[int, object, bool], str] | None = None,
    shadows: bool = True,
    trace: bool = False,
) -> list[pathlib.Path]:
    """Render the robot executing ``waypoints`` offscreen into a file or folder.

    Args:
        out_path: an ``.mp4`` or ``.gif`` file (see `cgda_jax.sim.video.write_video`),
            or a folder for ``frame_0000.png``...
        fps: frame rate of the video.
        The others: as `render_frames`.

    Returns:
        The files written.

    Raises:
        ValueError: waypoints of the wrong shape.
        RuntimeError: no offscreen OpenGL (see the module doc for ``MUJOCO_GL``).
    """
    frames = render_frames(
        sim, waypoints, frames_per_waypoint=frames_per_waypoint, width=width,
        height=height, lookat=lookat, distance=distance, azimuth=azimuth,
        elevation=elevation, goal_points=goal_points, captions=captions,
        shadows=shadows, trace=trace,
    )
    return write_video(frames.images, pathlib.Path(out_path).expanduser(), fps)
