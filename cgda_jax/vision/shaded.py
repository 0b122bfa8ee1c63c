"""Rendered clips of a coloured solid under shading and changing light, with ground
truth from MuJoCo's segmentation image (for the tracker's tests and benchmark).

The scene: a grey table seen obliquely (camera 0.55 m from the table's centre, 50
degrees above it, 45 degree vertical field of view), a coloured box (5 x 3.6 x 3 cm)
or cylinder (radius 2.2 cm, height 4 cm) sliding along a quarter-circle arc while it
turns by ``turn_deg`` about its vertical axis. The camera sees the solid's top and
two or three of its sides, so faces of one material are drawn at very different
brightness. Light: a directional "sun" (diffuse 0.7, specular 0.3) and an ambient
fill (0.3), no shadows; a face the sun does not reach is drawn at about 0.3 of the
top face's brightness. With ``light="move"`` the sun's direction swings from 50
degrees to the camera's left to 50 degrees to its right (faces brighten and darken
in turn, highlights move); with ``light="dim"`` it stays above and both fall over
the clip (sun 0.7 -> 0.2, fill 0.3 -> 0.15: the scene 2.7 times darker).

Ground truth never comes from colour: the solid's pixels are those the segmentation
render gives its geom (``area_px`` their count, ``u_px``, ``v_px`` their mean
column and row, pixel centres at integer coordinates as in OpenCV's moments). The
colour image is anti-aliased (MuJoCo's default multisampling), so its rim pixels
mix with the table; the segmentation image is not.
"""

from __future__ import annotations

import dataclasses
import pathlib

import mujoco
import numpy as np

from cgda_jax.sim import make_renderer
from cgda_jax.vision.cv import cv2

__all__ = ["SOLIDS", "ShadedClip", "render_shaded", "shaded_scene_xml"]

SOLIDS = {
    "box": 'type="box" size="0.025 0.018 0.015"',
    "cylinder": 'type="cylinder" size="0.022 0.02"',
}
LIGHTS = ("move", "dim")
_HALF_HEIGHT = {"box": 0.015, "cylinder": 0.02}


def shaded_scene_xml(solid: str = "box", rgba=(0.8, 0.1, 0.1)) -> str:
    """The scene's MJCF (module doc) with a ``solid`` of colour ``rgba`` (RGB 0-1)."""
    if solid not in SOLIDS:
        raise ValueError(f"unknown solid {solid!r}; expected one of {tuple(SOLIDS)}")
    r, g, b = (float(c) for c in rgba[:3])
    return f"""
<mujoco model="shaded">
  <visual>
    <headlight ambient="0 0 0" diffuse="0 0 0" specular="0 0 0"/>
    <global offwidth="640" offheight="480"/>
    <map znear="0.01" zfar="5"/>
  </visual>
  <statistic extent="1" center="0 0 0"/>
  <asset>
    <material name="table" rgba="0.55 0.55 0.55 1" specular="0.1" shininess="0.2"/>
    <material name="solid" rgba="{r} {g} {b} 1" specular="0.3" shininess="0.4"/>
  </asset>
  <worldbody>
    <light name="fill" directional="true" pos="0 0 2" dir="0 0 -1"
           ambient="0.3 0.3 0.3" diffuse="0 0 0" specular="0 0 0" castshadow="false"/>
    <light name="sun" directional="true" pos="0 0 2" dir="0 0 -1" ambient="0 0 0"
           diffuse="0.7 0.7 0.7" specular="0.3 0.3 0.3" castshadow="false"/>
    <geom name="table" type="box" size="0.5 0.4 0.01" pos="0 0 -0.01" material="table"/>
    <camera name="view" pos="0 -0.354 0.421" xyaxes="1 0 0 0 0.766 0.643" fovy="45"/>
    <body name="solid" mocap="true" pos="0 0 {_HALF_HEIGHT[solid]}">
      <geom name="solid" {SOLIDS[solid]} material="solid"/>
    </body>
  </worldbody>
</mujoco>
"""


@dataclasses.dataclass(frozen=True)
class ShadedClip:
    """A rendered clip: ``frames`` (T, H, W, 3) uint8 BGR; per frame the ground truth
    ``u_px``, ``v_px``, ``area_px`` (T,) from the segmentation image, and ``mask``
    (T, H, W) bool, the solid's pixels."""

    frames: np.ndarray
    u_px: np.ndarray
    v_px: np.ndarray
    area_px: np.ndarray
    mask: np.ndarray

    def write(self, folder: str | pathlib.Path) -> pathlib.Path:
        """The frames as ``folder/frame_0000.png``... (a frame folder `cgda track`
        reads); returns the folder."""
        folder = pathlib.Path(folder).expanduser()
        folder.mkdir(parents=True, exist_ok=True)
        for k, img in enumerate(self.frames):
            if not cv2().imwrite(str(folder / f"frame_{k:04d}.png"), img,
                                 (cv2().IMWRITE_PNG_COMPRESSION, 1)):
                raise ValueError(f"{folder}: cannot write frame {k}")
        return folder


def render_shaded(
    solid: str = "box",
    *,
    light: str = "move",
    n_frames: int = 90,
    width: int = 640,
    height: int = 480,
    turn_deg: float = 60.0,
    rgba=(0.8, 0.1, 0.1),
) -> ShadedClip:
    """Render one clip of the scene (module doc).

    Args:
        solid: ``"box"`` or ``"cylinder"``.
        light: ``"move"`` (the spot travels left to right) or ``"dim"`` (its
            diffuse intensity falls from 0.9 to 0.3).
        n_frames: frames in the clip (at least 2).
        width, height: image size in pixels.
        turn_deg: the solid's turn about its vertical axis over the clip.
        rgba: the solid's colour (RGB 0-1).

    Raises:
        ValueError: an unknown solid or light, or fewer than 2 frames.
        RuntimeError: no offscreen OpenGL.
    """
    if light not in LIGHTS:
        raise ValueError(f"unknown light {light!r}; expected one of {LIGHTS}")
    if int(n_frames) < 2:
        raise ValueError(f"n_frames must be at least 2, got {n_frames}")
    model = mujoco.MjModel.from_xml_string(shaded_scene_xml(solid, rgba))
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    data = mujoco.MjData(model)
    geom = model.geom("solid").id
    mocap = model.body("solid").mocapid[0]
    sun, fill = model.light("sun").id, model.light("fill").id
    s = np.linspace(0.0, 1.0, int(n_frames))
    arc = np.radians(-135.0 + 90.0 * s)  # a quarter circle of radius 0.12 m
    xy = np.stack([0.12 * np.cos(arc), 0.12 + 0.12 * np.sin(arc)], -1)
    yaw = np.radians(15.0 + turn_deg * s)
    renderers = [make_renderer(model, height, width) for _ in range(2)]
    renderers[1].enable_segmentation_rendering()
    frames, masks = [], []
    try:
        for k in range(len(s)):
            data.mocap_pos[mocap, :2] = xy[k]
            data.mocap_quat[mocap] = [np.cos(yaw[k] / 2), 0.0, 0.0, np.sin(yaw[k] / 2)]
            if light == "move":
                tilt = np.radians(-50.0 + 100.0 * s[k])
                model.light_dir[sun] = [-np.sin(tilt), 0.0, -np.cos(tilt)]
            else:
                model.light_diffuse[sun] = 0.7 - 0.5 * s[k]
                model.light_ambient[fill] = 0.3 - 0.15 * s[k]
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            images = []
            for r in renderers:
                r.update_scene(data, camera="view")
                images.append(r.render())
            frames.append(np.ascontiguousarray(images[0][..., ::-1]))
            seg = images[1]
            is_geom = seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM
            masks.append((seg[..., 0] == geom) & is_geom)
    finally:
        for r in renderers:
            r.close()
    mask = np.asarray(masks)
    area = mask.sum((1, 2)).astype(float)
    if not area.all():
        raise RuntimeError("the solid is out of view in some frame")
    cols = np.arange(width, dtype=float)
    rows = np.arange(height, dtype=float)
    u = (mask.sum(1) * cols).sum(1) / area
    v = (mask.sum(2) * rows).sum(1) / area
    return ShadedClip(np.asarray(frames), u, v, area, mask)
