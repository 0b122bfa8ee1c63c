"""One frame: find the coloured object and measure it.

The object is the largest 8-connected region of pixels inside an HSV colour range
(OpenCV's HSV: hue 0-180, saturation and value 0-255), with its holes filled (a
highlight or a mark inside the object that falls out of the range is still the
object). Its measurements:

* image position: the filled region's centroid (u, v) in pixels;
* area: its pixel count; with depth, its area on the object's surface in m^2 (each
  pixel's footprint on the plane fitted to the region's 3-D points);
* colour: mean hue (circular), saturation and value over the in-range pixels of the
  region's interior (the region eroded by one pixel, so the anti-aliased rim that
  mixes with the background does not bias them; the whole region if nothing is
  left), and ``value_top``, the 90th percentile of their value (the object's lit
  faces: what the followed range's value floor is a fraction of, `ColorRange.around`);
* angle: orientation of the region's principal axis from its second central
  moments, in degrees counter-clockwise as seen in the image (-90, 90];
* with depth: X, Y, Z of the centroid pixel at the median depth of the interior.

The object counts as *lost* in a frame (`measure` returns None) when no region of
at least ``min_area`` pixels is in range, when the region touches the image border
(partly out of view), or, with depth, when it has no valid depth reading.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from cgda_jax.vision.camera import Intrinsics
from cgda_jax.vision.cv import cv2

__all__ = ["VALUE_FLOOR", "VALUE_SPAN", "Blob", "ColorRange", "auto_color", "find",
           "hsv_image", "in_range", "measure", "measure_near"]

#: the followed range's value floor as a fraction of the lit faces' value
VALUE_SPAN = 0.2
#: the darkest value (0-255) a followed range admits: below it an 8-bit camera's
#: hue is noise, so darker faces are not counted as the object
VALUE_FLOOR = 20.0


@dataclasses.dataclass(frozen=True)
class ColorRange:
    """An HSV range: hue from ``hue_lo`` to ``hue_hi`` (OpenCV's 0-180; wraps when
    ``hue_lo > hue_hi``, e.g. red 170-10), saturation and value at least
    ``sat_min`` / ``val_min`` (0-255)."""

    hue_lo: float
    hue_hi: float
    sat_min: float = 80.0
    val_min: float = 40.0

    def __post_init__(self) -> None:
        for key in ("hue_lo", "hue_hi"):
            v = float(getattr(self, key))
            if not 0 <= v <= 180:
                raise ValueError(f"colour range: {key} must be in [0, 180], got {v!r}")
        for key in ("sat_min", "val_min"):
            v = float(getattr(self, key))
            if not 0 <= v <= 255:
                raise ValueError(f"colour range: {key} must be in [0, 255], got {v!r}")

    @classmethod
    def parse(cls, text: str) -> ColorRange:
        """``"HLO-HHI"`` or ``"HLO-HHI,SMIN,VMIN"``, e.g. ``"40-80,100,50"``."""
        parts = [p.strip() for p in str(text).split(",")]
        try:
            lo, hi = (float(x) for x in parts[0].split("-"))
            rest = [float(x) for x in parts[1:]]
        except ValueError:
            raise ValueError(
                f"colour range {text!r}: expected HLO-HHI[,SMIN,VMIN] (OpenCV HSV: "
                "hue 0-180, saturation and value 0-255), e.g. 40-80,100,50"
            ) from None
        if len(rest) not in (0, 2):
            raise ValueError(f"colour range {text!r}: give both SMIN and VMIN, or neither")
        return cls(lo, hi, *rest)

    def around(self, hue: float, sat: float, top: float, tol: float) -> ColorRange:
        """The colour model: a range led by hue around a measured colour. Hue +/-
        ``tol``; saturation at least half the measured mean ``sat`` (30 at the
        least); value at least `VALUE_SPAN` times ``top``, the value of the object's
        lit faces (`Blob.value_top`; `VALUE_FLOOR` at the least): a face in shade,
        at a third of the lit faces' brightness or less, stays inside (under white
        light a darker face keeps its hue and saturation, only its value falls)."""
        return ColorRange(
            float((hue - tol) % 180), float((hue + tol) % 180),
            max(30.0, 0.5 * sat), max(VALUE_FLOOR, VALUE_SPAN * top),
        )

    def __str__(self) -> str:
        return (f"hue {self.hue_lo:.0f}-{self.hue_hi:.0f}, saturation >= "
                f"{self.sat_min:.0f}, value >= {self.val_min:.0f}")


@dataclasses.dataclass(frozen=True)
class Blob:
    """Measurements of the object in one frame (units in the module doc).
    ``xyz`` and ``area_m2`` are None without depth."""

    u: float
    v: float
    area_px: float
    hue: float
    saturation: float
    value: float
    angle_deg: float
    bbox: tuple[int, int, int, int]  # x, y, width, height in pixels
    value_top: float
    xyz: tuple[float, float, float] | None = None
    area_m2: float | None = None


def hsv_image(bgr: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 OpenCV HSV of a BGR frame."""
    return cv2().cvtColor(bgr, cv2().COLOR_BGR2HSV)


def in_range(hsv: np.ndarray, rng: ColorRange) -> np.ndarray:
    """(H, W) uint8 mask (255 inside the range)."""
    c = cv2()
    lo_s, lo_v = int(np.ceil(rng.sat_min)), int(np.ceil(rng.val_min))
    lo, hi = int(np.ceil(rng.hue_lo)), int(np.floor(rng.hue_hi))
    if rng.hue_lo <= rng.hue_hi:
        return c.inRange(hsv, (lo, lo_s, lo_v), (hi, 255, 255))
    return c.inRange(hsv, (lo, lo_s, lo_v), (180, 255, 255)) | c.inRange(
        hsv, (0, lo_s, lo_v), (hi, 255, 255)
    )


def _colour(hsv_pixels: np.ndarray) -> tuple[float, float, float]:
    """Circular mean hue (0-180) and mean saturation and value of (K, 3) pixels."""
    ang = hsv_pixels[:, 0].astype(np.float64) * (np.pi / 90.0)
    hue = np.degrees(np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())) / 2.0
    return float(hue % 180.0), float(hsv_pixels[:, 1].mean()), float(hsv_pixels[:, 2].mean())


def _filled(region: np.ndarray) -> np.ndarray:
    """(h, w) bool ``region`` with its holes (background not 4-connected to the
    outside) filled."""
    c = cv2()
    pad = np.pad(region.view(np.uint8), 1)
    c.floodFill(pad, None, (0, 0), 2)
    return pad[1:-1, 1:-1] != 2


def _area_m2(us, vs, zs, cam: Intrinsics) -> float:
    """Surface area of pixels (us, vs) on the plane fitted to their 3-D points."""
    dx, dy = (us - cam.cx) / cam.fx, (vs - cam.cy) / cam.fy
    ok = np.isfinite(zs)
    pts = np.stack([dx[ok] * zs[ok], dy[ok] * zs[ok], zs[ok]], -1)
    normal = np.array([0.0, 0.0, 1.0])
    mean = pts.mean(0)
    if len(pts) >= 3:
        centred = pts - mean
        w, vec = np.linalg.eigh(centred.T @ centred)  # 3 x 3: least-squares plane
        if w[1] > 1e-12 * max(w[2], 1e-300):  # not a line of points
            normal = vec[:, 0] * np.sign(vec[2, 0] or 1.0)
    c = float(mean @ normal)  # plane n.P = c
    nd = np.abs(dx * normal[0] + dy * normal[1] + normal[2])
    return float(c * c / (cam.fx * cam.fy) * np.sum(nd**-3.0))


def measure(
    bgr: np.ndarray,
    rng: ColorRange,
    *,
    depth: np.ndarray | None = None,
    intrinsics: Intrinsics | None = None,
    min_area: int = 30,
    hsv: np.ndarray | None = None,
) -> Blob | None:
    """The object in one BGR frame, or None where it is lost (module doc).

    Args:
        bgr: (H, W, 3) uint8 frame.
        rng: the object's colour range.
        depth: optional (H, W) depth in metres (NaN: no reading), aligned with ``bgr``;
            needs ``intrinsics``.
        intrinsics: the camera (for X, Y, Z and the area in m^2).
        min_area: smallest region in pixels that counts as the object.
        hsv: the frame in HSV if already converted.
    """
    c = cv2()
    hsv = hsv_image(bgr) if hsv is None else hsv
    mask = in_range(hsv, rng)
    n, labels, stats, _ = c.connectedComponentsWithStats(mask, connectivity=8)
    if n < 2:
        return None
    k = 1 + int(np.argmax(stats[1:, c.CC_STAT_AREA]))
    x, y, w, h, area = (int(s) for s in stats[k])
    if area < min_area:
        return None
    height, width = mask.shape
    if x == 0 or y == 0 or x + w == width or y + h == height:
        return None  # touches the border: partly out of view
    in_range_px = labels[y:y + h, x:x + w] == k
    region = _filled(in_range_px)
    inner = c.erode(in_range_px.astype(np.uint8), np.ones((3, 3), np.uint8),
                    borderType=c.BORDER_CONSTANT, borderValue=0).astype(bool)
    if not inner.any():
        inner = in_range_px
    m = c.moments(region.view(np.uint8), binaryImage=True)
    area = m["m00"]
    u, v = x + m["m10"] / area, y + m["m01"] / area
    angle = -0.5 * np.degrees(np.arctan2(2.0 * m["mu11"], m["mu20"] - m["mu02"]))
    if angle <= -90.0:
        angle += 180.0
    pixels = hsv[y:y + h, x:x + w][inner]
    hue, sat, val = _colour(pixels)
    top = float(np.percentile(pixels[:, 2], 90))
    blob = Blob(u, v, float(area), hue, sat, val, float(angle), (x, y, w, h), top)
    if depth is None:
        return blob
    if intrinsics is None:
        raise ValueError("depth given without camera intrinsics")
    vs, us = np.nonzero(region)
    us, vs = us.astype(np.float64) + x, vs.astype(np.float64) + y
    z_region = depth[y:y + h, x:x + w]
    z_inner = z_region[inner]
    z_inner = z_inner[np.isfinite(z_inner)]
    if z_inner.size == 0:
        return None  # no depth reading on the object
    z = float(np.median(z_inner))
    xyz = tuple(float(q) for q in intrinsics.deproject(u, v, z))
    a_m2 = _area_m2(us, vs, z_region[region], intrinsics)
    return dataclasses.replace(blob, xyz=xyz, area_m2=a_m2)


def measure_near(
    bgr: np.ndarray,
    rng: ColorRange,
    bbox: tuple[int, int, int, int],
    *,
    depth: np.ndarray | None = None,
    intrinsics: Intrinsics | None = None,
    min_area: int = 30,
    margin: int = 40,
) -> Blob | None:
    """`measure` inside a window around ``bbox`` (x, y, w, h; the object's box in
    the previous frame) grown by ``margin`` pixels plus half the box's size on each
    side: the same measurements, several times less work. None where the window holds
    no region of ``min_area`` pixels or the region reaches the window's edge (the
    caller then measures the whole frame)."""
    x, y, w, h = bbox
    grow = margin + max(w, h) // 2
    height, width = bgr.shape[:2]
    x0, y0 = max(0, x - grow), max(0, y - grow)
    x1, y1 = min(width, x + w + grow), min(height, y + h + grow)
    cam = intrinsics
    if cam is not None:
        cam = dataclasses.replace(cam, width=x1 - x0, height=y1 - y0,
                                  cx=cam.cx - x0, cy=cam.cy - y0)
    blob = measure(bgr[y0:y1, x0:x1], rng, min_area=min_area, intrinsics=cam,
                   depth=None if depth is None else depth[y0:y1, x0:x1])
    if blob is None:
        return None
    bx, by, bw, bh = blob.bbox
    return dataclasses.replace(blob, u=blob.u + x0, v=blob.v + y0,
                               bbox=(bx + x0, by + y0, bw, bh))


def find(
    bgr: np.ndarray,
    rng: ColorRange,
    last_bbox: tuple[int, int, int, int] | None = None,
    **kw,
) -> Blob | None:
    """The tracker's step: `measure_near` the last box when there is one, else (or
    where that finds nothing whole) `measure` the whole frame. ``kw``: as `measure`."""
    if last_bbox is not None and last_bbox[0] >= 0:
        blob = measure_near(bgr, rng, last_bbox, **kw)
        if blob is not None:
            return blob
    return measure(bgr, rng, **kw)


def auto_color(
    bgr: np.ndarray, *, min_area: int = 30, sat_floor: float = 100.0,
    val_floor: float = 50.0, hue_tol: float = 10.0,
) -> tuple[ColorRange, Blob]:
    """Pick the object in a frame without a click: the most saturated region.

    Among the 8-connected regions of at least ``min_area`` pixels with saturation
    >= ``sat_floor`` and value >= ``val_floor``, the one with the highest mean
    saturation; its range is the colour model around it (`ColorRange.around`: its
    mean hue +/- ``hue_tol``, saturation at least half its mean, value at least
    `VALUE_SPAN` of its lit pixels' value).

    Raises:
        ValueError: no such region in the frame.
    """
    c = cv2()
    hsv = hsv_image(bgr)
    mask = c.inRange(hsv, (0, int(sat_floor), int(val_floor)), (180, 255, 255))
    n, labels, stats, _ = c.connectedComponentsWithStats(mask, connectivity=8)
    best, best_sat = None, -1.0
    for k in range(1, n):
        x, y, w, h, area = (int(s) for s in stats[k])
        if area < min_area:
            continue
        sat = float(hsv[y:y + h, x:x + w, 1][labels[y:y + h, x:x + w] == k].mean())
        if sat > best_sat:
            best, best_sat = k, sat
    if best is None:
        raise ValueError(
            f"no coloured object in the first frame (no region of >= {min_area} "
            f"pixels with saturation >= {sat_floor:g} and value >= {val_floor:g}); "
            "give its colour range"
        )
    x, y, w, h, _ = (int(s) for s in stats[best])
    pixels = hsv[y:y + h, x:x + w][labels[y:y + h, x:x + w] == best]
    hue, sat, _ = _colour(pixels)
    rng = ColorRange(0, 180).around(hue, sat, float(np.percentile(pixels[:, 2], 90)),
                                    hue_tol)
    blob = measure(bgr, rng, min_area=min_area, hsv=hsv)
    if blob is None:
        raise ValueError(f"the most saturated region ({rng}) touches the image border")
    return rng, blob
