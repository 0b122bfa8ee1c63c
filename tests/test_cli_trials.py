"""``cgda run CONFIG --trials N``: the success-rate table of N seeds, and its errors."""

import json
import pathlib

import numpy as np
import pytest

from cgda_jax.cli import main
from cgda_jax.experiment.success_rate import summarize, wilson_interval

EXPERIMENTS = pathlib.Path(__file__).resolve().parents[1] / "experiments"
SMALL = ["--set", "strategy.population_size=8", "--set", "strategy.max_generations=12",
         "--set", "strategy.tolerance=0.05"]


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CGDA_JAX_CACHE", str(tmp_path_factory.getbasetemp() / "jaxcache"))


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    lo, hi = wilson_interval(5, 10)
    assert (lo, hi) == (pytest.approx(0.2366, abs=1e-4), pytest.approx(0.7634, abs=1e-4))
    lo, hi = wilson_interval(30, 30)
    assert lo == pytest.approx(0.8865, abs=1e-4) and hi == 1.0
    s = summarize([{"seed": i, "success": i != 1, "max_point_error": 0.01 * i,
                    "generations": 10} for i in range(3)])
    assert s["successes"] == 2 and s["success_rate"] == pytest.approx(2 / 3)


def test_trials_writes_the_success_rate_table(tmp_path, capsys):
    out = tmp_path / "t"
    code = main(["run", str(EXPERIMENTS / "clean_ie.toml"), *SMALL, "--trials", "3",
                 "--out", str(out), "--quiet"])
    assert code == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    line = captured.out.strip().splitlines()[-1]
    assert "/3 seeds met the goal" in line and "Wilson 95%" in line
    data = json.loads((out / "trials.json").read_text())
    assert data["trials"] == 3 and [r["seed"] for r in data["records"]] == [0, 1, 2]
    for r in data["records"]:
        assert {"success", "max_point_error", "generations", "run_time_s"} <= set(r)
        assert r["success"] == (r["max_point_error"] < 0.05)
    k = sum(r["success"] for r in data["records"])
    assert data["successes"] == k and data["success_rate"] == pytest.approx(k / 3)
    lo, hi = data["wilson95"]
    assert lo <= k / 3 <= hi
    report = (out / "report.md").read_text()
    assert "Wilson 95% interval" in report and f"| 3 | {k} |" in report
    assert report.count("\n| ") >= 2 + 3  # two table rows + one row per seed
    assert json.loads((out / "result.json").read_text())["kind"] == "trials"


@pytest.mark.parametrize("n", ["0", "-2"])
def test_bad_trial_count_exits_2_with_one_line(n, capsys, tmp_path):
    code = main(["run", str(EXPERIMENTS / "clean_ie.toml"), "--trials", n,
                 "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2
    assert "--trials must be a whole number >= 1" in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_trials_not_a_number_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", str(EXPERIMENTS / "clean_ie.toml"), "--trials", "many"])
    assert exc.value.code == 2
    assert "--trials" in capsys.readouterr().err


def test_trials_of_a_recognition_config_is_refused(capsys):
    code = main(["run", str(EXPERIMENTS / "recognition_spatial.toml"), "--trials", "3"])
    err = capsys.readouterr().err
    assert code == 2 and "needs an execution experiment" in err


def test_processes_needs_trials_and_a_positive_count(capsys, tmp_path):
    code = main(["run", str(EXPERIMENTS / "clean_ie.toml"), "--processes", "2",
                 "--out", str(tmp_path / "x")])
    assert code == 2 and "--processes needs --trials" in capsys.readouterr().err
    code = main(["run", str(EXPERIMENTS / "clean_ie.toml"), "--trials", "2",
                 "--processes", "0", "--out", str(tmp_path / "y")])
    assert code == 2 and "--processes must be >= 1" in capsys.readouterr().err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


@pytest.mark.slow  # 53 s in CI; test_distributed checks two processes against one
def test_trials_over_two_processes_equal_one_process(tmp_path):
    """``--processes 2`` starts two local processes as one jax.distributed job (the
    README's command): process 0 alone writes the folder, whose records equal the
    one-process run's seed by seed."""
    import os
    import subprocess
    import sys

    args = ["run", str(EXPERIMENTS / "clean_ie.toml"), *SMALL, "--trials", "3",
            "--quiet", "--no-cache"]
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    env.pop("CGDA_PROCESS_ID", None)
    two = subprocess.run([sys.executable, "-m", "cgda_jax.cli", *args, "--processes",
                          "2", "--out", str(tmp_path / "two")], env=env, timeout=400,
                         capture_output=True, text=True)
    assert two.returncode == 0, two.stdout + two.stderr
    # one summary line, from the launching process once it moved the folder into
    # place (the workers say nothing of it)
    summary = [line for line in two.stdout.splitlines() if "seeds met the goal" in line]
    assert len(summary) == 1 and summary[0].startswith("[clean_ie] "), two.stdout
    assert summary[0].endswith(f"-> {tmp_path / 'two' / 'report.md'}")
    assert main([*args, "--out", str(tmp_path / "one")]) == 0
    one = json.loads((tmp_path / "one/trials.json").read_text())
    both = json.loads((tmp_path / "two/trials.json").read_text())
    assert both["processes"] == 2 and one["processes"] == 1
    keys = ("seed", "success", "generations", "evaluations")
    assert [[r[k] for k in keys] for r in both["records"]] == \
        [[r[k] for k in keys] for r in one["records"]]
    np.testing.assert_allclose([r["max_point_error"] for r in both["records"]],
                               [r["max_point_error"] for r in one["records"]],
                               rtol=1e-5)
    # the workers wrote nothing beside process 0's folder
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one", "two"]
