"""The robot's video: the GIF in one shared palette (late colours kept), every
frame written; the frames per waypoint of `render_run`'s videos."""

import types

import numpy as np
import pytest

Image = pytest.importorskip("PIL.Image")


def _frames(n: int = 10, size=(120, 160)) -> list[np.ndarray]:
    """Smooth colour ramps that shift per frame; a red square only in the last."""
    h, w = size
    y, x = np.mgrid[0:h, 0:w]
    out = []
    for k in range(n):
        img = np.stack([(x * 255 // w + 7 * k) % 256, y * 255 // h,
                        np.full_like(x, 40 + 10 * k)], axis=-1).astype(np.uint8)
        out.append(img)
    out[-1][40:80, 60:100] = (230, 10, 10)
    return out


def _read_gif(path) -> list[np.ndarray]:
    from PIL import ImageSequence

    return [np.asarray(f.convert("RGB")).astype(int)
            for f in ImageSequence.Iterator(Image.open(path))]


def test_gif_one_palette_for_all_frames_keeps_the_last_frames_colours(tmp_path):
    from cgda_jax.sim.video import write_video

    images = _frames()
    (path,) = write_video(images, tmp_path / "v.gif", fps=8)
    got = _read_gif(path)
    assert len(got) == len(images)
    assert got[0].shape == (120, 160, 3)
    # one shared palette: at most 255 colours over all frames (a palette per frame
    # of these shifting ramps would use many more)
    colours = np.unique(np.concatenate([g.reshape(-1, 3) for g in got]), axis=0)
    assert len(colours) <= 255
    # the red square, only in the last frame, is in the palette
    np.testing.assert_allclose(got[-1][40:80, 60:100].mean(axis=(0, 1)),
                               (230, 10, 10), atol=12)
    for g, img in zip(got, images):  # 2-D colour ramps in 255 colours: ~10 off
        assert np.abs(g - img).mean() < 16


def test_gif_palette_samples_the_first_and_the_last_frame():
    from cgda_jax.sim.video import gif_palette

    images = [np.zeros((8, 8, 3), np.uint8) for _ in range(40)]
    images[0][:] = (0, 200, 0)
    images[-1][:] = (200, 0, 0)
    palette = np.asarray(gif_palette(images, samples=3).getpalette()).reshape(-1, 3)
    for colour in ((0, 200, 0), (200, 0, 0), (0, 0, 0)):
        assert np.abs(palette - colour).sum(axis=1).min() == 0, colour


def test_frames_per_waypoint_of_the_videos():
    from cgda_jax.experiment.figures import (
        FRAMES_PER_WAYPOINT,
        PAINT_FRAMES_PER_WAYPOINT,
        frames_per_waypoint,
    )

    wall = types.SimpleNamespace(centres=np.zeros((16, 3)))

    def sim(scene, mode="kinematic", substeps=8):
        return types.SimpleNamespace(scene=scene, mode=mode, substeps=substeps)

    assert PAINT_FRAMES_PER_WAYPOINT == 4 and FRAMES_PER_WAYPOINT == 3
    assert frames_per_waypoint(sim(wall)) == 4  # the sweep, in 4 of 8 sub-steps
    assert frames_per_waypoint(sim(wall, substeps=2)) == 2
    assert frames_per_waypoint(sim(wall, mode="dynamic")) == 3
    assert frames_per_waypoint(sim(types.SimpleNamespace())) == 3  # marker scene


@pytest.mark.parametrize(("shape", "text"), [
    ((480, 640, 3), "paint_iet: point 3 of 17\ntarget 12.5 %, painted 6.2 %"),
    ((180, 240, 3), "start"),
    ((40, 300, 3), "a\nbox\ntaller\nthan the image"),
])
def test_caption_equals_drawing_into_the_whole_frame(shape, text):
    """The caption drawn into the rows its box covers equals drawing it into the
    whole frame (Pillow, as the caption was first written)."""
    from PIL import ImageDraw, ImageFont

    from cgda_jax.sim.video import caption

    image = np.random.default_rng(1).integers(0, 255, shape, dtype=np.uint8)
    im = Image.fromarray(image)
    try:
        font = ImageFont.load_default(size=max(10, shape[0] // 22))
    except TypeError:  # Pillow < 10.1
        font = ImageFont.load_default()
    draw = ImageDraw.Draw(im, "RGBA")
    x0, y0, x1, y1 = draw.multiline_textbbox((8, 6), text, font=font, spacing=4)
    draw.rectangle((x0 - 5, y0 - 4, x1 + 5, y1 + 4), fill=(0, 0, 0, 170))
    draw.multiline_text((8, 6), text, font=font, fill=(255, 255, 255, 255), spacing=4)
    got = caption(image, text)
    np.testing.assert_array_equal(got, np.asarray(im))
    assert not np.array_equal(got, image)  # something was drawn
    np.testing.assert_array_equal(image, np.random.default_rng(1).integers(
        0, 255, shape, dtype=np.uint8))  # the input is left as it was
