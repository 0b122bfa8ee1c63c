"""The recording scene and the scripted demonstrations rendered in it.

A desk seen from above by an RGB-D camera (640 x 480, 45 degree vertical field of
view, 0.88 m above the desk, looking straight down; image up = world +y); a thin
green marker (8 x 4 x 0.2 cm) on the desk; a skin-coloured hand and forearm that
hold the marker by its edge on the demonstrator's side (never over it); an orange
cup as a less saturated distractor. One directional light shines straight down with
ambient + diffuse = 1 and no specular or shadow, so the marker's upward face is
drawn in exactly its material colour.

The paths copy `cgda_jax.datasets.synthetic`: the same actions, places on the desk
(in metres), durations and human variability (`repetition_progress`: pauses, a
hesitation, a minimum-jerk profile; per-repetition place, heading, duration):

* MOVE: 30 cm in a straight line (heading +/- 6 degrees);
* ROTATE: 90 degrees about the marker's centre;
* CLEAN: one revolution of a 30 cm circle;
* PAINT: the marker stays; its colour turns from green to blue (hue 60 -> 118,
  saturation 210 -> 160, value 190 -> 95 at full coverage) while the hand scribbles.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from cgda_jax.datasets.synthetic import ACTIONS, repetition_progress

__all__ = ["CAMERA_HEIGHT", "MARKER_HALF", "SCENE_XML", "Path", "scripted_path"]

CAMERA_HEIGHT = 0.88
MARKER_HALF = (0.04, 0.02, 0.001)  # half sizes (m) of the marker box
_HAND_HEIGHT = 0.03

SCENE_XML = f"""
<mujoco model="desk">
  <visual>
    <headlight ambient="0 0 0" diffuse="0 0 0" specular="0 0 0"/>
    <global offwidth="640" offheight="480"/>
    <map znear="0.01" zfar="5"/>
  </visual>
  <statistic extent="1" center="0 0 0.3"/>
  <asset>
    <material name="desk" rgba="0.62 0.6 0.56 1" specular="0" shininess="0"/>
    <material name="marker" rgba="0.2 0.75 0.2 1" specular="0" shininess="0"/>
    <material name="skin" rgba="0.85 0.64 0.52 1" specular="0" shininess="0"/>
    <material name="cup" rgba="0.85 0.5 0.25 1" specular="0" shininess="0"/>
    <material name="cover" rgba="0.35 0.3 0.3 1" specular="0" shininess="0"/>
  </asset>
  <worldbody>
    <light directional="true" pos="0 0 2" dir="0 0 -1" ambient="0.3 0.3 0.3"
           diffuse="0.7 0.7 0.7" specular="0 0 0" castshadow="false"/>
    <geom name="desk" type="box" size="0.8 0.6 0.01" pos="0 0 -0.01" material="desk"/>
    <geom name="cup" type="cylinder" size="0.035 0.05" pos="0.38 0.27 0.05"
          material="cup"/>
    <camera name="rgbd" pos="0 0 {CAMERA_HEIGHT}" xyaxes="1 0 0 0 1 0" fovy="45"/>
    <body name="marker" mocap="true" pos="0 0 {MARKER_HALF[2]}">
      <geom name="marker" type="box" size="{MARKER_HALF[0]} {MARKER_HALF[1]}
            {MARKER_HALF[2]}" material="marker"/>
    </body>
    <body name="hand" mocap="true" pos="0 -0.2 {_HAND_HEIGHT}">
      <geom name="hand" type="ellipsoid" size="0.03 0.022 0.014" material="skin"/>
      <geom name="forearm" type="capsule" fromto="0.035 0 0.01 0.4 0 0.12" size="0.027"
            material="skin"/>
    </body>
    <body name="cover" mocap="true" pos="0 0 -1">
      <geom name="cover" type="box" size="0.07 0.06 0.005" material="cover"/>
    </body>
  </worldbody>
</mujoco>
"""

_PLACE_M = {  # synthetic's places (mm) on this desk
    "MOVE": (-0.2, 0.0), "ROTATE": (0.15, 0.12), "CLEAN": (0.0, -0.02),
    "PAINT": (0.22, -0.18),
}
_DURATION_S = {"MOVE": 4.0, "ROTATE": 4.0, "CLEAN": 7.0, "PAINT": 9.0}
_SHOULDER = np.array([0.1, -0.75])  # where the forearm comes from (xy, m)
_GREEN_HSV = np.array([60.0, 210.0, 190.0])
_BLUE_HSV = np.array([118.0, 160.0, 95.0])


@dataclasses.dataclass(frozen=True)
class Path:
    """A scripted repetition: per frame the marker centre (T, 2) on the desk (m),
    yaw (T,) in radians, colour (T, 3) as OpenCV HSV, the hand (T, 2) xy and yaw
    (T,), and the occluder's xy (T, 2) (NaN: out of the way)."""

    times: np.ndarray
    marker_xy: np.ndarray
    marker_yaw: np.ndarray
    marker_hsv: np.ndarray
    hand_xy: np.ndarray
    hand_yaw: np.ndarray
    cover_xy: np.ndarray


def _extent(yaw: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Half-extent (T,) of the marker's rectangle along unit directions (T, 2)."""
    ax = np.stack([np.cos(yaw), np.sin(yaw)], -1)
    ay = np.stack([-np.sin(yaw), np.cos(yaw)], -1)
    return (MARKER_HALF[0] * np.abs((ax * direction).sum(-1))
            + MARKER_HALF[1] * np.abs((ay * direction).sum(-1)))


def scripted_path(
    action: str, rng: np.random.Generator, fps: float, *, occlude: bool = False
) -> Path:
    """One repetition of ``action`` sampled at ``fps`` (module doc).

    ``occlude``: a dark sheet passes over the marker for a few frames in the middle
    (for the lost-object rule).
    """
    if action not in ACTIONS:
        raise ValueError(f"unknown action {action!r}; expected one of {ACTIONS}")
    duration = _DURATION_S[action] * rng.uniform(0.75, 1.35)
    n = round((duration + 1.6) * fps)
    p, _ = repetition_progress(rng, n, fps, duration)
    times = np.arange(n) / fps
    place = np.asarray(_PLACE_M[action]) + rng.normal(0.0, 0.012, 2)
    yaw0 = np.radians(rng.uniform(-10.0, 10.0))
    xy = np.tile(place, (n, 1))
    yaw = np.full(n, yaw0)
    coverage = np.zeros(n)
    scribble = np.zeros((n, 2))
    if action == "MOVE":
        heading = rng.normal(0.0, np.radians(6.0))
        xy = place + 0.3 * p[:, None] * np.array([np.cos(heading), np.sin(heading)])
    elif action == "ROTATE":
        yaw = yaw0 + np.radians(90.0) * p
    elif action == "CLEAN":
        start = rng.uniform(-0.3, 0.3)
        theta = start + 2.0 * np.pi * p
        circle = np.stack([np.cos(theta), np.sin(theta)], -1)
        xy = place + 0.15 * (circle - circle[:1])
    else:  # PAINT
        coverage = rng.uniform(0.9, 0.97) * p
        w = 2.0 * np.pi * rng.uniform(1.5, 2.5) * times
        scribble = 0.012 * np.stack([np.sin(w), np.sin(1.7 * w)], -1)
        scribble *= ((p > 0.0) & (p < 1.0))[:, None]
    hsv = _GREEN_HSV + (_BLUE_HSV - _GREEN_HSV) * coverage[:, None]
    # The hand holds the marker's edge facing the demonstrator's shoulder.
    to_shoulder = _SHOULDER - xy
    to_shoulder /= np.linalg.norm(to_shoulder, axis=-1, keepdims=True)
    gap = _extent(yaw, to_shoulder) + 0.045 + np.abs(scribble).sum(-1)
    hand = xy + gap[:, None] * to_shoulder + scribble
    hand_yaw = np.arctan2(to_shoulder[:, 1], to_shoulder[:, 0])
    cover = np.full((n, 2), np.nan)
    if occlude:
        mid = n // 2
        cover[mid - 2:mid + 2] = xy[mid - 2:mid + 2]
    return Path(times, xy, yaw, hsv, hand, hand_yaw, cover)
