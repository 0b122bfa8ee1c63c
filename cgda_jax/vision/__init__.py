"""Demonstrations from a camera: track a coloured object in RGB(-D) video and get
the paper's object features (position, area, hue, saturation, value, angle) as
`cgda_jax.Demonstration`s.

Needs OpenCV, the optional ``[vision]`` extra (``pip install 'cgda_jax[vision]'``);
importing this package works without it, a call that needs it says what to install.

* `track_video`: one recording -> `Track` (its ``demo`` a `Demonstration`).
* `ColorRange`: the object's HSV range (or an automatic pick from the first frame,
  then the colour model `ColorRange.around` learned again every frame, which keeps
  shaded faces and follows light that moves or dims; `Track.colors` per frame).
* `Intrinsics`, `load_intrinsics`: the pinhole camera for X, Y, Z in metres.
* `contact_sheet`: frames with the tracked blob and its trajectory, to check by eye.
* `render_recording` (`cgda_jax.vision.record`): MuJoCo-rendered RGB-D recordings
  of scripted MOVE / ROTATE / CLEAN / PAINT demonstrations, with ground truth;
  `render_shaded` (`cgda_jax.vision.shaded`): a box or cylinder turning under
  moving or dimming light, with MuJoCo's segmentation image as the truth.
* `render_sequence` (`cgda_jax.vision.record`): several scripted actions in a row,
  the true segments from the script; `synthetic_units` turns its track into the
  synthetic set's features, for `cgda_jax.segment` against the synthetic library.

References:
    Morante et al., "Humanoid Robot Imitation through Continuous Goal-Directed
    Actions: An Evolutionary Approach", Advanced Robotics 2015, section 4.1 (a
    Kinect tracking a coloured marker).
"""

from cgda_jax.vision.blob import ColorRange
from cgda_jax.vision.camera import Intrinsics, load_intrinsics, save_intrinsics
from cgda_jax.vision.cv import MISSING
from cgda_jax.vision.sheet import contact_sheet
from cgda_jax.vision.track import DEPTH_FEATURES, IMAGE_FEATURES, Track, track_video

__all__ = [
    "DEPTH_FEATURES",
    "IMAGE_FEATURES",
    "MISSING",
    "ColorRange",
    "Intrinsics",
    "Track",
    "contact_sheet",
    "load_intrinsics",
    "save_intrinsics",
    "track_video",
]
