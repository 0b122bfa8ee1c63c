"""cgda_jax.vision.record renders what its ground truth says (needs offscreen GL:
each back-end is tried in a fresh process, as in test_render; skipped without one).

- MuJoCo's segmentation image gives the marker as many pixels as the projected face
  (the hand never covers it; the sheet does, on the frames marked not visible);
- the depth render at the marker's centre is the face's geometric depth;
- a fresh render reproduces the shipped test recording (tests/data/vision/move).
"""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("cv2")

DATA = pathlib.Path(__file__).resolve().parent / "data" / "vision"

SCRIPT = r"""
import json, sys
import numpy as np
from cgda_jax.vision.record import render_recording
from cgda_jax.vision.frames import read_depth
import pathlib
out = pathlib.Path(sys.argv[1])
occ = render_recording(out / "occ", "MOVE", 7, fps=3, occlude=True, segmentation=True,
                       png_compression=1)
mov = render_recording(out / "move", "MOVE", 1, fps=4, max_frames=3, png_compression=1)
f = occ.feature_names
u, v = occ.features[:, f.index("u_px")], occ.features[:, f.index("v_px")]
z = [read_depth(out / "occ/depth" / f"frame_{k:04d}.png", 1e-3)[int(round(v[k])),
     int(round(u[k]))] for k in range(occ.n_samples)]
print("RESULT", json.dumps({
    "seg": np.load(out / "occ/segment.npy").tolist(),
    "area": occ.features[:, f.index("area_px")].tolist(),
    "visible": occ.features[:, f.index("visible")].tolist(),
    "z_truth": occ.features[:, f.index("Z_m")].tolist(), "z_render": z,
    "move": mov.features.tolist()}))
"""


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec")
    for backend in ("egl", "osmesa"):
        env = dict(os.environ, MUJOCO_GL=backend, PYTHONPATH=str(DATA.parents[2]))
        proc = subprocess.run([sys.executable, "-c", SCRIPT, str(out)], env=env,
                              capture_output=True, text=True, timeout=300, check=False)
        for line in proc.stdout.splitlines():
            if line.startswith("RESULT "):
                return out, json.loads(line[7:])
    pytest.skip(f"no offscreen OpenGL: {proc.stderr[-500:]}")


def test_segmentation_agrees_with_visibility(rendered):
    _, r = rendered
    seg, area, vis = (np.asarray(r[k]) for k in ("seg", "area", "visible"))
    assert (vis == 0).sum() == 4  # the sheet's frames
    assert (seg[vis == 0] < 0.5 * area[vis == 0]).all()
    # visible: every face pixel is the marker's (+ its 2 mm rim seen in perspective)
    assert (seg[vis == 1] >= 0.97 * area[vis == 1]).all()  # pixel steps: about 1.5 %
    assert (seg[vis == 1] <= 1.05 * area[vis == 1]).all()


def test_depth_render_is_the_geometric_depth(rendered):
    _, r = rendered
    vis = np.asarray(r["visible"]) == 1
    err = np.abs(np.asarray(r["z_render"]) - np.asarray(r["z_truth"]))[vis]
    assert err.max() <= 0.001  # millimetre PNG steps


def test_a_fresh_render_reproduces_the_shipped_recording(rendered):
    import cv2

    from cgda_jax.data import load_csv

    out, r = rendered
    shipped = load_csv(DATA / "move" / "truth.csv")
    np.testing.assert_allclose(np.asarray(r["move"]), shipped.features[:3], atol=1e-9)
    for k in range(3):
        a = cv2.imread(str(out / "move/rgb" / f"frame_{k:04d}.png")).astype(int)
        b = cv2.imread(str(DATA / "move/rgb" / f"frame_{k:04d}.png")).astype(int)
        assert np.abs(a - b).mean() < 1.0  # GL implementations may round differently
