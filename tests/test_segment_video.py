"""segment() on a tracked video of an action sequence (issue 44, part 3).

One short, small video rendered by `cgda_jax.vision.record.render_sequence` (the desk
scene of the camera demonstrations: MOVE then PAINT back to back, 320 x 240 RGB-D
at 10 fps), tracked by `track_video` (automatic colour pick, depth), turned into
the synthetic set's features (`synthetic_units`) and segmented against the library
generalized from the synthetic demonstrations. The truth is the script's, never
the pixels. benchmarks/bench_sequence.py --videos runs 2-6 actions at 30 fps.
Rendering needs an offscreen OpenGL; each back-end is tried in a fresh process, and
the test skips without one.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

pytest.importorskip("cv2")

from cgda_jax import segmentation
from cgda_jax.datasets import synthetic_actions
from cgda_jax.plotting import plot_segmentation
from cgda_jax.recognition import ActionLibrary
from cgda_jax.segmentation import segment
from cgda_jax.vision import track_video
from cgda_jax.vision.record import render_sequence, synthetic_units
from cgda_jax.vision.scene import SEQUENCE_AREA_M, scripted_sequence

ACTIONS, SEED, FPS = ["MOVE", "PAINT"], 5, 10.0

SCRIPT = r"""
import sys
from cgda_jax.vision.record import render_sequence
render_sequence(sys.argv[1], ["MOVE", "PAINT"], 5, fps=10.0)
print("DONE")
"""


@pytest.fixture(scope="module")
def video(tmp_path_factory, offscreen_script):
    return offscreen_script(SCRIPT, tmp_path_factory.mktemp("sequence"))


def test_tracked_video_of_a_sequence_is_segmented(video, monkeypatch):
    meta = json.loads((video / "recording.json").read_text())
    truth = [tuple(s) for s in meta["segments"]]
    # the script's truth, drawn again without rendering
    path, again = scripted_sequence(ACTIONS, np.random.default_rng(SEED), FPS)
    assert [a for a, _, _ in truth] == ACTIONS
    np.testing.assert_allclose([s[1:] for s in truth], [s[1:] for s in again])
    track = track_video(video / "rgb", depth=video / "depth",
                        intrinsics=video / "intrinsics.json", fps=FPS)
    assert track.found.all() and track.n_frames == len(path.times)
    rec = synthetic_units(track.demo)
    # the synthetic set's frame: X, Y along the desk's x, y (mm), Z the depth
    np.testing.assert_allclose(rec.features[:, :2], 1000 * path.marker_xy, atol=1.5)
    np.testing.assert_allclose(rec.features[:, 2], 878.0, atol=1.0)
    # PAINT turns the green marker blue (hue 60 -> about 114)
    assert rec.features[0, 4] == pytest.approx(60.0, abs=1.0)
    assert rec.features[-1, 4] - rec.features[0, 4] > 45.0
    library = ActionLibrary.from_demonstrations(synthetic_actions(6, seed=0))
    segs = segment(rec, library, step_s=0.2, durations_s=(1.0, 15.0))
    assert [s.action for s in segs] == ACTIONS
    for s, (_, t0, t1) in zip(segs, truth):
        assert max(abs(s.start - t0), abs(s.end - t1)) <= 0.1 * (t1 - t0), (s, t0, t1)
    # the figure: the recognized actions shaded, the true starts and ends drawn
    fig = plot_segmentation(rec, segs, truth=truth)
    lines = [ln for ln in fig.axes[0].get_lines() if ln.get_linestyle() in ("--", ":")]
    assert sorted(ln.get_xdata()[0] for ln in lines) == sorted(
        v for _, t0, t1 in truth for v in (t0, t1))
    assert [t.get_text() for t in fig.axes[0].texts] == ACTIONS
    import matplotlib.pyplot as plt  # after cgda_jax.plotting chose the backend

    plt.close(fig)
    # the tracked marker is far cleaner than the demonstrations: in units of its
    # own noise, the library's wiggle in area and Z decides (MOVE MOVE PAINT)
    monkeypatch.setattr(segmentation, "_library_noise",
                        lambda lib: np.zeros(len(lib.feature_names)))
    with warnings.catch_warnings():  # an empty window of that wrong short MOVE
        warnings.simplefilter("ignore", RuntimeWarning)
        wrong = segment(rec, library, step_s=0.2, durations_s=(1.0, 15.0))
    assert [s.action for s in wrong] != ACTIONS


def test_sequences_that_cannot_be_filmed_are_refused():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="at most one PAINT"):
        scripted_sequence(["PAINT", "PAINT"], rng, FPS)
    with pytest.raises(ValueError, match="does not fit in the camera's view"):
        scripted_sequence(["MOVE", "MOVE", "MOVE"], rng, FPS)
    with pytest.raises(ValueError, match="unknown action"):
        scripted_sequence(["SWIM"], rng, FPS)
    with pytest.raises(ValueError, match=r"light_end must be in \(0, 1\]"):
        render_sequence("unused", ["MOVE"], light_end=0.0)
    drawn, truth = scripted_sequence(None, np.random.default_rng(1), FPS)
    assert 2 <= len(truth) <= 6
    assert [a for a, _, _ in truth].count("PAINT") <= 1
    (x0, x1), (y0, y1) = SEQUENCE_AREA_M
    assert drawn.marker_xy[:, 0].min() >= x0 and drawn.marker_xy[:, 0].max() <= x1
    assert drawn.marker_xy[:, 1].min() >= y0 and drawn.marker_xy[:, 1].max() <= y1


def test_synthetic_units_needs_a_track_with_depth():
    from cgda_jax.data import Demonstration

    flat = Demonstration(np.arange(3.0), np.zeros((3, 2)), ("u_px", "v_px"), "flat")
    with pytest.raises(ValueError, match=r"'flat': not a track with depth"):
        synthetic_units(flat)
