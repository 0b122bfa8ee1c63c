"""Folders under every path form (issue 25, part 5): symbolic links followed to
the folder they name (and said), dangling links and loops refused by name,
`ExecutionResult.save` under ``cgda run``'s atomic rules, and every file read back
(`load_run`, `ExecutionResult.load`) checked, its failure naming the file."""

import json
import os
import pathlib

import numpy as np
import pytest

from cgda_jax import load_run
from cgda_jax.cli import main
from cgda_jax.experiment import FolderError, RunFolder, dump_config, load_config
from cgda_jax.results_folder.rules import plan_folder
from cgda_jax.strategies.result import ExecutionResult

REPO = pathlib.Path(__file__).resolve().parents[1]
CLEAN = REPO / "experiments" / "clean_ie.toml"
# quick to check: the tiny arm, no feasibility check, nothing drawn
TINY = ["strategy.feasibility=false", "robot.model=tiny_arm.xml",
        'robot.joints=["yaw", "shoulder", "elbow"]', "robot.fixed={}",
        "output.plots=false", "output.render=false"]


def sets(settings):
    return [a for s in settings for a in ("--set", s)]


def files(folder: pathlib.Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def hidden(folder: pathlib.Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def one_error_line(err: str) -> str:
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cgda: error:"), err
    return lines[0]


def results_folder(folder: pathlib.Path, run: str = "previous") -> dict[str, bytes]:
    folder.mkdir(parents=True)
    (folder / "result.json").write_text(json.dumps({"run": run}))
    (folder / "config.toml").write_text(f'name = "{run}"\n')
    return files(folder)


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CGDA_JAX_CACHE", str(tmp_path_factory.getbasetemp() / "jc"))


# ------------------------------------------------------------------ links
def test_a_link_is_followed_to_its_folder_which_is_replaced_whole(tmp_path):
    real, link = tmp_path / "disk" / "exp", tmp_path / "exp"
    results_folder(real)
    (real / "stale.png").write_bytes(b"old")
    link.symlink_to(real)
    assert plan_folder(link, overwrite=True) == real
    with RunFolder(link, overwrite=True) as rf:
        assert rf.work.parent == real.parent  # written aside the real folder
        (rf.work / "result.json").write_text('{"run": "new"}')
    assert rf.committed and rf.path == real
    assert rf.note == f"{link} is a symbolic link, followed: results go to {real}"
    assert link.is_symlink() and link.resolve() == real  # the link stays a link
    assert files(real) == {"result.json": b'{"run": "new"}'}
    assert hidden(real.parent) == [] and hidden(tmp_path) == []
    # a link to an empty folder is taken without --overwrite
    (tmp_path / "empty").mkdir()
    (tmp_path / "to-empty").symlink_to(tmp_path / "empty")
    with RunFolder(tmp_path / "to-empty") as rf:
        (rf.work / "x").write_text("x")
    assert files(tmp_path / "empty") == {"x": b"x"}
    # without --overwrite a link to a results folder is refused like the folder
    with pytest.raises(FolderError, match=f"{real} is not empty"):
        RunFolder(link).__enter__()


@pytest.mark.parametrize("kind", ["dangling", "loop", "file"])
def test_a_link_to_nothing_or_to_a_file_is_refused_by_name(kind, tmp_path):
    link = tmp_path / "out"
    if kind == "dangling":
        link.symlink_to(tmp_path / "nowhere" / "exp")
        words = ["out is a symbolic link to", "nowhere/exp", "dangling"]
    elif kind == "loop":
        link.symlink_to(tmp_path / "other")
        (tmp_path / "other").symlink_to(link)
        words = ["out is a symbolic link to", "loop of links"]
    else:
        (tmp_path / "file.txt").write_text("mine")
        link.symlink_to(tmp_path / "file.txt")
        words = ["out is a symbolic link to", "file.txt", "not a folder"]
    before = sorted(p.name for p in tmp_path.iterdir())
    for attempt in (lambda: plan_folder(link, overwrite=True),
                    lambda: RunFolder(link, overwrite=True).__enter__()):
        with pytest.raises(FolderError) as err:
            attempt()
        for w in words:
            assert w in str(err.value), err.value
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing created
    assert not (tmp_path / "nowhere").exists()


def test_a_fresh_name_held_by_a_dangling_link_counts_as_taken(tmp_path):
    (tmp_path / "exp").symlink_to(tmp_path / "gone")
    with RunFolder(tmp_path / "exp", fresh=True) as rf:
        (rf.work / "result.json").write_text("{}")
    assert rf.path == tmp_path / "exp-2"
    assert rf.note == f"{tmp_path / 'exp'} is taken: results go to {tmp_path / 'exp-2'}"
    assert (tmp_path / "exp").is_symlink() and not (tmp_path / "gone").exists()


def test_cgda_run_refuses_a_dangling_out_before_running_and_dry_run_follows_a_link(
        tmp_path, capsys):
    link = tmp_path / "out"
    link.symlink_to(tmp_path / "missing")
    for dry in ([], ["--dry-run"]):
        code = main(["run", str(CLEAN), "--quiet", "--out", str(link), *sets(TINY),
                     *dry])
        line = one_error_line(capsys.readouterr().err)
        assert code == 2 and "dangling" in line and str(link) in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    real = tmp_path / "real"
    results_folder(real)
    link.unlink()
    link.symlink_to(real)
    assert main(["run", str(CLEAN), "--dry-run", "--out", str(link), "--overwrite",
                 *sets(TINY)]) == 0
    assert f"results would go to {real}\n" in capsys.readouterr().out


# ------------------------------------------------------------------ save
def result(n_points: int = 3, strategy: str = "ie") -> ExecutionResult:
    rng = np.random.default_rng(n_points)
    goal = rng.normal(size=(n_points, 3))
    return ExecutionResult(
        strategy=strategy, joints=rng.normal(size=(n_points, 3)), features=goal + 0.01,
        goal=goal, point_errors=np.full(n_points, 0.017), fitness_history=np.ones(
            (n_points, 4)), evaluations=96, generations=4, wall_time_s=0.5,
        compile_time_s=2.0, success=True, tolerance=0.02, final_fitness=0.017,
        info={"seed": 0})


def test_save_writes_a_whole_folder_and_refuses_an_existing_one(tmp_path):
    res = result()
    out = res.save(tmp_path / "r")
    assert out == tmp_path / "r" and sorted(files(out)) == ["arrays.npz",
                                                            "result.json"]
    back = ExecutionResult.load(out)
    np.testing.assert_array_equal(back.joints, res.joints)
    assert back.summary() == res.summary()
    before = files(out)
    with pytest.raises(FolderError, match="is not empty.*overwrite"):
        result(5).save(out)
    assert files(out) == before
    # overwrite replaces the folder whole: a run's config.toml does not survive,
    # so no later reader pairs it with the new joints
    results_folder(tmp_path / "run")
    (tmp_path / "run" / "arrays.npz").write_bytes(b"old")
    result(5).save(tmp_path / "run", overwrite=True)
    assert sorted(files(tmp_path / "run")) == ["arrays.npz", "result.json"]
    assert ExecutionResult.load(tmp_path / "run").points == 5
    with pytest.raises(FolderError, match="config.toml missing"):
        load_run(tmp_path / "run")
    # a folder of something else is never replaced
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("precious")
    with pytest.raises(FolderError, match="no result.json"):
        res.save(tmp_path / "mine", overwrite=True)
    assert files(tmp_path / "mine") == {"thesis.tex": b"precious"}
    # through a link: followed
    (tmp_path / "link").symlink_to(tmp_path / "r")
    assert res.save(tmp_path / "link", overwrite=True) == tmp_path / "r"
    assert (tmp_path / "link").is_symlink()
    assert hidden(tmp_path) == []


def test_save_that_fails_half_way_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    out = tmp_path / "r"
    result().save(out)
    before = files(out)

    def broken_savez(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", broken_savez)
    with pytest.raises(OSError, match="No space left"):
        result(5).save(out, overwrite=True)
    assert files(out) == before and hidden(tmp_path) == []
    with pytest.raises(OSError):
        result(5).save(tmp_path / "new")
    assert not (tmp_path / "new").exists() and hidden(tmp_path) == []


# ------------------------------------------------------------------ reading back
@pytest.fixture
def run_folder(tmp_path) -> pathlib.Path:
    """An execution run's folder as ``cgda run`` writes it (made by hand, no run)."""
    cfg = load_config(CLEAN, TINY)
    res = result(4)
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "config.toml").write_text(dump_config(cfg))
    summary = res.summary() | {
        "kind": "execution", "name": cfg.name, "feature_names": ["x", "y", "z"],
        "feature_labels": ["X [m]", "Y [m]", "Z [m]"], "error_unit": "m",
        "build": {"waypoint_s": 1.0}, "plots": [], "total_time_s": 3.0}
    (folder / "result.json").write_text(json.dumps(summary))
    np.savez(folder / "arrays.npz", **res.arrays(), knot_times=np.arange(4.0),
             knots=res.goal)  # a run's folder holds more than the strategy's arrays
    return folder


def edit_json(path: pathlib.Path, **changes) -> None:
    data = json.loads(path.read_text())
    data.update(changes)
    path.write_text(json.dumps(data))


def test_a_well_formed_folder_loads(run_folder):
    run = load_run(run_folder)
    assert run.kind == "execution" and run.arrays["goal"].shape == (4, 3)
    assert run.execution_result().points == 4


def truncate(path: pathlib.Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def single_array(path: pathlib.Path) -> None:
    with open(path, "wb") as f:  # a .npy file under the name arrays.npz
        np.save(f, np.zeros(3))


CORRUPT = {
    # case -> (how, words the error must hold)
    "npz-truncated": (lambda f: truncate(f / "arrays.npz"),
                      ["arrays.npz", "damaged or truncated"]),
    "npz-not-an-archive": (lambda f: single_array(f / "arrays.npz"),
                           ["arrays.npz", "not an archive"]),
    "npz-array-missing": (lambda f: np.savez(f / "arrays.npz", joints=np.zeros((4, 3))),
                          ["arrays.npz", "missing", "features"]),
    "json-list": (lambda f: (f / "result.json").write_text("[1, 2]"),
                  ["result.json", "expected a JSON object", "a list"]),
    "json-not-json": (lambda f: (f / "result.json").write_text("{'kind': 1"),
                      ["result.json", "not valid JSON"]),
    "json-wrong-type": (lambda f: edit_json(f / "result.json", generations="4"),
                        ["result.json", "'generations' must be int", '"4"']),
    "json-wrong-list": (lambda f: edit_json(f / "result.json", point_errors=[1, "x"]),
                        ["result.json", "'point_errors'", "list[number|null]"]),
    "json-bool-as-int": (lambda f: edit_json(f / "result.json", success=1),
                         ["result.json", "'success' must be bool"]),
    "json-key-missing": (lambda f: (f / "result.json").write_text('{"kind": '
                                                                  '"execution"}'),
                         ["result.json", "missing", "'name'"]),
    "json-trials-kind": (lambda f: edit_json(f / "result.json", kind="trials"),
                         ["result.json", "'trials'", "trials.json"]),
    "files-of-two-runs": (lambda f: np.savez(f / "arrays.npz", **result(6).arrays()),
                          ["result.json has 4 points", "a goal of 6 points",
                           "different runs"]),
    "config-of-another-kind": (lambda f: (f / "config.toml").write_text(
        dump_config(load_config(None, ["kind=recognition"]))),
                               ["config.toml is a recognition", "execution run"]),
}


@pytest.mark.parametrize("case", sorted(CORRUPT))
def test_every_file_read_back_names_itself_in_its_error(case, run_folder, capsys):
    how, words = CORRUPT[case]
    how(run_folder)
    with pytest.raises(FolderError) as err:
        load_run(run_folder)
    for w in words:
        assert w in str(err.value), err.value
    # cgda plot reads the folder the same way: one line, status 2
    assert main(["plot", str(run_folder), "--quiet", "--no-cache"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert words[0] in line, line


@pytest.mark.parametrize("case", ["npz-truncated", "json-list", "json-wrong-type",
                                  "json-key-missing", "npz-array-missing"])
def test_execution_result_load_checks_the_same_files(case, tmp_path):
    out = result().save(tmp_path / "r")
    how, words = CORRUPT[case]
    how(out)
    with pytest.raises(FolderError) as err:
        ExecutionResult.load(out)
    assert str(err.value).startswith(str(out / words[0])), err.value


def test_execution_result_load_checks_array_shapes(tmp_path):
    out = result().save(tmp_path / "r")
    arrays = result().arrays() | {"point_errors": np.zeros(7)}
    np.savez(out / "arrays.npz", **arrays)
    with pytest.raises(FolderError, match="arrays.npz: point_errors has 7 values "
                       "for a goal of 3 points"):
        ExecutionResult.load(out)
    np.savez(out / "arrays.npz", **(arrays | {"point_errors": np.zeros((3, 1))}))
    with pytest.raises(FolderError, match=r"point_errors has shape \(3, 1\)"):
        ExecutionResult.load(out)


def test_a_non_finite_value_written_as_null_reads_back(tmp_path):
    res = result()
    res.final_fitness = float("inf")
    out = res.save(tmp_path / "r")
    edit_json(out / "result.json", final_fitness=None, max_point_error=None)
    assert ExecutionResult.load(out).final_fitness == float("inf")
    assert os.path.exists(out / "arrays.npz")
