"""Plotting: each figure function returns a Figure with the data drawn and writes a PNG."""

import numpy as np
import pytest

from cgda_jax import plotting
from cgda_jax.datasets import clean_circle_demos, synthetic_actions


def _close_all() -> None:
    import matplotlib.pyplot as plt  # after cgda_jax.plotting chose the backend

    plt.close("all")


def _png(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 2000
    return data


def test_demonstrations_3d_and_panels(tmp_path):
    demos = clean_circle_demos(n=3, seed=1)
    goal = np.asarray(demos[0].features[::20])
    fig = plotting.plot_demonstrations(demos, goal, goal + 0.01, path=tmp_path / "a.png")
    ax = fig.axes[0]
    assert ax.name == "3d" and len(ax.lines) == 3 + 2  # demos, goal, executed
    np.testing.assert_allclose(ax.lines[3].get_data_3d()[2], goal[:, 2])
    _png(tmp_path / "a.png")
    paint = synthetic_actions(n_repetitions=2, seed=0)["PAINT"]
    fig = plotting.plot_demonstrations(paint, features=["hue", "value"], path=tmp_path / "b.png")
    assert [a.get_ylabel() for a in fig.axes if a.get_visible()] == ["hue", "value"]
    with pytest.raises(KeyError, match="nope"):
        plotting.plot_demonstrations(paint, features=["nope"])


def test_cost_matrix_marks_row_minimum(tmp_path):
    m = np.array([[1.0, 50.0], [300.0, 2.0e6]])
    fig = plotting.plot_cost_matrix(m, ["a", "b"], ["A", "B"], path=tmp_path / "c.png")
    texts = {t.get_text(): t.get_fontweight() for t in fig.axes[0].texts}
    assert texts["1"] == "bold" and texts["300"] == "bold"
    assert texts["50"] == "normal" and texts["2.000e+06"] == "normal"
    _png(tmp_path / "c.png")
    with pytest.raises(ValueError, match="does not match"):
        plotting.plot_cost_matrix(m, ["a"], ["A", "B"])


def test_fitness_goal_time_frames(tmp_path):
    h = np.r_[np.linspace(5, 1, 10), [np.nan] * 3]
    fig = plotting.plot_fitness(h, path=tmp_path / "f.png")
    x, y = fig.axes[0].lines[1].get_data()  # the red minimum marker
    assert x[0] == 10 and y[0] == 1.0  # generations counted from 1
    plotting.plot_fitness(np.ones((3, 5)), labels=["p0", "p1", "p2"], path=tmp_path / "g.png")
    goal = np.linspace(0, 100, 17)[:, None]
    fig = plotting.plot_goal_vs_executed(goal, goal + 1, ["painted"], tolerance=3.0,
                                         path=tmp_path / "e.png")
    np.testing.assert_allclose(fig.axes[0].lines[1].get_ydata(), goal[:, 0] + 1)
    with pytest.raises(ValueError, match="different F"):
        plotting.plot_goal_vs_executed(goal, np.zeros((17, 2)))
    plotting.plot_time_per_point(np.arange(17.0), path=tmp_path / "t.png")
    plotting.plot_frames([np.zeros((8, 8, 3))] * 3, path=tmp_path / "r.png")
    for name in "fgetr":
        _png(tmp_path / f"{name}.png")


def test_cost_matrix_has_a_labelled_log_colorbar():
    m = np.array([[1.0, 50.0], [300.0, 2.0e6]])
    fig = plotting.plot_cost_matrix(m, ["a", "b"], ["A", "B"], label="DTW cost")
    image = fig.axes[0].images[0]
    assert image.colorbar is not None and len(fig.axes) == 2
    assert "DTW cost" in image.colorbar.ax.get_ylabel()
    assert "low" in image.colorbar.ax.get_ylabel()
    assert image.norm.vmin == 1.0 and image.norm.vmax == 2.0e6  # log norm over the data


def test_flat_3d_trajectory_keeps_room_for_its_ticks():
    demos = clean_circle_demos(n=2, seed=1)  # a circle in the Y-Z plane: X nearly flat
    ax = plotting.plot_demonstrations(demos).axes[0]
    spans = [np.ptp(lim) for lim in (ax.get_xlim(), ax.get_ylim(), ax.get_zlim())]
    assert min(spans) >= 0.39 * max(spans)
    assert len([t for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]) <= 4


def test_knot_curve_is_the_generalized_action_between_its_knots():
    """Plots draw a GeneralizedAction in NumPy between its first and last knot only:
    equal to the RBF there, nothing extrapolated beyond."""
    from cgda_jax.generalization import generalize

    demos = clean_circle_demos(n=3, seed=1)
    for gen in (generalize(demos, interval_s=1.0), generalize(demos, interval_s=0.7)):
        t, curve = plotting.knot_curve(gen, 57)
        kt = np.asarray(gen.knot_times)
        assert t[0] == kt.min() and t[-1] == kt.max() and kt.min() > 0
        np.testing.assert_allclose(curve, np.asarray(gen(t)), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("title", [None, "one line", "two\nlines"])
def test_fast_layouts_match_tight_layout(title):
    """The layouts set without `tight_layout`'s pass are the ones it computes: a 3-D
    plot's pads and title room; the panel grid's room for the legend below."""
    _close_all()  # those the tests before left open
    demos = clean_circle_demos(n=2, seed=1)

    def margins(fig) -> np.ndarray:
        p, (w, h) = fig.subplotpars, fig.get_size_inches()
        return np.array([p.left * w, (1 - p.right) * w, p.bottom * h, (1 - p.top) * h,
                         p.wspace, p.hspace])

    fig = plotting.plot_demonstrations(demos, title=title)
    fast = margins(fig)
    fig.tight_layout()
    np.testing.assert_allclose(fast, margins(fig), atol=0.03)
    paint = synthetic_actions(n_repetitions=2, seed=0)["PAINT"]
    fig = plotting.plot_demonstrations(paint, title=title)  # 8 panels in 2 rows
    fast = margins(fig)
    fig.tight_layout(rect=(0, 0.35 / fig.get_figheight(), 1, 1))  # two passes
    np.testing.assert_allclose(fast, margins(fig), atol=0.03)
    _close_all()


def test_panel_grid_fixed_margins_checked_once_drawn(tmp_path):
    """Saved, a panel grid keeps its fixed margins where every label fits (checked
    on the drawn figure) and falls back to tight_layout's where one does not."""
    from cgda_jax.plotting._layout import GRID_SIDE_IN, _texts_fit

    paint = synthetic_actions(n_repetitions=2, seed=0)["PAINT"]
    names = list(paint[0].feature_names)
    fig = plotting.plot_demonstrations(paint, names=names, title="a title",
                                       path=tmp_path / "a.png")
    assert fig.subplotpars.left * fig.get_figwidth() == pytest.approx(GRID_SIDE_IN)
    grid = np.array(fig.axes).reshape(2, 4)
    assert _texts_fit(fig, grid)
    # a y label of four lines does not fit in the fixed room left of its panel
    names[5] = "a\nlong\nfeature\nname"
    fig = plotting.plot_demonstrations(paint, names=names, title="a title",
                                       path=tmp_path / "b.png")
    p, width = fig.subplotpars, fig.get_figwidth()
    saved = p.left, p.wspace
    axes_w = (p.right - p.left) * width / (4 + 3 * p.wspace)
    assert p.wspace * axes_w > GRID_SIDE_IN + 0.1  # more room than the fixed layout
    fig.tight_layout(rect=(0, 0.35 / fig.get_figheight(), 1, 1))
    np.testing.assert_allclose(saved, (fig.subplotpars.left, fig.subplotpars.wspace),
                               atol=0.005)
    _close_all()


def test_frame_strip_draws_large_frames_reduced_to_its_cells():
    """640x480 frames fill ~300-pixel cells: drawn from a half-size box-filtered copy
    (the same picture at the strip's size); small or float frames as given."""
    frame = np.zeros((480, 640, 3), np.uint8)
    frame[:240] = 200  # top half bright: the halving averages 2x2 blocks
    fig = plotting.plot_frames([frame, frame[:60, :80]])
    big, small = (ax.images[0].get_array() for ax in fig.axes[:2])
    assert big.shape == (240, 320, 3) and small.shape == (60, 80, 3)
    assert big[:120].min() == 200 and big[120:].max() == 0
    floats = np.zeros((480, 640, 3))
    assert plotting.plot_frames([floats]).axes[0].images[0].get_array().shape == (
        480, 640, 3)
    _close_all()
