"""Track one coloured object through a recording and emit a `Demonstration`.

Per frame `cgda_jax.vision.blob.measure` finds the object (or says it is lost):
first in a window around its box in the previous frame (`measure_near`), then, where
it is not found whole there, in the whole frame.
The colour range is given, or picked automatically from the first frame's most
saturated region (`auto_color`; `Track.color` says which range was used). With
``follow_color`` (the default for an automatic pick) the range is learned again from
the object's pixels after every frame (`ColorRange.around`, the colour model: led by
hue, the first range's hue width around its mean hue, saturation at least half its
mean, value at least `VALUE_SPAN` of its lit faces' value), so an object whose
colour changes (PAINT), whose faces turn into shade as it rotates, or whose light
moves or dims stays tracked whole; `Track.colors` holds the range of every frame,
`Track.summary` says the first and last and how low the value floor went. Where the
colour jumps out of the window between two frames, the most saturated region near
the last box is picked again, if its area is close to
the object's recent one (within ``min_area_ratio``).

Lost frames, the stated rule:

* a frame is also lost where the region's area is below ``min_area_ratio`` times the
  median area of the last 15 frames in which it was found (partly occluded);
* lost frames before the first and after the last found frame are cut: the
  demonstration starts and ends where the object is seen (`Track.first`,
  `Track.last`);
* a run of at most ``max_gap`` lost frames inside is filled by linear interpolation
  of every feature (the angle unwrapped, the hue on its circle) and marked in
  `Track.interpolated`;
* a longer run refuses the video: `ValueError` names the file and the frames.

Features (F = 8 without depth, 11 with; units in the names): ``u_px``, ``v_px``
(image position), with depth ``X_m``, ``Y_m``, ``Z_m`` (camera frame, or the
intrinsics' world frame), ``area_px`` and with depth ``area_m2``, ``hue_0_180``,
``saturation_0_255``, ``value_0_255``, ``angle_deg`` (unwrapped over the video, so a
turn past 90 degrees stays continuous).
"""

from __future__ import annotations

import dataclasses
import pathlib

import numpy as np

from cgda_jax.data import Demonstration
from cgda_jax.vision.blob import VALUE_FLOOR, Blob, ColorRange, auto_color, find
from cgda_jax.vision.camera import Intrinsics, load_intrinsics
from cgda_jax.vision.frames import DEPTH_SUFFIXES, iter_frames, list_frames, read_depth

__all__ = ["DEPTH_FEATURES", "FPS_RANGE", "IMAGE_FEATURES", "Track", "features_for",
           "track_video"]

#: Frame rates a track takes [frames per s]: one frame in 1000 s to 100,000 a second.
FPS_RANGE = (1e-3, 1e5)

IMAGE_FEATURES = (
    "u_px", "v_px", "area_px", "hue_0_180", "saturation_0_255", "value_0_255",
    "angle_deg",
)
DEPTH_FEATURES = (
    "u_px", "v_px", "X_m", "Y_m", "Z_m", "area_px", "area_m2", "hue_0_180",
    "saturation_0_255", "value_0_255", "angle_deg",
)


def features_for(depth: bool) -> tuple[str, ...]:
    """The feature names `track_video` emits with or without depth."""
    return DEPTH_FEATURES if depth else IMAGE_FEATURES


@dataclasses.dataclass(frozen=True)
class Track:
    """A tracked recording.

    Attributes:
        demo: the `Demonstration` (frames ``first`` .. ``last``).
        color: the colour range used first (picked or given).
        picked: True where ``color`` was picked automatically.
        found: (n_frames,) bool, the object measured in that frame.
        interpolated: (n_frames,) bool, filled by the gap rule.
        first, last: the first and last frames kept (inclusive).
        n_frames: frames in the video.
        bboxes: (n_frames, 4) int x, y, w, h of the region (-1 where lost).
        colors: (n_frames,) the colour range each frame was searched with (the
            followed range changes every frame; `write_colors` saves them).
    """

    demo: Demonstration
    color: ColorRange
    picked: bool
    found: np.ndarray
    interpolated: np.ndarray
    first: int
    last: int
    n_frames: int
    bboxes: np.ndarray
    colors: tuple[ColorRange, ...]

    def summary(self) -> str:
        """One line: frames, colour range (first and last where it was followed),
        frames kept, interpolated and cut."""
        text = (f"{self.n_frames} frames, object {'picked' if self.picked else 'range'} "
                f"{self.color}")
        if any(c != self.color for c in self.colors):
            floors = [c.val_min for c in self.colors]
            text += (f", followed to {self.colors[self.last]} at frame {self.last} "
                     f"(value floor {min(floors):.0f}-{max(floors):.0f})")
        text += f"; kept frames {self.first}-{self.last}"
        if self.interpolated.any():
            text += f", interpolated {int(self.interpolated.sum())} lost frame(s)"
        cut = self.first + (self.n_frames - 1 - self.last)
        if cut:
            text += f", cut {cut} lost frame(s) at the ends"
        return text

    def write_colors(self, path: str | pathlib.Path) -> pathlib.Path:
        """A CSV of the range used in each frame: ``frame, found, hue_lo, hue_hi,
        sat_min, val_min`` (OpenCV HSV)."""
        path = pathlib.Path(path).expanduser()
        lines = ["frame,found,hue_lo,hue_hi,sat_min,val_min"]
        lines += [f"{k},{int(f)},{c.hue_lo:.2f},{c.hue_hi:.2f},{c.sat_min:.2f},"
                  f"{c.val_min:.2f}" for k, (f, c) in enumerate(zip(self.found,
                                                                      self.colors))]
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return path


def _row(blob: Blob, depth: bool) -> list[float]:
    if not depth:
        return [blob.u, blob.v, blob.area_px, blob.hue, blob.saturation, blob.value,
                blob.angle_deg]
    return [blob.u, blob.v, *blob.xyz, blob.area_px, blob.area_m2, blob.hue,
            blob.saturation, blob.value, blob.angle_deg]


def _depth_files(depth_dir) -> list[pathlib.Path]:
    folder = pathlib.Path(depth_dir).expanduser()
    if not folder.is_dir():
        raise FileNotFoundError(f"no such depth folder: {folder}")
    return list_frames(folder, DEPTH_SUFFIXES)


def _count_error(depth_dir, n_depth: int, n_video: int | None, video) -> ValueError:
    video_frames = f"the {n_video} frames" if n_video else "more frames"
    return ValueError(
        f"{pathlib.Path(depth_dir).expanduser()}: {n_depth} depth frames for "
        f"{video_frames} of {video}; give one depth frame per video frame"
    )


def _reacquire(bgr, box, recent, ratio, color, kw):
    """Following a colour that jumped out of its window, or light that fell below
    the range's value floor at once: the most saturated region in the window around
    the last box (`auto_color` there, down to `VALUE_FLOOR`), taken when its area is
    within ``ratio`` .. 1 / ``ratio`` of the recent median. (new range, blob) or None."""
    x, y, w, h = box
    grow = 40 + max(w, h) // 2
    height, width = bgr.shape[:2]
    x0, y0 = max(0, x - grow), max(0, y - grow)
    x1, y1 = min(width, x + w + grow), min(height, y + h + grow)
    try:
        rng, _ = auto_color(bgr[y0:y1, x0:x1], min_area=kw["min_area"],
                            val_floor=VALUE_FLOOR,
                            hue_tol=0.5 * ((color.hue_hi - color.hue_lo) % 180))
    except ValueError:
        return None
    blob = find(bgr, rng, box, **kw)
    if blob is None or (recent and not ratio * recent <= blob.area_px <= recent / ratio):
        return None
    return rng, blob


def _learned(blob: Blob, color: ColorRange) -> ColorRange:
    """The colour model learned from the object's pixels in this frame, with the
    hue width of ``color``."""
    return color.around(blob.hue, blob.saturation, blob.value_top,
                        0.5 * ((color.hue_hi - color.hue_lo) % 180))


def _relearn(bgr, blob, color, box, kw):
    """Light that fell at once (the learned value or saturation floor below 0.8 of
    the one searched with): the frame measured again with the learned range, so
    faces that fell under the old floor are counted in this frame already.
    (blob, range used)."""
    new = _learned(blob, color)
    if new.val_min >= 0.8 * color.val_min and new.sat_min >= 0.8 * color.sat_min:
        return blob, color
    again = find(bgr, new, box, **kw)
    if again is None or again.area_px < blob.area_px:
        return blob, color
    return again, new


def _fill_gaps(rows: np.ndarray, found: np.ndarray, names, max_gap: int, where: str):
    """Cut lost ends, interpolate short inner gaps; (first, last, filled rows, mask)."""
    idx = np.flatnonzero(found)
    first, last = int(idx[0]), int(idx[-1])
    keep = np.arange(first, last + 1)
    gaps = np.flatnonzero(~found[keep]) + first
    if len(gaps):
        runs = np.split(gaps, np.flatnonzero(np.diff(gaps) > 1) + 1)
        long = [r for r in runs if len(r) > max_gap]
        if long:
            r = long[0]
            raise ValueError(
                f"{where}: the object is lost for {len(r)} frames ({r[0]}-{r[-1]}), "
                f"more than max_gap = {max_gap}; the demonstration is refused (cut the "
                "video, or raise max_gap)"
            )
    out = rows.copy()
    hue = names.index("hue_0_180")
    good = found[keep]
    for col in range(rows.shape[1]):
        y = rows[keep, col][good]
        if col == hue:  # interpolate on the circle
            y = np.unwrap(y, period=180.0)
            out[keep, col] = np.interp(keep, keep[good], y) % 180.0
        else:
            out[keep, col] = np.interp(keep, keep[good], y)
    interpolated = np.zeros_like(found)
    interpolated[gaps] = True
    return first, last, out, interpolated


def track_video(
    video: str | pathlib.Path,
    *,
    depth: str | pathlib.Path | None = None,
    intrinsics: Intrinsics | str | pathlib.Path | None = None,
    color: ColorRange | str | None = None,
    fps: float | None = None,
    follow_color: bool | None = None,
    max_gap: int = 5,
    min_area: int = 30,
    min_area_ratio: float = 0.5,
    name: str | None = None,
) -> Track:
    """Track the coloured object of one recording (module doc).

    Args:
        video: a video file or a folder of frames (`cgda_jax.vision.frames`).
        depth: optional folder of depth frames aligned with the video (needs
            ``intrinsics``).
        intrinsics: an `Intrinsics` or its JSON file.
        color: a `ColorRange` (or its text, ``"40-80,100,50"``); None or ``"auto"``
            picks it from the first frame.
        fps: frame rate; default the video's own, else 30 (a frame folder).
        follow_color: re-centre the hue window on the object every frame (default:
            True for an automatic pick, False for a given range).
        max_gap: the longest run of lost frames that is interpolated.
        min_area: smallest region (pixels) that counts as the object.
        min_area_ratio: a region smaller than this fraction of the recent median area
            counts as lost (partly occluded).
        name: the demonstration's name (default: the video's file or folder name).

    Raises:
        FileNotFoundError: a missing video, depth folder or intrinsics file.
        ValueError: an unreadable or empty video, depth frames of another count or
            size, no object in range, or a gap longer than ``max_gap`` (each names
            the file).
    """
    from cgda_jax.vision.frames import video_fps

    video = pathlib.Path(video).expanduser()
    if isinstance(intrinsics, (str, pathlib.Path)):
        intrinsics = load_intrinsics(intrinsics)
    if depth is not None and intrinsics is None:
        raise ValueError(f"{video}: depth frames need camera intrinsics (--intrinsics)")
    picked = color is None or color == "auto"
    if isinstance(color, str) and not picked:
        color = ColorRange.parse(color)
    follow = picked if follow_color is None else bool(follow_color)
    fps = float(fps) if fps is not None else float(video_fps(video) or 30.0)
    if not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
        raise ValueError(f"{video}: fps must be in [{FPS_RANGE[0]:g}, "
                         f"{FPS_RANGE[1]:g}] frames per second, got {fps:g}")
    if not (isinstance(max_gap, (int, np.integer)) and max_gap >= 0):
        raise ValueError(f"max_gap must be a whole number of frames >= 0, got "
                         f"{max_gap!r}")
    if not (isinstance(min_area, (int, np.integer)) and min_area >= 1):
        raise ValueError(f"min_area must be a whole number of pixels >= 1, got "
                         f"{min_area!r}")
    depth_files = _depth_files(depth) if depth is not None else None
    rows, found, boxes, areas, used = [], [], [], [], []
    last_box = None
    first_color = None
    for k, bgr in enumerate(iter_frames(video)):
        if k == 0:
            if intrinsics is not None and (bgr.shape[1], bgr.shape[0]) != (
                intrinsics.width, intrinsics.height
            ):
                raise ValueError(
                    f"{video}: frames are {bgr.shape[1]}x{bgr.shape[0]} but the "
                    f"intrinsics are for {intrinsics.width}x{intrinsics.height}"
                )
            if picked:
                try:
                    color, _ = auto_color(bgr, min_area=min_area)
                except ValueError as err:
                    raise ValueError(f"{video}: {err}") from None
            first_color = color
        z = None
        if depth_files is not None:
            if k >= len(depth_files):
                raise _count_error(depth, len(depth_files), None, video)
            z = read_depth(depth_files[k], intrinsics.depth_scale)
            if z.shape != bgr.shape[:2]:
                raise ValueError(
                    f"{depth_files[k]}: depth frame is {z.shape[1]}x{z.shape[0]}, the "
                    f"video {video} is {bgr.shape[1]}x{bgr.shape[0]}"
                )
        kw = {"depth": z, "intrinsics": intrinsics, "min_area": min_area}
        blob = find(bgr, color, last_box, **kw)
        recent = float(np.median(areas[-15:])) if areas else None
        if blob is None and follow and last_box is not None:
            again = _reacquire(bgr, last_box, recent, min_area_ratio, color, kw)
            if again is not None:
                color, blob = again
        if blob is not None and follow:
            blob, color = _relearn(bgr, blob, color, last_box, kw)
        if blob is not None and recent and blob.area_px < min_area_ratio * recent:
            blob = None  # partly occluded
        used.append(color)
        found.append(blob is not None)
        boxes.append(blob.bbox if blob is not None else (-1, -1, -1, -1))
        rows.append(_row(blob, depth is not None) if blob is not None else None)
        if blob is not None:
            last_box = blob.bbox
            areas.append(blob.area_px)
            if follow:
                color = _learned(blob, color)
    names = features_for(depth is not None)
    found = np.asarray(found, bool)
    if depth_files is not None and len(depth_files) != len(found):
        raise _count_error(depth, len(depth_files), len(found), video)
    if not found.any():
        raise ValueError(f"{video}: the object ({first_color}) is not found in any frame")
    if found.sum() < 2:
        raise ValueError(f"{video}: the object ({first_color}) is found in only 1 frame")
    table = np.full((len(found), len(names)), np.nan)
    table[found] = np.asarray([r for r in rows if r is not None])
    ang = names.index("angle_deg")
    table[found, ang] = np.unwrap(table[found, ang], period=180.0)
    first, last, table, interp = _fill_gaps(table, found, names, max_gap, str(video))
    times = np.arange(len(found)) / fps
    if name is None:
        name = video.stem if video.is_file() else video.name
    demo = Demonstration(times[first:last + 1], table[first:last + 1], names, name)
    return Track(demo, first_color, picked, found, interp, first, last, len(found),
                 np.asarray(boxes, int), tuple(used))
