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
from collections.abc import Sequence

import numpy as np

from cgda_jax.datasets.synthetic import ACTIONS, repetition_progress

__all__ = ["CAMERA_HEIGHT", "MARKER_HALF", "SCENE_XML", "SEQUENCE_AREA_M", "Path",
           "scripted_path", "scripted_sequence"]

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


def _motion(action: str, rng: np.random.Generator, fps: float):
    """One repetition's marker (times, xy, yaw, hsv, scribble) and its progress p."""
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
    return times, xy, yaw, hsv, scribble, p


def _with_hand(times, xy, yaw, hsv, scribble, cover) -> Path:
    """The path with the hand holding the marker's edge that faces the
    demonstrator's shoulder."""
    to_shoulder = _SHOULDER - xy
    to_shoulder /= np.linalg.norm(to_shoulder, axis=-1, keepdims=True)
    gap = _extent(yaw, to_shoulder) + 0.045 + np.abs(scribble).sum(-1)
    hand = xy + gap[:, None] * to_shoulder + scribble
    hand_yaw = np.arctan2(to_shoulder[:, 1], to_shoulder[:, 0])
    return Path(times, xy, yaw, hsv, hand, hand_yaw, cover)


def scripted_path(
    action: str, rng: np.random.Generator, fps: float, *, occlude: bool = False
) -> Path:
    """One repetition of ``action`` sampled at ``fps`` (module doc).

    ``occlude``: a dark sheet passes over the marker for a few frames in the middle
    (for the lost-object rule).
    """
    times, xy, yaw, hsv, scribble, _ = _motion(action, rng, fps)
    n = len(times)
    cover = np.full((n, 2), np.nan)
    if occlude:
        mid = n // 2
        cover[mid - 2:mid + 2] = xy[mid - 2:mid + 2]
    return _with_hand(times, xy, yaw, hsv, scribble, cover)


#: Where a sequence's marker centre may go on the desk (m): in the camera's view
#: with a margin for the marker and the hand, clear of the cup.
SEQUENCE_AREA_M = ((-0.38, 0.28), (-0.25, 0.2))


def scripted_sequence(
    actions: Sequence[str] | None, rng: np.random.Generator, fps: float, *,
    pause_s: tuple[float, float] = (0.0, 0.0),
) -> tuple[Path, list[tuple[str, float, float]]]:
    """Several actions in a row: each a fresh repetition (`scripted_path`'s
    variability), cut to its motion and moved to start where the previous one left
    the marker (place, heading, colour), as `cgda_jax.datasets.synthetic_sequence`
    builds its recordings. The marker rests 0.3-1 s before the first and after the
    last, and for a time drawn from ``pause_s`` between two actions (``(0, 0)``: back
    to back). The whole path is placed at random where it stays in
    `SEQUENCE_AREA_M`. ``actions=None`` draws 2 to 6 actions at random (drawn
    again until at most one is a PAINT and the path fits in the view).

    Returns:
        The path and the true ``(action, start, end)`` of each motion in seconds:
        from the last frame at rest before it to the first at rest after it.

    Raises:
        ValueError: an unknown action, more than one PAINT (a second would paint
            the blue marker black), or a sequence that does not fit in the view.
    """
    lo, hi = pause_s
    if not 0.0 <= lo <= hi:
        raise ValueError(f"pause_s must be (shortest, longest) with 0 <= shortest "
                         f"<= longest, got {pause_s!r}")
    if actions is None:
        for _ in range(1000):
            drawn = [str(a) for a in rng.choice(ACTIONS, size=rng.integers(2, 7))]
            try:
                return scripted_sequence(drawn, rng, fps, pause_s=pause_s)
            except ValueError:
                continue
        raise ValueError("no sequence drawn in 1000 tries fits in the view")
    actions = list(actions)
    if not actions:
        raise ValueError("a sequence needs at least one action")
    if actions.count("PAINT") > 1:
        raise ValueError(f"{actions}: at most one PAINT (the marker is painted once)")
    xy, yaw, hsv, scribble, truth = [], [], [], [], []
    here = (np.zeros(2), None, _GREEN_HSV)

    def rest(seconds):
        n = int(round(seconds * fps))
        xy.append(np.tile(here[0], (n, 1)))
        yaw.append(np.full(n, here[1]))
        hsv.append(np.tile(here[2], (n, 1)))
        scribble.append(np.zeros((n, 2)))

    count = 0
    for k, action in enumerate(actions):
        _, m_xy, m_yaw, m_hsv, m_scr, p = _motion(action, rng, fps)
        moving = np.flatnonzero((p > 0.0) & (p < 1.0))
        first, last = max(moving[0] - 1, 0), min(moving[-1] + 1, len(p) - 1)
        cut = slice(first, last + 1)
        if here[1] is None:
            here = (here[0], m_yaw[first], here[2])
        if k == 0 or hi > 0:
            rest(rng.uniform(0.3, 1.0) if k == 0 else rng.uniform(lo, hi))
            count += len(xy[-1])
        xy.append(m_xy[cut] - m_xy[first] + here[0])
        yaw.append(m_yaw[cut] - m_yaw[first] + here[1])
        hsv.append(m_hsv[cut] - m_hsv[first] + here[2])
        scribble.append(m_scr[cut])
        truth.append((action, float(count / fps), float((count + last - first) / fps)))
        count += last - first + 1
        here = (xy[-1][-1], yaw[-1][-1], hsv[-1][-1])
    rest(rng.uniform(0.3, 1.0))
    xy = np.concatenate(xy)
    (x0, x1), (y0, y1) = SEQUENCE_AREA_M
    low = np.array([x0, y0]) - xy.min(0)
    high = np.array([x1, y1]) - xy.max(0)
    if np.any(low > high):
        raise ValueError(f"{actions}: the marker's path ({np.ptp(xy, 0)} m) does not "
                         f"fit in the camera's view {SEQUENCE_AREA_M}")
    xy = xy + rng.uniform(low, high)
    times = np.arange(len(xy)) / fps
    return (_with_hand(times, xy, np.concatenate(yaw), np.concatenate(hsv),
                       np.concatenate(scribble), np.full((len(xy), 2), np.nan)), truth)
