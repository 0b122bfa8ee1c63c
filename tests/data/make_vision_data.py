"""Regenerate the rendered RGB-D test recordings in tests/data/vision/.

    MUJOCO_GL=egl python tests/data/make_vision_data.py

Each recording folder is written by `cgda_jax.vision.record.render_recording`
(frames, depth, intrinsics, ground truth); low frame rates keep the files small
(about 3 MB in all). The benchmark (benchmarks/bench_vision.py) renders more at 30 fps.
"""

import pathlib
import shutil

from cgda_jax.vision.record import render_recording

OUT = pathlib.Path(__file__).resolve().parent / "vision"

#: name: (action, seed, fps)
RECORDINGS = {
    "move": ("MOVE", 1, 4.0),
    "rotate": ("ROTATE", 2, 4.0),
    "clean": ("CLEAN", 3, 3.0),
    "paint": ("PAINT", 4, 3.0),
}

if __name__ == "__main__":
    shutil.rmtree(OUT, ignore_errors=True)
    for name, (action, seed, fps) in RECORDINGS.items():
        truth = render_recording(OUT / name, action, seed, fps=fps)
        print(name, truth.n_samples, "frames")
