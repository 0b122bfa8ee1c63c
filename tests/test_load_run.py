"""A results folder back in Python (`cgda_jax.load_run`) and `cgda plot FOLDER`."""

import json

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
    assert capsys.readouterr().err.startswith("cgda: error: --rate must be > 0")
    out = tmp_path / "clean_ruckig.json"
    assert cli.main(["export", str(folder), "--out", str(out), "--profile", "ruckig",
                     "--no-cache"]) in (cli.EXIT_MET, cli.EXIT_NOT_MET)
    assert cg.load_trajectory(out).info["profile"] == "ruckig"
