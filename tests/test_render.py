"""Offscreen rendering: frames and GIF written, painted squares visible.

MuJoCo reads MUJOCO_GL at import, so each back-end is tried in a fresh process;
the test skips where no offscreen GL works (no libegl1 / libosmesa6)."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

SCRIPT = r"""
import math, sys
import numpy as np
import cgda_jax as c
from cgda_jax.sim.render import render_frames, render_trajectory
out = sys.argv[1]
robot = c.Robot.from_mjcf(c.model_path("teo.xml"),
    ["r_shoulder_flexion", "r_shoulder_abduction", "r_elbow"], "marker",
    fixed={"r_forearm_rotation": math.radians(45)})
sim = c.Simulator(robot, c.PaintWall.grid(), substeps=3)
wps = np.radians([[40, 0, 60], [60, -30, 60], [70, -60, 40]]).astype(np.float32)
print("FEATURES", sim.execute(wps)[:, 0].tolist())
render_trajectory(sim, wps, out + "/run.gif", width=240, height=180,
                  frames_per_waypoint=3)
render_trajectory(sim, wps, out + "/frames", width=240, height=180,
                  frames_per_waypoint=3)
lit = [render_frames(sim, wps[:1], frames_per_waypoint=1, width=240, height=180,
                     shadows=s).images for s in (True, False)]
print("SHADOWS_SAME", all(np.array_equal(a, b) for a, b in zip(*lit)))
"""


def _render(tmp_path: pathlib.Path) -> str:
    for backend in ("egl", "osmesa"):
        env = dict(
            os.environ,
            MUJOCO_GL=backend,
            PYOPENGL_PLATFORM=backend,
            JAX_PLATFORMS="cpu",
        )
        proc = subprocess.run(
            [sys.executable, "-c", SCRIPT, str(tmp_path)],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        if proc.returncode == 0:
            return proc.stdout
        gl_words = ("offscreen MuJoCo renderer", "EGL", "OSMesa", "OpenGL", "libGL")
        if not any(word in proc.stderr for word in gl_words):
            raise AssertionError(proc.stderr[-3000:])
    pytest.skip("no offscreen OpenGL (MUJOCO_GL=egl or osmesa) on this machine")


def _red(img: np.ndarray) -> int:
    img = img.astype(int)
    return int(np.sum((img[..., 0] > 150) & (img[..., 1] < 60) & (img[..., 2] < 60)))


def test_render_gif_and_frames_show_the_painting(tmp_path):
    Image = pytest.importorskip("PIL.Image")
    stdout = _render(tmp_path)
    features = json.loads(stdout.split("FEATURES", 1)[1].strip().splitlines()[0])
    assert features[-1] > 0  # the path paints something
    frames = sorted((tmp_path / "frames").glob("frame_*.png"))
    assert len(frames) == 1 + 3 * 3  # start + frames per waypoint
    first = np.asarray(Image.open(frames[0]).convert("RGB"))
    last = np.asarray(Image.open(frames[-1]).convert("RGB"))
    assert first.shape == (180, 240, 3)
    # nothing painted at the start (only the small red marker site); squares later
    assert _red(first) < 20 and _red(last) > _red(first) + 100
    gif = Image.open(tmp_path / "run.gif")
    assert gif.n_frames == len(frames)
    # shadows off (as results folders render) changes no pixel of this scene
    assert "SHADOWS_SAME True" in stdout


def test_host_paint_states_match_the_scene_update_per_frame():
    """The renderer's paint states equal PaintWall.sweep along the path so far
    (the straight segments between consecutive markers, as the simulator paints)."""
    import cgda_jax as c
    from cgda_jax.sim.render import _scene_states

    wall = c.PaintWall.grid()
    rng = np.random.default_rng(0)
    # markers sweeping past the wall, grouped into frames of 1-3 markers
    path = np.linspace(wall.centres.min(0) - 0.1, wall.centres.max(0) + 0.1, 23)
    path += rng.normal(0, 0.05, path.shape)
    trails = np.split(path, [1, 3, 4, 7, 9, 10, 14, 15, 18, 21])
    got = _scene_states(wall, trails)
    assert len(got) == len(trails)
    ends = np.cumsum([len(t) for t in trails])
    for frame, end in zip(got, ends):
        state = wall.sweep(wall.init_state(), path[:end])
        np.testing.assert_array_equal(frame, np.asarray(state))
    # a stroke across square 5 with both ends 0.2 m from its centre paints it
    c, dy = wall.centres[5], np.array([-0.1, 0.2, 0.0])
    stroke = _scene_states(wall, [(c - dy)[None], (c + dy)[None]])
    assert not stroke[0][5] and stroke[1][5]
    assert 0 < np.sum(got[-1]) and np.sum(got[0]) < np.sum(got[-1])


def test_gl_back_end_is_chosen_when_rendering(tmp_path):
    """mujoco imported first with MUJOCO_GL unset fixes GLFW, whose context creation
    can abort a headless process; rendering then uses EGL or OSMesa, chosen at render
    time, or (no offscreen GL) refuses with a clear error, never an abort."""
    code = (
        "import os\n"
        "import mujoco\n"  # first: fixes GLFW as mujoco's back-end
        "import numpy as np\n"
        "from cgda_jax import MarkerScene, Robot, Simulator, model_path\n"
        "from cgda_jax.sim._mujoco_env import last_backend\n"
        "from cgda_jax.sim.render import render_trajectory\n"
        "r = Robot.from_mjcf(model_path('tiny_arm.xml'), ['yaw', 'shoulder', 'elbow'], "
        "'marker')\n"
        "try:\n"
        "    wps = np.array([[0.0, 0.2, 0.3], [0.8, 0.6, 0.9]])\n"
        f"    render_trajectory(Simulator(r, MarkerScene()), wps, r'{tmp_path / 'x.gif'}')\n"
        "    print('rendered with', last_backend(), os.environ.get('MUJOCO_GL'))\n"
        "except RuntimeError as err:\n"
        "    print('refused:', err)\n"
    )
    env = {k: v for k, v in os.environ.items()
           if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")}
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    if "refused:" in proc.stdout:
        assert "MUJOCO_GL=egl" in proc.stdout
        pytest.skip(f"no offscreen OpenGL here: {proc.stdout.strip()}")
    # rendered with EGL or OSMesa; MUJOCO_GL still unset
    assert proc.stdout.split()[-2:] in (["egl", "None"], ["osmesa", "None"]), proc.stdout
    Image = pytest.importorskip("PIL.Image")
    assert Image.open(tmp_path / "x.gif").n_frames > 1
