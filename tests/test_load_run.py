"""A results folder back in Python (`cgda_jax.load_run`) and `cgda plot FOLDER`."""

import hashlib
import json
import pathlib
import re
import shutil

import numpy as np
import pytest

import cgda_jax as cg
from cgda_jax import cli
from cgda_jax.experiment import load_config, run_experiment

CLEAN = ["kind=execution", "data.source=clean_circle", "scene.kind=marker",
         "strategy.name=ie", "strategy.population_size=8", "strategy.max_generations=4",
         "strategy.tolerance=0.05", "strategy.options.aim=0.5", "robot.substeps=2",
         "output.render=false"]
RECOGNITION = ["kind=recognition", "data.features=spatial", "data.n_repetitions=3",
               "data.n_train=2", "recognition.n_samples=30"]


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs") / "clean"
    cfg = load_config(None, CLEAN)
    run_experiment(cfg, folder)
    return cfg, folder


def test_load_run_round_trips_an_execution(clean_run):
    cfg, folder = clean_run
    run = cg.load_run(str(folder))
    assert run.folder == folder and run.kind == "execution"
    assert run.config == cfg
    assert run.result == json.loads((folder / "result.json").read_text())
    with np.load(folder / "arrays.npz") as z:
        assert sorted(run.arrays) == sorted(z.files)
        for k in z.files:
            np.testing.assert_array_equal(run.arrays[k], z[k])
    for k in ("joints", "features", "goal", "point_errors", "knot_times", "knots",
              "demo0_times", "demo0_features"):
        assert k in run.arrays
    np.testing.assert_allclose(run.arrays["knots"], run.arrays["goal"])
    assert run.result["feature_labels"] == ["X [m]", "Y [m]", "Z [m]"]
    assert run.result["error_unit"] == "m"
    sim = run.simulator()
    assert list(sim.feature_names) == run.result["feature_names"]
    replayed = run.replay(sim)
    np.testing.assert_allclose(replayed, run.arrays["features"], rtol=0, atol=1e-6)
    errors = np.linalg.norm(replayed - run.arrays["goal"], axis=1)
    np.testing.assert_allclose(errors, run.arrays["point_errors"], atol=1e-5)
    assert run.execution_result().points == len(run.arrays["goal"])
    assert len(run.demonstrations()) == cfg.data.n_demos
    assert "max point error" in (folder / "report.md").read_text()
    assert (" m (tolerance 0.05 m, each point evolved to 0.025 m: aim 0.5)"
            in (folder / "report.md").read_text())
    assert run.result["info"]["aim_tolerance"] == pytest.approx(0.025)


def test_load_run_of_a_recognition_has_no_simulator(tmp_path):
    cfg = load_config(None, RECOGNITION + ["output.plots=false"])
    run_experiment(cfg, tmp_path / "rec")
    run = cg.load_run(tmp_path / "rec")
    assert run.kind == "recognition" and run.config == cfg
    assert run.arrays["cost_matrix"].shape == (4, 4)
    assert len(run.demonstrations("MOVE")) == 2
    assert run.generalization("MOVE").knots.shape[1] == 3
    with pytest.raises(ValueError, match="recognition run has no simulator"):
        run.simulator()
    with pytest.raises(ValueError, match="no simulator"):
        run.replay()


def test_load_run_refuses_what_is_not_a_results_folder(tmp_path):
    with pytest.raises(cg.experiment.FolderError, match="not found"):
        cg.load_run(tmp_path / "missing")
    (tmp_path / "result.json").write_text("{}")
    with pytest.raises(cg.experiment.FolderError, match="config.toml, arrays.npz missing"):
        cg.load_run(tmp_path)


def test_cgda_plot_redraws_the_figures(clean_run, tmp_path, capsys):
    _, folder = clean_run
    before = sorted(p.name for p in (folder / "plots").glob("*.png"))
    assert "point_errors.png" in before and "trajectory_3d.png" in before
    out = tmp_path / "figs"
    rc = cli.main(["plot", str(folder), "--out", str(out), "--quiet", "--no-cache"])
    assert rc == cli.EXIT_MET
    assert sorted(p.name for p in out.glob("*.png")) == before
    for p in out.glob("*.png"):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # into the folder itself: the plots are replaced and report.md shows them
    (folder / "plots" / "fitness.png").unlink()
    assert cli.main(["plot", str(folder), "--quiet", "--no-cache"]) == cli.EXIT_MET
    assert (folder / "plots" / "fitness.png").is_file()
    assert "![plots/fitness.png](plots/fitness.png)" in (folder / "report.md").read_text()
    capsys.readouterr()
    assert cli.main(["plot", str(tmp_path / "nope"), "--no-cache"]) == cli.EXIT_USAGE
    err = capsys.readouterr().err
    assert err.startswith("cgda: error: results folder") and "Traceback" not in err


def test_cgda_export_writes_the_file_its_report_row_checked(clean_run, tmp_path,
                                                           capsys):
    """`cgda export` writes the trajectory of the run's joints; read back and
    replayed on MuJoCo C it gives what the run's report says of its export."""
    _, folder = clean_run
    run = cg.load_run(folder)
    export = run.result["export"]
    assert export["exported"] and export["rate_hz"] == 100
    assert export["max_feature_difference"] < 1e-4
    assert export["success"] == run.result["success"]
    assert "| exported trajectory (minimum jerk" in (folder / "report.md").read_text()
    out = tmp_path / "clean.csv"
    rc = cli.main(["export", str(folder), "--out", str(out), "--rate", "50",
                   "--no-cache"])
    assert rc == (cli.EXIT_MET if run.result["success"] else cli.EXIT_NOT_MET)
    err = capsys.readouterr().err
    assert f"-> {out}" in err and "replayed on MuJoCo C" in err
    traj = cg.load_trajectory(out)
    assert traj.rate == 50 and traj.joint_names == tuple(run.config.robot.joints)
    np.testing.assert_allclose(traj.waypoints, run.arrays["joints"], atol=1e-6)
    assert cli.main(["export", str(folder), "--rate", "0", "--no-cache"]) == \
        cli.EXIT_USAGE
    assert capsys.readouterr().err.startswith("cgda: error: --rate must be in [1, "
                                              "100000] Hz, got 0")
    out = tmp_path / "clean_ruckig.json"
    assert cli.main(["export", str(folder), "--out", str(out), "--profile", "ruckig",
                     "--no-cache"]) in (cli.EXIT_MET, cli.EXIT_NOT_MET)
    assert cg.load_trajectory(out).info["profile"] == "ruckig"


# ------------------------------------------------- bad input and full disks (issue 43)
def contents(folder) -> dict[str, str]:
    """Every file under ``folder`` (hidden ones included) and its SHA-256."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def one_line(capsys, code: int, status: int, *words: str) -> str:
    err = capsys.readouterr().err
    assert code == status, err
    assert err.count("\n") == 1 and err.startswith("cgda: error:"), err
    for w in words:
        assert w in err, err
    return err


@pytest.mark.parametrize("args, words", [
    (["--out", "{run}/arrays.npz"], ["arrays.npz is a file of the results folder"]),
    (["--out", "{run}/result.json"], ["result.json is a file of the results folder"]),
    (["--out", "{tmp}/folder.json"], ["folder.json is a folder; name a file"]),
    (["--out", "{tmp}/missing/t.json"], ["folder", "missing not found"]),
    (["--rate", "1e9"], ["--rate must be in [1, 100000] Hz, got 1e+09"]),
    (["--rate", "1e-300"], ["--rate must be in [1, 100000] Hz, got 1e-300"]),
    (["--rate", "1e308"], ["--rate must be in", "got 1e+308"]),
    (["--jerk", "-1"], ["--jerk must be a finite number > 0"]),
])
def test_export_refuses_bad_input_before_any_work(clean_run, tmp_path, capsys, args,
                                                  words):
    """It overwrote the run's own arrays.npz / result.json (status 0), grew past
    6 GB at --rate 1e9 and ended in an OverflowError at --rate 1e-300."""
    _, folder = clean_run
    (tmp_path / "folder.json").mkdir()
    before = contents(folder)
    args = [a.format(run=folder, tmp=tmp_path) for a in args]
    one_line(capsys, cli.main(["export", str(folder), *args, "--no-cache"]),
             cli.EXIT_USAGE, *words)
    assert contents(folder) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.json"]


def test_export_onto_a_full_disk_leaves_the_earlier_file_whole(clean_run, tmp_path,
                                                               capsys, full_disk):
    """It left a truncated JSON or a 0-byte .npz, and replaced a good file by a
    truncated one (each format: test_export's full-disk test)."""
    run = tmp_path / "run"
    shutil.copytree(clean_run[1], run)
    args = ["export", str(run), "--no-check", "--no-cache"]
    assert cli.main([*args, "--quiet"]) == cli.EXIT_MET  # run/trajectory.json
    capsys.readouterr()
    before = contents(tmp_path)
    with full_disk(20_000):
        code = cli.main(args)
    err = one_line(capsys, code, cli.EXIT_FAILURE, "cgda: error: OSError: ",
                   f"{run / 'trajectory.json'} could not be written (File too large): "
                   "nothing written, an earlier file there is kept")
    assert contents(tmp_path) == before  # the earlier file whole, no .tmp left
    log = re.search(r"traceback in (\S+cgda-error-\S+\.log)\)", err)
    if log:
        pathlib.Path(log[1]).unlink(missing_ok=True)


def _damaged(folder, tmp_path, what):
    run = tmp_path / what
    shutil.copytree(folder, run)
    arrays = dict(np.load(run / "arrays.npz"))
    config = (run / "config.toml").read_text()
    if what == "outside":
        arrays["joints"][2, 0] = 10.0
    elif what == "rows":
        arrays["joints"] = np.concatenate([arrays["joints"], arrays["joints"][:1]])
    elif what == "velocity":
        config = config.replace("[robot.limits]\n",
                                "[robot.limits]\nvelocity = 1e-30\n")
    elif what == "partial":
        del arrays["demo1_features"]
    elif what == "latin1":
        config = "# caf\xe9\n" + config
    np.savez(run / "arrays.npz", **arrays)
    (run / "config.toml").write_bytes(config.encode("latin-1"))
    return run


@pytest.mark.parametrize("what, args, words", [
    ("outside", [], ["arrays.npz's joints of point 3", "= 10 is outside its range"]),
    ("rows", [], ["arrays.npz's joints has shape (10, 3)", "(9)"]),
    ("velocity", ["--profile", "ruckig"], ["move 1 of the export", "3.27e+30 s at 100 "
                                           "Hz", "velocity 1e-30"]),
])
def test_export_of_a_damaged_or_impossible_result_names_the_cause(
        clean_run, tmp_path, capsys, what, args, words):
    """Broadcast errors, RuckigError (status 3), "Maximum allowed size exceeded",
    or joints silently clipped and written (waypoint_s = 1e308 and the minimum-jerk
    profile: test_export)."""
    run = _damaged(clean_run[1], tmp_path, what)
    before = contents(tmp_path)
    one_line(capsys, cli.main(["export", str(run), "--no-check", "--no-cache", *args]),
             cli.EXIT_USAGE, *words)
    assert contents(tmp_path) == before


def test_plot_names_the_damaged_file(clean_run, tmp_path, capsys):
    """It said "cgda: error: demo1_features" and, for a config.toml that is not
    UTF-8, "'utf-8' codec can't decode byte" without the file."""
    run = _damaged(clean_run[1], tmp_path, "partial")
    one_line(capsys, cli.main(["plot", str(run), "--no-render", "--no-cache",
                               "--out", str(tmp_path / "p")]), cli.EXIT_USAGE,
             "arrays.npz: array demo1_features missing")
    run = _damaged(clean_run[1], tmp_path, "latin1")
    one_line(capsys, cli.main(["plot", str(run), "--no-render", "--no-cache"]),
             cli.EXIT_USAGE, f"{run / 'config.toml'}: not a UTF-8 text file")
