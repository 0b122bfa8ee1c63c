"""Reading recordings: RGB frames from a video file or a folder of images, and
aligned depth frames from a folder.

A *frame folder* holds images (``.png``, ``.jpg``, ``.jpeg``, ``.bmp``, ``.tif``,
``.tiff``) taken in file-name order (so name them ``frame_0000.png``, ...). A *video
file* is anything OpenCV's ``VideoCapture`` reads (MP4, AVI, MKV, ... through its
FFmpeg back-end). A *depth folder* holds one depth image per RGB frame in the same
order: 16-bit PNG/TIFF (units of ``Intrinsics.depth_scale`` metres) or ``.npy``
float arrays in metres. A depth of 0 (or not finite) means "no reading".

Frames are yielded one at a time (``(H, W, 3)`` uint8 BGR, OpenCV's order), so a
long video is never held in memory.
"""

from __future__ import annotations

import pathlib
from collections.abc import Iterator

import numpy as np

from cgda_jax.vision.cv import cv2

__all__ = [
    "DEPTH_SUFFIXES",
    "IMAGE_SUFFIXES",
    "iter_frames",
    "list_frames",
    "read_depth",
    "video_fps",
]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
DEPTH_SUFFIXES = (".png", ".tif", ".tiff", ".npy")


def list_frames(folder: pathlib.Path, suffixes=IMAGE_SUFFIXES) -> list[pathlib.Path]:
    """The image files of a frame folder in name order.

    Raises:
        ValueError: the folder holds no such file.
    """
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in suffixes)
    if not files:
        raise ValueError(
            f"{folder}: no frames (files ending {', '.join(suffixes)}) in this folder"
        )
    return files


def video_fps(path: pathlib.Path) -> float | None:
    """The frame rate a video file states, or None (a frame folder, or none stated)."""
    if path.is_dir():
        return None
    cap = cv2().VideoCapture(str(path))
    try:
        fps = float(cap.get(cv2().CAP_PROP_FPS)) if cap.isOpened() else 0.0
    finally:
        cap.release()
    return fps if np.isfinite(fps) and fps > 0 else None


def _read_image(path: pathlib.Path) -> np.ndarray:
    img = cv2().imread(str(path), cv2().IMREAD_COLOR)
    if img is None:
        raise ValueError(f"{path}: cannot be read as an image")
    return img


def iter_frames(path: str | pathlib.Path) -> Iterator[np.ndarray]:
    """RGB frames (H, W, 3) uint8 in BGR order, from a video file or a frame folder.

    Raises:
        FileNotFoundError: no such file or folder.
        ValueError: a file that cannot be read as a video or image, frames of
            different sizes, or no frames at all (names the file).
    """
    path = pathlib.Path(path).expanduser()
    if not path.exists():
        raise FileNotFoundError(f"no such video file or frame folder: {path}")
    if path.is_dir():
        shape = None
        for f in list_frames(path):
            img = _read_image(f)
            if shape is not None and img.shape != shape:
                raise ValueError(
                    f"{f}: frame size {img.shape[1]}x{img.shape[0]} differs from the "
                    f"first frame's {shape[1]}x{shape[0]}"
                )
            shape = img.shape
            yield img
        return
    cap = cv2().VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise ValueError(f"{path}: cannot be read as a video (OpenCV cannot open it)")
        n = 0
        while True:
            ok, img = cap.read()
            if not ok:
                break
            n += 1
            yield img
        if n == 0:
            raise ValueError(f"{path}: the video has no frames (empty or unreadable)")
    finally:
        cap.release()


def read_depth(path: pathlib.Path, scale: float) -> np.ndarray:
    """One depth frame (H, W) float64 in metres; 0 or non-finite readings -> NaN.

    Raises:
        ValueError: unreadable, not a single-channel image, or not 16-bit / float.
    """
    if path.suffix.lower() == ".npy":
        try:
            z = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as err:
            raise ValueError(f"{path}: cannot be read as a .npy depth frame ({err})") from None
        if z.ndim != 2 or not np.issubdtype(z.dtype, np.floating):
            raise ValueError(
                f"{path}: a .npy depth frame must be a 2-D float array in metres, got "
                f"{z.dtype} of shape {z.shape}"
            )
        z = z.astype(np.float64)
    else:
        raw = cv2().imread(str(path), cv2().IMREAD_UNCHANGED)
        if raw is None:
            raise ValueError(f"{path}: cannot be read as a depth image")
        if raw.ndim != 2 or raw.dtype not in (np.uint16, np.float32):
            raise ValueError(
                f"{path}: a depth image must be single-channel 16-bit (or 32-bit "
                f"float), got {raw.dtype} with shape {raw.shape}"
            )
        z = raw.astype(np.float64) * scale
    z[~np.isfinite(z) | (z <= 0)] = np.nan
    return z
