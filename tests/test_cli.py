"""The `cgda` command: demo end to end, dry runs, and one-line user errors."""

import json
import pathlib

import pytest

from cgda_jax.cli import main

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[1] / "experiments"


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CGDA_JAX_CACHE", str(tmp_path_factory.getbasetemp() / "jaxcache"))


@pytest.mark.slow  # 134 s in CI: the whole demo; test_results_folder checks the demo's folder rules
def test_demo_small_succeeds_and_writes_results(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--small", "--quiet"]) == 0
    assert capsys.readouterr().err == ""  # --quiet
    result = json.loads((out / "result.json").read_text())
    assert result["success"] is True
    exps = result["experiments"]
    assert set(exps) == {"recognition_all_features", "recognition_spatial",
                         "recognition_arm_points", "clean_ie", "paint_iet"}
    assert exps["clean_ie"]["max_point_error"] < 0.02
    assert exps["paint_iet"]["success"] and exps["paint_iet"]["points"] == 17
    for name, r in exps.items():
        assert r["plots"], name
        for p in r["plots"]:
            assert (out / name / p).stat().st_size > 2000
    assert "## clean_ie" in (out / "report.md").read_text()


@pytest.mark.parametrize("path", sorted(EXPERIMENTS.glob("*.toml")), ids=lambda p: p.stem)
def test_dry_run_validates_each_experiment(path, capsys, monkeypatch, request):
    if "xgnitive" in path.stem:  # the dry run loads the demonstrations
        xgnitive = request.getfixturevalue("xgnitive_dir")
        monkeypatch.setenv("CGDA_XGNITIVE_DIR", str(xgnitive))
    assert main(["run", str(path), "--dry-run", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "valid" in out and "results would go to" in out
    # only the keys that apply: a recognition has no [strategy], an execution no
    # [recognition]; a clean circle no paint keys
    recognition = 'kind = "recognition"' in out
    assert ("[strategy]" in out) != recognition
    assert ("[recognition]" in out) == recognition
    if 'source = "clean_circle"' in out:
        assert not any(f"\n{k} = " in out for k in ("goal_points", "stream", "action"))


@pytest.mark.parametrize(
    "args, words",
    [
        (["--set", "strategy.bogus=1"], ["unknown key", "strategy.bogus"]),
        (["--set", "strategy.population_size=many"], ["strategy.population_size", "expected int"]),
        (["--set", "robot.model=/nowhere/robot.xml"], ["/nowhere/robot.xml", "not found"]),
        (["--set", "data.source=xgnitive", "--set", "data.data_dir=/nowhere/data"],
         ["/nowhere/data", "not found"]),
        (["--set", "strategy.options.bogus=3"],
         ["strategy.options.bogus", "not an option of strategy 'ie'", "devices"]),
        (["--set", "strategy.options.seed=3"], ["strategy.options.seed", "strategy.seed"]),
    ],
)
def test_user_mistakes_exit_nonzero_with_one_line(args, words, capsys):
    code = main(["run", str(EXPERIMENTS / "clean_ie.toml"), "--dry-run", *args])
    err = capsys.readouterr().err
    assert code != 0
    assert err.count("\n") == 1 and err.startswith("cgda: error:"), err
    assert "Traceback" not in err
    for w in words:
        assert w in err


def test_bad_file_names_the_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[scene]\nkind = 3\n")
    assert main(["run", str(bad), "--dry-run"]) != 0
    err = capsys.readouterr().err
    assert "bad.toml" in err and "scene.kind" in err and err.count("\n") == 1
    assert main(["run", str(tmp_path / "none.toml")]) != 0
    assert "none.toml" in capsys.readouterr().err


def test_demo_report_starts_with_a_summary_table():
    from cgda_jax.cli.demo import summary_table

    rows = summary_table({
        "rec": {"kind": "recognition", "success": True, "accuracy": 1.0,
                "features": ["X", "Y", "Z"], "metric": "dtw", "compute_s": 1.25,
                "outputs_s": 0.5},
        "clean": {"kind": "execution", "success": False, "strategy": "ie",
                  "max_point_error": 0.031, "tolerance": 0.02, "points": 11,
                  "generations": 40, "compute_s": 3.0, "outputs_s": 2.0},
    })
    assert rows[0] == "| experiment | result | key figure | computing | figures, video |"
    assert rows[2] == ("| [rec](#rec) | ok | accuracy 100% (3 features, dtw) | 1.2 s | "
                       "0.5 s |")
    assert "**NOT met**" in rows[3] and "max point error 0.031 (tolerance 0.02)" in rows[3]


def test_demo_report_times_add_up_and_sections_nest():
    from cgda_jax.cli.demo import demoted, total_line

    results = {"a": {"compute_s": 2.0, "outputs_s": 1.5},
               "b": {"compute_s": 3.0, "outputs_s": 1.0}}
    line = total_line(results, 6.1, True)
    # the computing times add up below the total; the outputs are said to overlap
    assert "6.1 s in total: 5.0 s computing" in line and "second thread" in line
    text = demoted("# a\n\nx\n\n## Feasibility\n\n![p](plots/f.png)\n", "a")
    assert text.splitlines()[0] == "## a" and "### Feasibility" in text
    assert "](a/plots/f.png)" in text


def test_help_texts_show_examples(capsys):
    for cmd in ("run", "demo"):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        out = capsys.readouterr().out
        assert "examples:" in out and f"cgda {cmd}" in out and "report.md" in out


def test_diverged_simulation_exits_3_with_one_line(monkeypatch, capsys, tmp_path):
    from cgda_jax import SimulationDiverged, strategies

    def diverging_run_ie(sim, goal, **kwargs):
        raise SimulationDiverged("every one of the 96 candidate evaluations of the IE "
                                 "run diverged (non-finite features): check the gains")

    monkeypatch.setattr(strategies, "run_ie", diverging_run_ie)
    code = main(["run", str(EXPERIMENTS / "clean_ie.toml"), "--quiet",
                 "--set", "output.render=false", "--set", "output.plots=false",
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 3
    assert err.startswith("cgda: error: every one of the 96") and err.count("\n") == 1
    assert "Traceback" not in err


def test_warnings_go_to_the_stderr_of_each_call(monkeypatch):
    """`cgda` called twice in one process (pytest, a notebook): the warning handler
    made by the first call wrote to that call's stderr, closed by then, and the
    second printed a "Logging error" report instead of its warning."""
    import io
    import logging
    import sys

    from cgda_jax.cli.output import log_warnings

    first = io.StringIO()
    monkeypatch.setattr(sys, "stderr", first)
    log_warnings()
    first.close()
    second = io.StringIO()
    monkeypatch.setattr(sys, "stderr", second)
    log_warnings()
    logging.getLogger("cgda_jax").warning("%s", "no speed limit for yaw")
    assert second.getvalue() == "cgda: warning: no speed limit for yaw\n"
