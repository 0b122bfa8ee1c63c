"""The real iron recordings' wrist force (jr3): clock alignment, the authors' X, Y, Z,
Fz goal and their iron fitness."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cgda_jax.data import load_xgnitive, load_xgnitive_force, xgnitive_clock_offsets
from cgda_jax.distance import point_sum
from cgda_jax.generalization import generalize_streams

IRON = "xgnitive_icra2018/iron"


@pytest.mark.parametrize("reduced", [True, False])
def test_clock_offsets_match_the_codebook(xgnitive_dir, reduced):
    """jr3 runs 608.5-609.1 s behind the arm (codebook), from start to end."""
    off = xgnitive_clock_offsets(xgnitive_dir, "iron", reduced=reduced)
    assert off.shape == (4,)
    assert np.all((off > 608.5) & (off < 609.1)), off
    for rep, o in zip(range(1, 5), off):
        name = f"reduced-data-{rep}.csv" if reduced else f"data-{rep}.log"
        arm = np.loadtxt(xgnitive_dir / IRON / "teo/rightArm" / name)
        jr3 = np.loadtxt(xgnitive_dir / IRON / "jr3" / name)
        assert o == pytest.approx(arm[0, 1] - jr3[0, 1], abs=1e-9)
        # the same offset closes the recordings: no drift between the two clocks
        # (reduced files keep every 10th row: their last rows may be 0.2 s apart)
        assert abs((arm[-1, 1] - jr3[-1, 1]) - o) < (0.25 if reduced else 0.05)


def test_force_beside_the_arm_on_the_arm_clock(xgnitive_dir):
    demos = load_xgnitive_force(xgnitive_dir, "iron", ["X", "Y", "Z"], ["Fz", "Fx"],
                                reduced=False)
    arm = load_xgnitive(xgnitive_dir, "iron", "teo/rightArm", ["X", "Y", "Z"],
                        reduced=False)
    assert len(demos) == 4
    for rep, (d, a) in enumerate(zip(demos, arm), start=1):
        assert d.feature_names == ("X", "Y", "Z", "Fz", "Fx")
        np.testing.assert_array_equal(d.times, a.times)
        np.testing.assert_array_equal(d.features[:, :3], a.features)
        raw_a = np.loadtxt(xgnitive_dir / IRON / f"teo/rightArm/data-{rep}.log")
        raw_f = np.loadtxt(xgnitive_dir / IRON / f"jr3/data-{rep}.log")
        # a jr3 sample's time on the arm clock = its own + the offset (~ +609 s)
        k = len(raw_f) // 2
        t = raw_f[k, 1] + (raw_a[0, 1] - raw_f[0, 1]) - raw_a[0, 1]
        i = int(np.argmin(np.abs(d.times - t)))
        assert abs(d.times[i] - t) < 0.011  # 50 Hz streams
        lo = min(raw_f[k - 1, 4], raw_f[k, 4], raw_f[k + 1, 4])
        hi = max(raw_f[k - 1, 4], raw_f[k, 4], raw_f[k + 1, 4])
        assert lo - 1e-9 <= d.features[i, 3] <= hi + 1e-9
    # pressing on the board: the hardest push is tens of newtons, negative
    assert min(d.features[:, 3].min() for d in demos) < -40


def test_goal_is_the_authors_iron_target(xgnitive_dir):
    """X, Y, Z (arm) and Fz (jr3), each stream binned on its own clock as the authors
    did: their target_iron[9][4] to 1e-5."""
    want = np.loadtxt(xgnitive_dir / "xgnitive_derived/hardcoded_targets/"
                      "iron_target_9x4.txt")[:, 1:]
    arm = load_xgnitive(xgnitive_dir, "iron", "teo/rightArm", ["X", "Y", "Z"])
    force = load_xgnitive(xgnitive_dir, "iron", "jr3", ["Fz"])
    g = generalize_streams([arm, force], interval_s=3.0, method="xgnitive")
    assert g.feature_names == ("X", "Y", "Z", "Fz")
    assert g.knots.shape == (9, 4)
    np.testing.assert_allclose(np.asarray(g.knots), want, atol=1e-5, rtol=0)
    # the stacked RBF passes through every knot
    np.testing.assert_allclose(np.asarray(g(g.knot_times)), np.asarray(g.knots),
                               atol=1e-4)


def test_point_sum_is_the_authors_iron_fitness():
    rng = np.random.default_rng(1)
    target = np.column_stack([rng.uniform(-0.5, 0.5, (9, 3)), rng.uniform(-30, 10, 9)])
    cands = target + np.concatenate([rng.normal(0, 0.02, (5, 9, 3)),
                                     rng.normal(0, 5, (5, 9, 1))], axis=-1)
    # the C++ loop: sum over points of sqrt(dX^2 + dY^2 + dZ^2 + (dFz / 300)^2)
    ref = [sum(np.sqrt(sum((c[i, k] - target[i, k]) ** 2 for k in range(3))
                       + ((c[i, 3] - target[i, 3]) / 300) ** 2) for i in range(9))
           for c in cands]
    w = jnp.array([1, 1, 1, 1 / 300])
    got = jax.jit(jax.vmap(lambda c: point_sum(c, target, w)))(cands)
    np.testing.assert_allclose(got, ref, rtol=1e-5)
    assert float(point_sum(cands[0], target)) > float(point_sum(cands[0], target, w))
    with pytest.raises(ValueError, match="weights has shape"):
        point_sum(cands[0], target, jnp.ones(3))


def test_iron_force_config_goal_and_scene(xgnitive_dir, monkeypatch):
    """iron_force_xgnitive: the goal is target_iron[9][4] with Fz weighted 1/300 as
    the scene's force feature; the demonstrations carry the force in the same
    weight; the scene reads the iron's tool point and sensor."""
    import pathlib

    from cgda_jax.experiment import load_config
    from cgda_jax.experiment.build import build_goal, scene_feature_names

    monkeypatch.setenv("CGDA_XGNITIVE_DIR", str(xgnitive_dir))
    path = pathlib.Path(__file__).parents[1] / "experiments/iron_force_xgnitive.toml"
    cfg = load_config(path)
    goal, demos, gen = build_goal(cfg)
    want = np.loadtxt(xgnitive_dir / "xgnitive_derived/hardcoded_targets/"
                      "iron_target_9x4.txt")[:, 1:]
    np.testing.assert_allclose(goal[:, :3], want[:, :3], atol=1e-5, rtol=0)
    np.testing.assert_allclose(goal[:, 3] * 300, want[:, 3], atol=1e-4, rtol=0)
    assert len(demos) == 4 and demos[0].feature_names == ("X", "Y", "Z", "Fz")
    assert scene_feature_names(cfg) == ["iron/tcp.x [m]", "iron/tcp.y [m]",
                                        "iron/tcp.z [m]", "iron/ft.fz [300 N]"]
