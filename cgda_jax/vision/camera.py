"""Pinhole camera intrinsics (and an optional camera-to-world pose) in a JSON file.

Pixel coordinates follow OpenCV: ``u`` to the right, ``v`` down, the centre of the
top-left pixel at (0, 0). The camera frame follows OpenCV too: X right, Y down, Z
along the optical axis (depth), in metres. A depth image holds Z per pixel (not the
distance along the ray) in units of ``depth_scale`` metres (1e-3: millimetres, the
usual 16-bit PNG of RGB-D cameras; a float ``.npy`` in metres has scale 1).

File layout (JSON object)::

    {"width": 640, "height": 480, "fx": 579.4, "fy": 579.4, "cx": 319.5,
     "cy": 239.5, "depth_scale": 0.001,
     "camera_to_world": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}

``depth_scale`` (default 0.001) and ``camera_to_world`` (a 4 x 4 rigid transform;
when given, X, Y, Z are reported in that world frame) are optional.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib

import numpy as np

__all__ = ["Intrinsics", "load_intrinsics", "save_intrinsics"]

_REQUIRED = ("width", "height", "fx", "fy", "cx", "cy")


@dataclasses.dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera: image size (pixels), focal lengths and principal point
    (pixels), depth units (metres per depth unit) and an optional 4 x 4
    camera-to-world pose."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    depth_scale: float = 0.001
    camera_to_world: tuple[tuple[float, ...], ...] | None = None

    def __post_init__(self) -> None:
        for key in ("width", "height"):
            v = getattr(self, key)
            if int(v) != v or v < 1:
                raise ValueError(f"intrinsics: {key} must be a positive integer, got {v!r}")
        for key in ("fx", "fy", "depth_scale"):
            v = float(getattr(self, key))
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"intrinsics: {key} must be positive, got {v!r}")
        for key in ("cx", "cy"):
            if not np.isfinite(float(getattr(self, key))):
                raise ValueError(f"intrinsics: {key} must be finite")
        if self.camera_to_world is not None:
            m = np.asarray(self.camera_to_world, dtype=float)
            if m.shape != (4, 4) or not np.all(np.isfinite(m)):
                raise ValueError("intrinsics: camera_to_world must be a finite 4 x 4 matrix")
            rot = m[:3, :3]
            if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or not np.allclose(
                m[3], [0, 0, 0, 1]
            ):
                raise ValueError(
                    "intrinsics: camera_to_world must be a rigid transform (rotation "
                    "block orthonormal, last row 0 0 0 1)"
                )
            object.__setattr__(self, "camera_to_world", tuple(map(tuple, m.tolist())))

    def deproject(self, u, v, z) -> np.ndarray:
        """Points (..., 3) in metres from pixel coordinates and depth Z (metres), in
        the camera frame, or the world frame when ``camera_to_world`` is given."""
        u, v, z = (np.asarray(a, dtype=np.float64) for a in (u, v, z))
        pts = np.stack([(u - self.cx) / self.fx * z, (v - self.cy) / self.fy * z, z], -1)
        if self.camera_to_world is not None:
            m = np.asarray(self.camera_to_world)
            pts = pts @ m[:3, :3].T + m[:3, 3]
        return pts

    def project(self, points) -> np.ndarray:
        """Pixel coordinates (..., 2) of camera-frame points (..., 3) in metres."""
        p = np.asarray(points, dtype=np.float64)
        return np.stack(
            [self.fx * p[..., 0] / p[..., 2] + self.cx,
             self.fy * p[..., 1] / p[..., 2] + self.cy], -1
        )


def load_intrinsics(path: str | pathlib.Path) -> Intrinsics:
    """Read an `Intrinsics` JSON file (layout in the module doc).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not JSON, a missing or unknown key, or a bad value (names the file).
    """
    path = pathlib.Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"no such intrinsics file: {path}")
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"{path}: not a JSON file ({err})") from None
    if not isinstance(raw, dict):
        raise ValueError(f"{path}: expected a JSON object with keys {_REQUIRED}")  # noqa: TRY004
    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        raise ValueError(f"{path}: missing key(s) {missing}")
    known = {f.name for f in dataclasses.fields(Intrinsics)}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown}; known: {sorted(known)}")
    try:
        return Intrinsics(**raw)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: {err}") from None


def save_intrinsics(intrinsics: Intrinsics, path: str | pathlib.Path) -> pathlib.Path:
    """Write ``intrinsics`` as JSON (the layout `load_intrinsics` reads)."""
    path = pathlib.Path(path).expanduser()
    raw = dataclasses.asdict(intrinsics)
    if raw["camera_to_world"] is None:
        del raw["camera_to_world"]
    path.write_text(json.dumps(raw, indent=1) + "\n", encoding="utf-8")
    return path
