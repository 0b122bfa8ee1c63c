"""Rendered RGB-D recordings of scripted demonstrations, with ground truth.

`render_recording` renders one repetition of MOVE / ROTATE / CLEAN / PAINT
(`cgda_jax.vision.scene`) with MuJoCo from a camera whose intrinsics follow from
the model (fovy, image size), and writes a *recording folder*::

    rgb/frame_0000.png ...    colour frames, 8-bit
    depth/frame_0000.png ...  depth Z, 16-bit PNG in millimetres
    intrinsics.json           `cgda_jax.vision.camera` layout
    recording.json            fps, action, seed, frame count
    truth.csv                 ground truth per frame (`load_csv` format)

The ground truth never looks at the rendered pixels: positions are the marker's
upward face centre from MuJoCo's body pose, in the OpenCV camera frame (metres)
and projected with the intrinsics (pixels); area is the projected face's polygon
(pixels) and the face's true area (m^2); colour is the material's RGBA converted to
OpenCV HSV; angle is the projected long axis of the marker (degrees,
counter-clockwise in the image). ``visible`` is 1 where the marker is fully in the
image and the occluding sheet is away (MuJoCo's segmentation image then also shows
every face pixel as the marker's: checked in the tests).

Depth is MuJoCo's depth render, which `mujoco.Renderer` turns from the OpenGL depth
buffer into linear depth in metres with znear / zfar from ``model.vis.map`` times
``model.stat.extent``. Rendering needs an offscreen OpenGL (``MUJOCO_GL=egl`` or
``osmesa``; see `cgda_jax.sim.render`).

`render_sequence` renders several actions in a row (`scripted_sequence`), with the
true segments in recording.json, and `synthetic_units` turns its track into the
synthetic set's features, for `cgda_jax.segmentation.segment` against the
synthetic action library.
"""

from __future__ import annotations

import json
import pathlib
from collections.abc import Sequence

import mujoco
import numpy as np

from cgda_jax.data import Demonstration, save_csv
from cgda_jax.datasets.synthetic import MARKER_FEATURES
from cgda_jax.sim import make_renderer
from cgda_jax.vision.camera import Intrinsics, save_intrinsics
from cgda_jax.vision.cv import cv2
from cgda_jax.vision.scene import (
    MARKER_HALF,
    SCENE_XML,
    Path,
    scripted_path,
    scripted_sequence,
)
from cgda_jax.vision.track import DEPTH_FEATURES

__all__ = ["TRUTH_FEATURES", "camera_intrinsics", "hsv_to_rgb", "render_recording",
           "render_sequence", "synthetic_units"]

TRUTH_FEATURES = (
    "u_px", "v_px", "X_m", "Y_m", "Z_m", "area_px", "area_m2", "hue_0_180",
    "saturation_0_255", "value_0_255", "angle_deg", "visible",
)
_CAMERA = "rgbd"


def camera_intrinsics(model: mujoco.MjModel, width: int, height: int) -> Intrinsics:
    """Intrinsics of the scene's camera at ``width`` x ``height``: square pixels,
    fy from the vertical field of view, principal point at the image centre."""
    cam = model.camera(_CAMERA)
    f = 0.5 * height / np.tan(np.radians(float(cam.fovy[0])) / 2.0)
    return Intrinsics(width, height, f, f, width / 2.0 - 0.5, height / 2.0 - 0.5)


def hsv_to_rgb(hsv) -> np.ndarray:
    """(3,) OpenCV HSV -> (3,) RGB in [0, 1] (8-bit steps)."""
    px = np.clip(np.round(np.asarray(hsv, float)), 0, [179, 255, 255]).astype(np.uint8)
    bgr = cv2().cvtColor(px.reshape(1, 1, 3), cv2().COLOR_HSV2BGR)[0, 0]
    return bgr[::-1] / 255.0


def _rgba_to_hsv(rgba) -> np.ndarray:
    px = np.round(np.asarray(rgba[:3]) * 255.0).astype(np.uint8)[::-1].reshape(1, 1, 3)
    return cv2().cvtColor(px, cv2().COLOR_BGR2HSV)[0, 0].astype(float)


def _to_camera(data: mujoco.MjData, cam_id: int, points: np.ndarray) -> np.ndarray:
    """World points (..., 3) in the OpenCV camera frame (x right, y down, z ahead)."""
    rot = data.cam_xmat[cam_id].reshape(3, 3)  # columns: camera x, y (up), z (back)
    local = (points - data.cam_xpos[cam_id]) @ rot
    return local * np.array([1.0, -1.0, -1.0])


def _truth(model, data, cam: Intrinsics, cover_away: bool) -> list[float]:
    cam_id = model.camera(_CAMERA).id
    body = model.body("marker").id
    centre = data.xpos[body]
    rot = data.xmat[body].reshape(3, 3)
    hx, hy, hz = MARKER_HALF
    face = centre + rot[:, 2] * hz
    corners = face + np.array(
        [sx * hx * rot[:, 0] + sy * hy * rot[:, 1]
         for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
    )
    ends = face + np.array([hx, -hx])[:, None] * rot[:, 0]
    xyz = _to_camera(data, cam_id, face)
    uv = cam.project(xyz)
    poly = cam.project(_to_camera(data, cam_id, corners))
    x, y = poly[:, 0], poly[:, 1]
    area_px = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    e = cam.project(_to_camera(data, cam_id, ends))
    d = e[0] - e[1]
    angle = np.degrees(np.arctan2(-d[1], d[0]))  # counter-clockwise in the image
    angle = (angle + 90.0) % 180.0 - 90.0
    if angle <= -90.0:
        angle += 180.0
    hsv = _rgba_to_hsv(model.mat_rgba[model.material("marker").id])
    inside = bool(np.all((poly >= 1.0) & (poly <= [cam.width - 2.0, cam.height - 2.0])))
    visible = float(inside and cover_away)
    return [*uv, *xyz, area_px, 4.0 * hx * hy, *hsv, angle, visible]


def _pose(model, data, path: Path, k: int) -> None:
    def quat(yaw):
        return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])

    m, h, c = (model.body(n).mocapid[0] for n in ("marker", "hand", "cover"))
    data.mocap_pos[m, :2] = path.marker_xy[k]
    data.mocap_quat[m] = quat(path.marker_yaw[k])
    data.mocap_pos[h, :2] = path.hand_xy[k]
    data.mocap_quat[h] = quat(path.hand_yaw[k])
    away = bool(np.isnan(path.cover_xy[k]).any())
    data.mocap_pos[c] = [0.0, 0.0, -1.0] if away else [*path.cover_xy[k], 0.08]
    model.mat_rgba[model.material("marker").id, :3] = hsv_to_rgb(path.marker_hsv[k])
    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)


def render_recording(
    folder: str | pathlib.Path,
    action: str,
    seed: int = 0,
    *,
    fps: float = 30.0,
    width: int = 640,
    height: int = 480,
    occlude: bool = False,
    max_frames: int | None = None,
    segmentation: bool = False,
    png_compression: int = 9,
) -> Demonstration:
    """Render one scripted repetition of ``action`` into a recording folder.

    Args:
        folder: the recording folder to write (created; existing frames are replaced).
        action: MOVE, ROTATE, CLEAN or PAINT.
        seed: seed of the repetition's variability (host NumPy).
        fps: frame rate.
        width, height: image size in pixels.
        occlude: a sheet passes over the marker for 4 frames mid-way.
        max_frames: keep only the first ``max_frames`` frames.
        segmentation: also write ``segment.npy``, (T,) the count of pixels MuJoCo's
            segmentation image gives the marker in each frame.
        png_compression: zlib level of the PNG files, 0-9 (9: smallest, slowest).

    Returns:
        The ground truth as a `Demonstration` (also written to ``truth.csv``).

    Raises:
        ValueError: an unknown action.
        RuntimeError: no offscreen OpenGL.
    """
    path = scripted_path(action, np.random.default_rng(seed), fps, occlude=occlude)
    meta = {"fps": fps, "action": action, "seed": seed, "occlude": occlude}
    return _render(folder, path, meta, f"{action}-{seed}", width=width, height=height,
                   max_frames=max_frames, segmentation=segmentation,
                   png_compression=png_compression)


def render_sequence(
    folder: str | pathlib.Path,
    actions: Sequence[str] | None,
    seed: int = 0,
    *,
    fps: float = 8.0,
    width: int = 320,
    height: int = 240,
    pause_s: tuple[float, float] = (0.0, 0.0),
    light_end: float = 1.0,
    png_compression: int = 1,
) -> tuple[Demonstration, list[tuple[str, float, float]]]:
    """Render several scripted actions in a row (`scripted_sequence`: each starts
    where the previous left the marker; with or without pauses) into a recording
    folder, as `render_recording` writes one; ``recording.json`` also holds the
    true ``"segments"``: ``[action, start_s, end_s]`` of each motion.

    Args:
        folder: the recording folder to write.
        actions: the action names in order (at most one PAINT), or None: 2 to 6
            drawn at random (`scripted_sequence`).
        seed: seed of the repetitions' variability and placement.
        fps, width, height, png_compression: as `render_recording` (defaults kept
            small: rendering is the cost).
        pause_s: (shortest, longest) rest between two actions in seconds.
        light_end: the light (ambient and diffuse) at the last frame as a share of
            the first, falling linearly (1: steady; 0.7: 30 % darker by the end,
            the marker's value with it).

    Returns:
        The ground truth per frame (a `Demonstration`; its colour is the
        material's, not the dimmed one) and the true segments.

    Raises:
        ValueError: an unknown action, two PAINTs, a path that does not fit in the
            view (`scripted_sequence`), a light_end outside (0, 1].
        RuntimeError: no offscreen OpenGL.
    """
    if not 0.0 < light_end <= 1.0:
        raise ValueError(f"light_end must be in (0, 1], got {light_end!r}")
    path, truth = scripted_sequence(actions, np.random.default_rng(seed), fps,
                                    pause_s=pause_s)
    meta = {"fps": fps, "actions": [a for a, _, _ in truth], "seed": seed,
            "pause_s": list(pause_s), "light_end": light_end,
            "segments": [list(s) for s in truth]}
    light = np.linspace(1.0, light_end, len(path.times))
    demo = _render(folder, path, meta, f"sequence-{seed}", width=width,
                   height=height, png_compression=png_compression, light=light)
    return demo, truth


def synthetic_units(track: Demonstration) -> Demonstration:
    """A track of a recording of this scene (`track_video` with depth and the
    folder's intrinsics: `DEPTH_FEATURES`) in the features and units of the
    synthetic set (`cgda_jax.datasets.synthetic.MARKER_FEATURES`), so the synthetic
    action library recognizes it: X, Y, Z in millimetres in the synthetic set's
    camera frame (X right, Y away from the demonstrator: up the image, the OpenCV
    frame's -Y; Z depth), area in pixels, hue, saturation, value, angle in degrees
    (counter-clockwise in the image, as both measure it).

    Raises:
        ValueError: a demonstration without the tracker's depth features (names the
            missing ones).
    """
    names = track.feature_names
    missing = [n for n in DEPTH_FEATURES if n not in names]
    if missing:
        raise ValueError(f"{track.name!r}: not a track with depth (no {missing}); "
                         "track the recording with its depth folder and intrinsics")
    col = {n: track.features[:, names.index(n)] for n in DEPTH_FEATURES}
    x = np.stack([1000.0 * col["X_m"], -1000.0 * col["Y_m"], 1000.0 * col["Z_m"],
                  col["area_px"], col["hue_0_180"], col["saturation_0_255"],
                  col["value_0_255"], col["angle_deg"]], 1)
    return Demonstration(track.times, x, MARKER_FEATURES, track.name)


def _render(folder, path: Path, meta: dict, name: str, *, width: int, height: int,
            max_frames: int | None = None, segmentation: bool = False,
            png_compression: int = 9, light: np.ndarray | None = None) -> Demonstration:
    """Render ``path`` into a recording folder (module doc); ``meta`` goes into
    recording.json with the frame count; ``light`` (T,): the scene light's
    ambient and diffuse per frame as a share of the model's."""
    folder = pathlib.Path(folder).expanduser()
    n = len(path.times) if max_frames is None else min(int(max_frames), len(path.times))
    model = mujoco.MjModel.from_xml_string(SCENE_XML)
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    data = mujoco.MjData(model)
    cam = camera_intrinsics(model, width, height)
    for sub in ("rgb", "depth"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
        for old in (folder / sub).glob("frame_*.png"):
            old.unlink()
    png = (cv2().IMWRITE_PNG_COMPRESSION, int(png_compression))
    renderers = [make_renderer(model, height, width) for _ in range(2 + segmentation)]
    renderers[1].enable_depth_rendering()
    if segmentation:
        renderers[2].enable_segmentation_rendering()
    rows, seg_counts = [], []
    marker_geom = model.geom("marker").id
    try:
        ambient, diffuse = model.light_ambient.copy(), model.light_diffuse.copy()
        for k in range(n):
            if light is not None:
                model.light_ambient[:] = ambient * light[k]
                model.light_diffuse[:] = diffuse * light[k]
            _pose(model, data, path, k)
            images = []
            for r in renderers:
                r.update_scene(data, camera=_CAMERA)
                images.append(r.render())
            rgb, depth = images[:2]
            if segmentation:
                seg = images[2]
                seg_counts.append(int(np.sum(
                    (seg[..., 0] == marker_geom) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)
                )))
            name = f"frame_{k:04d}.png"
            cv2().imwrite(str(folder / "rgb" / name), rgb[..., ::-1], png)
            mm = np.round(np.nan_to_num(depth, nan=0.0) * 1000.0)
            cv2().imwrite(str(folder / "depth" / name),
                          np.clip(mm, 0, 65535).astype(np.uint16), png)
            rows.append(_truth(model, data, cam, bool(np.isnan(path.cover_xy[k]).any())))
    finally:
        for r in renderers:
            r.close()
    save_intrinsics(cam, folder / "intrinsics.json")
    (folder / "recording.json").write_text(
        json.dumps({**meta, "frames": n}) + "\n", encoding="utf-8")
    if segmentation:
        np.save(folder / "segment.npy", np.asarray(seg_counts))
    truth = Demonstration(path.times[:n], np.asarray(rows), TRUTH_FEATURES, name)
    save_csv(truth, folder / "truth.csv")
    return truth
