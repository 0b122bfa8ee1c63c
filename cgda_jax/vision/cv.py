"""OpenCV, imported on first use: the ``[vision]`` extra is optional.

``import cgda_jax`` and ``import cgda_jax.vision`` work without OpenCV; a function
that needs it calls `cv2` and gets a clear error naming the extra when it is missing.
"""

from __future__ import annotations

__all__ = ["MISSING", "cv2"]

#: What to install when OpenCV is missing.
MISSING = (
    "cgda_jax.vision needs OpenCV: pip install 'cgda_jax[vision]' "
    "(or pip install opencv-python-headless)"
)


def cv2():
    """The ``cv2`` module.

    Raises:
        ImportError: OpenCV is not installed (names the ``[vision]`` extra).
    """
    try:
        import cv2 as mod
    except ImportError as err:
        raise ImportError(f"{MISSING} ({err})") from None
    return mod
