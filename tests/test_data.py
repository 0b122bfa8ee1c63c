"""Demonstration validation and the CSV / NPZ / xgnitive loaders."""

import numpy as np
import pytest

from cgda_jax.data import (
    Demonstration,
    load_csv,
    load_npz,
    load_xgnitive,
    save_csv,
    save_npz,
    validate_demonstrations,
)


def _demo(name="d"):
    t = np.linspace(0.0, 2.0, 5)
    return Demonstration(t, np.stack([t, t**2], 1), ("x", "y"), name)


def test_demonstration_basics():
    d = _demo()
    assert d.n_samples == 5 and d.n_features == 2 and d.duration == 2.0
    np.testing.assert_allclose(d.normalized_times, np.linspace(0, 1, 5))
    one = Demonstration([1.0, 2.0, 4.0], [3.0, 4.0, 5.0], "v")
    assert one.features.shape == (3, 1) and one.feature_names == ("v",)
    sel = d.select(["y"])
    np.testing.assert_array_equal(sel.features[:, 0], d.features[:, 1])


@pytest.mark.parametrize(
    "times,feats,names,match",
    [
        ([0.0, 1.0, np.nan], [[0], [1], [2]], ("a",), r"'bad', sample 2: time is nan"),
        (
            [0.0, 1.0, 2.0], [[0], [np.inf], [2]], ("a",),
            r"sample 1: feature 0 \('a'\) is inf",
        ),
        ([0.0, 1.0, 1.0], [[0], [1], [2]], ("a",), r"sample 2: time does not increase"),
        ([0.0, 2.0, 1.0], [[0], [1], [2]], ("a",), "time does not increase"),
        ([0.0], [[0]], ("a",), "'bad': needs at least 2 samples"),
        ([0.0, 1.0], [[0, 1], [1, 2]], ("a",), r"1 feature names .* for 2 feature"),
        ([0.0, 1.0], [[0, 1], [1, 2]], ("a", "a"), "duplicate feature names"),
        ([0.0, 1.0, 2.0], [[0], [1]], ("a",), "3 times but 2 feature rows"),
    ],
)
def test_demonstration_rejects_bad_input(times, feats, names, match):
    with pytest.raises(ValueError, match=match):
        Demonstration(np.array(times), np.array(feats, float), names, "bad")


def test_validate_demonstrations_names_the_odd_demo():
    validate_demonstrations([_demo("a"), _demo("b")])
    t = np.linspace(0, 1, 3)
    odd = Demonstration(t, np.zeros((3, 3)), ("x", "y", "z"), "odd")
    with pytest.raises(ValueError, match="'odd' has 3 features but 'a' has 2"):
        validate_demonstrations([_demo("a"), odd])
    renamed = Demonstration(t, np.zeros((3, 2)), ("x", "w"), "renamed")
    with pytest.raises(ValueError, match="'renamed' has feature names"):
        validate_demonstrations([_demo("a"), renamed])
    with pytest.raises(ValueError, match="no demonstrations"):
        validate_demonstrations([])
    with pytest.raises(ValueError, match="item 1 is ndarray"):
        validate_demonstrations([_demo(), np.zeros(3)])


def test_csv_and_npz_round_trip(tmp_path):
    d = _demo("orig")
    save_csv(d, tmp_path / "d.csv")
    assert (tmp_path / "d.csv").read_text().splitlines()[0] == "time,x,y"
    back = load_csv(tmp_path / "d.csv")
    np.testing.assert_array_equal(back.times, d.times)
    np.testing.assert_array_equal(back.features, d.features)
    assert back.feature_names == ("x", "y") and back.name == str(tmp_path / "d.csv")
    only_y = load_csv(tmp_path / "d.csv", columns=["y"], name="yy")
    assert only_y.feature_names == ("y",) and only_y.name == "yy"
    save_npz(d, tmp_path / "d.npz")
    z = load_npz(tmp_path / "d.npz")
    np.testing.assert_array_equal(z.features, d.features)
    assert z.feature_names == d.feature_names and z.name == "orig"


def test_csv_errors_name_file_and_line(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("time,a\n0,1\n1,2\n1,3\n")
    with pytest.raises(ValueError, match=r"bad\.csv, line 4: time does not increase"):
        load_csv(p)
    p.write_text("time,a\n0,1\n1,nan\n")
    with pytest.raises(ValueError, match=r"bad\.csv, line 3: feature 0 \('a'\) is nan"):
        load_csv(p)
    p.write_text("time,a\n0,1\n1,x\n")
    with pytest.raises(ValueError, match=r"line 3: not a number"):
        load_csv(p)
    p.write_text("t,a\n0,1\n1,2\n")
    with pytest.raises(ValueError, match=r"line 1: header must be 'time"):
        load_csv(p)
    p.write_text("time,a\n0,1\n")
    with pytest.raises(ValueError, match=r"bad\.csv: needs at least 2 samples"):
        load_csv(p)
    p.write_text("")
    with pytest.raises(ValueError, match=r"bad\.csv: file is empty"):
        load_csv(p)
    p.write_text("time,a\n0,1\n1,2\n")
    with pytest.raises(KeyError, match="no column 'b'"):
        load_csv(p, columns=["b"])
    with pytest.raises(FileNotFoundError, match="missing.csv"):
        load_csv(tmp_path / "missing.csv")
    (tmp_path / "e.npz").write_bytes(b"")
    with pytest.raises(ValueError, match=r"e\.npz: file is empty"):
        load_npz(tmp_path / "e.npz")


def test_load_xgnitive_reduced_and_raw(xgnitive_dir):
    force = load_xgnitive(xgnitive_dir, "iron", "jr3", ["Fz"])
    assert len(force) == 4 and force[0].feature_names == ("Fz",)
    # Each stream's own t0 is subtracted (removes the ~609 s jr3 clock offset).
    assert all(d.times[0] == 0.0 for d in force)
    arm = load_xgnitive(xgnitive_dir / "xgnitive_icra2018", "iron", "teo/rightArm")
    assert arm[0].feature_names == ("X", "Y", "Z", "ax", "ay", "az", "angle")
    # jr3 and the arm of the same demo last about as long once aligned.
    for f, a in zip(force, arm):
        assert abs(f.duration - a.duration) < 2.0
    raw = load_xgnitive(xgnitive_dir, "iron", "jr3", ["Fz"], reduced=False,
                        repetitions=[1])
    np.testing.assert_array_equal(raw[0].features[::10], force[0].features)
    assert raw[0].name == "iron/jr3/data-1.log"
    # The never-recorded paint/teo/rightArm repetition 2 is skipped / reported.
    right = load_xgnitive(xgnitive_dir, "paint", "teo/rightArm", ["X"])
    assert [d.name.rsplit("-", 1)[1] for d in right] == ["1.csv", "3.csv", "4.csv"]
    with pytest.raises(FileNotFoundError, match="repetition 2 of paint/teo/rightArm"):
        load_xgnitive(xgnitive_dir, "paint", "teo/rightArm", repetitions=[2])
    paint = load_xgnitive(xgnitive_dir, "paint", "paintSquaresOnScreen")
    assert paint[0].feature_names == ("percent",)
    assert paint[0].features[-1, 0] == 100.0


def test_load_xgnitive_errors(tmp_path, xgnitive_dir):
    with pytest.raises(ValueError, match="unknown action 'cook'"):
        load_xgnitive(xgnitive_dir, "cook", "jr3")
    with pytest.raises(ValueError, match="unknown stream 'camera'"):
        load_xgnitive(xgnitive_dir, "iron", "camera")
    with pytest.raises(KeyError, match="no column 'Fw'"):
        load_xgnitive(xgnitive_dir, "iron", "jr3", ["Fw"])
    with pytest.raises(FileNotFoundError, match="no folder iron/jr3"):
        load_xgnitive(tmp_path, "iron", "jr3")
    folder = tmp_path / "iron" / "jr3"
    folder.mkdir(parents=True)
    (folder / "reduced-data-1.csv").write_text("")
    with pytest.raises(ValueError, match=r"reduced-data-1\.csv: file is empty"):
        load_xgnitive(tmp_path, "iron", "jr3")
    rows = "1 10.0 0 0 0 0 0 0\n2 9.0 0 0 0 0 0 0\n"
    (folder / "reduced-data-1.csv").write_text(rows)
    with pytest.raises(ValueError, match=r"reduced-data-1\.csv, line 2: time does not"):
        load_xgnitive(tmp_path, "iron", "jr3")


# --- numeric and file guards (issue 12) ------------------------------------------


def test_values_beyond_float32_are_refused_naming_demo_sample_and_column(tmp_path):
    t = np.linspace(0.0, 1.0, 4)
    feats = np.zeros((4, 2))
    feats[2, 1] = -1e39  # finite in float64, -inf in float32
    with pytest.raises(ValueError, match=(
        r"demonstration 'big', sample 2: feature 1 \('y'\) is -1e\+39, beyond "
        r"float32's range"
    )):
        Demonstration(t, feats, ("x", "y"), "big")
    feats[2, 1] = 3.0e38  # the largest float32 is 3.4e38: kept
    assert Demonstration(t, feats, ("x", "y")).features[2, 1] == 3.0e38
    p = tmp_path / "big.csv"
    p.write_text("time,x,y\n0,1,2\n1,1e39,2\n")
    with pytest.raises(ValueError, match=(
        r"big\.csv, line 3: feature 0 \('x'\) is 1e\+39, beyond float32"
    )):
        load_csv(p)


def test_non_utf8_file_names_the_file_and_a_bom_is_accepted(tmp_path):
    p = tmp_path / "latin1.csv"
    p.write_bytes("time,caf\u00e9\n0,1\n1,2\n".encode("latin-1"))
    with pytest.raises(ValueError, match=r"latin1\.csv, line 1: not UTF-8 text"):
        load_csv(p)
    bom = tmp_path / "bom.csv"
    bom.write_bytes("time,caf\u00e9\n0,1\n1,2\n".encode("utf-8-sig"))
    d = load_csv(bom)
    assert d.feature_names == ("caf\u00e9",)
    np.testing.assert_array_equal(d.features[:, 0], [1.0, 2.0])
    # save_csv writes UTF-8 whatever the locale, so non-ASCII names round-trip
    save_csv(d, tmp_path / "back.csv")
    assert load_csv(tmp_path / "back.csv").feature_names == ("caf\u00e9",)
    # the xgnitive reader shares the decoding
    folder = tmp_path / "iron" / "jr3"
    folder.mkdir(parents=True)
    (folder / "reduced-data-1.csv").write_bytes(
        b"1 0.0 0 0 0 0 0 0\n2 1.0 \xff 0 0 0 0 0"
    )
    with pytest.raises(ValueError, match=r"reduced-data-1\.csv, line 2: not UTF-8"):
        load_xgnitive(tmp_path, "iron", "jr3")


def test_tilde_paths_are_expanded(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    d = _demo("home")
    save_csv(d, "~/d.csv")
    save_npz(d, "~/d.npz")
    assert (tmp_path / "d.csv").is_file() and (tmp_path / "d.npz").is_file()
    np.testing.assert_array_equal(load_csv("~/d.csv").features, d.features)
    assert load_npz("~/d.npz").name == "home"
    folder = tmp_path / "xg" / "iron" / "jr3"
    folder.mkdir(parents=True)
    (folder / "reduced-data-1.csv").write_text("1 0.0 0 0 1 0 0 0\n2 1.0 0 0 2 0 0 0\n")
    (force,) = load_xgnitive("~/xg", "iron", "jr3", ["Fz"])
    np.testing.assert_array_equal(force.features[:, 0], [1.0, 2.0])
