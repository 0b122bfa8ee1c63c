"""Runs you can trust: the results folder (written aside, moved into place, locked,
never mixing runs), honest exit statuses, and every bad input refused by name, by
``--dry-run`` and by the run alike (issue 12)."""

import hashlib
import json
import os
import pathlib
import select
import signal
import subprocess
import sys
import tempfile
import time

import pytest

from cgda_jax.cli import main
from cgda_jax.experiment import FolderBusy, FolderError, RunFolder, load_config

REPO = pathlib.Path(__file__).resolve().parents[1]
CLEAN = REPO / "experiments" / "clean_ie.toml"
RECOGNITION = REPO / "experiments" / "recognition_spatial.toml"
QUIET = ["output.plots=false", "output.render=false"]
TINY = ["strategy.population_size=4", "strategy.max_generations=5", *QUIET]
# a run that goes on for minutes unless interrupted
LONG = ["strategy.population_size=4", "strategy.max_generations=1000000",
        "strategy.tolerance=1e-9", "strategy.options.stagnation=1000000", *QUIET]


def sets(settings):
    return [a for s in settings for a in ("--set", s)]


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One compilation cache for every run of this module (compiles once)."""
    return tmp_path_factory.getbasetemp() / "jaxcache"


@pytest.fixture(autouse=True)
def _cache(cache, monkeypatch):
    monkeypatch.setenv("CGDA_JAX_CACHE", str(cache))


@pytest.fixture(scope="module")
def env(cache):
    """The child's environment: this checkout first on the path, CPU, shared cache."""
    path = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path, "JAX_PLATFORMS": "cpu",
            "CGDA_JAX_CACHE": str(cache)}


def cgda(env, *args, cwd=None, **kwargs):
    cmd = [sys.executable, "-m", "cgda_jax.cli", *map(str, args)]
    return subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=300, check=False, **kwargs)


def snapshot(folder: pathlib.Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def previous_run(folder: pathlib.Path) -> dict[str, str]:
    """A results folder of an earlier run (with a PNG the next run must not list)."""
    (folder / "plots").mkdir(parents=True)
    (folder / "result.json").write_text('{"success": true, "run": "previous"}\n')
    (folder / "config.toml").write_text('name = "previous"\n')
    (folder / "report.md").write_text("# previous\n\n![old](plots/old.png)\n")
    (folder / "plots" / "old.png").write_bytes(b"png")
    return snapshot(folder)


def no_leftovers(folder: pathlib.Path) -> None:
    """Nothing but the results folders themselves beside ``folder``: no temporary
    folder, no lock file."""
    hidden = [p.name for p in folder.parent.iterdir() if p.name.startswith(".")]
    assert hidden == [], hidden


def one_error_line(err: str, start: str = "cgda: error:") -> str:
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(start), err
    return lines[0]


# --------------------------------------------------------------------------- RunFolder
def test_run_folder_moves_a_complete_run_into_place(tmp_path):
    target = tmp_path / "results" / "exp"
    with RunFolder(target) as rf:
        assert rf.work.parent == target.parent and not target.exists()
        (rf.work / "result.json").write_text("{}")
        assert (target.parent / ".exp.lock").is_file()  # held while running
    assert rf.committed and rf.path == target
    assert snapshot(target) == {"result.json": snapshot(target)["result.json"]}
    assert oct(target.stat().st_mode & 0o777) == oct(0o777 & ~_umask())
    no_leftovers(target)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_run_folder_refuses_replaces_and_picks_fresh_names(tmp_path):
    target = tmp_path / "exp"
    before = previous_run(target)
    with pytest.raises(FolderError, match="exp is not empty.*--overwrite"):
        RunFolder(target).__enter__()
    assert snapshot(target) == before
    # fresh: the first free name, and the chosen one is told
    with RunFolder(target, fresh=True) as rf:
        (rf.work / "result.json").write_text("{}")
    assert rf.path == tmp_path / "exp-2" and snapshot(target) == before
    # overwrite replaces the whole folder: no file of the previous run is left
    with RunFolder(target, overwrite=True) as rf:
        (rf.work / "result.json").write_text('{"run": "new"}')
    assert list(snapshot(target)) == ["result.json"]
    # an empty folder is taken; a non-results folder is never replaced
    (tmp_path / "empty").mkdir()
    with RunFolder(tmp_path / "empty") as rf:
        (rf.work / "x").write_text("x")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("precious")
    with pytest.raises(FolderError, match="no result.json"):
        RunFolder(tmp_path / "mine", overwrite=True).__enter__()
    (tmp_path / "file").write_text("x")
    with pytest.raises(FolderError, match="not a folder"):
        RunFolder(tmp_path / "file", overwrite=True).__enter__()
    no_leftovers(target)


def test_run_folder_failure_keeps_the_previous_results_and_cleans_up(tmp_path):
    target = tmp_path / "exp"
    before = previous_run(target)
    for exc in (RuntimeError("boom"), KeyboardInterrupt()):
        with pytest.raises(type(exc)), RunFolder(target, overwrite=True) as rf:
            (rf.work / "result.json").write_text("{}")
            raise exc
        assert not rf.committed and snapshot(target) == before
        no_leftovers(target)


def test_run_folder_lock_and_leftovers_of_a_killed_run(tmp_path):
    target = tmp_path / "exp"
    with RunFolder(target) as first:
        busy = f"in use by another run \\(pid {os.getpid()}"
        with pytest.raises(FolderBusy, match=busy):
            RunFolder(target).__enter__()
        with RunFolder(target, fresh=True) as other:  # fresh: skips the busy name
            (other.work / "result.json").write_text("{}")
        (first.work / "result.json").write_text("{}")
    assert other.path == tmp_path / "exp-2"
    # a killed run leaves its temporary folder (and maybe an unlocked lock file)
    (tmp_path / ".exp.tmp-dead").mkdir()
    (tmp_path / ".exp.lock").write_text("999999\n")
    with RunFolder(target, overwrite=True) as rf:
        (rf.work / "result.json").write_text("{}")
    no_leftovers(target)


def test_results_folder_with_tilde_is_expanded(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    with RunFolder("~/res/exp") as rf:
        (rf.work / "result.json").write_text("{}")
    assert rf.path == tmp_path / "res" / "exp" and (rf.path / "result.json").is_file()


# --------------------------------------------------------------------------- bad input
BAD_INPUT = [
    (CLEAN, ["strategy.seed=-1"], ["strategy.seed", "-1", "4294967295"]),
    (CLEAN, ["strategy.seed=4294967296"], ["strategy.seed"]),
    (CLEAN, ["data.interval_s=1e-9"], ["data.interval_s", "intervals"]),
    (RECOGNITION, ["data.interval_s=1e-9"], ["data.interval_s", "intervals"]),
    (RECOGNITION, ["data.seed=-1"], ["data.seed"]),
    (RECOGNITION, ["recognition.n_samples=10000000"], ["recognition.n_samples"]),
    (CLEAN, ["strategy.population_size=1"], ["strategy.population_size", "too small"]),
    (CLEAN, ["strategy.population_size=100000000"], ["strategy.population_size"]),
    (CLEAN, ["strategy.algorithm=NoSuchES"],
     ["strategy.algorithm", "NoSuchES", "CMA_ES"]),
    (CLEAN, ['robot.joints=["r_elbow", "no_such_joint"]'],
     ["robot.joints", "no_such_joint"]),
    (CLEAN, ["robot.marker_site=no_such_site"], ["robot.marker_site", "no_such_site"]),
    (CLEAN, ["robot.fixed.no_such_joint=3"], ["robot.fixed", "no_such_joint"]),
    (CLEAN, ["robot.fixed.r_forearm_rotation=nan"],
     ["robot.fixed.r_forearm_rotation", "finite"]),
    (CLEAN, ["robot.fixed.r_forearm_rotation=400"],
     ["robot.fixed.r_forearm_rotation", "400 deg", "[-90, 90] deg"]),
    (CLEAN, ["robot.keyframe=no_such_key"], ["robot.keyframe", "no_such_key"]),
    (CLEAN, ["scene.kind=paint"], ["scene.kind", "3 feature(s)"]),
    (CLEAN, ["robot.mode=dynamic", "robot.timestep=1e-9"],
     ["robot.timestep", "physics steps"]),
]


@pytest.mark.parametrize("config, settings, words", BAD_INPUT,
                         ids=[f"{c.stem}:{' '.join(s)}" for c, s, _ in BAD_INPUT])
@pytest.mark.parametrize("dry", [True, False], ids=["dry-run", "run"])
def test_bad_input_is_refused_by_name_by_dry_run_and_run_alike(
        config, settings, words, dry, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["run", str(config), "--quiet", "--out", str(out), *sets(settings),
                 *(["--dry-run"] if dry else [])])
    line = one_error_line(capsys.readouterr().err)
    assert code == 2, line
    for w in words:
        assert w in line, line
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_empty_config_file_is_an_error(tmp_path, capsys):
    for text in ("", "# nothing but a comment\n"):
        (tmp_path / "empty.toml").write_text(text)
        assert main(["run", str(tmp_path / "empty.toml"), "--dry-run"]) == 2
        line = one_error_line(capsys.readouterr().err)
        assert "empty.toml" in line and "empty config" in line


@pytest.mark.parametrize("case", ["seed", "interval", "out", "cache", "empty"])
def test_issue_cases_exit_2_in_a_real_process(case, env, tmp_path):
    """The issue's tracebacks, run as a user runs them (without --dry-run; --out
    and the cache also with it): one line, status 2, nothing written."""
    out = tmp_path / "out"
    args = ["run", CLEAN, "--quiet", "--out", out, *sets(TINY)]
    child_env = env
    if case == "seed":
        args += sets(["strategy.seed=-1"])
    elif case == "interval":
        args += sets(["data.interval_s=1e-9"])
    elif case == "out":
        args[4] = "/sys/cgda-results"
    elif case == "cache":
        child_env = {**env, "CGDA_JAX_CACHE": "/sys/cgda-cache"}
    else:
        (tmp_path / "empty.toml").write_text("")
        args[1] = tmp_path / "empty.toml"
    for extra in ([], ["--dry-run"]) if case in ("out", "cache") else ([],):
        proc = cgda(child_env, *args, *extra)
        line = one_error_line(proc.stderr)
        assert proc.returncode == 2, proc.stderr
        assert {"seed": "strategy.seed", "interval": "data.interval_s",
                "out": "/sys/cgda-results", "cache": "CGDA_JAX_CACHE",
                "empty": "empty.toml"}[case] in line
        assert not out.exists()


# --------------------------------------------------------------------------- runs
def test_rerun_picks_a_fresh_folder_refuses_a_full_one_and_overwrites_whole(
        env, tmp_path):
    (tmp_path / "exp.toml").write_text(CLEAN.read_text())
    first = cgda(env, "run", "exp.toml", *sets(TINY), cwd=tmp_path)
    assert first.returncode in (0, 1), first.stderr
    assert first.stdout.strip() == str(pathlib.Path("results/exp/report.md"))
    again = cgda(env, "run", "exp.toml", *sets(TINY), cwd=tmp_path)
    assert again.returncode in (0, 1), again.stderr
    assert "results/exp is taken: results go to results/exp-2" in again.stderr
    assert again.stdout.strip() == str(pathlib.Path("results/exp-2/report.md"))
    exp = tmp_path / "results" / "exp"
    (exp / "plots").mkdir()
    (exp / "plots" / "stale.png").write_bytes(b"png")  # an earlier run's plot
    before = snapshot(exp)
    refused = cgda(env, "run", "exp.toml", "--out", exp, *sets(TINY), cwd=tmp_path)
    assert refused.returncode == 2
    assert "not empty" in one_error_line(refused.stderr) and snapshot(exp) == before
    over = cgda(env, "run", "exp.toml", "--out", exp, "--overwrite", "--quiet",
                *sets(TINY + ["strategy.seed=7"]), cwd=tmp_path)
    assert over.returncode in (0, 1) and over.stderr == ""
    assert sorted(snapshot(exp)) == ["arrays.npz", "config.toml", "report.md",
                                     "result.json"]
    assert "seed = 7" in (exp / "config.toml").read_text()
    assert json.loads((exp / "result.json").read_text())["plots"] == []
    assert "stale" not in (exp / "report.md").read_text()
    no_leftovers(exp)


def _wait_for_progress(proc, timeout=240.0) -> list[str]:
    """stderr lines of ``proc`` up to its first progress line (the run is going)."""
    lines, deadline = [], time.monotonic() + timeout
    while time.monotonic() < deadline:
        ready, _, _ = select.select([proc.stderr], [], [], 1.0)
        if not ready:
            continue
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        if " gen " in line:
            return lines
    proc.kill()
    pytest.fail(f"no progress line from the run: {''.join(lines)}")


@pytest.mark.parametrize("sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)],
                         ids=["SIGINT", "SIGTERM"])
def test_interrupted_run_leaves_the_previous_results_untouched(
        sig, status, env, tmp_path):
    out = tmp_path / "out"
    before = previous_run(out)
    proc = subprocess.Popen(
        [sys.executable, "-m", "cgda_jax.cli", "run", str(CLEAN), "--out", str(out),
         "--overwrite", *sets(LONG)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_progress(proc)
        if sig == signal.SIGTERM:  # meanwhile a second run into the folder is refused
            second = cgda(env, "run", CLEAN, "--out", out, "--overwrite", "--quiet",
                          *sets(TINY))
            assert second.returncode == 2
            assert "in use by another run" in one_error_line(second.stderr)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == status, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last == (f"cgda: interrupted ({sig.name}); nothing written ({out} left as "
                    "it was)"), err
    assert snapshot(out) == before
    no_leftovers(out)


def test_two_runs_started_at_once_one_wins_the_other_is_refused(env, tmp_path):
    out = tmp_path / "out"
    procs = {
        who: subprocess.Popen(
            [sys.executable, "-m", "cgda_jax.cli", "run", str(CLEAN), "--out", str(out),
             "--quiet", *sets(TINY + [f'description="run {who}"'])],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for who in "AB"
    }
    done = {who: (p.communicate(timeout=300), p.returncode) for who, p in procs.items()}
    winners = [who for who, (_, code) in done.items() if code in (0, 1)]
    assert len(winners) == 1, done
    (loser,) = set("AB") - set(winners)
    (_, err), code = done[loser]
    line = one_error_line(err)
    assert code == 2 and ("in use by another run" in line or "not empty" in line), line
    # the folder holds the winner's run, every file of it
    assert sorted(snapshot(out)) == ["arrays.npz", "config.toml", "report.md",
                                     "result.json"]
    assert f'description = "run {winners[0]}"' in (out / "config.toml").read_text()
    assert f"run {winners[0]}" in (out / "report.md").read_text()
    no_leftovers(out)


@pytest.mark.parametrize("error", [ZeroDivisionError, ValueError, MemoryError])
def test_unexpected_failure_exits_3_with_the_traceback_in_a_log(
        error, monkeypatch, capsys, tmp_path):
    """Once the checks passed, anything the run raises is a failure (3), a
    ValueError too: a bug, not the user's input."""
    from cgda_jax import strategies

    def broken_run_ie(sim, goal, **kwargs):
        raise error("something inside broke")

    monkeypatch.setattr(strategies, "run_ie", broken_run_ie)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    out = tmp_path / "results" / "out"
    before = previous_run(out)
    code = main(["run", str(CLEAN), "--quiet", "--out", str(out), "--overwrite",
                 *sets(TINY)])
    line = one_error_line(capsys.readouterr().err)
    assert code == 3
    assert line.startswith(f"cgda: error: {error.__name__}: something inside broke "
                           "(traceback in ")
    log = pathlib.Path(line.split("traceback in ")[1].rstrip(")"))
    assert log.parent == tmp_path and "Traceback" in log.read_text()
    assert "broken_run_ie" in log.read_text()
    assert snapshot(out) == before
    no_leftovers(out)


def _tiny_demo(monkeypatch, fail_second=False):
    """``cgda demo`` on two tiny executions (the real demo is test_cli's)."""
    import cgda_jax.experiment as ex

    configs = [load_config(CLEAN, TINY + [f"name={n}"]) for n in ("a", "b")]
    monkeypatch.setattr(ex, "demo_configs", lambda small=False: configs)
    if fail_second:
        real = ex.start_run

        def start_run(cfg, folder, progress_fn=None, built=None):
            if cfg.name == "b":  # while a's figures may still be drawing
                raise KeyboardInterrupt
            return real(cfg, folder, progress_fn, built)

        monkeypatch.setattr(ex, "start_run", start_run)


def test_demo_follows_the_same_folder_rules(monkeypatch, capsys, tmp_path):
    _tiny_demo(monkeypatch)
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--quiet"]) in (0, 1)
    assert main(["demo"]) in (0, 1)
    err = capsys.readouterr().err
    assert "results/demo is taken: results go to results/demo-2" in err
    demo = tmp_path / "results" / "demo"
    assert sorted(snapshot(demo)) == [
        "a/arrays.npz", "a/config.toml", "a/report.md", "a/result.json",
        "b/arrays.npz", "b/config.toml", "b/report.md", "b/result.json",
        "report.md", "result.json"]
    before = snapshot(demo)
    assert main(["demo", "--out", "results/demo"]) == 2
    assert "not empty" in one_error_line(capsys.readouterr().err)
    assert snapshot(demo) == before
    # interrupted half-way: the demo folder stays as it was
    _tiny_demo(monkeypatch, fail_second=True)
    assert main(["demo", "--out", "results/demo", "--overwrite", "--quiet"]) == 130
    err = capsys.readouterr().err
    assert err == ("cgda: interrupted (SIGINT); nothing written (results/demo left "
                   "as it was)\n")
    assert snapshot(demo) == before
    folders = sorted(p.name for p in (tmp_path / "results").iterdir())
    assert folders == ["demo", "demo-2"]  # no temporary folder, no lock left


@pytest.mark.parametrize("bad", ["a", "b"])
def test_demo_checks_side_by_side_and_names_the_bad_config(monkeypatch, capsys,
                                                           tmp_path, bad):
    """The demo's configs are checked two at a time: a bad one is still the error,
    by its name, before anything is written."""
    import cgda_jax.experiment as ex

    configs = [load_config(CLEAN, TINY + [f"name={n}"] + (
        [f"robot.model={tmp_path / 'missing.xml'}"] if n == bad else []))
        for n in ("a", "b")]
    monkeypatch.setattr(ex, "demo_configs", lambda small=False: configs)
    assert main(["demo", "--out", str(tmp_path / "demo"), "--quiet"]) == 2
    assert "missing.xml" in one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "demo").exists()


def _record_drawing(monkeypatch, fail=None):
    """Record which thread finishes each demo experiment (and when its compute
    starts); ``fail``: the experiment whose drawing raises."""
    import threading

    import cgda_jax.experiment.run as run_mod

    events = []
    real_finish, real_start = run_mod.Outputs.finish, run_mod.start_run

    def finish(self):
        events.append(("draw", self.cfg.name, threading.current_thread().name))
        if self.cfg.name == fail:
            raise RuntimeError("the figure broke")
        return real_finish(self)

    def start_run(cfg, folder, progress_fn=None, built=None):
        events.append(("compute", cfg.name, threading.current_thread().name))
        return real_start(cfg, folder, progress_fn, built)

    monkeypatch.setattr(run_mod.Outputs, "finish", finish)
    monkeypatch.setattr("cgda_jax.experiment.start_run", start_run)
    return events


@pytest.mark.parametrize("offscreen_thread", [True, False])
def test_demo_draws_in_a_second_thread_while_the_next_experiment_computes(
        monkeypatch, tmp_path, offscreen_thread):
    import cgda_jax.cli.demo as cli_demo

    _tiny_demo(monkeypatch)
    monkeypatch.setattr(cli_demo, "_offscreen_thread_ok", lambda: offscreen_thread)
    events = _record_drawing(monkeypatch)
    assert main(["demo", "--out", str(tmp_path / "d"), "--quiet"]) in (0, 1)
    main_thread = [e[2] for e in events if e[0] == "compute"]
    drawers = {e[1]: e[2] for e in events if e[0] == "draw"}
    assert set(main_thread) == {"MainThread"} and set(drawers) == {"a", "b"}
    if offscreen_thread:  # a GLFW context would have to stay on the main thread
        assert all(t.startswith("cgda-outputs") for t in drawers.values())
    else:
        assert set(drawers.values()) == {"MainThread"}
        # drawn inline: a is finished before b starts computing
        assert events.index(("draw", "a", "MainThread")) < events.index(
            ("compute", "b", "MainThread"))
    for name in ("a", "b"):  # every experiment's result and report are complete
        result = json.loads((tmp_path / "d" / name / "result.json").read_text())
        assert result["total_time_s"] > 0 and result["plots"] == []
        assert (tmp_path / "d" / name / "report.md").is_file()
    assert json.loads((tmp_path / "d" / "result.json").read_text())[
        "experiments"].keys() == {"a", "b"}


def test_demo_drawing_error_in_the_second_thread_is_one_error_line(
        monkeypatch, capsys, tmp_path):
    import cgda_jax.cli.demo as cli_demo

    _tiny_demo(monkeypatch)
    monkeypatch.setattr(cli_demo, "_offscreen_thread_ok", lambda: True)
    _record_drawing(monkeypatch, fail="a")
    out = tmp_path / "d"
    code = main(["demo", "--out", str(out), "--quiet"])
    assert code not in (0, 1)
    assert "the figure broke" in one_error_line(capsys.readouterr().err)
    assert not out.exists()  # nothing half-written moved into place
    no_leftovers(out)


@pytest.mark.slow  # 25 s in CI; the CLI runs of the same rules stay
def test_run_experiment_api_follows_the_same_rules(tmp_path):
    from cgda_jax.experiment import run_experiment

    cfg = load_config(CLEAN, TINY + [f"output.dir={tmp_path}"])
    first = run_experiment(cfg)
    second = run_experiment(cfg)
    assert first["folder"] == str(tmp_path / "clean_ie")
    assert second["folder"] == str(tmp_path / "clean_ie-2")
    with pytest.raises(FolderError, match="not empty"):
        run_experiment(cfg, tmp_path / "clean_ie")
    again = run_experiment(cfg, tmp_path / "clean_ie", overwrite=True)
    assert again["folder"] == str(tmp_path / "clean_ie")
    assert "folder" not in json.loads((tmp_path / "clean_ie/result.json").read_text())
