"""Figures fit for a paper: units on the axes, legends for every band and marker,
whole-number ticks for points and generations (numbered from 1), no extrapolated
generalization; videos of the right size."""

import re

import numpy as np
import pytest

from cgda_jax import plotting
from cgda_jax.datasets import clean_circle_demos, synthetic_actions
from cgda_jax.plotting import units

UNIT = re.compile(r"\[[^\]]+\]")


def _png(path):
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _integer_ticks(axis) -> np.ndarray:
    lo, hi = sorted(axis.get_view_interval())
    ticks = [t for t in axis.get_ticklocs() if lo <= t <= hi]
    assert ticks and all(float(t).is_integer() for t in ticks), ticks
    return np.asarray(ticks)


def _legend_texts(ax) -> list[str]:
    legend = ax.get_legend()
    assert legend is not None
    return [t.get_text() for t in legend.get_texts()]


def test_units_from_names_and_tables():
    assert units.split_unit("box.x [m]") == ("box.x", "m")
    assert units.label("X", "m") == "X [m]" and units.label("a [mm]", "m") == "a [mm]"
    assert units.with_units(["X", "painted", "box.y [m]"], units.SIM_UNITS) == (
        "X [m]", "painted [%]", "box.y [m]")
    assert units.common_unit(["X [m]", "Y [m]"]) == "m"
    assert units.common_unit(["X [mm]", "area [px]"]) is None


def test_demonstrations_3d_units_legend_and_no_extrapolation(tmp_path):
    from cgda_jax.generalization import generalize

    demos = clean_circle_demos(n=3, seed=1)
    gen = generalize(demos, interval_s=1.0)
    names = units.with_units(demos[0].feature_names, units.SIM_UNITS)
    executed = np.asarray(gen.knots) + 0.01
    fig = plotting.plot_demonstrations(demos, gen, executed, names=names,
                                       title="clean: demos", path=tmp_path / "d.png")
    ax = fig.axes[0]
    for label in (ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()):
        assert label.endswith("[m]")
    texts = _legend_texts(ax)
    assert any("demonstrations" in t for t in texts) and "executed" in texts
    assert any("knots" in t for t in texts) and any("generalization" in t for t in texts)
    curve = np.column_stack(ax.lines[3].get_data_3d())  # after the 3 demonstrations
    knots = np.asarray(gen.knots)
    np.testing.assert_allclose(curve[0], knots[0], atol=1e-6)  # starts at knot 1
    np.testing.assert_allclose(curve[-1], knots[-1], atol=1e-6)  # ends at the last
    _png(tmp_path / "d.png")


def test_demonstrations_panels_stay_between_the_knots(tmp_path):
    from cgda_jax.generalization import generalize

    move = synthetic_actions(n_repetitions=3, seed=0)["MOVE"]
    gen = generalize(move, interval_s=1.0)
    names = units.with_units(move[0].feature_names, units.MARKER_UNITS)
    fig = plotting.plot_demonstrations(move, gen, names=names, path=tmp_path / "p.png")
    axes = [a for a in fig.axes if a.get_visible()]
    assert len(axes) == 8
    kt = np.asarray(gen.knot_times)
    knots = np.asarray(gen.knots)
    for f, ax in enumerate(axes):
        assert UNIT.search(ax.get_ylabel()), ax.get_ylabel()
        # one time axis per column: labelled on the bottom row, bare above it
        bottom = f + 4 >= len(axes)
        assert ("normalized time" in ax.get_xlabel()) == bottom
        assert ax.xaxis.get_tick_params()["labelbottom"] == bottom
        assert ax.get_xlim() == axes[f % 4].get_xlim()
        t, y = ax.lines[3].get_data()  # the generalization, after 3 demonstrations
        assert t.min() == pytest.approx(kt.min()) and t.max() == pytest.approx(kt.max())
        # within the knots' range: no spike beyond the first and last knot
        assert y.min() >= knots[:, f].min() - 1e-9 and y.max() <= knots[:, f].max() + 1e-9
    assert fig.legends  # one legend for all panels
    _png(tmp_path / "p.png")


def test_goal_vs_executed_points_from_one_and_tolerance_band(tmp_path):
    goal = np.linspace(0, 100, 17)[:, None]
    fig = plotting.plot_goal_vs_executed(goal, goal + 1, ["painted [%]"], tolerance=3.0,
                                         tolerance_unit="%", path=tmp_path / "g.png")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "painted [%]"
    np.testing.assert_array_equal(ax.lines[0].get_xdata(), np.arange(1, 18))
    ticks = _integer_ticks(ax.xaxis)
    assert ticks.min() >= 0
    texts = _legend_texts(ax)
    assert "goal ± tolerance (3 %)" in texts and "executed" in texts
    _png(tmp_path / "g.png")


def test_fitness_one_and_many_evolutions(tmp_path):
    fig = plotting.plot_fitness(np.linspace(5, 1, 7), unit="m", path=tmp_path / "a.png")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "best fitness [m]" and "generation" in ax.get_xlabel()
    _integer_ticks(ax.xaxis)
    assert any("minimum 1 m" in t for t in _legend_texts(ax))
    # 17 points, most solved in one generation: each still visible, one legend
    h = np.full((17, 6), np.nan)
    h[:, 0] = 0.0
    h[3, :4] = [9.0, 6.0, 6.0, 0.0]
    fig = plotting.plot_fitness(h, unit="%", path=tmp_path / "b.png")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "best fitness [%]"
    assert len(_legend_texts(ax)) == 2
    drawn = [line for line in ax.lines if line.get_marker() == "o"]
    assert len(drawn) == 17 and all(len(line.get_xdata()) >= 1 for line in drawn)
    xs = np.concatenate([line.get_xdata() for line in drawn])
    assert xs.min() == 1 and xs.max() == 16 + 4  # 16 one-generation points + 4
    _integer_ticks(ax.xaxis)
    bar = fig.axes[1]  # the point colour bar
    assert "goal point" in bar.get_ylabel()
    _integer_ticks(bar.yaxis)
    for name in "ab":
        _png(tmp_path / f"{name}.png")


def test_point_errors_and_effort_per_point(tmp_path):
    errors = np.array([0.01, 0.03, np.inf, 0.015])
    fig = plotting.plot_point_errors(errors, 0.02, unit="m", path=tmp_path / "e.png")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "point error [m]"
    texts = _legend_texts(ax)
    assert "tolerance 0.02 m" in texts and "within tolerance" in texts
    assert "beyond tolerance" in texts and "no finite execution" in texts
    assert _integer_ticks(ax.xaxis).min() >= 1
    fig = plotting.plot_time_per_point([1, 1, 12, 3], ylabel="generations",
                                       path=tmp_path / "t.png")
    ax = fig.axes[0]
    centres = sorted(p.get_x() + p.get_width() / 2 for p in ax.patches)
    assert centres == [1, 2, 3, 4]
    _integer_ticks(ax.xaxis)
    _integer_ticks(ax.yaxis)
    for name in "et":
        _png(tmp_path / f"{name}.png")


def test_cost_matrix_units_and_frame_labels(tmp_path):
    m = np.array([[1.0, 50.0], [300.0, 2.0e6]])
    fig = plotting.plot_cost_matrix(m, ["a", "b"], ["A", "B"], label="DTW cost [mm]",
                                    title="recognition_spatial: DTW", path=tmp_path / "c.png")
    assert "[mm]" in fig.axes[0].images[0].colorbar.ax.get_ylabel()
    assert fig.axes[0].get_title().startswith("recognition_spatial")
    fig = plotting.plot_frames([np.zeros((6, 8, 3))] * 3)
    assert [t.get_text() for ax in fig.axes for t in ax.texts] == [
        "start", "point 1", "point 2"]


@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_video_written_at_its_size(tmp_path, suffix):
    iio = pytest.importorskip("imageio.v3")
    from cgda_jax.sim.video import caption, write_video

    rng = np.random.default_rng(0)
    images = [caption(rng.integers(0, 255, (480, 640, 3), dtype=np.uint8), f"point {k}")
              for k in range(6)]
    (path,) = write_video(images, tmp_path / f"v{suffix}", fps=6)
    frames = iio.imread(path, index=None) if suffix == ".gif" else np.stack(
        list(iio.imiter(path, plugin="pyav" if _has_pyav() else None)))
    assert frames.shape[1:3] == (480, 640)
    assert frames.shape[0] == 6
    with pytest.raises(ValueError, match="different sizes"):
        write_video([images[0], images[0][:10]], tmp_path / f"w{suffix}")


def _has_pyav() -> bool:
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True
