"""A contact sheet: a grid of a recording's frames with the tracked object's box,
its outline (the pixels in the frame's colour range inside the box, as measured),
its centroid, its trajectory up to that frame and the frame's state drawn on, to
check a track by eye: a shaded face left out of the outline shows at once."""

from __future__ import annotations

import pathlib

import numpy as np

from cgda_jax.vision.blob import hsv_image, in_range
from cgda_jax.vision.cv import cv2
from cgda_jax.vision.frames import iter_frames

__all__ = ["contact_sheet"]

_GREEN, _YELLOW, _RED, _WHITE = (60, 220, 60), (0, 220, 255), (40, 40, 240), (255, 255, 255)
_CYAN = (255, 255, 0)


def contact_sheet(
    video: str | pathlib.Path,
    track,
    out_path: str | pathlib.Path,
    *,
    n_frames: int = 12,
    columns: int = 4,
    thumb_width: int = 320,
) -> pathlib.Path:
    """Write a PNG grid of ``n_frames`` frames spread over the video.

    Each thumbnail shows the object's box (green: measured, yellow: interpolated
    position, red "lost": cut or lost), where measured its outline (cyan: the
    outer contour of the pixels inside the box that are in the frame's colour range,
    ``track.colors``) and centroid (a cyan cross), the image trajectory so far (the
    ``u_px``, ``v_px`` features) and the frame number and time.

    Args:
        video: the recording that ``track`` (a `cgda_jax.vision.Track`) came from.
        out_path: the PNG file to write.
    """
    c = cv2()
    out_path = pathlib.Path(out_path).expanduser()
    picks = np.unique(np.linspace(0, track.n_frames - 1, n_frames).round().astype(int))
    demo = track.demo
    uv = demo.features[:, [demo.feature_names.index("u_px"),
                           demo.feature_names.index("v_px")]]
    thumbs = []
    wanted = set(picks.tolist())
    for k, img in enumerate(iter_frames(video)):
        if k not in wanted:
            continue
        frame, img = img, img.copy()
        row = k - track.first
        kept = 0 <= row < len(uv)
        if kept and row > 0:
            pts = uv[: row + 1].round().astype(np.int32).reshape(-1, 1, 2)
            c.polylines(img, [pts], False, _YELLOW, 2, c.LINE_AA)
        if track.found[k]:
            x, y, w, h = (int(v) for v in track.bboxes[k])
            mask = in_range(hsv_image(frame[y:y + h, x:x + w]), track.colors[k])
            outline, _ = c.findContours(mask, c.RETR_EXTERNAL, c.CHAIN_APPROX_NONE,
                                        offset=(x, y))
            c.drawContours(img, outline, -1, _CYAN, 2, c.LINE_AA)
            c.rectangle(img, (x - 2, y - 2), (x + w + 1, y + h + 1), _GREEN, 2)
            u, v = uv[row].round().astype(int)
            c.drawMarker(img, (int(u), int(v)), _CYAN, c.MARKER_CROSS, 12, 2)
            label, colour = "", _GREEN
        elif kept:
            u, v = uv[row].round().astype(int)
            c.circle(img, (int(u), int(v)), 12, _YELLOW, 2)
            label, colour = "interpolated", _YELLOW
        else:
            label, colour = "lost (cut)", _RED
        text = f"frame {k}" + (f"  t={demo.times[row]:.2f}s" if kept else "")
        c.putText(img, text, (8, 24), c.FONT_HERSHEY_SIMPLEX, 0.7, _WHITE, 2, c.LINE_AA)
        if label:
            c.putText(img, label, (8, 52), c.FONT_HERSHEY_SIMPLEX, 0.7, colour, 2,
                      c.LINE_AA)
        scale = thumb_width / img.shape[1]
        thumbs.append(c.resize(img, (thumb_width, round(img.shape[0] * scale)),
                               interpolation=c.INTER_AREA))
    h, w = thumbs[0].shape[:2]
    rows = -(-len(thumbs) // columns)
    sheet = np.full((rows * (h + 4) + 4, columns * (w + 4) + 4, 3), 30, np.uint8)
    for i, t in enumerate(thumbs):
        r, col = divmod(i, columns)
        sheet[4 + r * (h + 4):4 + r * (h + 4) + h, 4 + col * (w + 4):4 + col * (w + 4) + w] = t
    out_path.parent.mkdir(parents=True, exist_ok=True)
    if not c.imwrite(str(out_path), sheet):
        raise ValueError(f"{out_path}: cannot write the contact sheet")
    return out_path
